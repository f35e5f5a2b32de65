"""`gevi imu`'s baselines and noise model: the complementary grid's edge rule, the time-constant
complementary filter against gyro integration, and the noise model measured at rest when none is stated."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli import estimators as est
from gevi_cli.evaluation.imu_report import COMPLEMENTARY_TAUS_S, best_on_grid, imu_report, noise_model, step_125
from gevi_cli.inertial.attitude import complementary, complementary_bank, gyro_only, level_rotations
from gevi_cli.inertial.imu_stream import DEFAULT_NOISE, ImuStream


def test_step_125_walks_the_series_both_ways():
    assert [step_125(t, True) for t in (0.1, 0.2, 0.5, 5.0, 500.0)] == [0.2, 0.5, 1.0, 10.0, 1000.0]
    assert [step_125(t, False) for t in (0.1, 0.2, 1.0, 0.05)] == [0.05, 0.1, 0.5, 0.02]


def test_grid_is_extended_past_a_winning_edge_and_flagged_when_it_still_wins():
    def score(best):
        return lambda taus: [(abs(np.log(t / best)),) for t in taus]

    inside = best_on_grid(COMPLEMENTARY_TAUS_S, score(5.0))
    assert inside.best == 5.0 and not inside.at_edge and len(inside.tried) == len(COMPLEMENTARY_TAUS_S)
    # optimum beyond the upper edge (500 s): 1000 and 2000 s are added, then 5000 s shows 2000 is a minimum
    above = best_on_grid(COMPLEMENTARY_TAUS_S, score(2000.0))
    assert above.best == 2000.0 and not above.at_edge and above.tried[-1][0] == 5000.0
    # below the lower edge, but no time constant under the sample period (k = dt / tau <= 1)
    below = best_on_grid(COMPLEMENTARY_TAUS_S, score(1e-3), min_tau=0.02)
    assert below.best == 0.02 and below.at_edge and below.tried[0][0] == 0.02
    # a score that keeps falling: extended MAX_GRID_EXTENSION times, then flagged
    falling = best_on_grid(COMPLEMENTARY_TAUS_S, lambda taus: [(-t,) for t in taus], max_extension=2)
    assert falling.best == 2000.0 and falling.at_edge


def _tumbling(n=2000, rate=200.0, seed=0):
    rng = np.random.default_rng(seed)
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    gyro = 0.8 * np.sin(np.arange(n)[:, None] / rate * np.array([1.1, 0.7, 0.4]) * 2 * np.pi) + rng.normal(0, 0.01, (n, 3))
    acc = np.tile([0.0, 0.0, 9.81], (n, 1)) + rng.normal(0, 0.3, (n, 3))
    return t, gyro, acc


def test_complementary_with_an_endless_time_constant_is_gyro_integration():
    """k = dt / tau -> 0: the accelerometer never turns g, which then follows the gyro exactly."""
    t, gyro, acc = _tumbling()
    R0, b = est.rtilt(0.3, -0.2), np.array([0.01, -0.02, 0.0])
    g_ref = gyro_only(R0, b, t, gyro)[:, 2, :]  # R^T e3
    g = complementary_bank(R0, b, t, gyro, acc, [1e12, 1.0])
    assert np.abs(g[0] - g_ref).max() < 1e-9
    assert np.allclose(level_rotations(g[1]), complementary(R0, b, t, gyro, acc, 1.0), atol=1e-12)
    assert np.allclose(np.linalg.norm(g, axis=2), 1.0, atol=1e-12)


def test_time_constant_means_the_same_at_any_rate():
    """A tilt error decays as exp(-t / tau) at rest: after tau seconds 1/e of it is left, at 50 or 400 Hz."""
    for rate in (50.0, 400.0):
        n = int(2.0 * rate) + 1
        t = (np.arange(n) * 1e9 / rate).astype(np.int64)
        g = complementary_bank(est.rtilt(0.05, 0.0), np.zeros(3), t, np.zeros((n, 3)),
                               np.tile([0.0, 0.0, 9.81], (n, 1)), [1.0])[0]
        err = np.arcsin(np.linalg.norm(np.cross(g, [0.0, 0.0, 1.0]), axis=1))
        k = int(rate)  # t = 1 s
        assert err[k] / err[0] == pytest.approx(np.exp(-1.0), rel=0.02 if rate == 50.0 else 0.005)


def _still_stream(noise_missing: bool):
    from gevi_cli.datasets.sequence import ImuData

    rng = np.random.default_rng(3)
    n, rate = 2000, 200.0  # 10 s at rest: gyro 0.02 rad/s and acc 0.2 m/s^2 per sample (vibration)
    t = (np.arange(n) * 1e9 / rate).astype(np.int64)
    g = rng.normal(0, 0.02, (n, 3)) + [0.01, -0.02, 0.005]
    a = rng.normal(0, 0.2, (n, 3)) + [0.0, 0.0, 9.81]
    stated = {} if noise_missing else DEFAULT_NOISE
    return ImuStream.from_sequence(ImuData(t, g, a, **stated), 0.0, "imu.csv")


def test_noise_model_measured_at_rest_when_none_is_stated():
    """No densities stated: the filter runs with std x sqrt(dt) measured over the standstill (0.02 rad/s and
    0.2 m/s^2 per sample at 200 Hz: 1.41e-3 and 1.41e-2 per sqrt(Hz), within the 2 % of 10 s of samples),
    and one line says so; the random walks cannot be measured in seconds and stay the defaults."""
    rep = imu_report(_still_stream(noise_missing=True))
    n = rep.noise_used
    assert n.gyro_noise_density == pytest.approx(0.02 / np.sqrt(200.0), rel=0.03)
    assert n.acc_noise_density == pytest.approx(0.2 / np.sqrt(200.0), rel=0.03)
    assert n.gyro_random_walk == DEFAULT_NOISE["gyro_random_walk"]
    assert rep.noise_note.startswith("noise model: none stated; using the white noise measured at rest (0.0-")
    assert f"gyro {n.gyro_noise_density:.3g} rad/s/sqrt(Hz)" in rep.noise_note and "\n" not in rep.noise_note
    assert rep.noise_stated == {"gyro_noise_density": None, "acc_noise_density": None}


def test_a_stated_noise_model_wins():
    stream = _still_stream(noise_missing=False)
    noise, note = noise_model(stream, {"gyro_noise_density": 1.0, "acc_noise_density": 1.0, "over_s": 10.0},
                              [(0.0, 10.0)], [(0, 2000)])
    assert noise == stream.noise and note == "noise model: as stated by the dataset"
