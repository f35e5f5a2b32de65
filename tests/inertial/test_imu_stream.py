"""ImuStream: clock shift, interval rotation, gaps and refused input (one-line GeviError)."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli import estimators as est
from gevi_cli.errors import GeviError
from gevi_cli.inertial.imu_stream import DEFAULT_NOISE, ImuNoise, ImuStream

NOISE = ImuNoise(**DEFAULT_NOISE)


def _stream(n=401, rate=200.0, w=(0.1, -0.2, 0.3), shift=0.0):
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    return ImuStream(t, np.tile(w, (n, 1)), np.tile([0.0, 0.0, 9.81], (n, 1)), NOISE, shift)


def test_interval_integrates_the_rate_minus_bias():
    s = _stream()
    b = np.array([0.01, 0.0, -0.02])
    fi = s.interval(100_000_000, 600_000_000, b)  # 0.5 s
    assert not fi.gap and fi.n == 100
    assert np.allclose(fi.rotvec, (np.array([0.1, -0.2, 0.3]) - b) * 0.5, atol=1e-12)
    assert np.allclose(fi.dR, est.exp_so3(fi.rotvec)) and fi.dt == pytest.approx(0.5)


def test_time_shift_moves_the_imu_onto_the_camera_clock():
    s = _stream(shift=0.01)  # t_imu = t_cam + 10 ms
    assert s.t_ns[0] == -10_000_000


def test_gap_and_order():
    s = _stream()
    t = s.t_ns.copy()
    keep = (t < 1.0e8) | (t > 2.0e8)
    g = ImuStream(t[keep], s.gyro[keep], s.acc[keep], NOISE)
    assert g.interval(50_000_000, 250_000_000, np.zeros(3)).gap
    assert not g.interval(250_000_000, 300_000_000, np.zeros(3)).gap
    t[10], t[11] = t[11], t[10]
    with pytest.raises(GeviError, match="out of order"):
        ImuStream(t, s.gyro, s.acc, NOISE, source="imu.csv")


def test_missing_noise_uses_defaults_with_a_warning():
    from gevi_cli.datasets.sequence import ImuData

    s = _stream()
    warnings = []
    ImuStream.from_sequence(ImuData(s.t_ns, s.gyro, s.acc), 0.0, "bag", warnings.append)
    assert len(warnings) == 1 and "EuRoC ADIS16448" in warnings[0]
    assert est is not None


def test_window_moments_are_numpys_mean_and_std_over_any_span():
    """The standstill test's O(1) statistics (prefix sums of the samples minus the first) agree with
    np.mean / np.std over arbitrary spans of a long stream: 30 min at 200 Hz of a vibrating IMU at rest
    (gyro 0.07 rad/s bias, |a| 9.81 +- 0.02 m/s^2, the offset that a plain E[x^2] - E[x]^2 would cancel
    catastrophically).  Tolerance: 1e-9 of each spread, where the rounding of 3.6e5-term sums leaves
    ~1e-12; the limits test then answers as imu_at_rest."""
    from gevi_cli.inertial.standstill import imu_at_rest, rest_limits_hold

    rng = np.random.default_rng(5)
    n = 360_000
    gyro = rng.normal(0.0, 0.03, (n, 3)) + [0.002, 0.021, 0.078]
    acc = rng.normal(0.0, 0.02, (n, 3)) + [0.3, -0.2, 9.8]
    s = ImuStream((np.arange(n) * 5e6).astype(np.int64), gyro, acc, NOISE)
    an = np.linalg.norm(acc, axis=1)
    for i0, i1 in [(0, 2), (0, n), (17, 400), (n - 1000, n), (123_456, 300_001)]:
        g_std, a_std, a_mean = s.moments.window(i0, i1)
        assert np.allclose(g_std, gyro[i0:i1].std(0), rtol=1e-9, atol=0)
        assert a_std == pytest.approx(an[i0:i1].std(), rel=1e-9)
        assert a_mean == pytest.approx(an[i0:i1].mean(), rel=1e-14)
        # a difference of two prefix sums: their rounding is a random walk of sqrt(3.6e5) steps of
        # eps |S| (|S| <= 2.2e4 here), 3e-9 in all, over the window's >= 2 samples; the gyro bias it
        # estimates is needed to 2e-3 rad/s
        assert np.allclose(s.moments.gyro_mean(i0, i1), gyro[i0:i1].mean(0), rtol=0, atol=3e-9 / (i1 - i0))
        for limits in [(0.1, 0.5, 0.5), (0.029, 0.5, 0.5), (0.1, 0.019, 0.5), (0.1, 0.5, 0.01)]:
            assert rest_limits_hold(g_std, a_std, a_mean, *limits) == imu_at_rest(gyro[i0:i1], acc[i0:i1], *limits)
    assert s.span(5_000_000, 15_000_000) == (1, 4)  # t0 <= t <= t1, as window()
    # built as far as asked for: growing in pieces gives the very sums of one pass
    grown = ImuStream((np.arange(n) * 5e6).astype(np.int64), gyro, acc, NOISE).moments
    for i1 in (3, 5000, 9000, 70_000, n):
        grown.window(0, i1)
    assert all(np.array_equal(getattr(grown, k), getattr(s.moments, k)) for k in ("_g1", "_g2", "_a1", "_a2"))
