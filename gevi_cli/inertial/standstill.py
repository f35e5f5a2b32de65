"""Standstill: detecting it in the IMU and estimating gravity and gyro bias over it.

At rest the gyro measures its bias and the accelerometer the specific force ``R_IW (g e3) + b_a``,
so over a standstill the mean rate is the gyro bias and the mean specific force gives the gravity
direction in the body frame, off by the unknown accelerometer bias (|b_a_perp| / g rad; 0.57 deg on
EuRoC V1_01).  Real platforms "at rest" vibrate (EuRoC's MAV on the floor with rotors idling: gyro std
0.02-0.06 rad/s, |a| std 0.26 m/s^2, ten times the stated white noise), so the IMU test is loose and
the image motion, checked by the pipeline, is the sharper criterion.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gevi_cli.estimators.initialization import GRAVITY


@dataclass(frozen=True)
class StandstillEstimate:
    """Gravity direction and gyro bias from a standstill interval.

    ``gravity_dir_B`` (3,) unit specific-force direction in the body frame (= R_IW e3 up to b_a);
    ``roll``/``pitch`` (rad) of R_WI (ZYX, spec 1); ``b_g`` (3,) rad/s; ``acc_norm`` mean |a| (m/s^2);
    ``duration_s``, ``n`` samples; ``gyro_std`` (3,) rad/s.
    """

    gravity_dir_B: np.ndarray
    roll: float
    pitch: float
    b_g: np.ndarray
    acc_norm: float
    duration_s: float
    n: int
    gyro_std: np.ndarray


def tilt_from_specific_force(a) -> tuple[float, float]:
    """(roll, pitch) whose R_WI^T e3 is the direction of ``a`` (spec 1: R_IW e3 = a / |a| at rest)."""
    a = np.asarray(a, dtype=float)
    n = a / np.linalg.norm(a)
    return float(np.arctan2(n[1], n[2])), float(-np.arcsin(np.clip(n[0], -1.0, 1.0)))


def standstill_estimate(t_ns, gyro, acc) -> StandstillEstimate:
    """Mean-rate gyro bias and mean-specific-force tilt over the samples (all assumed at rest)."""
    gyro = np.asarray(gyro, dtype=float)
    acc = np.asarray(acc, dtype=float)
    a = acc.mean(0)
    roll, pitch = tilt_from_specific_force(a)
    t = np.asarray(t_ns, dtype=np.int64)
    return StandstillEstimate(a / np.linalg.norm(a), roll, pitch, gyro.mean(0), float(np.linalg.norm(acc, axis=1).mean()),
                              float(t[-1] - t[0]) * 1e-9 if len(t) > 1 else 0.0, len(t), gyro.std(0))


#: at rest: gyro std per axis below this (rad/s; vibrating platforms reach 0.06)
STILL_MAX_GYRO_STD = 0.1
#: at rest: std of |a| below this (m/s^2)
STILL_MAX_ACC_STD = 0.5
#: at rest: | mean |a| - g | below this (m/s^2)
STILL_MAX_GRAVITY_ERR = 0.5
#: the three, in imu_at_rest's order (GeVI's start and gevi imu's standstills test the same)
STILL_LIMITS = (STILL_MAX_GYRO_STD, STILL_MAX_ACC_STD, STILL_MAX_GRAVITY_ERR)


def imu_at_rest(gyro, acc, max_gyro_std: float, max_acc_std: float, max_gravity_err: float,
                gravity: float = GRAVITY) -> bool:
    """Loose IMU standstill test over a window: gyro std per axis, |a| std and |mean |a| - g| bounded.

    A rotation or an acceleration large enough to matter shows in these; slow translation does not
    (that is left to the image motion).
    """
    gyro = np.asarray(gyro, dtype=float)
    acc = np.asarray(acc, dtype=float)
    if len(gyro) < 2:
        return False
    an = np.linalg.norm(acc, axis=1)
    return rest_limits_hold(gyro.std(0), an.std(), an.mean(), max_gyro_std, max_acc_std, max_gravity_err, gravity)


def rest_limits_hold(gyro_std, acc_norm_std: float, acc_norm_mean: float, max_gyro_std: float, max_acc_std: float,
                     max_gravity_err: float, gravity: float = GRAVITY) -> bool:
    """The limits of :func:`imu_at_rest` on a window's statistics (rad/s, m/s^2)."""
    return bool(np.all(np.asarray(gyro_std) <= max_gyro_std) and acc_norm_std <= max_acc_std
                and abs(acc_norm_mean - gravity) <= max_gravity_err)


