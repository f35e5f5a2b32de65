"""Gravity in the body frame from a window of visually tracked positions and the preintegrated IMU
[PROPOSAL, ours] (docs/method.md, "Window gravity").

Why: the gravity residual of the BCD (spec 8.1) needs the direction of gravity in the body frame, and
the specific force alone is off by ``a / g`` rad under an acceleration ``a`` (0.5 m/s^2 on the pool
presets: 3 deg).  Removing an acceleration differentiated twice from the tracked positions amplifies
their noise: on a turbid floor (~2 mm per frame) that estimate is mostly noise.  Integrating the IMU
twice instead and comparing with the positions over a window of ``T`` seconds observes gravity through
``g T^2 / 2``, so the position noise enters divided by ``T^2``: with 2 s, 40 frames, a quadratic fit,
2 mm of noise moves gravity by ~2e-3 m/s^2 (0.01 deg).

Model, for the frames j of the window and a reference frame r (all vectors in body-r coordinates;
``R_r``: r's tracked orientation in W, ``p_j``: body positions in W)::

    R_r^T (p_j - p_r) - P_r(j) = c0 + v_r tau_j + gamma_r tau_j^2 / 2,   tau_j = t_j - t_r,

``P_r(j)`` the double integral of the gyro-rotated, bias-corrected specific force from ``t_r`` to
``t_j`` (preintegration, spec 9.2), ``gamma_r = R_r^T g_W``; a linear least-squares fit per axis.  Only
displacements and relative rotations enter, so a tilt of W itself does not (a tilt error of ``R_r``
against the positions moves the displacements by ``d x (p_j - p_r)``, which the velocity term takes
up to first order).  The accelerometer bias is the estimate's; its error moves gravity by ``b / g`` rad
as it moves the specific force.
"""
from __future__ import annotations

import numpy as np

from gevi_cli.inertial.standstill import GRAVITY


class WindowGravity:
    """Visually tracked frames (stamp, body position, body orientation) chained by preintegrated IMU
    intervals; :meth:`up` is the unit up direction (``-R_r^T g_W / g``) in the body frame of a frame.

    Accumulated in the body frame of the first frame kept (index 0): ``R0[j] = R_0^T R_j`` from the
    gyro, ``V0[j]``, ``P0[j]`` the single and double integrals of ``R_0s f_s`` from ``t_0`` (gravity
    not removed).  Dropping old frames re-references them to the new first frame.
    """

    def __init__(self, window_s: float, min_span_s: float = 1.0, max_g_err: float = 0.05):
        self.window_ns = int(window_s * 1e9)
        self.min_span_ns = int(min_span_s * 1e9)
        self.max_g_err = float(max_g_err)
        self.reset()

    def reset(self) -> None:
        self._memo: dict[int, np.ndarray | None] = {}  # up() of the frames kept, until the next add
        self.t = np.zeros(0, np.int64)
        self.p = np.zeros((0, 3))
        self.R = np.zeros((0, 3, 3))   # tracked body orientations in W
        self.R0 = np.zeros((0, 3, 3))  # gyro: R_0^T R_j
        self.V0 = np.zeros((0, 3))
        self.P0 = np.zeros((0, 3))

    def __len__(self) -> int:
        return len(self.t)

    def add(self, t_ns: int, p_W: np.ndarray, R_wb: np.ndarray, pre=None) -> None:
        """Append a tracked frame; ``pre`` the preintegrated interval from the last frame added
        (``dR``, ``dv``, ``dp``, ``dt``), None to start a new history."""
        if pre is None or len(self.t) == 0:
            self.reset()
            R0, V0, P0 = np.eye(3), np.zeros(3), np.zeros(3)
        else:
            Rl, Vl = self.R0[-1], self.V0[-1]
            R0 = Rl @ pre.dR
            V0 = Vl + Rl @ pre.dv
            P0 = self.P0[-1] + Vl * pre.dt + Rl @ pre.dp
        self._memo = {}
        self.t = np.append(self.t, np.int64(t_ns))
        self.p = np.vstack([self.p, np.asarray(p_W, float)[None]])
        self.R = np.concatenate([self.R, np.asarray(R_wb, float)[None]])
        self.R0 = np.concatenate([self.R0, R0[None]])
        self.V0 = np.vstack([self.V0, V0[None]])
        self.P0 = np.vstack([self.P0, P0[None]])
        old = self.t[-1] - self.t > self.window_ns
        if old.any():
            self._rebase(int(np.argmin(old)))

    def _rebase(self, m: int) -> None:
        """Drop frames before ``m`` and refer the integrals to frame m."""
        # re-orthonormalised: R0 is re-multiplied by R0[m]^T at every rebase, and a rounding error in
        # it would about double with each (measured: |R^T R - I| 1e-16 -> 5e-15 in 6 rebases)
        U, _, Vt = np.linalg.svd(self.R0[m])
        Rm = U @ Vt
        dt = (self.t[m:] - self.t[m]) * 1e-9
        self.P0 = (self.P0[m:] - self.P0[m] - self.V0[m] * dt[:, None]) @ Rm
        self.V0 = (self.V0[m:] - self.V0[m]) @ Rm
        self.R0 = np.einsum("ji,njk->nik", Rm, self.R0[m:])
        self.t, self.p, self.R = self.t[m:], self.p[m:], self.R[m:]

    def up(self, t_ns: int) -> np.ndarray | None:
        """Up direction (unit, body frame) at the kept frame stamped ``t_ns``, or None: not kept, a window
        shorter than ``min_span_s``, or a fitted ``|g|`` off by more than ``max_g_err`` (relative).
        Asked again before the next :meth:`add` (the pipeline asks for the last frame's twice), the
        fit is not redone."""
        key = int(t_ns)
        if key not in self._memo:
            self._memo[key] = self._up(key)
        return self._memo[key]

    def _up(self, t_ns: int) -> np.ndarray | None:
        r = np.flatnonzero(self.t == int(t_ns))
        if len(r) == 0 or self.t[-1] - self.t[0] < self.min_span_ns or len(self.t) < 6:
            return None
        r = int(r[0])
        Rr = self.R0[r]
        tau = (self.t - self.t[r]) * 1e-9
        # body-r displacements from the positions, minus the IMU's (gravity reaction included in both)
        y = (self.p - self.p[r]) @ self.R[r] - (self.P0 - self.P0[r] - self.V0[r] * tau[:, None]) @ Rr
        A = np.column_stack([np.ones_like(tau), tau, 0.5 * tau * tau])
        keep = np.ones(len(tau), bool)
        for _ in range(2):  # the second pass without frames far off the first fit (a tracking glitch)
            c, *_ = np.linalg.lstsq(A[keep], y[keep], rcond=None)
            e = np.linalg.norm(y - A @ c, axis=1)
            med = float(np.median(e[keep]))
            new = e <= max(4.0 * med, 1e-4)
            if new.sum() < 6 or np.array_equal(new, keep):
                break
            keep = new
        gamma = c[2]  # R_r^T g_W
        g = float(np.linalg.norm(gamma))
        if not np.isfinite(g) or abs(g / GRAVITY - 1.0) > self.max_g_err:
            return None
        return -gamma / g
