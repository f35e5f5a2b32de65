#!/usr/bin/env python3
"""Per-frame cost of the LK front end (rectify / pyramid / LK / detect / stereo) next to a floor.

    python scripts/bench_frontend.py [--data ../shared/data] [--keyframe-every 5] [--repeat 2]
                                     [--no-strategies]

Floor, measured in the same run on the same frames: ``cv2.imread`` of the two images plus one plain
``cv2.calcOpticalFlowPyrLK`` (same window, levels and criteria) of the points ``track()`` got.  The
front end is fed frames already in memory, so its numbers exclude reading.  Target (front-end issue):
on euroc_micro, ``track()`` and ``keyframe()`` well under 10 ms each.

The second part measures the stereo search strategies on real frames (the numbers quoted in
``gevi_cli/frontend/stereo.py``): matches per keyframe and how many agree within 1 px with an OpenCV
SGBM disparity of the same rectified pair (an independent dense method, used as the reference).
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import cv2
import numpy as np

from gevi_cli.datasets import open_sequence
from gevi_cli.frontend.config import LK_EPS, LK_ITERS, LK_LEVELS, FrontendConfig
from gevi_cli.frontend.grid import GridDetector
from gevi_cli.frontend.image_frontend import STAGES, ImageFrontEnd
from gevi_cli.frontend.klt import build_pyramid
from gevi_cli.frontend.rectify import Rectifier
from gevi_cli.frontend.stereo import match_stereo

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
SEQUENCES = {"euroc_micro": "euroc_micro", "kitti06_head": "kitti06_head/dataset/sequences/06"}


def _image_paths(seq):
    """Left/right file names of a reader (EuRoC and KITTI readers keep them as _left/_right)."""
    return list(seq._left), list(seq._right)


def bench_sequence(path: Path, every: int, repeat: int) -> dict:
    seq = open_sequence(path)
    frames = list(seq.frames())
    lefts, rights = _image_paths(seq)
    cfg = FrontendConfig()
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, LK_ITERS, LK_EPS)
    for _ in range(repeat):  # the last pass is reported: caches and allocator are warm
        fe = ImageFrontEnd(seq.calibration, cfg)
        rows = {"track": [], "keyframe": []}
        totals = {"track": [], "keyframe": []}
        floor_read, floor_lk, n_feat, n_stereo = [], [], [], []
        for i, frame in enumerate(frames):
            uv_before = fe.uv.astype(np.float32).reshape(-1, 1, 2)
            t0 = time.perf_counter()
            obs = fe.track(frame)
            dt = time.perf_counter() - t0
            if i > 0:  # the first call detects instead of tracking
                rows["track"].append([fe.timings[s] for s in STAGES])
                totals["track"].append(dt)
                n_feat.append(len(uv_before))
                t0 = time.perf_counter()
                cv2.imread(lefts[i], cv2.IMREAD_GRAYSCALE)
                cv2.imread(rights[i], cv2.IMREAD_GRAYSCALE)
                floor_read.append(time.perf_counter() - t0)
                if len(uv_before):
                    t0 = time.perf_counter()
                    cv2.calcOpticalFlowPyrLK(frames[i - 1].left, frame.left, uv_before, None,
                                             winSize=(cfg.lk_window,) * 2, maxLevel=LK_LEVELS, criteria=crit)
                    floor_lk.append(time.perf_counter() - t0)
            if i % every == 0:
                t0 = time.perf_counter()
                st = fe.keyframe(frame)
                totals["keyframe"].append(time.perf_counter() - t0)
                rows["keyframe"].append([fe.timings[s] for s in STAGES])
                n_stereo.append(len(st))
        del obs
    return {"rows": {k: np.array(v) * 1e3 for k, v in rows.items()},
            "totals": {k: np.array(v) * 1e3 for k, v in totals.items()},
            "read": np.array(floor_read) * 1e3, "lk": np.array(floor_lk) * 1e3,
            "n_feat": np.array(n_feat), "n_stereo": np.array(n_stereo), "frames": len(frames),
            "size": frames[0].left.shape}


def print_timings(results: dict, every: int):
    print(f"Front-end cost per call, median ms (mean in brackets); keyframe every {every} frames; "
          "default FrontendConfig")
    head = f"{'sequence':<14}{'call':<10}" + "".join(f"{s:>15}" for s in STAGES) + f"{'total':>15}"
    print(head)
    print("-" * len(head))
    for name, r in results.items():
        for call in ("track", "keyframe"):
            m, tot = r["rows"][call], r["totals"][call]
            cells = "".join(f"{np.median(m[:, j]):7.2f} ({np.mean(m[:, j]):5.2f})" for j in range(len(STAGES)))
            print(f"{name:<14}{call:<10}{cells}{np.median(tot):7.2f} ({np.mean(tot):5.2f})")
    print()
    print(f"{'sequence':<14}{'size':>10}{'feat/frame':>11}{'stereo/kf':>10}{'imread x2':>11}"
          f"{'plain LK':>10}{'floor':>8}{'track()':>9}{'track/LK':>9}{'keyframe()':>11}")
    for name, r in results.items():
        h, w = r["size"]
        read, lk = np.median(r["read"]), np.median(r["lk"])
        tr, kf = np.median(r["totals"]["track"]), np.median(r["totals"]["keyframe"])
        print(f"{name:<14}{f'{w}x{h}':>10}{np.median(r['n_feat']):>11.0f}{np.median(r['n_stereo']):>10.0f}"
              f"{read:>11.2f}{lk:>10.2f}{read + lk:>8.2f}{tr:>9.2f}{tr / lk:>9.2f}{kf:>11.2f}")
    print("floor = imread of both images + one plain calcOpticalFlowPyrLK of the same points (ms); "
          "track() gets images in memory, so compare track() with 'plain LK' and imread+track() with 'floor'.")


def sgbm_disparity(left: np.ndarray, right: np.ndarray, max_disp: int) -> np.ndarray:
    n = int(np.ceil(max_disp / 16.0)) * 16
    sgbm = cv2.StereoSGBM_create(0, n, 5, P1=8 * 25, P2=32 * 25, uniquenessRatio=10,
                                 speckleWindowSize=100, speckleRange=2, mode=cv2.STEREO_SGBM_MODE_HH)
    return sgbm.compute(left, right).astype(np.float32) / 16.0


def strategies(path: Path, frame_ids: list[int], max_disp: int):
    """Stereo strategies on the keyframes ``frame_ids`` of one sequence (default config)."""
    seq = open_sequence(path)
    cfg = FrontendConfig()
    rect = Rectifier(seq.calibration)
    cam = rect.camera
    det = GridDetector(cfg)
    data = []
    for i, frame in enumerate(seq.frames()):
        if i in frame_ids:
            left, right = rect.rectify(frame.left, frame.right)
            data.append((build_pyramid(left, cfg), build_pyramid(right, cfg), det(left, None),
                         sgbm_disparity(left, right, max_disp)))
    variants = {  # name: (rungs, use the previous keyframe's median disparity, gain compensation)
        "zero start, 1 try": (1, False, True),
        "prior start, 1 try": (1, True, True),
        "ladder from prior (product)": (3, True, True),
        "ladder, no gain comp.": (3, True, False),
    }
    print(f"{'strategy':<30}{'matched':>9}{'SGBM-agree':>11}{'disagree':>9}{'agree d>40':>11}{'ms':>7}")
    for name, (rungs, use_prior, gain) in variants.items():
        prior, acc, t = None, np.zeros(4), 0.0
        for pl, pr, uv, disp in data:
            t0 = time.perf_counter()
            uv_r, ok = match_stereo(pl, pr, uv, cam, cfg, disparity_prior=prior if use_prior else None,
                                    rungs=rungs, gain=gain)
            t += time.perf_counter() - t0
            d = uv[:, 0] - uv_r[:, 0]
            ref = disp[uv[:, 1].astype(int), uv[:, 0].astype(int)]
            valid = ok & (ref > 0)
            agree = valid & (np.abs(d - ref) < 1.0)
            acc += [ok.sum(), agree.sum(), (valid & ~agree).sum(), (agree & (d > 40)).sum()]
            if ok.any():
                prior = float(np.median(d[ok]))
        acc /= len(data)
        print(f"{name:<30}{acc[0]:>9.1f}{acc[1]:>11.1f}{acc[2]:>9.1f}{acc[3]:>11.1f}{t / len(data) * 1e3:>7.2f}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(DATA), help="the shared data folder (default ../shared/data)")
    parser.add_argument("--keyframe-every", type=int, default=5)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--no-strategies", action="store_true", help="skip the stereo-strategy measurement")
    args = parser.parse_args()
    data = Path(args.data)
    load0 = os.getloadavg()[0]
    results = {}
    for name, rel in SEQUENCES.items():
        if not (data / rel).exists():
            print(f"{name}: not found under {data}, skipped")
            continue
        results[name] = bench_sequence(data / rel, args.keyframe_every, args.repeat)
    print_timings(results, args.keyframe_every)
    load1 = os.getloadavg()[0]
    print(f"1-min load average {load0:.2f} before, {load1:.2f} after on {os.cpu_count()} CPUs"
          + ("  (other work was running: the ms are upper bounds)" if max(load0, load1) > 0.5 * (os.cpu_count() or 1) else ""))
    if args.no_strategies:
        return
    for name, frame_ids, max_disp in (("kitti06_head", list(range(0, 50, 5)), 192),
                                      ("euroc_micro", list(range(0, 95, 10)), 112)):
        if name in results:
            print(f"\nStereo strategies on {name}, keyframes {frame_ids[0]}, {frame_ids[1]}, .. {frame_ids[-1]} "
                  "(per-keyframe means; agree = |d - d_SGBM| < 1 px where SGBM is valid)")
            strategies(data / SEQUENCES[name], frame_ids, max_disp)


if __name__ == "__main__":
    main()
