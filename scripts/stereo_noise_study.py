#!/usr/bin/env python3
"""Is the keyframe points' covariance (spec 4) consistent with the data?  Keyframe to keyframe, with the truth.

    python scripts/stereo_noise_study.py SEQUENCE [SEQUENCE ...] [--frames N]

For every SEQUENCE with ground truth (a `gevi simulate` render, or a real one such as kitti06_head)
it runs `gevi run SEQUENCE --method cfo` in this process and keeps every keyframe's triangulated points
``p`` (keyframe-left, m) with their covariance ``Sigma = sigma^2 cov_unit`` as the pipeline made them
(the noise variance ``sigma^2`` estimated from the temporal matches at that moment, spec 3; the right
row tied to the left for row-refined matches).  A feature seen by two consecutive keyframes A and B
was triangulated twice from independent stereo pairs, so with the true motion ``T_BA``

    e = p_B - (R_BA p_A + t_BA),   m2 = e^T (Sigma_B + R_BA Sigma_A R_BA^T)^-1 e

is chi-square with 3 degrees of freedom if the model holds: median 2.37, mean 3.  A median above that
means the stereo points are noisier than the covariance says, below that they are cleaner; the mean
against the median shows the tail (wrong stereo matches).  Printed per sequence: pairs, the noise std
of the last keyframe (px), median / mean / 99 %-trimmed mean of m2, the variance ratio the median
implies (median / 2.37), and the median per depth band.  Why: docs/method.md 4.  Ground-truth errors
count as point errors, so a real sequence reads high where its ground truth is coarse (KITTI: cm).
A reproduction, not a test.
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
from pathlib import Path

import numpy as np

CHI2_3_MEDIAN = 2.366


def record(seq: Path, frames: int | None) -> list[dict]:
    """Keyframes of a CFO run: stamp, ids, points, covariance (m^2), pixel noise std, T_B_C0."""
    from gevi_cli.cli import main as gevi_main
    from gevi_cli.pipelines import odometry as od

    kfs: list[dict] = []
    orig = od.KeyframeOdometry._insert_keyframe

    def spy(self, frame, res, timings):
        orig(self, frame, res, timings)
        k = self.kf
        if k is not None and k.index == res.index:
            kfs.append({"t": k.t_ns, "ids": k.ids.copy(), "p": k.p.copy(), "cov": k.cov_unit * self.sigma2,
                        "sigma_px": float(np.sqrt(self.sigma2) * self.camera.f),
                        "T_B_C0": np.asarray(self.camera.T_B_C0)})

    od.KeyframeOdometry._insert_keyframe = spy
    argv = ["run", str(seq), "--method", "cfo", "-q"] + (["--max-frames", str(frames)] if frames else [])
    try:
        with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(sys.stderr):
            try:
                gevi_main(argv + ["-o", tmp])
            except SystemExit as ex:
                if ex.code not in (0, 3, None):
                    raise
    finally:
        od.KeyframeOdometry._insert_keyframe = orig
    return kfs


def consistency(seq: Path, kfs: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """m2 and the depth (in keyframe B) of every feature shared by consecutive keyframes."""
    from gevi_cli.datasets import open_sequence

    gt = open_sequence(seq).groundtruth
    row = {int(t): i for i, t in enumerate(gt.t_ns)}
    m2, depth = [], []
    for a, b in zip(kfs[:-1], kfs[1:]):
        if a["t"] not in row or b["t"] not in row:
            continue
        Ta, Tb = gt.matrices[row[a["t"]]] @ a["T_B_C0"], gt.matrices[row[b["t"]]] @ b["T_B_C0"]
        T_ba = np.linalg.inv(Tb) @ Ta
        R, t = T_ba[:3, :3], T_ba[:3, 3]
        _, ia, ib = np.intersect1d(a["ids"], b["ids"], assume_unique=True, return_indices=True)
        if len(ia) == 0:
            continue
        e = b["p"][ib] - (a["p"][ia] @ R.T + t)
        S = b["cov"][ib] + R @ a["cov"][ia] @ R.T
        m2.append(np.einsum("ni,ni->n", e, np.linalg.solve(S, e[:, :, None])[:, :, 0]))
        depth.append(b["p"][ib, 2])
    if not m2:
        return np.empty(0), np.empty(0)
    return np.concatenate(m2), np.concatenate(depth)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequences", nargs="+", type=Path, help="sequences with ground truth")
    ap.add_argument("--frames", type=int, default=None, help="at most this many frames per sequence")
    args = ap.parse_args(argv)
    from gevi_cli.datasets import open_sequence
    from gevi_cli.errors import GeviError

    for seq in args.sequences:
        try:
            has_gt = open_sequence(seq).groundtruth is not None
        except GeviError as err:
            print(f"stereo_noise_study.py: error: {err}", file=sys.stderr)
            return 2
        if not has_gt:
            print(f"stereo_noise_study.py: error: {seq}: no ground truth in the sequence (the study needs the "
                  "true motion between keyframes)", file=sys.stderr)
            return 2
    print("| sequence | keyframes | pairs | sigma px (last) | median m2 | mean m2 | 99 % trimmed mean | "
          "variance ratio | median m2 by depth (m) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for seq in args.sequences:
        kfs = record(seq, args.frames)
        m2, dep = consistency(seq, kfs)
        if len(m2) == 0:
            print(f"| {seq.name} | {len(kfs)} | 0 | | | | | | |")
            continue
        trim = m2[m2 <= np.quantile(m2, 0.99)].mean()
        bands = []
        for lo, hi in ((0, 2), (2, 5), (5, 10), (10, 30), (30, np.inf)):
            s = (dep >= lo) & (dep < hi)
            if s.sum() >= 20:
                bands.append(f"{lo}-{hi:g}: {np.median(m2[s]):.2f} ({s.sum()})")
        med = float(np.median(m2))
        print(f"| {seq.name} | {len(kfs)} | {len(m2)} | {kfs[-1]['sigma_px']:.3f} | {med:.2f} | {m2.mean():.2f} | "
              f"{trim:.2f} | {med / CHI2_3_MEDIAN:.2f} | {'; '.join(bands)} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
