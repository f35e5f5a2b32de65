"""Alignment: posyaw recovers a known yaw + translation exactly; se3/sim3 via evo; ordering of ATEs."""
import numpy as np
import pytest
from eval_support import synthetic, transformed
from scipy.spatial.transform import Rotation

from gevi_cli.errors import GeviError
from gevi_cli.evaluation.align import align, estimate_alignment
from gevi_cli.evaluation.ate import compute_ate


def rot_z(a):
    return Rotation.from_euler("z", a).as_matrix()


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.9, np.pi - 1e-3])
def test_posyaw_recovers_known_yaw_and_translation_exactly(yaw):
    gt = synthetic()
    t = np.array([3.5, -12.0, 0.8])
    est = transformed(gt, rot_z(yaw), t)  # est world = Rz(yaw), t applied to gt
    aligned, a = align(gt, est, "posyaw")
    # the inverse transform: R = Rz(-yaw), t = -Rz(-yaw) t
    np.testing.assert_allclose(a.R, rot_z(-yaw), atol=1e-12)
    np.testing.assert_allclose(a.t, -rot_z(-yaw) @ t, atol=1e-10)
    assert a.scale == 1.0
    np.testing.assert_allclose(aligned.positions, gt.positions, atol=1e-10)
    ate = compute_ate(gt, aligned)
    assert ate.trans_rmse < 1e-10 and ate.rot_rmse_deg < 1e-5


def test_posyaw_single_pose_uses_first_pose_yaw():
    gt = synthetic()
    est = transformed(gt, rot_z(1.1), np.array([1.0, 2.0, 3.0]))
    a = estimate_alignment(gt, est, "posyaw", n_align=1)
    np.testing.assert_allclose(a.R, rot_z(-1.1), atol=1e-12)
    np.testing.assert_allclose(a.apply(est).positions, gt.positions, atol=1e-10)


def test_posyaw_does_not_use_roll_pitch():
    gt = synthetic()
    R = Rotation.from_euler("x", 0.2).as_matrix()  # a tilt cannot be corrected by 4-DOF alignment
    est = transformed(gt, R, np.zeros(3))
    e4 = compute_ate(gt, align(gt, est, "posyaw")[0]).trans_rmse
    e6 = compute_ate(gt, align(gt, est, "se3")[0]).trans_rmse
    assert e6 < 1e-9 < 1e-3 < e4


def test_sim3_recovers_scale_and_ordering():
    gt = synthetic()
    R = Rotation.from_euler("zyx", [0.3, 0.1, -0.2]).as_matrix()
    est = transformed(gt, R, np.array([1, 2, 3.0]), s=0.5)
    rng = np.random.default_rng(1)
    noisy = type(est)(est.t_ns, est.positions + rng.normal(0, 0.01, est.positions.shape), est.quat_wxyz)
    _, a = align(gt, est, "sim3")
    assert a.scale == pytest.approx(2.0, rel=1e-10)
    errs = [compute_ate(gt, align(gt, noisy, m)[0]).trans_rmse for m in ("posyaw", "se3", "sim3")]
    assert errs[0] >= errs[1] >= errs[2]


def test_origin_alignment_matches_first_pose():
    gt = synthetic()
    est = transformed(gt, Rotation.from_euler("zyx", [1, 0.2, 0.1]).as_matrix(), np.array([5, 0, 0.0]))
    aligned, _ = align(gt, est, "origin")
    np.testing.assert_allclose(aligned.matrices[0], gt.matrices[0], atol=1e-10)


def test_sim3_needs_three_poses():
    gt = synthetic(n=10)
    with pytest.raises(GeviError, match="at least 3"):
        align(gt, gt, "sim3", n_align=2)
