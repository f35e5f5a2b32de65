"""The l1-PnP stage of the verification keeps the RANSAC survivors when its own pose is degenerate."""
from __future__ import annotations

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.pipelines import verification
from gevi_cli.pipelines.config import VerifyConfig


def test_degenerate_l1_pose_keeps_every_match(monkeypatch):
    def degenerate(*a, **k):
        raise est.DegenerateInput("recover_pose: kappa <= 0 (centroid behind the current camera)")

    monkeypatch.setattr(est, "pnp_l1_filter", degenerate)
    rng = np.random.default_rng(0)
    p, q = rng.normal(size=(30, 3)) + [0, 0, 5], rng.normal(size=(30, 2))
    keep = verification.l1_stage(p, q, VerifyConfig())
    assert keep.dtype == bool and keep.all() and len(keep) == 30


def test_l1_stage_drops_the_worst_tenth():
    rng = np.random.default_rng(1)
    p = rng.uniform(-2, 2, (50, 3)) + [0, 0, 6]
    q = p[:, :2] / p[:, 2:] + rng.normal(0, 1e-3, (50, 2))
    q[:3] += 0.2  # three gross outliers
    keep = verification.l1_stage(p, q, VerifyConfig())
    assert keep.sum() == 45 and not keep[:3].any()
