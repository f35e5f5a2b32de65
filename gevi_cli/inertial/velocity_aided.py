"""IMU-only roll/pitch for platforms that accelerate: gyro + accelerometer integrated to a velocity
that must stay bounded [PROPOSAL].

Why not the gravity prior of :class:`~gevi_cli.inertial.attitude.GravityAttitudeFilter`: the
accelerometer direction is gravity only on average.  A multirotor tilts to accelerate, and then its
specific force points along its thrust and reads "level" for as long as the acceleration lasts;
rotor vibration adds band-limited noise far above the white-noise density.  Errors of that kind are
correlated over seconds, so updating the tilt with them 50 times a second, however their covariance
is estimated, follows the acceleration (EuRoC-like flight is forgiving, aggressive flight is not).
What every platform does obey is that its velocity stays bounded: integrated with the right
attitude, the specific force minus gravity gives a velocity that returns to zero; with a tilt error
``dtheta`` it drifts by ``g dtheta`` per second.  So the accelerometer enters here as the input of a
velocity with the pseudo-measurement ``v = 0``, and, weighted by how much the platform accelerates,
as the gravity direction.

Error-state Kalman filter, state ``R_WI`` (right perturbation ``R = R_hat Exp(dtheta)``), gyro bias
``b_g``, gyro scale-factor error ``s`` (per axis: ``w_meas = (1 + s) w + b_g + n``), velocity ``v_W``
(world frame, z up).  Per IMU sample ``k -> k+1`` (zero-order hold, ``dt``):

* ``w = (w_k - b_g) (1 - s)``, ``R <- R Exp(w dt)``, ``v <- v + (R a_k - g e3) dt``;
* ``F``: ``dtheta <- Exp(-w dt) dtheta - J_r dt ((1 - s) db + diag(w_k - b_g) ds)``,
  ``dv <- dv - R [a_k]x dtheta dt``; ``Q = diag(sigma_g^2 dt, sigma_bg^2 dt, 0, sigma_a^2 dt)``
  (the noise model's densities).

Per block (``update_hz``, length ``T_block``), two updates, each a prior on the motion written as a
spectral density (so it means the same at any update or sample rate):

* **gravity direction**: the block's mean unit specific force ``a_dir = R^T e3 + (horizontal
  non-gravitational acceleration) / g``, ``H = [[R^T e3]x, 0, 0, 0]``, covariance
  ``2 tau_a sigma_a^2 / g^2 / T_block I``: an error of RMS ``sigma_a / g`` correlated over
  ``tau_a`` (``accel_corr_s``).  ``sigma_a^2`` is measured on the way: the variance of the horizontal
  part of ``R a - g e3`` (means over ``accel_sub_s``) over the last ``accel_window_s``, or over the
  last ``accel_short_s`` when that is larger (the start of a manoeuvre counts at once, its end only
  when the window has forgotten it).  The variance, not the mean square: a tilt error adds a
  constant ``g dtheta`` that must not weaken the update meant to remove it.  Floor: the white noise.
  At rest and in calm motion this is the tight prior; in aggressive flight it fades.
* **velocity**: ``0 = v + n_v``, ``Cov(n_v) = q_v / T_block I``, ``q_v`` (m^2/s, ``velocity_psd``) the
  spectral density of the platform's velocity seen as white noise (a velocity of RMS ``sigma``
  decorrelating in ``tau`` seconds has ``q_v = 2 sigma^2 tau``).  A tilt error is corrected on the
  time scale at which its velocity drift ``g dtheta t`` outgrows that bound.

The gyro's bias and scale factor are estimated on the way (the yaw-axis bias only as far as the
motion tilts that axis).  No Euler angles anywhere.  Units: rad, s, m, m/s, m/s^2.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from gevi_cli.estimators.initialization import GRAVITY
from gevi_cli.geometry import exp_so3_and_jr, skew
from gevi_cli.inertial.imu_stream import ImuNoise

E3 = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class VelocityAidedConfig:
    """Settings of :class:`VelocityAidedFilter` (SI units)."""

    update_hz: float = 50.0  # updates per second (their covariances follow the block length)
    velocity_psd: float = 0.25  # q_v [m^2/s]: e.g. 0.5 m/s RMS decorrelating within 0.5 s (docs/studies/imu_attitude.md)
    accel_corr_s: float = 8.0  # tau_a [s]: correlation time of the horizontal non-gravitational acceleration
    accel_window_s: float = 10.0  # sigma_a^2 over this window [s] ...
    accel_short_s: float = 1.0  # ... or over this one when larger [s]
    accel_sub_s: float = 0.25  # of means of R a - g e3 over this [s] (vibration averaged out)
    scale_sigma0: float = 0.01  # prior std of each gyro scale-factor error (a MEMS gyro's 1% class)
    bias_sigma0: float = 5e-3  # prior std of the initial gyro bias around its estimate (rad/s)
    tilt_sigma0: float = 0.01  # prior std of the initial tilt (rad)
    velocity_sigma0: float = 0.05  # prior std of the initial velocity (m/s; the filter starts at rest)


class VelocityAidedFilter:
    """The filter's state and its steps; ``R`` is R_WI (world z up, yaw arbitrary), ``v`` in W."""

    def __init__(self, R_WI0: np.ndarray, b_g0: np.ndarray, noise: ImuNoise, dt_sample: float,
                 cfg: VelocityAidedConfig = VelocityAidedConfig(), b_a: np.ndarray | None = None):
        self.R = np.asarray(R_WI0, dtype=float).copy()
        self.b_g = np.asarray(b_g0, dtype=float).copy()
        self.scale = np.zeros(3)
        self.v = np.zeros(3)
        self.b_a = np.zeros(3) if b_a is None else np.asarray(b_a, dtype=float)
        self.noise, self.cfg = noise, cfg
        self.P = np.diag([cfg.tilt_sigma0**2] * 2 + [1e-4] + [cfg.bias_sigma0**2] * 3 + [cfg.scale_sigma0**2] * 3
                         + [cfg.velocity_sigma0**2] * 3)
        self.dt_sample = dt_sample
        T_block = max(1.0 / cfg.update_hz, dt_sample)
        self.dir_floor = max((noise.acc_noise_density / np.sqrt(T_block) / GRAVITY) ** 2, 1e-12)  # rad^2
        self._sub_dv, self._sub_t = np.zeros(3), 0.0  # R a - g e3 integrated since the last sub-block
        self._sub_means: deque = deque(maxlen=max(int(round(cfg.accel_window_s / cfg.accel_sub_s)), 2))
        self._blk_acc, self._blk_n = np.zeros(3), 0
        self.accel_var: float | None = None  # sigma_a^2 [m^2/s^4], None until two sub-blocks are in

    def propagate(self, w_meas: np.ndarray, a_meas: np.ndarray, dt: float) -> None:
        wb = np.asarray(w_meas, dtype=float) - self.b_g
        phi = wb * (1.0 - self.scale) * dt
        dR, Jr = exp_so3_and_jr(phi)
        a = np.asarray(a_meas, dtype=float) - self.b_a
        F = np.eye(12)
        F[:3, :3] = dR.T
        F[:3, 3:6] = -Jr * ((1.0 - self.scale) * dt)
        F[:3, 6:9] = -Jr * (wb * dt)
        F[9:, :3] = -self.R @ skew(a) * dt
        a_W = self.R @ a - GRAVITY * E3
        self.v = self.v + a_W * dt
        self._sub_dv += a_W * dt
        self._sub_t += dt
        self._blk_acc += a
        self._blk_n += 1
        P = F @ self.P @ F.T
        n = self.noise
        P[:3, :3] += n.gyro_noise_density**2 * dt * np.eye(3)
        P[3:6, 3:6] += n.gyro_random_walk**2 * dt * np.eye(3)
        P[9:, 9:] += n.acc_noise_density**2 * dt * np.eye(3)
        self.P = P
        self.R = self.R @ dR

    def update(self, T_block: float) -> None:
        """The gravity-direction update, then the velocity pseudo-measurement ``v = 0``, over a block of
        ``T_block`` seconds (the samples propagated since the last update)."""
        cfg = self.cfg
        if self._sub_t >= cfg.accel_sub_s:
            self._sub_means.append(self._sub_dv[:2] / self._sub_t)
            self._sub_dv, self._sub_t = np.zeros(3), 0.0
            if len(self._sub_means) >= 2:
                m = np.array(self._sub_means)
                n_short = max(int(round(cfg.accel_short_s / cfg.accel_sub_s)), 2)
                self.accel_var = float(max(m.var(0).sum(), m[-n_short:].var(0).sum()))
        if self._blk_n and self.accel_var is not None:
            a = self._blk_acc / self._blk_n
            g_B = self.R.T @ E3
            r = a / np.linalg.norm(a) - g_B
            var = max(2.0 * cfg.accel_corr_s * self.accel_var / GRAVITY**2 / max(T_block, 1e-9), self.dir_floor)
            H = np.zeros((3, 12))
            H[:, :3] = skew(g_B)
            self._correct(H, r, var)
        self._blk_acc, self._blk_n = np.zeros(3), 0
        H = np.zeros((3, 12))
        H[:, 9:] = np.eye(3)
        self._correct(H, -self.v, cfg.velocity_psd / max(T_block, 1e-9))

    def _correct(self, H: np.ndarray, r: np.ndarray, var: float) -> None:
        """Kalman update with residual ``r``, Jacobian ``H`` (3, 12), measurement covariance ``var I``."""
        S = H @ self.P @ H.T + var * np.eye(3)
        K = np.linalg.solve(S, H @ self.P).T  # (12, 3); S and P symmetric
        dx = K @ r
        I_KH = np.eye(12) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + var * (K @ K.T)  # Joseph form
        dR, _ = exp_so3_and_jr(dx[:3])
        self.R = self.R @ dR
        self.b_g = self.b_g + dx[3:6]
        self.scale = self.scale + dx[6:9]
        self.v = self.v + dx[9:]

    def run(self, t_ns, gyro, acc):
        """Propagate with every sample and update once per block; an
        :class:`~gevi_cli.inertial.attitude.AttitudeTrack` per block (``Sigma``: the attitude-error
        covariance P_theta, rad^2) with the scale-factor estimates in ``scale``."""
        from gevi_cli.inertial.attitude import AttitudeTrack

        t = np.asarray(t_ns, dtype=np.int64)
        gyro = np.asarray(gyro, dtype=float)
        acc = np.asarray(acc, dtype=float)
        dts = np.diff(t) * 1e-9
        block = max(int(round(1.0 / (self.cfg.update_hz * np.median(dts)))), 1)
        out_t, out_R, out_b, out_S, out_s = [], [], [], [], []
        for k0 in range(0, len(t) - 1, block):
            k1 = min(k0 + block, len(t) - 1)
            for k in range(k0, k1):
                self.propagate(gyro[k], acc[k], dts[k])
            self.update(float(dts[k0:k1].sum()))
            out_t.append(t[k1])
            out_R.append(self.R.copy())
            out_b.append(self.b_g.copy())
            out_S.append(self.P[:3, :3].copy())
            out_s.append(self.scale.copy())
        return AttitudeTrack(np.array(out_t, dtype=np.int64), np.array(out_R), np.array(out_b), np.array(out_S),
                             scale=np.array(out_s))
