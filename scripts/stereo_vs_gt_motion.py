"""Where a stereo-(inertial) run loses its scale, against the ground truth (docs/studies/euroc_mh01.md).

    python scripts/stereo_vs_gt_motion.py SEQ_DIR [--gt FILE] [--method cfo] [TRAJ ...]

Runs the method on the sequence with nothing applied from the disparity self-calibration and keeps every
tracked step's keyframe points (left normalized pixels, raw disparities) and their tracks in the frame.
Prints (1) per stereo-depth band, the points' inverse depth from the two views with the ground-truth
relative pose (metric, linear along the translation, weighted by its information) over their stereo
inverse depth: 1 where the stereo depths are right, below 1 where they are short; and the line fitted
through all points as a disparity offset (px); (2) for the run's trajectory and each TRAJ (body poses,
e.g. another system's), the sum over frame pairs 1 / 5 / 20 apart of the rotation angle and of the
translation length over the ground truth's, and per axis of the camera.  Frames: the rectified left camera (``T_B_C0`` of the
rectified pair), metres; ground truth: body poses.  About a minute on euroc_mh01_head.
"""
from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from gevi_cli.pipelines.disparity_offset import DisparityOffset
from gevi_cli.run.assemble import build
from gevi_cli.run.folder import RunStatus
from gevi_cli.run.pipeline import run_and_evaluate
from gevi_cli.run.session import RunRequest, resolve
from gevi_cli.trajectory import read_trajectory

BANDS = [(0, 2), (2, 3), (3, 5), (5, 8), (8, 12), (12, 20), (20, 60)]


class _Recorder(DisparityOffset):
    """Keeps what each step observed; estimates and applies nothing."""

    def __init__(self):
        super().__init__()
        self.seen = []

    def observe(self, index, keyframe, z, q, raw_disparity_px, T_ck, fx, baseline_m):
        self.seen.append((index, keyframe, z.copy(), q.copy(), raw_disparity_px.copy()))


def _rotations(traj) -> Rotation:
    q = traj.quat_wxyz
    return Rotation.from_quat(np.column_stack([q[:, 1:], q[:, :1]]))


