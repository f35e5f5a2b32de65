#!/usr/bin/env python3
"""The 6-DOF tracking pose of CurrentFeature Odometry against a render's truth, estimator by estimator.

    python scripts/pnp_study.py RENDER [RENDER ...]

For every RENDER (a folder written by `gevi simulate`) it runs `gevi run RENDER --method cfo --no-ba`
in this process and records, for every tracked frame, the verified keyframe<->current matches that
the pose step received (keyframe-left ``z``, keyframe-right ``y``, current ``q``, the noise variance).
Then, frame by frame and from the same inputs, it computes ``T_ck`` (keyframe-left into current-left)
with each variant below and compares it with the render's true ``T_ck``:

* ``epnp``: OpenCV EPnP + iterated LM (unweighted), i.e. ``--pnp epnp``, without the re-verification;
* ``epnp + reverify``: the same with the re-verification (3D-2D RANSAC when the median reprojection
  error is too large), as ``--pnp epnp`` runs now;
* ``one step``: Bias-Eli + S2's single weighted step (with the current frame's noise ``sigma^2 I``) and
  the four stereo coordinates independent (gevi's ``be-w`` before the step rule);
* ``+ steps``: stepping until the step is within 2 standard deviations (``pose6.STEP_TOL``);
* ``be-w before the chi2 gate``: also with the right row tied to the left one for row-refined
  matches (``tied_rows``, docs/method.md 4) and the re-verification;
* ``be-w``: as the pipeline runs it now, i.e. also with the chi-square gate on the weighted
  residuals (``pose6.CHI2_GATE``: wrong stereo depths out, the steps redone).

Every variant goes through the pipeline's tracking gates (``tracked_pose6``: the SQPnP fallback of
be-w, the median-error limit).

Printed per render: RMS and median of the translation error (mm), RMS of the rotation error (deg)
and the mean of the rotation-error vectors (deg, current-camera axes: a bias), and the mean number
of weighted steps.  Why: docs/method.md 5.4.  A reproduction, not a
test; a 30 s pool render takes about 40 s.
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np


def record(render: Path) -> list[dict]:
    """Run CFO without BA on ``render`` and return the pose step's inputs with the true ``T_ck``."""
    from gevi_cli.cli import main as gevi_main
    from gevi_cli.datasets import open_sequence
    from gevi_cli.pipelines import cfo as cfo_mod

    recs: list[dict] = []
    orig = cfo_mod.CurrentFeatureOdometry.estimate_T_ck

    def spy(self, m, frame):
        recs.append({"z": m.z, "y": m.y, "q": m.q, "s2": self.sigma2, "f": self.camera.f, "tk": self.kf.t_ns,
                     "tc": int(frame.t_ns), "R_rl": self.camera.R_rl, "t_rl": self.camera.t_rl,
                     "T_B_C0": np.asarray(self.camera.T_B_C0)})
        return orig(self, m, frame)

    cfo_mod.CurrentFeatureOdometry.estimate_T_ck = spy
    try:
        with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stdout(sys.stderr):
            try:
                gevi_main(["run", str(render), "--method", "cfo", "--no-ba", "-q", "-o", tmp])
            except SystemExit as ex:
                if ex.code not in (0, 3, None):
                    raise
    finally:
        cfo_mod.CurrentFeatureOdometry.estimate_T_ck = orig
    gt = open_sequence(render).groundtruth
    row = {int(t): i for i, t in enumerate(gt.t_ns)}
    T = gt.matrices
    out = []
    for r in recs:
        if r["tk"] in row and r["tc"] in row:
            Tk, Tc = T[row[r["tk"]]] @ r["T_B_C0"], T[row[r["tc"]]] @ r["T_B_C0"]
            r["T_ck"] = np.linalg.inv(Tc) @ Tk
            out.append(r)
    return out


