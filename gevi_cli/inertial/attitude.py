"""IMU-only roll/pitch: gyro propagation anchored by an adaptively weighted gravity prior [PROPOSAL].

The spec's BCD (section 8) needs visual residuals; with the IMU alone we keep its two ideas -- the
gravity prior ``a_dir - R_WI^T e3`` and a covariance of that prior estimated from the residuals
themselves (the closed-form Sigma-step of spec 8.3 over a sliding window, eigenvalues clipped to
``[lo, hi]``) -- inside an error-state Kalman filter whose state is the attitude ``R_WI`` (right
perturbation ``R = R_hat Exp(dphi)``, body frame) and the gyro bias ``b_g``:

* propagation per IMU sample: ``R <- R Exp((w - b_g) dt)``, ``F = [[Exp(-(w-b)dt), -J_r dt], [0, I]]``,
  ``Q = diag(sigma_g^2 dt I, sigma_bg^2 dt I)`` (densities);
* update per block of samples (``update_hz``): measured unit specific force ``a_dir`` (block mean,
  accelerometer bias removed), predicted ``R^T e3``, ``H = [[R^T e3]_x, 0]``, measurement covariance
  ``Sigma_imu`` = clip(sliding mean of the residual outer products, lo, hi).  When the platform
  accelerates the residuals grow, Sigma grows with them and the gyro carries the attitude; at rest
  the prior tightens to the noise floor ``lo = (sigma_a / sqrt(T_block) / g)^2``.

Through the gravity updates the horizontal gyro-bias components become observable, which is what
decides long-run accuracy (with a fixed standstill bias, gyro-only integration drifts by degrees
within a minute on EuRoC).  The yaw-axis bias is not observable from gravity.  Units: rad, s, m/s^2.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.estimators.initialization import GRAVITY
from gevi_cli.geometry import right_jacobian
from gevi_cli.inertial.imu_stream import ImuNoise

E3 = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class AttitudeFilterConfig:
    update_hz: float = 50.0  # gravity updates per second (block means of the accelerometer)
    window_s: float = 2.0  # sliding window of residuals for the adaptive Sigma_imu (100 residuals at 50 Hz: a
    # stable 3x3 estimate; on EuRoC V1_01 0.5/1/2/4 s gave tilt RMSE 1.38/1.16/1.04/0.99 deg)
    hi: float = 0.2**2  # upper eigenvalue bound of Sigma_imu (spec 8.3)
    adaptive: bool = True  # False: Sigma_imu = lo I (the fixed-weight baseline)
    bias_sigma0: float = 5e-3  # prior std of the initial gyro bias around its estimate (rad/s)
    tilt_sigma0: float = 0.01  # prior std of the initial tilt (rad)


@dataclass
class AttitudeTrack:
    """Per-update output: stamps (ns), R_WI (n, 3, 3), gyro bias (n, 3), Sigma (n, 3, 3): the gravity
    prior's Sigma_imu here, the attitude-error covariance in :mod:`.velocity_aided`, which also gives
    the gyro scale-factor errors (n, 3) in ``scale``."""

    t_ns: np.ndarray
    R_WI: np.ndarray
    b_g: np.ndarray
    Sigma: np.ndarray
    scale: np.ndarray | None = None

    @property
    def tilt(self) -> np.ndarray:
        roll, pitch = est.tilt_angles(self.R_WI)
        return np.stack([roll, pitch], axis=1)


class GravityAttitudeFilter:
    """The filter's state and its two steps; ``R_WI`` is gravity-aligned (world z up), yaw arbitrary."""

    def __init__(self, R_WI0: np.ndarray, b_g0: np.ndarray, noise: ImuNoise, dt_sample: float,
                 cfg: AttitudeFilterConfig = AttitudeFilterConfig(), b_a: np.ndarray | None = None):
        self.R = np.asarray(R_WI0, dtype=float).copy()
        self.b_g = np.asarray(b_g0, dtype=float).copy()
        self.b_a = np.zeros(3) if b_a is None else np.asarray(b_a, dtype=float)
        self.noise, self.cfg = noise, cfg
        self.P = np.diag([cfg.tilt_sigma0**2] * 2 + [1e-4] + [cfg.bias_sigma0**2] * 3)
        T_block = max(1.0 / cfg.update_hz, dt_sample)
        self.lo = max((noise.acc_noise_density / np.sqrt(T_block) / GRAVITY) ** 2, 1e-10)
        self.Sigma = self.lo * np.eye(3)
        self._window: deque = deque()
        self._S = np.zeros((3, 3))
        self._window_n = max(int(round(cfg.window_s * cfg.update_hz)), 3)

    def propagate(self, w: np.ndarray, dt: float) -> None:
        phi = (np.asarray(w, dtype=float) - self.b_g) * dt
        dR = est.exp_so3(phi)
        F = np.eye(6)
        F[:3, :3] = dR.T
        F[:3, 3:] = -right_jacobian(phi) * dt
        q_g, q_b = self.noise.gyro_noise_density**2 * dt, self.noise.gyro_random_walk**2 * dt
        self.P = F @ self.P @ F.T
        self.P[:3, :3] += q_g * np.eye(3)
        self.P[3:, 3:] += q_b * np.eye(3)
        self.R = self.R @ dR

    def update(self, acc_mean: np.ndarray) -> None:
        a = np.asarray(acc_mean, dtype=float) - self.b_a
        a_dir = a / np.linalg.norm(a)
        g_B = self.R.T @ E3
        r = a_dir - g_B
        if self.cfg.adaptive:
            outer = np.outer(r, r)
            self._window.append(outer)
            self._S += outer
            if len(self._window) > self._window_n:
                self._S -= self._window.popleft()
            s, V = np.linalg.eigh(self._S / len(self._window))
            self.Sigma = (V * np.clip(s, self.lo, self.cfg.hi)) @ V.T
        H = np.zeros((3, 6))
        H[:, :3] = est.skew(g_B)
        S = H @ self.P @ H.T + self.Sigma
        K = np.linalg.solve(S, H @ self.P).T
        dx = K @ r
        I_KH = np.eye(6) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ self.Sigma @ K.T  # Joseph form: stays symmetric PSD
        self.R = self.R @ est.exp_so3(dx[:3])
        self.b_g = self.b_g + dx[3:]


