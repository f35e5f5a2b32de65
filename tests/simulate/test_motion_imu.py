"""Motion derivatives and IMU synthesis are exact (issue 5)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from gevi_cli.simulate.imu import G_W, ImuParams, synthesize_imu
from gevi_cli.simulate.motion import max_acceleration
from gevi_cli.simulate.presets import PRESETS, build_motion


@pytest.mark.parametrize("preset", ["pool-easy", "pool-hard", "euroc-like", "kitti-like"])
def test_derivatives_match_finite_differences(preset):
    motion = build_motion(PRESETS[preset], seed=3, duration=20.0)
    t = np.linspace(0.3, 19.7, 97)
    h = 1e-4
    m, mp, mm = motion(t), motion(t + h), motion(t - h)
    np.testing.assert_allclose(m.v_W, (mp.p_W - mm.p_W) / (2 * h), atol=1e-6)
    np.testing.assert_allclose(m.a_W, (mp.v_W - mm.v_W) / (2 * h), atol=1e-6)
    # omega_B from R_WB^T dR/dt
    dR = (mp.R_WB - mm.R_WB) / (2 * h)
    W = np.einsum("nji,njk->nik", m.R_WB, dR)
    omega_fd = np.stack([W[:, 2, 1], W[:, 0, 2], W[:, 1, 0]], axis=1)
    np.testing.assert_allclose(m.omega_B, omega_fd, atol=1e-6)


@pytest.mark.parametrize("preset", ["pool-easy", "pool-hard"])
def test_underwater_motion_profile(preset):
    spec = PRESETS[preset]
    motion = build_motion(spec, seed=1, duration=60.0)
    assert max_acceleration(motion, 60.0) < 1.0
    t = np.arange(0.0, 60.0, 0.01)
    m = motion(t)
    still = t < 1.0
    assert np.abs(m.v_W[still]).max() == 0.0 and np.abs(m.omega_B[still]).max() == 0.0
    acc = np.linalg.norm(m.a_W, axis=1)
    # quiet and busy periods: 5 s windows with clearly different acceleration levels
    win = acc[t > 2.0][: 5000].reshape(10, 500).max(axis=1)
    assert win.max() > 2.0 * win.min()
    # roll and pitch vary, not only yaw
    e = Rotation.from_matrix(m.R_WB).as_euler("ZYX", degrees=True)
    assert np.ptp(e[:, 1]) > 3.0 and np.ptp(e[:, 2]) > 3.0 and np.ptp(e[:, 0]) > 10.0
    # stays inside the 10 m x 5 m x 2 m pool, about 1 m above the floor
    assert m.p_W[:, 0].min() > 0.5 and m.p_W[:, 0].max() < 9.5
    assert m.p_W[:, 1].min() > 0.5 and m.p_W[:, 1].max() < 4.5
    assert 0.6 < m.p_W[:, 2].min() and m.p_W[:, 2].max() < 1.6


def _integrate(imu_t, gyro, acc, q0_xyzw, v0, p0, t_eval):
    """High-order integration of noise-free IMU samples (cubic-spline interpolated, DOP853)."""
    gs, as_ = CubicSpline(imu_t, gyro), CubicSpline(imu_t, acc)

    def rhs(t, x):
        q = x[:4] / np.linalg.norm(x[:4])  # xyzw
        w = gs(t)
        qx, qy, qz, qw = q
        # q_dot = 0.5 q (x) [w, 0]
        dq = 0.5 * np.array([
            qw * w[0] + qy * w[2] - qz * w[1],
            qw * w[1] + qz * w[0] - qx * w[2],
            qw * w[2] + qx * w[1] - qy * w[0],
            -qx * w[0] - qy * w[1] - qz * w[2],
        ])
        R = Rotation.from_quat(q).as_matrix()
        dv = R @ as_(t) + G_W
        return np.concatenate([dq, dv, x[4:7]])

    x0 = np.concatenate([q0_xyzw, v0, p0])
    sol = solve_ivp(rhs, (t_eval[0], t_eval[-1]), x0, method="DOP853", t_eval=t_eval, rtol=1e-11, atol=1e-12)
    assert sol.success
    return sol.y.T


@pytest.mark.parametrize("preset", ["pool-hard", "euroc-like"])
def test_noise_free_imu_integrates_to_ground_truth(preset):
    """Integrating the noise-free 200 Hz IMU of a 10 s sequence reproduces the GT pose (1 mm, 0.01 deg)."""
    motion = build_motion(PRESETS[preset], seed=7, duration=10.0)
    t0_ns = 1_600_000_000_000_000_000
    t_ns = t0_ns + np.arange(0, 2001) * 5_000_000
    imu = synthesize_imu(motion, t_ns, t0_ns, ImuParams().noise_free(), np.random.default_rng(0))
    assert np.all(imu.gyro == imu.gyro_true) and np.all(imu.acc == imu.acc_true)
    t = (t_ns - t0_ns) * 1e-9
    gt = motion(t)
    q0 = Rotation.from_matrix(gt.R_WB[0]).as_quat()
    x = _integrate(t, imu.gyro, imu.acc, q0, gt.v_W[0], gt.p_W[0], t[::20])
    pos_err = np.linalg.norm(x[:, 7:10] - gt.p_W[::20], axis=1).max()
    R_est = Rotation.from_quat(x[:, :4])
    rot_err = np.degrees((R_est.inv() * Rotation.from_matrix(gt.R_WB[::20])).magnitude()).max()
    print(f"{preset}: max position error {pos_err * 1e3:.4f} mm, max rotation error {rot_err:.6f} deg")
    assert pos_err < 1e-3
    assert rot_err < 0.01


def test_imu_noise_statistics():
    """White noise std = density / sqrt(dt); bias random walk increments std = walk * sqrt(dt)."""
    motion = build_motion(PRESETS["pool-easy"], seed=1, duration=100.0)
    p = ImuParams(gyro_bias_init=0.0, acc_bias_init=0.0)
    t0 = 0
    t_ns = np.arange(0, 20001) * 5_000_000
    imu = synthesize_imu(motion, t_ns, t0, p, np.random.default_rng(5))
    dt = 0.005
    ng = imu.gyro - imu.gyro_true - imu.bias_gyro
    na = imu.acc - imu.acc_true - imu.bias_acc
    assert abs(ng.std() / (p.gyro_noise_density / np.sqrt(dt)) - 1) < 0.02
    assert abs(na.std() / (p.acc_noise_density / np.sqrt(dt)) - 1) < 0.02
    assert abs(np.diff(imu.bias_gyro, axis=0).std() / (p.gyro_random_walk * np.sqrt(dt)) - 1) < 0.02
    assert abs(np.diff(imu.bias_acc, axis=0).std() / (p.acc_random_walk * np.sqrt(dt)) - 1) < 0.02


def test_static_specific_force_points_up():
    motion = build_motion(PRESETS["pool-easy"], seed=2, duration=5.0)
    imu = synthesize_imu(motion, np.array([0, 5_000_000]), 0, ImuParams().noise_free(), np.random.default_rng(0))
    m = motion(np.array([0.0]))
    np.testing.assert_allclose(m.R_WB[0] @ imu.acc[0], [0, 0, 9.81], atol=1e-12)


def test_written_files_integrate_to_written_ground_truth(tmp_path):
    """End to end through the EuRoC files and the reader: noise-free imu0 integrates to the GT csv."""
    from gevi_cli.datasets import open_sequence
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    cfg = SimulationConfig("euroc-like", seed=4, duration_s=6.0, rate_hz=1.0, resolution=(32, 24),
                           imu=ImuParams().noise_free())
    seq = open_sequence(simulate(cfg, tmp_path / "s", "euroc", progress=False, workers=1))
    imu, gt = seq.imu, seq.groundtruth
    t = (imu.t_ns - imu.t_ns[0]) * 1e-9
    np.testing.assert_array_equal(imu.t_ns, gt.t_ns)
    # velocity from the GT file's 17 columns is needed for the initial state
    import pandas as pd
    table = pd.read_csv(tmp_path / "s" / "mav0" / "state_groundtruth_estimate0" / "data.csv", comment="#", header=None)
    v0 = table.iloc[0, 8:11].to_numpy(float)
    x = _integrate(t, imu.gyro, imu.acc, gt.quat_xyzw[0], v0, gt.positions[0], t[::40])
    pos_err = np.linalg.norm(x[:, 7:10] - gt.positions[::40], axis=1).max()
    rot_err = np.degrees((Rotation.from_quat(x[:, :4]).inv() * Rotation.from_quat(gt.quat_xyzw[::40])).magnitude()).max()
    assert pos_err < 1e-3 and rot_err < 0.01
