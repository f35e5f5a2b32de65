"""Window gravity (pipelines/window_gravity.py): gravity in the body frame from tracked positions
against the twice-integrated IMU, on a synthetic accelerating, rotating body."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation as Rot

from gevi_cli.estimators.preintegration import preintegrate
from gevi_cli.pipelines.window_gravity import GRAVITY, WindowGravity

IMU_HZ, FRAME_HZ = 200, 20
G_W = np.array([0.0, 0.0, -GRAVITY])


def _motion(duration_s):
    """Smooth attitude and position (peak accelerations ~0.5 m/s^2, the pool presets'), with the
    IMU's specific force and body rate."""
    t = np.arange(int(duration_s * IMU_HZ) + 1) / IMU_HZ
    ang = np.stack([0.05 * np.sin(0.7 * t), 0.04 * np.cos(0.5 * t), 0.3 * np.sin(0.2 * t)], 1)
    R = Rot.from_euler("xyz", ang).as_matrix()
    w = np.array([0.9, 0.6, 1.1])
    amp = np.array([0.6, 0.5, 0.15])
    pos = amp * np.sin(w * t[:, None])
    acc = -amp * w**2 * np.sin(w * t[:, None])
    f = np.einsum("nji,nj->ni", R, acc - G_W)
    # the body rate that carries R[k] into R[k + 1] over one sample (zero-order hold, as the preintegration)
    om = Rot.from_matrix(np.einsum("nji,njk->nik", R[:-1], R[1:])).as_rotvec() * IMU_HZ
    return t, R, pos, f, om


def _feed(wg, t, R, pos, f, om, pos_noise=0.0, acc_scale=1.0, seed=0):
    """Frames at FRAME_HZ into ``wg``; returns [(k, up or None)]."""
    rng = np.random.default_rng(seed)
    step = IMU_HZ // FRAME_HZ
    out, last = [], None
    for k in range(0, len(t) - 1, step):
        pre = None
        if last is not None:
            pre = preintegrate(om[last:k], acc_scale * f[last:k], np.full(k - last, 1.0 / IMU_HZ))
        wg.add(int(round(t[k] * 1e9)), pos[k] + pos_noise * rng.standard_normal(3), R[k], pre)
        last = k
        out.append((k, wg.up(int(round(t[k] * 1e9)))))
    return out


def _errors_deg(results, R):
    true_up = np.einsum("nji,j->ni", R, np.array([0.0, 0.0, 1.0]))
    return np.array([np.degrees(np.arccos(np.clip(u @ true_up[k], -1.0, 1.0))) for k, u in results if u is not None])


def test_exact_under_acceleration_where_the_specific_force_is_degrees_off():
    t, R, pos, f, om = _motion(8.0)
    res = _feed(WindowGravity(2.0), t, R, pos, f, om)
    err = _errors_deg(res, R)
    # the window needs 1 s of frames first: 20 frames without an answer, then every frame has one
    assert sum(u is None for _, u in res) == FRAME_HZ and len(err) == len(res) - FRAME_HZ
    # zero-order hold of the IMU at 200 Hz against the exact motion: measured 0.005 deg at most
    assert err.max() < 0.02
    f_err = _errors_deg([(k, f[k] / np.linalg.norm(f[k])) for k, _ in res], R)
    assert f_err.max() > 2.0  # what the specific force alone says


def test_position_noise_enters_as_the_least_squares_variance():
    t, R, pos, f, om = _motion(20.0)
    sigma_p = 2e-3  # a turbid floor's tracked positions (m per frame)
    res = _feed(WindowGravity(2.0), t, R, pos, f, om, pos_noise=sigma_p, seed=3)
    err = np.radians(_errors_deg(res, R))
    # full 2 s windows: 41 frames; gamma is the coefficient of tau^2 / 2, per axis std sigma_p sqrt(C22)
    tau = np.arange(-40, 1) / FRAME_HZ
    A = np.column_stack([np.ones_like(tau), tau, 0.5 * tau**2])
    s_gamma = sigma_p * np.sqrt(np.linalg.inv(A.T @ A)[2, 2])
    # the angle error is the horizontal part of the gamma error over g: Rayleigh, RMS sqrt(2) s / g
    expected = np.sqrt(2.0) * s_gamma / GRAVITY
    full = err[2 * FRAME_HZ:]
    assert 0.5 * expected < np.sqrt(np.mean(full**2)) < 1.5 * expected
    assert np.degrees(expected) < 0.05  # what makes it worth it: 2 mm of noise, hundredths of a degree


def test_a_long_run_keeps_its_rotations_orthonormal():
    # the integrals are re-referenced at every frame once the window is full (1200 times here)
    t, R, pos, f, om = _motion(60.0)
    wg = WindowGravity(2.0)
    err = _errors_deg(_feed(wg, t, R, pos, f, om), R)
    assert np.max(np.abs(np.einsum("nji,njk->nik", wg.R0, wg.R0) - np.eye(3))) < 1e-12
    assert err.max() < 0.02


def test_no_answer_outside_its_domain():
    t, R, pos, f, om = _motion(4.0)
    wg = WindowGravity(2.0)
    _feed(wg, t, R, pos, f, om)
    assert wg.up(123) is None  # not a kept frame
    # a mis-scaled accelerometer: the fitted |g| is 5 % off -> no answer rather than a wrong one
    bad = WindowGravity(2.0)
    assert all(u is None for _, u in _feed(bad, t, R, pos, f, om, acc_scale=1.06))
    # a frame added without an interval starts a new history (a tracking loss)
    wg.add(int(5e9), pos[0], R[0], None)
    assert len(wg) == 1 and wg.up(int(5e9)) is None


@pytest.mark.parametrize("window_s", [1.0, 3.0])
def test_other_windows(window_s):
    t, R, pos, f, om = _motion(8.0)
    err = _errors_deg(_feed(WindowGravity(window_s, min_span_s=min(1.0, window_s)), t, R, pos, f, om), R)
    assert len(err) > 0 and err.max() < 0.02
