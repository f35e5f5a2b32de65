#!/usr/bin/env python3
"""Benchmark of the l1-PnP pre-filter (spec 5.5): HiGHS LP vs IRLS + exact vertex polish.

1. Milliseconds per call of ``pnp_l1_filter(p, q, method=...)`` (the call the odometry makes every
   frame: l1 pose + reprojection errors + drop rule) at n = 100, 200, 500, 1000, for "lp" and
   "irls" (and plain IRLS without the polish, for reference), measured in the same run on the
   same inputs, interleaved: median over ``--repeat`` timings of ``--number`` calls, over
   ``--scenes`` synthetic scenes per n (spec 5.6 scenes, triangulated keyframe points, 7 % gross
   outliers in the current frame as in tests/estimators/test_pnp6.py).
2. Agreement of the keep-masks on the real KITTI 04 tracks (``../shared/data/cfo_kitti04``, parsed
   as scripts/cfo_kitti04.py does: 0.5-40 m depth gate, tracks matched by id to the latest
   keyframe), every frame of the gray and colour sequences: total agreement, worst frame, frames
   whose polish ended with an optimality certificate, pivots, time per frame.

Timing is not a test (machine dependent); tests/realdata/test_l1_fast.py asserts the agreement.

    python scripts/bench_l1.py [--repeat 9] [--number 3] [--scenes 5]
"""
from __future__ import annotations

import argparse
import math
import time
import timeit
from pathlib import Path

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.estimators.pnp6 import build_H, l1_regression, pnp_l1_filter
from gevi_cli.studies import simulation as sim

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "cfo_kitti04"
FOLDER = {"gray": ("ov2slam_data_kitti_04_gray", "gray_calib.txt"), "color": ("ov2slam_data_kitti_04", "colour_calib.txt")}


def synthetic(n, rng):
    s = sim.scene6(rng, n)
    p, _ = est.triangulate(s.z, s.y, s.R_rl, s.t_rl, s.sigma**2)
    q = s.q.copy()
    k = int(round(0.07 * n))
    bad = rng.choice(n, k, replace=False)
    q[bad] += rng.choice([-1, 1], (k, 2)) * rng.uniform(0.05, 0.2, (k, 2))
    return p, q


def kitti04_frames(cameras, min_depth=0.5, max_depth=40.0):
    """(frame, p, q) per frame of the export: keyframe points (depth gate) matched by id to the
    frame's tracks that OV2SLAM kept (its outlier flag 0), through the pipeline's own reader."""
    from gevi_cli.datasets.track_export import open_track_export
    from gevi_cli.frontend.export import ExportFrontEnd
    from gevi_cli.pipelines.keyframe import make_keyframe

    folder, calib = FOLDER[cameras]
    if not (DATA / "data" / "ov2slam_data" / folder).is_dir():
        return None
    export = open_track_export(DATA / "data" / "ov2slam_data" / folder, DATA / "calib" / calib)
    fe = ExportFrontEnd(export, use_outlier_flags=True)
    frames, kf = [], None
    for frame in export.frames():
        obs = fe.track(frame)
        if kf is not None:
            _, i_kf, i_tr = np.intersect1d(kf.ids, obs.ids, return_indices=True)
            frames.append((frame.index, kf.p[i_kf], fe.camera.normalize(obs.uv[i_tr])))
        if frame.stereo is not None:
            kf = make_keyframe(frame.index, frame.t_ns, np.eye(4), fe.keyframe(frame), fe.camera, min_depth, max_depth)
    return frames


def timing_table(a):
    variants = {
        "lp": lambda p, q: pnp_l1_filter(p, q, method="lp"),
        "irls": lambda p, q: pnp_l1_filter(p, q, method="irls"),
        "plain irls": lambda p, q: pnp_l1_filter_plain(p, q),
    }
    print(f"pnp_l1_filter, ms per call (median over {a.scenes} scenes x {a.repeat} repeats of {a.number} calls; "
          f"7 % gross outliers)")
    print(f"{'n':>6s}{'lp':>9s}{'irls':>9s}{'speed-up':>10s}{'plain irls':>12s}{'pivots':>8s}{'same mask':>11s}")
    for n in (100, 200, 500, 1000):
        rng = np.random.default_rng(n)
        scenes = [synthetic(n, rng) for _ in range(a.scenes)]
        times = {k: [] for k in variants}
        for p, q in scenes:
            for _ in range(a.repeat):  # interleaved, so drifts of the machine hit all variants alike
                for name, fn in variants.items():
                    times[name].append(timeit.timeit(lambda: fn(p, q), number=a.number) / a.number * 1e3)
        pivots = [l1_regression(*build_H(p, q)[:2]).pivots for p, q in scenes]
        same = all(np.array_equal(variants["lp"](p, q), variants["irls"](p, q)) for p, q in scenes)
        med = {k: float(np.median(v)) for k, v in times.items()}
        print(f"{n:6d}{med['lp']:9.2f}{med['irls']:9.3f}{med['lp'] / med['irls']:9.1f}x{med['plain irls']:12.3f}"
              f"{np.median(pivots):8.0f}{'yes' if same else 'NO':>11s}")


