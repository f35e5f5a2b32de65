"""Smooth body trajectories with closed-form first and second derivatives.

All trajectories describe the body (= IMU) frame B in the world frame W (z up, gravity -9.81 e3):
``p_WB(t)`` in metres, ``v_WB`` in m/s, ``a_WB`` in m/s^2 (world frame), orientation
``R_WB = Rz(yaw) Ry(pitch) Rx(roll)`` and the body-frame angular velocity ``omega_B`` in rad/s.
Time ``t`` is in seconds from the start of the sequence.

Building blocks are scalar signals returning (value, first derivative, second derivative):

* :class:`Sines` - a sum of sinusoids;
* :class:`Smoothstep` - a quintic 0 -> 1 ramp (zero velocity and acceleration at both ends), used
  for the still start;
* :class:`TimeWarp` - ``tau(t)`` with a sinusoidally varying rate, giving quiet and busy periods.

:class:`HoverMotion` (pool / room presets) is ``x(t) = x0 + s(t) (F(tau(t)) - F(0))`` per
coordinate and Euler angle; :class:`CarMotion` (street preset) drives along a curved road.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gevi_cli.geometry import euler_zyx_rates_to_body_rate, euler_zyx_to_matrix


@dataclass(frozen=True)
class MotionSample:
    """Body state at times ``t`` (arrays with a leading time axis).

    Attributes:
        t: (n,) seconds from the sequence start.
        p_W: (n, 3) position of B in W [m].
        v_W: (n, 3) velocity of B in W [m/s].
        a_W: (n, 3) acceleration of B in W [m/s^2] (without gravity).
        R_WB: (n, 3, 3) orientation (body -> world).
        omega_B: (n, 3) angular velocity of B relative to W, in B coordinates [rad/s].
    """

    t: np.ndarray
    p_W: np.ndarray
    v_W: np.ndarray
    a_W: np.ndarray
    R_WB: np.ndarray
    omega_B: np.ndarray

    @property
    def T_WB(self) -> np.ndarray:
        T = np.zeros((len(self.t), 4, 4))
        T[:, :3, :3] = self.R_WB
        T[:, :3, 3] = self.p_W
        T[:, 3, 3] = 1.0
        return T


# ------------------------------------------------------------------------------------ signals
@dataclass(frozen=True)
class Sines:
    """``f(t) = sum_i amp_i sin(2 pi freq_i t + phase_i)``; freq in Hz (or cycles per unit of t)."""

    amp: tuple[float, ...]
    freq: tuple[float, ...]
    phase: tuple[float, ...]

    def __call__(self, t):
        t = np.asarray(t, float)[..., None]
        a, w, ph = np.asarray(self.amp), 2.0 * np.pi * np.asarray(self.freq), np.asarray(self.phase)
        arg = w * t + ph
        s, c = np.sin(arg), np.cos(arg)
        return (a * s).sum(-1), (a * w * c).sum(-1), (-a * w * w * s).sum(-1)

    def scaled(self, k: float) -> "Sines":
        return Sines(tuple(k * a for a in self.amp), self.freq, self.phase)

    @staticmethod
    def random(rng: np.random.Generator, total_amp: float, periods: tuple[float, float], n: int = 3) -> "Sines":
        """``n`` sinusoids with random periods in ``periods`` (s) whose amplitudes sum to ``total_amp``."""
        weights = rng.uniform(0.5, 1.0, n)
        amp = total_amp * weights / weights.sum()
        per = rng.uniform(periods[0], periods[1], n)
        phase = rng.uniform(0.0, 2.0 * np.pi, n)
        return Sines(tuple(amp.tolist()), tuple((1.0 / per).tolist()), tuple(phase.tolist()))


@dataclass(frozen=True)
class Smoothstep:
    """Quintic ramp from 0 (t <= t0) to 1 (t >= t1); C2 continuous."""

    t0: float
    t1: float

    def __call__(self, t):
        t = np.asarray(t, float)
        if self.t1 <= self.t0:
            one = np.ones_like(t)
            return np.where(t >= self.t0, one, 0.0), np.zeros_like(t), np.zeros_like(t)
        d = self.t1 - self.t0
        x = np.clip((t - self.t0) / d, 0.0, 1.0)
        inside = (t > self.t0) & (t < self.t1)
        f = x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)
        f1 = np.where(inside, 30.0 * x * x * (1.0 - x) ** 2 / d, 0.0)
        f2 = np.where(inside, 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x) / d ** 2, 0.0)
        return f, f1, f2


@dataclass(frozen=True)
class TimeWarp:
    """``tau(t) = r0 t + (r1 / w) (cos(phi) - cos(w t + phi))``: rate ``r0 + r1 sin(w t + phi)`` (> 0).

    With ``w = 2 pi / period`` the motion alternates between quiet (slow) and busy (fast) periods;
    accelerations scale with the square of the rate.
    """

    r0: float = 1.0
    r1: float = 0.0
    period: float = 30.0
    phase: float = 0.0

    def __call__(self, t):
        t = np.asarray(t, float)
        w = 2.0 * np.pi / self.period
        arg = w * t + self.phase
        tau = self.r0 * t + (self.r1 / w) * (np.cos(self.phase) - np.cos(arg))
        return tau, self.r0 + self.r1 * np.sin(arg), self.r1 * w * np.cos(arg)


def _warped_offset(F: Sines, warp: TimeWarp, step: Smoothstep, t):
    """``g(t) = s(t) (F(tau(t)) - F(0))`` with its first and second time derivatives."""
    tau, tau1, tau2 = warp(t)
    f, f1, f2 = F(tau)
    f0 = F(np.zeros(1))[0][0]
    h, h1, h2 = f - f0, f1 * tau1, f2 * tau1 * tau1 + f1 * tau2
    s, s1, s2 = step(t)
    return s * h, s1 * h + s * h1, s2 * h + 2.0 * s1 * h1 + s * h2


# ------------------------------------------------------------------------------------ motions
@dataclass(frozen=True)
class HoverMotion:
    """A vehicle hovering around ``p0`` (pool, room): still start, then smooth 6-DOF motion.

    Attributes:
        p0: start position [m]; euler0: start (yaw, pitch, roll) [rad].
        pos: three :class:`Sines` (x, y, z offsets in metres, as functions of warped time).
        ang: three :class:`Sines` (yaw, pitch, roll offsets in radians).
        warp: quiet/busy time warp; step: the still-start ramp.
    """

    p0: tuple[float, float, float]
    euler0: tuple[float, float, float]
    pos: tuple[Sines, Sines, Sines]
    ang: tuple[Sines, Sines, Sines]
    warp: TimeWarp
    step: Smoothstep

    def __call__(self, t) -> MotionSample:
        t = np.atleast_1d(np.asarray(t, float))
        P = [_warped_offset(F, self.warp, self.step, t) for F in self.pos]
        A = [_warped_offset(F, self.warp, self.step, t) for F in self.ang]
        p = np.stack([P[i][0] for i in range(3)], -1) + np.asarray(self.p0)
        v = np.stack([P[i][1] for i in range(3)], -1)
        a = np.stack([P[i][2] for i in range(3)], -1)
        yaw, pitch, roll = (A[i][0] + self.euler0[i] for i in range(3))
        R = euler_zyx_to_matrix(yaw, pitch, roll)
        omega = euler_zyx_rates_to_body_rate(yaw, pitch, roll, A[0][1], A[1][1], A[2][1])
        return MotionSample(t, p, v, a, R, omega)

    def with_position_scale(self, k: float, p0=None) -> "HoverMotion":
        return HoverMotion(tuple(p0 if p0 is not None else self.p0), self.euler0, tuple(F.scaled(k) for F in self.pos),
                           self.ang, self.warp, self.step)


@dataclass(frozen=True)
class CarMotion:
    """A car driving along the road ``y = road(x)`` (world frame, z up) at roughly ``speed`` m/s.

    ``x(t) = x0 + speed t + surge(t)``, ``y(t) = road(x(t)) + lane(t)``, ``z(t) = height + bump(t)``.
    Yaw follows the velocity direction (``atan2(vy, vx)``); pitch and roll are small sinusoids
    (suspension).  Everything has closed-form derivatives via the chain rule.
    """

    x0: float
    speed: float
    height: float
    surge: Sines
    road: Sines
    lane: Sines
    bump: Sines
    pitch: Sines
    roll: Sines

    def __call__(self, t) -> MotionSample:
        t = np.atleast_1d(np.asarray(t, float))
        sx, sx1, sx2 = self.surge(t)
        x, x1, x2 = self.x0 + self.speed * t + sx, self.speed + sx1, sx2
        r, r1, r2 = self.road(x)
        ln, ln1, ln2 = self.lane(t)
        y, y1, y2 = r + ln, r1 * x1 + ln1, r2 * x1 * x1 + r1 * x2 + ln2
        bz, bz1, bz2 = self.bump(t)
        p = np.stack([x, y, self.height + bz], -1)
        v = np.stack([x1, y1, bz1], -1)
        a = np.stack([x2, y2, bz2], -1)
        yaw = np.arctan2(y1, x1)
        dyaw = (x1 * y2 - y1 * x2) / (x1 * x1 + y1 * y1)
        pt, pt1, _ = self.pitch(t)
        rl, rl1, _ = self.roll(t)
        R = euler_zyx_to_matrix(yaw, pt, rl)
        omega = euler_zyx_rates_to_body_rate(yaw, pt, rl, dyaw, pt1, rl1)
        return MotionSample(t, p, v, a, R, omega)


def max_acceleration(motion, duration: float, dt: float = 0.01) -> float:
    """Largest |a_W| [m/s^2] over [0, duration] on a ``dt`` grid."""
    t = np.arange(0.0, duration + dt, dt)
    return float(np.linalg.norm(motion(t).a_W, axis=1).max())
