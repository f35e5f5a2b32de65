"""IMU synthesis from an analytic trajectory.

The IMU frame is the body frame B.  Measurements at stamp ``t_k``:

* gyro  ``w_k = omega_B(t_k) + b_g(t_k) + n_g``,  ``n_g ~ N(0, sigma_g^2 / dt)``;
* accel ``a_k = R_WB(t_k)^T (a_W(t_k) - g_W) + b_a(t_k) + n_a``, ``g_W = (0, 0, -9.81)`` (world z up),
  ``n_a ~ N(0, sigma_a^2 / dt)``;
* biases are random walks ``b_{k+1} = b_k + sigma_bw sqrt(dt) N(0, I)``.

``sigma_g, sigma_a`` are the continuous-time noise densities and ``sigma_bw`` the random-walk
densities, the same numbers that are written to ``imu0/sensor.yaml`` (Kalibr/EuRoC convention).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# the simulator's own g (the estimators' is estimators.initialization.GRAVITY, the same 9.81): `gevi
# simulate` does not load the estimator library (~0.1 s of imports)
GRAVITY = 9.81
G_W = np.array([0.0, 0.0, -GRAVITY])


@dataclass(frozen=True)
class ImuParams:
    """IMU rate and noise model (continuous-time densities, EuRoC ADIS16448 defaults).

    Attributes:
        rate_hz: sample rate [Hz].
        gyro_noise_density: [rad / s / sqrt(Hz)].
        gyro_random_walk: [rad / s^2 / sqrt(Hz)].
        acc_noise_density: [m / s^2 / sqrt(Hz)].
        acc_random_walk: [m / s^3 / sqrt(Hz)].
        gyro_bias_init: std of the initial gyro bias per axis [rad/s].
        acc_bias_init: std of the initial accelerometer bias per axis [m/s^2].
    """

    rate_hz: float = 200.0
    gyro_noise_density: float = 1.6968e-04
    gyro_random_walk: float = 1.9393e-05
    acc_noise_density: float = 2.0e-03
    acc_random_walk: float = 3.0e-03
    gyro_bias_init: float = 2.0e-3
    acc_bias_init: float = 2.0e-2

    def noise_free(self) -> "ImuParams":
        return ImuParams(self.rate_hz, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ImuSeries:
    """Synthesised IMU samples; all arrays have a leading axis of length n.

    Attributes:
        t_ns: stamps [ns]; gyro [rad/s], acc [m/s^2]: measurements in the body frame.
        bias_gyro, bias_acc: the true biases at each stamp (for the ground truth file).
        gyro_true, acc_true: noise- and bias-free angular rate and specific force.
    """

    t_ns: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    bias_gyro: np.ndarray
    bias_acc: np.ndarray
    gyro_true: np.ndarray
    acc_true: np.ndarray


def specific_force(R_WB: np.ndarray, a_W: np.ndarray) -> np.ndarray:
    """``R_WB^T (a_W - g_W)`` in the body frame, (n, 3)."""
    return np.einsum("nji,nj->ni", R_WB, a_W - G_W)


def random_walk(rng: np.random.Generator, n: int, init_std: float, density: float, dt: float) -> np.ndarray:
    """(n, 3) random walk starting at N(0, init_std^2) with increments N(0, density^2 dt)."""
    b0 = rng.normal(0.0, 1.0, 3) * init_std
    steps = rng.normal(0.0, 1.0, (n, 3)) * density * np.sqrt(dt)
    steps[0] = 0.0
    return b0 + np.cumsum(steps, axis=0)


def synthesize_imu(motion, t_ns: np.ndarray, t0_ns: int, params: ImuParams, rng: np.random.Generator) -> ImuSeries:
    """Sample ``motion`` (a callable returning :class:`~gevi_cli.simulate.motion.MotionSample`) at ``t_ns``.

    ``t0_ns`` is the stamp of motion time 0.  The random draws happen in a fixed order (gyro bias,
    accel bias, gyro noise, accel noise), so equal seeds give equal series.
    """
    t_ns = np.asarray(t_ns, dtype=np.int64)
    dt = 1.0 / params.rate_hz
    m = motion((t_ns - t0_ns).astype(np.float64) * 1e-9)
    n = len(t_ns)
    gyro_true = m.omega_B
    acc_true = specific_force(m.R_WB, m.a_W)
    bg = random_walk(rng, n, params.gyro_bias_init, params.gyro_random_walk, dt)
    ba = random_walk(rng, n, params.acc_bias_init, params.acc_random_walk, dt)
    ng = rng.normal(0.0, 1.0, (n, 3)) * params.gyro_noise_density / np.sqrt(dt)
    na = rng.normal(0.0, 1.0, (n, 3)) * params.acc_noise_density / np.sqrt(dt)
    return ImuSeries(t_ns, gyro_true + bg + ng, acc_true + ba + na, bg, ba, gyro_true, acc_true)
