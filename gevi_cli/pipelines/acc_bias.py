"""Horizontal accelerometer bias tracked online from yaw changes [PROPOSAL, ours] (docs/method.md 9b,
"The horizontal bias in flight").

Why: every gravity direction GeVI compares with (the specific force, or the window gravity of
window_gravity.py) is off by ``b_h / g`` rad for a horizontal accelerometer-bias error ``b_h``.  A
standstill cannot tell that bias from a tilt (spec 9.6), so GeVI's roll/pitch carry it: on the 60 s
pool renders 0.2-0.3 deg of the 0.19-0.34 deg tilt error, growing as the bias random-walks.

What separates them: the bias is fixed in the body, gravity in the world.  Chain the frames by the
gyro alone (no accelerometer in the rotations), ``Q_j = R_0^T R_j`` (``R_0`` of the history's first
frame, kept when older frames leave the window); the up direction measured in body
j then reads ``u_j = Q_j^T w + b / g`` with ``w`` the world up in body-0 coordinates.  When the
vehicle yaws, ``Q_j^T w`` turns in the body while ``b / g`` does not, so both are found by linear
least squares over a window of ``T`` seconds.  A slow gyro-bias error tilts the chained frames
linearly in time; ``w + omega tau_j`` takes it up.  The bias random-walks, so it enters as
``beta + beta' tau_j`` (its trend over the window, with the prior of a Brownian path's slope), and
what is returned is its value at the last frame.  The bias enters with a Gaussian prior at the
current estimate, so without yaw the solution stays where it was.  Only the component of ``b``
perpendicular to up is used: the measured ``u_j`` are unit vectors, blind to the vertical bias.

The measurements are taken with the bias estimate of their time (``b_used``); ``u_j + b_used / g``
is what the true bias explains, so the history stays valid across updates.
"""
from __future__ import annotations

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.inertial.standstill import GRAVITY