def variants():
    from gevi_cli import estimators as est
    from gevi_cli.pipelines import pose6
    from gevi_cli.pipelines.config import PnPConfig
    from gevi_cli.pipelines.pose6 import tracked_pose6

    cfg = PnPConfig()
    # the variants before the gate, without the re-verification, with one step: the pipeline's constants
    # (pose6.CHI2_GATE, pose6.STEP_TOL) and its re-verification switched for the one call
    old = {"CHI2_GATE": 0.0}
    no_reverify = {**old, "reverified": lambda *a, **k: None}

    def run(c, tied, patch=None):
        def fn(r):
            p, cov = est.triangulate(r["z"], r["y"], r["R_rl"], r["t_rl"], r["s2"],
                                     tied_rows=(r["z"][:, 1] == r["y"][:, 1]) if tied else None)
            saved = {k: getattr(pose6, k) for k in (patch or {})}
            try:
                for k, v in (patch or {}).items():
                    setattr(pose6, k, v)
                R, t, _ = tracked_pose6(p, cov, r["q"], c, r["s2"], r["f"])
            finally:
                for k, v in saved.items():
                    setattr(pose6, k, v)
            return R, t
        return fn

    # (the column without the current frame's noise went with that setting: docs/studies/method_history.md)
    return {
        "epnp": run(replace(cfg, method="epnp"), False, no_reverify),
        "epnp + reverify": run(replace(cfg, method="epnp"), False, old),
        "one step": run(cfg, False, {**no_reverify, "STEP_TOL": 0.0}),
        "+ steps": run(cfg, False, no_reverify),
        "be-w before the chi2 gate": run(cfg, True, old),
        "be-w": run(cfg, True),
    }


def evaluate(recs: list[dict]) -> dict[str, tuple]:
    """Per variant: translation RMS and median (mm), rotation RMS (deg), mean rotation-error vector
    (deg, (3,)), mean weighted steps, frames the variant could not track (not in the statistics)."""
    from scipy.spatial.transform import Rotation

    from gevi_cli import estimators as est
    from gevi_cli.pipelines.verification import TrackingFailure

    out = {}
    orig = est.pnp6_refine
    for name, fn in variants().items():
        steps = [0]

        def counting(*a, _steps=steps, **k):
            _steps[0] += 1
            return orig(*a, **k)

        est.pnp6_refine = counting
        et, er, failed = [], [], 0
        try:
            for r in recs:
                try:
                    R, t = fn(r)
                except TrackingFailure:
                    failed += 1
                    continue
                G = r["T_ck"]
                et.append(np.linalg.norm(t - G[:3, 3]) * 1e3)
                er.append(np.degrees(Rotation.from_matrix(G[:3, :3].T @ R).as_rotvec()))
        finally:
            est.pnp6_refine = orig
        et, er = np.array(et), np.array(er).reshape(-1, 3)
        out[name] = (float(np.sqrt(np.mean(et**2))), float(np.median(et)),
                     float(np.sqrt(np.mean(np.sum(er**2, axis=1)))), er.mean(axis=0), steps[0] / max(len(recs), 1), failed)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("renders", nargs="+", type=Path, help="folders written by gevi simulate")
    args = ap.parse_args(argv)
    for r in args.renders:
        if not (r / "simulation.yaml").is_file():
            print(f"pnp_study.py: error: {r}: not a gevi simulate render (no simulation.yaml)", file=sys.stderr)
            return 2
    print("| render | frames | variant | t RMS mm | t median mm | R RMS deg | mean R error deg (x, y, z) | steps/frame "
          "| failed |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in args.renders:
        recs = record(r)
        for name, (rms, med, rot, bias, steps, failed) in evaluate(recs).items():
            print(f"| {r.name} | {len(recs)} | {name} | {rms:.3f} | {med:.3f} | {rot:.4f} | "
                  f"{bias[0]:+.4f}, {bias[1]:+.4f}, {bias[2]:+.4f} | {steps:.2f} | {failed} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
