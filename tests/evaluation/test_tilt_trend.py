"""TiltErrors.trend_deg_per_min: the least-squares slope of the windowed roll/pitch RMSE over a run."""
from __future__ import annotations

import math

import numpy as np
import pytest

from gevi_cli.evaluation.tilt import TiltErrors


def _errors(err_of_t_s, rate_hz=20.0, duration_s=60.0, start_s=3.0):
    t = start_s + np.arange(int(duration_s * rate_hz)) / rate_hz
    err = err_of_t_s(t)
    return TiltErrors(np.round(t * 1e9).astype(np.int64), err, np.zeros((len(t), 2)))


def test_linear_drift_is_read_back():
    # error growing 0.05 deg per minute from 0.1 deg at t0: each 5 s window's RMSE is its mean to within
    # the window's spread (0.05/12 deg / sqrt(12)), so the slope comes back to ~1e-6 deg/min
    te = _errors(lambda t: 0.1 + 0.05 * (t - 3.0) / 60.0)
    assert te.trend_deg_per_min(int(3e9)) == pytest.approx(0.05, abs=1e-4)


def test_stationary_fluctuation_has_no_trend():
    # a tilt error that fluctuates about 0.1 deg without drifting: slope ~ 0 within the windows' noise
    rng = np.random.default_rng(1)
    te = _errors(lambda t: np.abs(0.1 + 0.02 * rng.standard_normal(len(t))))
    slope = te.trend_deg_per_min(int(3e9))
    # 11-12 windows of 100 samples: window RMSE noise ~0.02/sqrt(100) = 2e-3 deg over a 1 min lever arm
    assert abs(slope) < 0.01


def test_settling_reads_negative_and_short_runs_nan():
    te = _errors(lambda t: 0.3 * np.exp(-(t - 3.0) / 20.0) + 0.05)
    assert te.trend_deg_per_min(int(3e9)) < -0.1
    short = _errors(lambda t: 0.1 + 0 * t, duration_s=12.0)
    assert math.isnan(short.trend_deg_per_min(int(3e9)))  # two full 5 s windows only
    with pytest.raises(ValueError):
        te.trend_deg_per_min(int(3e9), window_s=0.0)