class AccBiasTracker:
    """Window of (stamp, gyro-chained orientation, measured up + b_used / g); :meth:`solve` returns the
    horizontal bias (m/s^2, body frame) that best explains it, with its posterior std.

    ``prior_sigma`` (m/s^2): the bias prior around the current estimate; ``omega_sigma`` (rad/s): the
    prior of the chain's tilt drift (the gyro-bias error); ``meas_sigma`` (rad): the std of one up
    measurement, with ``corr_frames`` neighbours it is correlated with (the window gravity's overlap);
    ``walk`` (m/s^2/sqrt(s)): the bias random walk, which sets the prior of its trend (0: no trend).
    """

    def __init__(self, window_s: float, prior_sigma: float, omega_sigma: float = 2e-4, meas_sigma: float = 2e-3,
                 corr_frames: float = 20.0, walk: float = 0.0):
        self.window_ns = int(window_s * 1e9)
        self.walk = float(walk)
        self.prior_sigma = float(prior_sigma)
        self.omega_sigma = float(omega_sigma)
        self.meas_sigma = float(meas_sigma)
        self.corr_frames = float(corr_frames)
        self.reset()

    def reset(self) -> None:
        self.t = np.zeros(0, np.int64)
        self.Q = np.zeros((0, 3, 3))
        self.m = np.zeros((0, 3))

    def __len__(self) -> int:
        return len(self.t)

    @property
    def span_s(self) -> float:
        return float(self.t[-1] - self.t[0]) * 1e-9 if len(self.t) else 0.0

    def add(self, t_ns: int, rotvec: np.ndarray | None, up: np.ndarray, b_used: np.ndarray) -> None:
        """Append a frame: ``rotvec`` the gyro rotation (rad, body) from the last frame added (None: start
        a new history), ``up`` the measured unit up direction in the body frame, ``b_used`` the
        accelerometer bias it was computed with."""
        if rotvec is None or len(self.t) == 0 or not np.all(np.isfinite(rotvec)):
            self.reset()
            Q = np.eye(3)
        else:
            Q = self.Q[-1] @ est.exp_so3(rotvec)
        self.t = np.append(self.t, np.int64(t_ns))
        self.Q = np.concatenate([self.Q, Q[None]])
        self.m = np.vstack([self.m, (np.asarray(up, float) + np.asarray(b_used, float) / GRAVITY)[None]])
        old = self.t[-1] - self.t > self.window_ns
        if old.any():
            # dropped without re-referencing the rest: the model only needs Q_j = C R_0^T R_j for one
            # constant C (w absorbs it, and omega's isotropic prior does not see it)
            k = int(np.argmin(old))
            self.t, self.Q, self.m = self.t[k:], self.Q[k:], self.m[k:]

    def solve(self, b_current: np.ndarray) -> tuple[np.ndarray, float] | None:
        """(bias with its horizontal part re-estimated, posterior std of that part in m/s^2), or None
        with fewer than 10 frames.  Unknowns ``x = [w, omega, beta = b / g, beta']``; rows
        ``m_j = Q_j^T w + tau_j Q_j^T omega + beta + tau_j beta'`` (``tau`` from the window's mid-time);
        the bias returned is ``g (beta + beta' tau_last)``."""
        n = len(self.t)
        if n < 10:
            return None
        tau = (self.t - self.t[0]) * 1e-9
        tau = tau - tau.mean()  # w at the window's mid-time: omega and w decouple
        QT = np.swapaxes(self.Q, 1, 2)
        A = np.zeros((n, 3, 12))
        A[:, :, :3] = QT
        A[:, :, 3:6] = QT * tau[:, None, None]
        A[:, :, 6:9] = np.eye(3)
        A[:, :, 9:] = np.eye(3) * tau[:, None, None]
        A = A.reshape(3 * n, 12)
        y = self.m.reshape(3 * n)
        # the rows are correlated over ~corr_frames frames: their information is counted once per group
        wv = 1.0 / (self.meas_sigma ** 2 * self.corr_frames)
        N = wv * (A.T @ A)
        r = wv * (A.T @ y)
        beta0 = np.asarray(b_current, float) / GRAVITY
        pb = (GRAVITY / self.prior_sigma) ** 2
        N[6:9, 6:9] += pb * np.eye(3)
        r[6:9] += pb * beta0
        N[3:6, 3:6] += np.eye(3) / self.omega_sigma ** 2
        # the bias random-walks (density ``walk``, m/s^2/sqrt(s)): its trend over the window, with the
        # prior std of a Brownian path's least-squares slope over T seconds, sqrt(1.2 / T) walk
        T = max(float(tau.max() - tau.min()), 1e-3)
        sl = self.walk * np.sqrt(1.2 / T) / GRAVITY
        N[9:, 9:] += np.eye(3) / max(sl, 1e-12) ** 2
        try:
            C = np.linalg.inv(N)  # the posterior covariance, which the std needs anyway
        except np.linalg.LinAlgError:
            return None
        x = C @ r
        up = self.m.mean(0)
        up = up / np.linalg.norm(up)
        P = np.eye(3) - np.outer(up, up)  # the horizontal plane of the body (mean up of the window)
        # the bias now: the window's mid-time value carried to its last frame by the trend
        b_now = (x[6:9] + x[9:] * tau[-1]) * GRAVITY
        b = np.asarray(b_current, float) + P @ (b_now - b_current)
        J = np.hstack([np.eye(3), np.eye(3) * tau[-1]])
        std = float(np.sqrt(max(np.trace(P @ J @ C[6:, 6:] @ J.T @ P), 0.0) / 2.0)) * GRAVITY
        return b, std


class InFlightBias:
    """The horizontal accelerometer bias in flight [PROPOSAL]: each visually tracked frame's window
    gravity into ``tracker`` (None: off), chained by the gyro to the frame before when that one is in it
    too; at keyframes the estimate is adopted when its posterior std is below ``max_std`` (m/s^2).

    ``std``: the last estimate's posterior std (NaN: none yet); ``updates``: seconds since the first
    frame of each adoption."""

    def __init__(self, tracker: AccBiasTracker | None, max_std: float):
        self.tracker, self.max_std = tracker, max_std
        self.std = float("nan")
        self.updates: list[float] = []

    def observe(self, t_ns: int, up: np.ndarray | None, rotvec: np.ndarray, t_prev_ns: int | None, keyframe: bool,
                b_a: np.ndarray, since_start_s: float) -> np.ndarray:
        """A frame at ``t_ns`` with its window gravity ``up`` (body, None: not tracked or none) and the
        gyro rotation ``rotvec`` since the frame at ``t_prev_ns``; returns the bias to use from now on."""
        bt = self.tracker
        if up is None:
            bt.reset()
            return b_a
        chained = len(bt) and t_prev_ns is not None and int(bt.t[-1]) == t_prev_ns
        bt.add(t_ns, rotvec if chained else None, up, b_a)
        if not keyframe:
            return b_a
        sol = bt.solve(b_a)
        if sol is None:
            return b_a
        b, self.std = sol
        if self.std < self.max_std:
            self.updates.append(since_start_s)
            return b
        return b_a
