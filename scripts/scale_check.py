#!/usr/bin/env python3
"""The scale of a run, next to an independent stereo check: OpenCV SGBM depth + ORB + PnP.

    python scripts/scale_check.py SEQUENCE [--run RUN_DIR ...] [--stride K] [--max-depth M ...]

SEQUENCE is a KITTI odometry sequence folder (``image_0``, ``image_1``, ``calib.txt``, ``times.txt``;
ground truth at ``../../poses/<name>.txt``).  The scale of a trajectory is the median, over its steps,
of the estimated step length over the ground-truth one (1 = right scale; steps shorter than 0.1 m are
left out).  Each ``--run`` (a ``gevi run`` folder of the same sequence and stride: ``traj_cam0_kitti.txt``)
is read; the independent check estimates each step on its own, with nothing of gevi: SGBM disparity
of frame a (OpenCV, semi-global block matching), ORB features of frames a and b matched by Hamming
distance with a ratio test, their 3-D points in frame a from the SGBM depth (only where it is at most
``--max-depth``), and ``cv2.solvePnPRansac`` + LM refinement on frame b's pixels.  A scale error that
shows in gevi's runs but not in the check is gevi's; one in both comes from the images or calibration.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from gevi_cli.datasets.kitti import read_calib


def _calib(seq: Path) -> tuple[np.ndarray, float]:
    """(K 3x3, baseline m) of the rectified pair, from calib.txt's P0 and P1 (gevi's KITTI reader)."""
    P = read_calib(seq / "calib.txt")
    return P["P0"][:, :3], -P["P1"][0, 3] / P["P1"][0, 0]


def _gt_positions(seq: Path, stride: int) -> np.ndarray:
    poses = np.loadtxt(seq.parent.parent / "poses" / f"{seq.name}.txt").reshape(-1, 3, 4)
    return poses[::stride, :, 3]


def step_ratios(est: np.ndarray, gt: np.ndarray, min_step_m: float = 0.1) -> np.ndarray:
    """Estimated over ground-truth step lengths (consecutive rows of (n, 3) positions)."""
    n = min(len(est), len(gt))
    g = np.linalg.norm(np.diff(gt[:n], axis=0), axis=1)
    e = np.linalg.norm(np.diff(est[:n], axis=0), axis=1)
    ok = g >= min_step_m
    return e[ok] / g[ok]


def sgbm_pnp_steps(seq: Path, stride: int, max_depth_m: float) -> np.ndarray:
    """Step lengths (m) between consecutive used frames from SGBM depth + ORB matches + PnP (NaN: failed)."""
    K, baseline = _calib(seq)
    f = K[0, 0]
    left = sorted((seq / "image_0").glob("*.png"))[::stride]
    right = sorted((seq / "image_1").glob("*.png"))[::stride]
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=128, blockSize=5, P1=8 * 25, P2=32 * 25,
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    orb = cv2.ORB_create(3000)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    steps = []
    for a in range(len(left) - 1):
        la, ra = cv2.imread(str(left[a]), 0), cv2.imread(str(right[a]), 0)
        lb = cv2.imread(str(left[a + 1]), 0)
        disp = sgbm.compute(la, ra).astype(np.float32) / 16.0  # SGBM returns 4 fractional bits
        ka, da = orb.detectAndCompute(la, None)
        kb, db = orb.detectAndCompute(lb, None)
        pairs = [m[0] for m in matcher.knnMatch(da, db, k=2) if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
        ua = np.array([ka[m.queryIdx].pt for m in pairs])
        ub = np.array([kb[m.trainIdx].pt for m in pairs])
        d = disp[np.round(ua[:, 1]).astype(int), np.round(ua[:, 0]).astype(int)]
        z = np.where(d > 0, f * baseline / np.maximum(d, 1e-6), np.inf)
        ok = z <= max_depth_m
        X = np.column_stack([(ua[ok, 0] - K[0, 2]) * z[ok] / f, (ua[ok, 1] - K[1, 2]) * z[ok] / K[1, 1], z[ok]])
        if len(X) < 6:
            steps.append(np.nan)
            continue
        found, rvec, tvec, inl = cv2.solvePnPRansac(X, ub[ok], K, None, reprojectionError=1.0, iterationsCount=500,
                                                   flags=cv2.SOLVEPNP_SQPNP)
        if not found or inl is None or len(inl) < 6:
            steps.append(np.nan)
            continue
        rvec, tvec = cv2.solvePnPRefineLM(X[inl[:, 0]], ub[ok][inl[:, 0]], K, None, rvec, tvec)
        R, _ = cv2.Rodrigues(rvec)
        steps.append(float(np.linalg.norm(-R.T @ tvec.ravel())))  # frame b's centre in frame a
    return np.array(steps)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence", type=Path)
    ap.add_argument("--run", type=Path, action="append", default=[], help="gevi run folder (repeatable)")
    ap.add_argument("--stride", type=int, default=1)
    ap.add_argument("--max-depth", type=float, action="append", help="SGBM points up to this depth (m; repeatable)")
    args = ap.parse_args()
    gt = _gt_positions(args.sequence, args.stride)
    g = np.linalg.norm(np.diff(gt, axis=0), axis=1)
    print(f"{args.sequence} stride {args.stride}: {len(gt)} frames, ground-truth step {np.median(g):.2f} m (median)")
    print("| trajectory | median step ratio | p10 | p90 | steps |")
    print("|---|---|---|---|---|")
    for run in args.run:
        est = np.loadtxt(run / "traj_cam0_kitti.txt").reshape(-1, 3, 4)[:, :, 3]
        r = step_ratios(est, gt)
        print(f"| {run} | {np.median(r):.4f} | {np.percentile(r, 10):.4f} | {np.percentile(r, 90):.4f} | {len(r)} |")
    for depth in args.max_depth or [40.0, 100.0]:
        steps = sgbm_pnp_steps(args.sequence, args.stride, depth)
        ok = np.isfinite(steps) & (g[:len(steps)] >= 0.1)
        r = steps[ok] / g[:len(steps)][ok]
        print(f"| SGBM + ORB + PnP, depth <= {depth:g} m | {np.median(r):.4f} | {np.percentile(r, 10):.4f} | "
              f"{np.percentile(r, 90):.4f} | {ok.sum()} |")


if __name__ == "__main__":
    main()