def _inverse_depth(z, q, R, t):
    """Inverse depth (1/m) of keyframe rays ``z`` seen at ``q`` after the metric pose (R, t), by Gauss-Newton
    along the translation from 0, and its information |d projection / d rho|^2 (normalized units)."""
    a = np.column_stack([z, np.ones(len(z))]) @ R.T
    rho = np.zeros(len(z))
    for _ in range(3):
        p = a + rho[:, None] * t
        g = np.column_stack([t[0] / p[:, 2] - p[:, 0] * t[2] / p[:, 2] ** 2,
                             t[1] / p[:, 2] - p[:, 1] * t[2] / p[:, 2] ** 2])
        r = q - p[:, :2] / p[:, 2:3]
        gg = np.einsum("ij,ij->i", g, g)
        rho = rho + np.einsum("ij,ij->i", g, r) / np.maximum(gg, 1e-300)
    return rho, gg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sequence")
    ap.add_argument("--gt", default=None)
    ap.add_argument("--method", default="cfo")
    ap.add_argument("--min-baseline-m", type=float, default=0.03, help="steps shorter than this are skipped")
    ap.add_argument("traj", nargs="*", help="more body trajectories to compare step by step")
    a = ap.parse_args()

    resolved = resolve(RunRequest(sequence=a.sequence, method=a.method, quiet=True, groundtruth=a.gt))
    frontend, odometry = build(resolved.source, resolved.kind, resolved.cfg, a.method)
    odometry.disparity_offset = recorder = _Recorder()
    result = run_and_evaluate(resolved, RunStatus(method=a.method), pipeline=(frontend, odometry))  # one pair: no restart
    cam, stamps = frontend.camera, resolved.source.stamps_ns
    gt = result.groundtruth
    fb = cam.fx * cam.baseline
    t_gt = gt.t_ns.astype(np.float64)
    slerp = Slerp(t_gt, _rotations(gt))

    def T_W_C(t_ns):
        T = np.eye(4)
        T[:3, :3] = slerp([float(t_ns)]).as_matrix()[0]
        T[:3, 3] = [np.interp(float(t_ns), t_gt, gt.positions[:, k]) for k in range(3)]
        return T @ cam.T_B_C0

    rows = []
    for index, kf, z, q, raw in recorder.seen:
        T_ck = np.linalg.inv(T_W_C(stamps[index])) @ T_W_C(stamps[kf])
        if np.linalg.norm(T_ck[:3, 3]) < a.min_baseline_m:
            continue
        rho, info = _inverse_depth(z, q, T_ck[:3, :3], T_ck[:3, 3])
        ok = np.isfinite(rho) & np.isfinite(raw) & (raw > 0)
        rows.append(np.column_stack([rho[ok], raw[ok] / fb, info[ok]]))
    R = np.concatenate(rows)
    rho_gt, rho_st, w = R[:, 0], R[:, 1], R[:, 2]
    depth = 1.0 / rho_st
    print(f"(1) {len(R)} point observations over {len(rows)} steps of at least {a.min_baseline_m:g} m; fx b = {fb:.3f} px m")
    print("| stereo depth [m] | points | two-view (GT) / stereo inverse depth |")
    print("|---|---|---|")
    for lo, hi in BANDS:
        m = (depth >= lo) & (depth < hi)
        if m.sum() < 30:
            continue
        ratio = np.sum(w[m] * rho_gt[m] * rho_st[m]) / np.sum(w[m] * rho_st[m] ** 2)
        res = rho_gt[m] - ratio * rho_st[m]
        se = np.sqrt(np.sum((w[m] * res * rho_st[m]) ** 2)) / np.sum(w[m] * rho_st[m] ** 2)
        print(f"| {lo}-{hi} | {m.sum()} | {ratio:.4f} ± {se:.4f} |")
    X = np.column_stack([rho_st, np.ones(len(R))])
    slope, icpt = np.linalg.solve((X * w[:, None]).T @ X, (X * w[:, None]).T @ rho_gt)
    print(f"line through all: slope {slope:.4f}, as a disparity offset {icpt * fb / slope:+.3f} px")

    print("\n(2) rotation angle and translation length over the ground truth's, frame pairs k apart")
    slr = Slerp(t_gt, _rotations(gt))
    trajs = [("this run", result.trajectory)] + [(p, read_trajectory(p, name="e", frame="body")) for p in a.traj]
    print("| trajectory | k | rotation est / GT | translation est / GT | per camera axis x / y / z |")
    print("|---|---|---|---|---|")
    for name, est in trajs:
        t = est.t_ns.astype(np.float64)
        keep = (t >= t_gt[0]) & (t <= t_gt[-1])
        t, Re, pe = t[keep], _rotations(est)[np.flatnonzero(keep)], est.positions[keep]
        Rg = slr(t)
        pg = np.column_stack([np.interp(t, t_gt, gt.positions[:, k]) for k in range(3)])
        R_BC = Rotation.from_matrix(cam.T_B_C0[:3, :3])
        for k in (1, 5, 20):
            ag, ae = (Rg[:-k].inv() * Rg[k:]).magnitude(), (Re[:-k].inv() * Re[k:]).magnitude()
            tg, te = np.linalg.norm(pg[k:] - pg[:-k], axis=1), np.linalg.norm(pe[k:] - pe[:-k], axis=1)
            mr, mt = ag > np.radians(0.3), tg > 0.005 * k
            # per axis of the rectified left camera: the estimate's rotation vector on the ground truth's
            vg = (R_BC.inv() * (Rg[:-k].inv() * Rg[k:]) * R_BC).as_rotvec()
            ve = (R_BC.inv() * (Re[:-k].inv() * Re[k:]) * R_BC).as_rotvec()
            axes = " / ".join(f"{np.sum(ve[:, i] * vg[:, i]) / np.sum(vg[:, i] ** 2):.4f}" for i in range(3))
            print(f"| {name} | {k} | {ae[mr].sum() / ag[mr].sum():.4f} | {te[mt].sum() / tg[mt].sum():.4f} | {axes} |")


if __name__ == "__main__":
    main()