class WindowMoments:
    """Mean and (population) standard deviation of the gyro per axis and of |a| over any index range
    of a stream, in O(1) per range from prefix sums (built as far as the ranges asked for reach).

    Why: the pipeline's standstill test asks for them over everything since the first frame, at every
    frame while the standstill lasts; recomputed, that cost grew with the standstill (8 ms per frame
    after 10 min at 200 Hz, 27 ms after 30 min: quadratic in its length).  The sums are of the samples
    minus the first one, so the variance E[x^2] - E[x]^2 does not cancel the offset (|a| ~ 9.8,
    std ~ 0.01): the rounding left is ~1e-16 of the spread's square, not of g^2.
    """

    def __init__(self, gyro, acc):
        self._gyro = np.asarray(gyro, dtype=float)
        self._acc = np.asarray(acc, dtype=float)
        self.g_ref = self._gyro[0].copy()
        self.a_ref = float(np.linalg.norm(self._acc[0]))
        # built as far as asked for, doubling: a standstill is the start of a stream, whose prefix sums
        # over hours of a 1 kHz IMU would otherwise take ~0.7 GB
        self._n = 0
        self._g1, self._g2 = np.zeros((1, 3)), np.zeros((1, 3))
        self._a1, self._a2 = np.zeros(1), np.zeros(1)

    def _cover(self, i1: int) -> None:
        if i1 <= self._n:
            return
        n = min(len(self._gyro), max(i1, 2 * self._n, 4096))
        x = self._gyro[self._n:n] - self.g_ref
        y = np.linalg.norm(self._acc[self._n:n], axis=1) - self.a_ref

        def extend(prefix, v):
            # one running sum continued from the last entry: the same additions in the same order
            return np.concatenate([prefix[:-1], np.cumsum(np.concatenate([prefix[-1:], v]), axis=0)])

        self._g1, self._g2 = extend(self._g1, x), extend(self._g2, x * x)
        self._a1, self._a2 = extend(self._a1, y), extend(self._a2, y * y)
        self._n = n

    def gyro_mean(self, i0: int, i1: int) -> np.ndarray:
        """Mean rate (3,) of samples i0 .. i1-1 (rad/s)."""
        self._cover(i1)
        return self.g_ref + (self._g1[i1] - self._g1[i0]) / (i1 - i0)

    def window(self, i0: int, i1: int):
        """(gyro std (3,), |a| std, |a| mean) of samples i0 .. i1-1 (at least 1)."""
        self._cover(i1)
        n = i1 - i0
        gm = (self._g1[i1] - self._g1[i0]) / n
        gv = (self._g2[i1] - self._g2[i0]) / n - gm * gm
        am = (self._a1[i1] - self._a1[i0]) / n
        av = (self._a2[i1] - self._a2[i0]) / n - am * am
        return np.sqrt(np.maximum(gv, 0.0)), float(np.sqrt(max(av, 0.0))), self.a_ref + am


def _unit(v):
    return v / np.linalg.norm(v)


def _standstill_bias(t_ns, gyro, acc, i0: int, j: int, window: int, b_prev):
    """The gyro bias that samples ``i0 .. j-1`` (a standstill of the loose IMU test, after the first) say, or
    None when they do not say it.

    The loose test passes slow rotation as well as rest (a constant rate has no spread), so the mean rate
    is the bias only if the specific force did not turn with it: the rate's part perpendicular to the
    mean specific force (the part that would tilt the body), over the time between the first and the last
    window, predicts a turn ``phi_gyr`` of the specific-force direction; the accelerometer shows
    ``phi_acc`` between those windows.  Rest predicts ``phi_acc`` ~ 0, rotation ``phi_acc`` ~ ``phi_gyr``:
    the nearer hypothesis wins (``phi_acc < phi_gyr / 2``).  Only that perpendicular part is taken (the
    part along gravity, a rate about the vertical, is not checked by the accelerometer): returns
    ``b_prev`` + it.  At least two windows.
    """
    if j - i0 < 2 * window:
        return None
    u0, u1 = _unit(acc[i0:i0 + window].mean(0)), _unit(acc[j - window:j].mean(0))
    up = _unit(acc[i0:j].mean(0))
    w = gyro[i0:j].mean(0) - b_prev
    perp = w - up * (up @ w)
    span_s = (int(t_ns[j - 1 - window // 2]) - int(t_ns[i0 + window // 2])) * 1e-9
    phi_acc = float(np.arccos(np.clip(u0 @ u1, -1.0, 1.0)))
    phi_gyr = float(np.linalg.norm(perp)) * span_s
    if phi_gyr > 0.0 and phi_acc >= 0.5 * phi_gyr:
        return None
    return b_prev + perp


def standstill_bias_track(t_ns, gyro, acc, standstills, b0, window: int, causal: bool) -> np.ndarray:
    """Gyro bias (n, 3) rad/s per sample from the standstills of the stream (index ranges ``[i0, i1)`` of
    the loose IMU test, ``window`` samples per test window), starting from ``b0`` (the starting
    standstill's mean rate, or zeros).

    A gyro bias shifts during a flight (the flight in ``../shared/data/mav_vicon_imu`` lands with 2.4 deg/s
    on one axis, 0.02 deg/s at take-off); every later standstill whose specific force did not turn
    (:func:`_standstill_bias`) measures it again.  ``causal``: the latest such measurement, taken over the
    standstill's windows seen so far and applied from the end of the last of them; offline
    (``causal=False``): linear in time between the standstills' centres (each standstill's whole
    measurement; the starting standstill's is ``b0``), constant before the first and after the last.  No
    standstill after the start whose specific force stayed still: ``b0`` throughout.
    """
    t = np.asarray(t_ns, dtype=np.int64)
    g = np.asarray(gyro, dtype=float)
    a = np.asarray(acc, dtype=float)
    n = len(t)
    b = np.asarray(b0, dtype=float).copy()
    out = np.tile(b, (n, 1))
    later = [(i0, i1) for i0, i1 in standstills if i0 > 0]
    if causal:
        for i0, i1 in later:
            base = b
            for j in range(i0 + 2 * window, i1 + 1, window):
                new = _standstill_bias(t, g, a, i0, j, window, base)
                if new is not None:
                    b = new
                    out[j - 1:] = b
        return out
    first = [(i0, i1) for i0, i1 in standstills if i0 == 0]
    centres = [0.5 * (t[0] + t[first[0][1] - 1])] if first else []
    biases = [b] if first else []
    for i0, i1 in later:
        new = _standstill_bias(t, g, a, i0, i1, window, b)
        if new is not None:
            b = new
            centres.append(0.5 * (t[i0] + t[i1 - 1]))
            biases.append(b)
    if not biases:
        return out
    c = np.asarray(centres, dtype=float)
    B = np.asarray(biases)
    return np.stack([np.interp(t.astype(float), c, B[:, i]) for i in range(3)], axis=1)
