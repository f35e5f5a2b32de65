"""The recent visually tracked motion of the body: velocity and acceleration in W from positions.

GeVI keeps the body positions (metres, in the gravity-aligned world W) of its last visually tracked
frames.  Two things are read from them:

* the velocity (m/s) that the IMU carries on over frames vision cannot track: a line fit over the
  last 0.5 s;
* the body acceleration ``a_W`` (m/s^2) that the gravity residual of the BCD refinement removes from
  the specific force (docs/method.md, "acceleration compensation", [PROPOSAL]): a least-squares
  polynomial fit over the last ``window_s`` evaluated at the frame being tracked.

Stereo gives metric positions, so the acceleration comes without the tilt: a tilt error ``d`` changes
``a_W`` by ``d x a_W``, second order, while the specific force itself is off by ``a / g`` rad.  The
history restarts whenever a frame is not tracked visually: IMU-carried positions would feed the tilt
back into the estimate of its own correction.
"""
from __future__ import annotations

import numpy as np

VELOCITY_WINDOW_NS = 500_000_000
MIN_VELOCITY_SPAN_NS = 150_000_000
POWER_WINDOW_NS = 2_000_000_000


class RecentMotion:
    """Body positions ``p_W`` (m) at stamps ``t_ns`` of the last visually tracked frames."""

    def __init__(self, acc_window_s: float, acc_order: int = 2):
        self.acc_window_ns = int(acc_window_s * 1e9)
        self.acc_order = int(acc_order)
        self.keep_ns = max(VELOCITY_WINDOW_NS, self.acc_window_ns)
        self.t: list[int] = []
        self.p: list[np.ndarray] = []
        self._arr: tuple[np.ndarray, np.ndarray] | None = None  # (t, p) as arrays, until the next add/reset
        self.power: list[tuple[int, float]] = []  # (t_ns, |a|^2 / 3 - var(a)) of recent estimates

    def reset(self) -> None:
        self.t, self.p = [], []
        self._arr = None

    def add(self, t_ns: int, p_W: np.ndarray) -> None:
        keep = [k for k, t in enumerate(self.t) if t_ns - t <= self.keep_ns]
        self.t = [self.t[k] for k in keep] + [int(t_ns)]
        self.p = [self.p[k] for k in keep] + [np.asarray(p_W, dtype=float)]
        self._arr = None

    def _arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The history as arrays, built once per added frame (the BCD window re-reads it several times)."""
        if self._arr is None:
            self._arr = (np.array(self.t, dtype=np.int64), np.array(self.p, dtype=float).reshape(-1, 3))
        return self._arr

    def _since(self, t_ns: int, span_ns: int) -> tuple[np.ndarray, np.ndarray]:
        t, P = self._arrays()
        sel = t_ns - t <= span_ns
        return (t[sel] - t_ns) * 1e-9, P[sel]

    def velocity(self) -> np.ndarray | None:
        """Line-fit velocity over the last 0.5 s (m/s), or None with less than 3 frames over 0.15 s."""
        if not self.t:
            return None
        tau, P = self._since(self.t[-1], VELOCITY_WINDOW_NS)
        if len(tau) < 3 or tau[-1] - tau[0] < MIN_VELOCITY_SPAN_NS * 1e-9:
            return None
        tc = tau - tau.mean()
        return (tc @ (P - P.mean(0))) / (tc @ tc)

    def acceleration(self, t_ns: int) -> np.ndarray:
        """Acceleration at ``t_ns`` (m/s^2, W) from the positions over ``acc_window_s``: the window ends
        at ``t_ns`` for the frame being tracked and slides forward, up to centred on ``t_ns``, as later
        frames are known (a frame of the BCD window is re-read each frame).  Zero until the window holds
        6 frames over at least 60 % of its length (a standstill start begins at rest).

        Polynomials of degree 2 and 3 are fitted by least squares; with time measured from ``t_ns`` the
        acceleration there is twice the quadratic coefficient, whatever the degree.  Degree 2 gives the
        window's mean acceleration (a lag of half the window when it ends at ``t_ns``), degree 3
        extrapolates its trend at a higher noise.  The one with the smaller estimated mean squared error
        is kept: ``var3`` for degree 3, ``var2 + bias^2`` for degree 2, the bias from the two estimates'
        difference (for nested fits ``Var(a3 - a2) = var3 - var2``), the noise from the cubic's
        residuals.  The estimate is then shrunk toward zero by the Wiener gain ``S / (S + mse)``, ``S``
        the recent signal power.  Where the tracked positions are noisy (a turbid floor, ~2 mm per frame)
        the second derivative is mostly noise: measured on pool-hard_s2 (60 s), the unshrunk degree-3
        estimate was off by 0.1-0.9 m/s^2 RMS per 5 s against 0.06-0.57 m/s^2 of true acceleration.
        ``acc_order`` 2 or 3 forces that degree instead."""
        W = self.acc_window_ns
        if W <= 0 or not self.t:
            return np.zeros(3)
        t, P_all = self._arrays()
        ahead = min(max(int(t[-1]) - int(t_ns), 0), W // 2)
        sel = (t >= t_ns - W + ahead) & (t <= t_ns + ahead)
        tau = (t[sel] - t_ns) * 1e-9
        if len(tau) < 6 or tau[-1] - tau[0] < 0.6 * W * 1e-9:
            return np.zeros(3)
        P = P_all[sel]
        P = P - P[-1]
        V3 = np.vander(tau, 4, increasing=True)
        c3, rss3, *_ = np.linalg.lstsq(V3, P, rcond=None)
        if len(rss3) == 0:
            return np.zeros(3)
        s2 = float(np.sum(rss3)) / (3 * (len(tau) - 4))  # position noise variance per axis (m^2)
        a3 = 2.0 * c3[2]
        var3 = 4.0 * s2 * float(np.linalg.inv(V3.T @ V3)[2, 2])
        a, mse = a3, var3
        if self.acc_order != 3:
            V2 = V3[:, :3]
            c2, *_ = np.linalg.lstsq(V2, P, rcond=None)
            a2 = 2.0 * c2[2]
            var2 = 4.0 * s2 * float(np.linalg.inv(V2.T @ V2)[2, 2])
            bias2 = max(float((a3 - a2) @ (a3 - a2)) / 3 - (var3 - var2), 0.0)
            if self.acc_order == 2 or var2 + bias2 < var3:
                a, mse = a2, var2 + bias2
        self.power = [x for x in self.power if t_ns - x[0] <= POWER_WINDOW_NS] + [(int(t_ns), float(a @ a) / 3 - mse)]
        S = max(float(np.mean([x[1] for x in self.power])), 0.0)
        return a * (S / (S + mse)) if S + mse > 0 else np.zeros(3)
