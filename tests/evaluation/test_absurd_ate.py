"""The evaluator refuses an ATE no real estimate can have (issue 35): a failed cell with the reason."""
from __future__ import annotations

import numpy as np

from gevi_cli.evaluation.evaluate import ABSURD_ATE_RATIO, EvalSettings, evaluate_pair
from gevi_cli.trajectory import Trajectory


def _drive(n=400, step_m=1.0) -> Trajectory:
    """A 10 Hz drive along a gentle curve, ``step_m`` per frame (extent ~ n * step_m)."""
    a = np.linspace(0.0, 1.0, n)
    p = np.column_stack([np.arange(n) * step_m, 50.0 * np.sin(a * 3.0), 0.5 * np.cos(a * 7.0)])
    return Trajectory(1_000_000_000 + np.arange(n) * 100_000_000, p, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))


def _evaluate(est: Trajectory):
    return evaluate_pair(_drive(), est, EvalSettings(kitti=False), "se3", method="m", sequence="s")


def test_a_corrupt_tail_is_a_failed_cell_not_a_number():
    gt = _drive()
    p = gt.positions.copy()
    p[100:, 1] *= 1e6  # a persistent corrupt tail (read with --allow-jumps)
    r = _evaluate(Trajectory(gt.t_ns, p, gt.quat_wxyz))
    assert r.status == "failed"
    assert r.reason.startswith("ATE ") and "not physical" in r.reason and "extent" in r.reason


def test_a_badly_drifting_real_estimate_keeps_its_number():
    """Scale drift to 3x and a 200 m offset: a bad estimate, but in the ground truth's world."""
    gt = _drive()
    p = gt.positions * np.linspace(1.0, 3.0, len(gt))[:, None] + [0.0, 200.0, 0.0]
    r = _evaluate(Trajectory(gt.t_ns, p, gt.quat_wxyz))
    extent = float(np.linalg.norm(np.ptp(gt.positions, axis=0)))
    assert r.ok, r.reason
    assert 10.0 < r.ate.trans_rmse < ABSURD_ATE_RATIO * (extent + 1.0)
