"""Association (tolerance, offset, coverage) and RPE deltas in frames, metres and seconds."""
import numpy as np
import pytest
from eval_support import synthetic

from gevi_cli.errors import GeviError
from gevi_cli.evaluation.associate import associate
from gevi_cli.evaluation.evaluate import EvalSettings, evaluate_pair
from gevi_cli.evaluation.rpe import compute_rpe
from gevi_cli.trajectory import Trajectory


def test_time_offset_and_tolerance():
    gt = synthetic(n=400)
    late = Trajectory(gt.t_ns + 500_000_000, gt.positions, gt.quat_wxyz, name="late")  # clock 0.5 s ahead
    with pytest.raises(GeviError, match="no pose matches"):
        associate(gt, Trajectory(gt.t_ns + 10**12, gt.positions, gt.quat_wxyz))
    r = evaluate_pair(gt, late, EvalSettings(t_offset_s=-0.5), "se3", method="m", sequence="s")
    assert r.association.n_matched == 400 and r.ate.trans_rmse < 1e-9
    # a 4 ms jitter is within 10 ms, 15 ms is not
    jit = Trajectory(gt.t_ns + 4_000_000, gt.positions, gt.quat_wxyz)
    assert associate(gt, jit).n_matched == 400
    far = Trajectory(gt.t_ns + 15_000_000, gt.positions, gt.quat_wxyz)
    with pytest.raises(GeviError, match="within 10 ms"):
        associate(gt, far, max_diff_s=0.01)
    assert associate(gt, far, max_diff_s=0.02).n_matched == 400


def test_coverage_of_a_partial_estimate():
    gt = synthetic(n=401)
    a = associate(gt, gt.select(slice(100, 301)))
    assert a.coverage == pytest.approx(0.5)
    assert a.summary() == "matched 201 of 201 poses, coverage 50.0 % of the GT time span"


def test_dense_estimate_uses_each_gt_pose_once():
    gt = synthetic(n=200, dt_ns=50_000_000)
    dense = synthetic(n=1000, dt_ns=10_000_000)
    a = associate(gt, dense)
    assert len(np.unique(a.gt_index)) == a.n_matched == len(a.est_index)


def test_rpe_units():
    gt = synthetic(n=600)  # 20 Hz
    rng = np.random.default_rng(3)
    est = Trajectory(gt.t_ns, gt.positions + rng.normal(0, 0.002, gt.positions.shape), gt.quat_wxyz)
    f = compute_rpe(gt, est, 1, "frames")
    assert f.n_pairs == 599
    s = compute_rpe(gt, est, 1.0, "s")
    assert s.n_pairs == 30  # 29.95 s at 1 s steps (the last pair is 0.95 s, within 10 %)
    m = compute_rpe(gt, est, 1.0, "m")
    assert m.n_pairs > 5 and m.unit == "m"
    assert f.trans_mean < s.trans_mean * 10
    with pytest.raises(GeviError, match="no pose pair"):
        compute_rpe(gt, est, 1000.0, "s")