def run_filter(filt, t_ns, gyro, acc) -> AttitudeTrack:
    """Propagate with every sample (zero-order hold) and update once per block; output per block.
    A filter with its own ``run`` (:class:`~gevi_cli.inertial.velocity_aided.VelocityAidedFilter`) runs it."""
    if hasattr(filt, "run"):
        return filt.run(t_ns, gyro, acc)
    t = np.asarray(t_ns, dtype=np.int64)
    gyro = np.asarray(gyro, dtype=float)
    acc = np.asarray(acc, dtype=float)
    dts = np.diff(t) * 1e-9
    block = max(int(round(1.0 / (filt.cfg.update_hz * np.median(dts)))), 1)
    out_t, out_R, out_b, out_S = [], [], [], []
    for k0 in range(0, len(t) - 1, block):
        k1 = min(k0 + block, len(t) - 1)
        for k in range(k0, k1):
            filt.propagate(gyro[k], dts[k])
        filt.update(acc[k0 + 1:k1 + 1].mean(0))
        out_t.append(t[k1])
        out_R.append(filt.R.copy())
        out_b.append(filt.b_g.copy())
        out_S.append(filt.Sigma.copy())
    return AttitudeTrack(np.array(out_t, dtype=np.int64), np.array(out_R), np.array(out_b), np.array(out_S))


def gyro_only(R_WI0: np.ndarray, b_g: np.ndarray, t_ns, gyro) -> np.ndarray:
    """Plain gyro integration from ``R_WI0`` with a fixed bias: R_WI at every sample (n, 3, 3)."""
    t = np.asarray(t_ns, dtype=np.int64)
    dts = np.diff(t) * 1e-9
    dR = est.exp_so3((np.asarray(gyro, dtype=float)[:-1] - b_g) * dts[:, None])
    out = np.empty((len(t), 3, 3))
    out[0] = R = np.asarray(R_WI0, dtype=float)
    for k in range(len(dts)):
        R = R @ dR[k]
        out[k + 1] = R
    return out


def complementary_bank(R_WI0: np.ndarray, b_g: np.ndarray, t_ns, gyro, acc, taus_s) -> np.ndarray:
    """Fixed-gain complementary filters, one per time constant in ``taus_s`` (s), run side by side.

    Per sample ``k -> k+1`` the gravity direction in the body frame ``g = R_WI^T e3`` is carried by the
    gyro (``g <- Exp((w_k - b_g) dt)^T g``, the zero-order hold of :func:`run_filter`) and then turned
    toward the measured unit specific force ``a`` by the angle ``(dt / tau) |g x a|`` (a Mahony
    proportional term with gain ``1 / tau`` rad/s per rad: the same filter at any sample rate).  The
    turn is applied as ``g + k (a - (g.a) g)``, renormalised (``k = dt / tau`` <= 1; it differs from the
    exact rotation by O(k^3)).  Returns ``g`` per filter and sample, (len(taus), n, 3), unit vectors.
    Only ``g`` is propagated: roll and pitch depend on nothing else, and the filters stay cheap (one
    (G, 3) step per sample for the whole grid)."""
    t = np.asarray(t_ns, dtype=np.int64)
    dts = np.diff(t) * 1e-9
    dR = est.exp_so3((np.asarray(gyro, dtype=float)[:-1] - b_g) * dts[:, None])
    a = np.asarray(acc, dtype=float)
    a_dir = a / np.linalg.norm(a, axis=1, keepdims=True)
    k_all = np.minimum(dts[:, None] / np.asarray(taus_s, dtype=float)[None, :], 1.0)[:, :, None]  # (n-1, G, 1)
    g = np.tile(np.asarray(R_WI0, dtype=float)[2], (len(k_all[0]), 1))  # R^T e3 = third row of R
    out = np.empty((len(t), len(g), 3))
    out[0] = g
    for k in range(len(dts)):
        g = g @ dR[k]  # (dR^T g^T)^T for every row
        ak = a_dir[k + 1]
        g = g + k_all[k] * (ak - (g @ ak)[:, None] * g)
        g /= np.sqrt(np.einsum("ij,ij->i", g, g))[:, None]
        out[k + 1] = g
    return out.transpose(1, 0, 2)


def level_rotations(g_B: np.ndarray) -> np.ndarray:
    """Yaw-free ``R_WI = Ry(pitch) Rx(roll)`` (n, 3, 3) whose ``R^T e3`` is the unit vector ``g_B`` (n, 3)."""
    g = np.asarray(g_B, dtype=float)
    return est.rtilt(np.arctan2(g[:, 1], g[:, 2]), -np.arcsin(np.clip(g[:, 0], -1.0, 1.0)))


def complementary(R_WI0: np.ndarray, b_g: np.ndarray, t_ns, gyro, acc, tau_s: float) -> np.ndarray:
    """One complementary filter of :func:`complementary_bank` with time constant ``tau_s`` (s): the
    yaw-free R_WI per sample (n, 3, 3)."""
    return level_rotations(complementary_bank(R_WI0, b_g, t_ns, gyro, acc, [tau_s])[0])
