"""The body's motion as GeVI knows it between the images: the IMU summary of each frame, the recent
visually tracked positions (velocity, acceleration), the window gravity, and IMU propagation over a
frame vision could not track.

Frames: W is gravity-aligned (z up, gravity ``-GRAVITY`` e3); B is the IMU frame; ``T_B_C0`` maps
rectified cam0 into B.  Stamps in ns, positions in m, velocities in m/s.
"""
from __future__ import annotations

import numpy as np

from gevi_cli.estimators.preintegration import imu_segment, integrate_increments
from gevi_cli.inertial.imu_stream import ImuStream
from gevi_cli.inertial.standstill import GRAVITY
from gevi_cli.pipelines.config import ACC_ORDER, FusionConfig
from gevi_cli.pipelines.inertial_state import FrameSample, ImuBiases
from gevi_cli.pipelines.recent_motion import RecentMotion
from gevi_cli.pipelines.types import OK
from gevi_cli.pipelines.window_gravity import WindowGravity


class BodyMotion:
    """IMU samples per frame and the motion of the visually tracked frames, corrected by ``biases``.

    ``recent`` fits the last tracked body positions (velocity over IMU-only frames, the acceleration
    the specific force is compensated by); ``gravity`` (window_gravity.py, None when
    ``fusion.gravity_window_s`` is 0) is gravity in the body frame from the same frames and the
    preintegrated IMU; ``v_W`` is the body velocity in W, from the track, carried by the IMU over losses.
    """

    def __init__(self, imu: ImuStream, biases: ImuBiases, T_B_C0: np.ndarray, frame_period_s: float,
                 fusion: FusionConfig):
        self.imu = imu
        self.biases = biases
        self.R_ic = T_B_C0[:3, :3]
        self.T_B_C0, self.T_C0_B = T_B_C0, np.linalg.inv(T_B_C0)
        self.frame_period = float(frame_period_s)
        self.recent = RecentMotion(fusion.acc_window_s, ACC_ORDER)
        self.gravity = WindowGravity(fusion.gravity_window_s) if fusion.gravity_window_s > 0 else None
        self.v_W = np.zeros(3)

    # ------------------------------------------------------------------------- per-frame IMU summary
    def sample(self, index: int, t_ns: int, t_prev_ns: int | None, R_w_last: np.ndarray | None) -> FrameSample:
        """IMU summary of frame ``index`` at ``t_ns``: the gyro rotation since ``t_prev_ns`` (NaN over a
        gap) and the gravity direction, bias-corrected.  ``R_w_last``: the last frame's camera orientation
        in W (None before W is known), from which the gyro predicts the body orientation the acceleration
        compensation uses (its tilt error is second order there)."""
        rotvec, dt = np.zeros(3), 0.0
        if t_prev_ns is not None:
            fi = self.imu.interval(t_prev_ns, t_ns, self.biases.b_g)
            rotvec, dt = fi.rotvec, (t_ns - t_prev_ns) * 1e-9
            if fi.gap:
                rotvec = np.full(3, np.nan)
        s = FrameSample(index, t_ns, t_prev_ns, None, rotvec, dt, np.zeros(2), self.mean_specific_force(t_ns))
        if R_w_last is not None and np.all(np.isfinite(rotvec)):
            s.R_wb = R_w_last @ self.R_ic.T @ s.gyro_rotation()
        if self.gravity is not None and s.R_wb is not None and t_prev_ns is not None:
            up = self.gravity.up(t_prev_ns)  # the last tracked frame's, carried over by the gyro
            if up is not None:
                s.acc_dir = s.gyro_rotation().T @ up
        if s.acc_dir is None:
            s.acc_dir = self.acc_dir(t_ns, s.f_mean, s.R_wb)
        return s

    def mean_specific_force(self, t_ns: int) -> np.ndarray:
        """Mean specific force (m/s^2, body) over a frame period centred on ``t_ns`` (NaN: no samples)."""
        h = int(0.5 * self.frame_period * 1e9)
        _, _, a = self.imu.window(t_ns - h, t_ns + h)
        return a.mean(0) if len(a) else np.full(3, np.nan)

    def acc_dir(self, t_ns: int, f_mean: np.ndarray, R_wb: np.ndarray | None = None) -> np.ndarray:
        """The gravity direction (``-R_wb^T g_W / g``, body frame) the gravity residual compares with at
        ``t_ns``: from the window of tracked frames when it has that frame, else the unit specific force,
        accelerometer bias removed and, given the body orientation ``R_wb``, the visually tracked body
        acceleration too."""
        if self.gravity is not None and R_wb is not None:
            up = self.gravity.up(t_ns)
            if up is not None:
                return up
        a = f_mean - self.biases.b_a
        if R_wb is not None:
            a = a - R_wb.T @ self.recent.acceleration(t_ns)
        return a / np.linalg.norm(a)

    def refresh_acc_dirs(self, samples: list[FrameSample]) -> None:
        """Re-read the acceleration of the ``samples`` whose fit window has not yet slid to centred: the
        frames tracked since make it a smoother, unlagged estimate."""
        if self.recent.acc_window_ns <= 0 or not self.recent.t:
            return
        now = self.recent.t[-1]
        for s in samples:
            if s.R_wb is not None and now - s.t_ns <= self.recent.acc_window_ns // 2 + int(self.frame_period * 1e9):
                s.acc_dir = self.acc_dir(s.t_ns, s.f_mean, s.R_wb)

    # ---------------------------------------------------------------------------- tracked frames
    def update(self, res, t_prev_ns: int | None, cur: FrameSample | None, still: bool) -> None:
        """A frame's result into the recent motion and the window gravity (whose answer becomes the
        frame's gravity direction ``cur.acc_dir``); the velocity from the recent motion's fit, except at
        rest.  A frame vision did not track starts both histories anew."""
        if res.status != OK:
            self.recent.reset()
            if self.gravity is not None:
                self.gravity.reset()
            return
        self.add_tracked(res.t_ns, res.T_w_c, t_prev_ns)
        if self.gravity is not None:
            up = self.gravity.up(res.t_ns)
            if up is not None and cur is not None and cur.t_ns == res.t_ns:
                cur.acc_dir = up
        if still:
            return  # at rest: the velocity is zero, not the fit's
        v = self.recent.velocity()
        if v is not None:
            self.v_W = v

    def add_tracked(self, t_ns: int, T_w_c: np.ndarray, chain_from: int | None) -> None:
        """A visually tracked frame (rectified cam0 pose ``T_w_c`` in W) for the recent-motion fit and the
        window gravity; the window chains it to its last frame by the preintegrated IMU when that frame
        is stamped ``chain_from`` and the IMU covers the interval, else starts a new history."""
        T_wb = T_w_c @ self.T_C0_B
        self.recent.add(t_ns, T_wb[:3, 3])
        w = self.gravity
        if w is None:
            return
        pre = None
        if len(w) and chain_from is not None and int(w.t[-1]) == chain_from and self.imu.covers(chain_from, t_ns):
            g, a, dts = imu_segment(self.imu.t_ns, self.imu.gyro, self.imu.acc, chain_from, t_ns)
            pre = integrate_increments(g, a, dts, self.biases.b_g, self.biases.b_a)
        w.add(t_ns, T_wb[:3, 3], T_wb[:3, :3], pre)

    def seed(self, held: list[tuple[int, int, np.ndarray]], T_WV: np.ndarray, index: int) -> None:
        """Give the recent-motion fit and the window gravity the frames held back during the
        initialisation, ``(index, t_ns, T_v_c)`` in the provisional frame V, moved to W by ``T_WV`` and
        preintegrated with the biases now known, so that both answer from the first frame after the
        initialisation instead of a window length later (the frame ``index`` itself comes through
        :meth:`update`).  A standstill start is declared over late; without these frames the start of
        motion in between was read from the bare specific force."""
        prev = None
        for i, t_ns, T_vc in held:
            if i >= index:
                break
            self.add_tracked(t_ns, T_WV @ T_vc, prev[1] if prev is not None and prev[0] == i - 1 else None)
            prev = (i, t_ns)

    # -------------------------------------------------------------------------------- propagation
    def propagate(self, T_w_last: np.ndarray, t_prev_ns: int, t_ns: int) -> np.ndarray:
        """Rectified-cam0 pose at ``t_ns`` in W by IMU preintegration from the pose ``T_w_last`` at
        ``t_prev_ns`` and the velocity ``v_W`` (which it carries on)."""
        g, a, dts = imu_segment(self.imu.t_ns, self.imu.gyro, self.imu.acc, t_prev_ns, t_ns)
        pre = integrate_increments(g, a, dts, self.biases.b_g, self.biases.b_a)
        T_wb = T_w_last @ self.T_C0_B
        R, p, T = T_wb[:3, :3], T_wb[:3, 3], pre.dt
        g_W = np.array([0.0, 0.0, -GRAVITY])
        T_new = np.eye(4)
        T_new[:3, :3] = R @ pre.dR
        T_new[:3, 3] = p + self.v_W * T + 0.5 * g_W * T * T + R @ pre.dp
        self.v_W = self.v_W + g_W * T + R @ pre.dv
        return T_new @ self.T_B_C0
