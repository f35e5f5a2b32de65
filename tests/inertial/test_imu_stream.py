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