def pnp_l1_filter_plain(p, q, drop=0.10):
    """The drop rule of pnp_l1_filter on plain IRLS (no polish), for reference only."""
    H, d, pbar = build_H(p, q)
    R, t = est.recover_pose(l1_regression(H, d, polish=False).theta, pbar)
    X = p @ R.T + t
    err = np.full(len(p), np.inf)
    front = X[:, 2] > 0
    err[front] = np.linalg.norm(q[front] - est.project(X[front]), axis=1)
    k = int(math.ceil(drop * len(p) - 1e-12))
    keep = np.ones(len(p), dtype=bool)
    keep[np.argsort(err, kind="stable")[len(p) - k:]] = False
    return keep


def agreement_table():
    print("\nKITTI 04 (cfo_kitti04 tracks, every frame): keep-mask agreement with the LP")
    print(f"{'cameras':8s}{'frames':>7s}{'points':>8s}{'n median':>9s}{'irls':>10s}{'worst frame':>17s}"
          f"{'certified':>11s}{'pivots med/max':>16s}{'plain irls':>12s}{'plain worst':>12s}"
          f"{'lp ms':>8s}{'irls ms':>9s}")
    for cameras in ("gray", "color"):
        frames = kitti04_frames(cameras)
        if frames is None:
            print(f"{cameras:8s} skipped: {DATA} is absent")
            continue
        agree = plain_agree = total = certified = 0
        worst, plain_worst, pivots, t_lp, t_irls, errors = (2.0, -1), 2.0, [], 0.0, 0.0, []
        for f, p, q in frames:
            outcome = []
            for method in ("lp", "irls"):
                t0 = time.perf_counter()
                try:
                    outcome.append(pnp_l1_filter(p, q, method=method))
                except est.EstimatorError as err:
                    outcome.append(type(err).__name__)
                outcome.append(time.perf_counter() - t0)
            keep_lp, dt_lp, keep, dt_irls = outcome
            if isinstance(keep_lp, str) or isinstance(keep, str):
                errors.append((f, keep_lp if isinstance(keep_lp, str) else "ok", keep if isinstance(keep, str) else "ok"))
                continue
            t_lp, t_irls = t_lp + dt_lp, t_irls + dt_irls
            fit = l1_regression(*build_H(p, q)[:2])
            certified += fit.certified
            pivots.append(fit.pivots)
            same = int(np.sum(keep == keep_lp))
            plain = int(np.sum(pnp_l1_filter_plain(p, q) == keep_lp))
            agree, plain_agree, total = agree + same, plain_agree + plain, total + len(p)
            worst = min(worst, (same / len(p), f))
            plain_worst = min(plain_worst, plain / len(p))
        used = len(frames) - len(errors)
        print(f"{cameras:8s}{len(frames):7d}{total:8d}{np.median([len(p) for _, p, _ in frames]):9.0f}"
              f"{agree / total:10.4%}{f'{worst[0]:.2%} (f {worst[1]})':>17s}{f'{certified}/{used}':>11s}"
              f"{f'{np.median(pivots):.0f}/{max(pivots)}':>16s}{plain_agree / total:12.2%}{plain_worst:12.2%}"
              f"{1e3 * t_lp / used:8.2f}{1e3 * t_irls / used:9.3f}")
        for f, lp_err, irls_err in errors:
            print(f"  frame {f}: lp {lp_err}, irls {irls_err}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=9)
    ap.add_argument("--number", type=int, default=3)
    ap.add_argument("--scenes", type=int, default=5)
    a = ap.parse_args()
    timing_table(a)
    agreement_table()


if __name__ == "__main__":
    main()
