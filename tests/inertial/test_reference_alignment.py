"""The mocap reference put on the IMU clock and into the IMU frame from the angular rates alone
(gevi_cli/inertial/reference_alignment.py), on a `gevi simulate mav` render (rotor vibration, gyro bias and
scale errors) whose ground truth is shifted and rotated by known amounts."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gevi_cli.inertial.reference_alignment import estimate_alignment
from gevi_cli.simulate.imu import ImuParams
from gevi_cli.simulate.mav import MavParams, mav_imu
from gevi_cli.trajectory import Trajectory


@pytest.fixture(scope="module")
def render():
    s, gt = mav_imu(MavParams(duration_s=30.0), ImuParams(rate_hz=200.0), seed=2, t0_ns=0)
    return s, gt


def _marker_reference(s, gt, offset_s: float, R_IR: np.ndarray, stride: int = 2) -> Trajectory:
    """The render's IMU attitude as a mocap system would log it: a marker body R (R_WR = R_WI R_IR), at
    half the IMU rate, on a clock ``offset_s`` behind the IMU's (stamp + offset = IMU time)."""
    t = s.t_ns[::stride] - int(round(offset_s * 1e9))
    R_WR = gt.R_WB[::stride] @ R_IR
    return Trajectory.from_rotations(t, R_WR, np.zeros((len(t), 3)), frame="body")


@pytest.mark.parametrize("offset_s", [-0.037, 0.0, 0.0175])
def test_known_offset_and_rotation_are_recovered(render, offset_s):
    """The estimated offset moves by the known shift to within 0.5 ms and the rotation by the known 2.5 deg
    to within 0.05 deg, whatever the render's own sampling convention (the unshifted, unrotated reference
    is the baseline: its 0.14 deg come from the render's 1 % gyro scale-factor errors, which a rotation fit
    on rates cannot tell from a rotation); the gyro's bias does not enter (the fit is on centred rates)."""
    s, gt = render
    R_true = Rotation.from_rotvec(np.radians(2.5) * np.array([0.6, -0.8, 0.0])).as_matrix()
    base = estimate_alignment(s.t_ns, s.gyro, _marker_reference(s, gt, 0.0, np.eye(3)))
    got = estimate_alignment(s.t_ns, s.gyro + [0.01, -0.02, 0.005], _marker_reference(s, gt, offset_s, R_true))
    assert abs(base.offset_s) < 0.005 and base.angle_deg < 0.3  # the render itself is aligned
    assert got.offset_s - base.offset_s == pytest.approx(offset_s, abs=5e-4)
    err = Rotation.from_matrix(got.R_IR @ R_true.T @ base.R_IR.T).magnitude()  # w_I = R_IR w_R: R_IR = R_true
    assert np.degrees(err) < 0.05 and got.correlation > 0.9


def test_applied_alignment_restores_the_imu_attitude(render):
    """apply() turns the marker poses back into IMU poses on the IMU clock: the tilt between them and the
    render's attitude is below 0.1 deg everywhere (the remaining error: the estimate's sub-ms offset
    error times the rate)."""
    from gevi_cli.evaluation.imu_report import TiltReference

    s, gt = render
    R_true = Rotation.from_rotvec(np.radians([1.0, -1.2, 3.0])).as_matrix()
    ref = _marker_reference(s, gt, 0.021, R_true)
    al = estimate_alignment(s.t_ns, s.gyro, ref)
    base = estimate_alignment(s.t_ns, s.gyro, _marker_reference(s, gt, 0.0, np.eye(3)))
    from dataclasses import replace

    # the render's own convention and scale-factor rotation taken out
    al = replace(al, offset_s=al.offset_s - base.offset_s, R_IR=base.R_IR.T @ al.R_IR)
    te = TiltReference(al.apply(ref)).tilt(s.t_ns, gt.R_WB)
    assert len(te.t_ns) > 0.9 * len(s.t_ns) and te.err_deg.max() < 0.1
    te_raw = TiltReference(ref).tilt(s.t_ns, gt.R_WB)
    assert te_raw.rmse_deg > 1.0  # unaligned, the same attitude reads degrees off


def test_no_rotation_no_alignment():
    """A reference that does not rotate carries no clock: None, not a guess."""
    t = np.arange(2000, dtype=np.int64) * 5_000_000
    gyro = np.random.default_rng(0).normal(0, 1e-3, (2000, 3))
    ref = Trajectory.from_rotations(t[::2], np.tile(np.eye(3), (1000, 1, 1)), np.zeros((1000, 3)), frame="body")
    assert estimate_alignment(t, gyro, ref) is None


def test_a_reference_in_the_imu_frame_gets_a_clock_offset_only(render):
    """rotation=False (the dataset states its ground truth in the IMU frame): R_IR is I and the clock offset
    is still recovered; describe() says why no rotation was estimated."""
    s, gt = render
    got = estimate_alignment(s.t_ns, s.gyro, _marker_reference(s, gt, 0.021, np.eye(3)), rotation=False)
    base = estimate_alignment(s.t_ns, s.gyro, _marker_reference(s, gt, 0.0, np.eye(3)), rotation=False)
    assert np.array_equal(got.R_IR, np.eye(3)) and got.angle_deg == 0.0
    assert got.offset_s - base.offset_s == pytest.approx(0.021, abs=5e-4)
    assert "no IMU-from-reference rotation (stated)" in got.describe("stated")


def test_gevi_imu_on_a_render_estimates_no_rotation_unless_asked(tmp_path, capsys):
    """A render's ground truth is the body (IMU) frame's pose, as EuRoC's: `gevi imu` estimates its clock offset
    only and says why; --align-rotation estimates a rotation too."""
    from support import run_cli

    code, out, err = run_cli(["simulate", "pool-easy", tmp_path / "r", "--imu-only", "--duration", "12", "--seed", "3"],
                             capsys)
    assert code == 0, err
    code, out, err = run_cli(["imu", tmp_path / "r", "-o", tmp_path / "a", "--no-plots"], capsys)
    assert code == 0, err
    assert "no IMU-from-reference rotation (the dataset's ground truth is the body (IMU) frame's pose)" in out
    code, out, err = run_cli(["imu", tmp_path / "r", "-o", tmp_path / "b", "--no-plots", "--align-rotation"], capsys)
    assert code == 0, err
    assert "IMU-from-reference rotation " in out and "no IMU-from-reference rotation" not in out
