"""GeVI: gravity-enhanced stereo visual-inertial odometry ("GeVI-SLAM", spec 2, 6-9).

Per frame, on top of :class:`~gevi_cli.pipelines.odometry.KeyframeOdometry` (front end, keyframes,
triangulation from the current keyframe only, noise variance, bridging, run-driver contract):

1. IMU: the gyro rotation since the previous frame (bias-corrected) predicts the current roll/pitch
   from the last estimate: ``tilt_c = tilt(R_tilt(tilt_prev) dR)`` (yaw-invariant, spec 8.1.3).
2. Verification: upright 3-point RANSAC with the levelling rotations ``L_k``, ``L_c`` (spec 7).
3. 4-DOF bias-eliminated estimate of (psi, t_ck) (spec 6.2) and one Gauss-Newton step on the
   point-to-epipolar-line distances in both keyframe images (spec 6.3).
4. 6-DOF refinement with the jointly estimated gravity-prior covariance, by block coordinate descent
   (spec 8) over the frames since the keyframe: visual reprojection residuals of the current frame,
   one gravity residual per frame (the unit mean specific force over a frame period centred on the
   frame stamp, accelerometer bias removed), the gyro chain between frames and the keyframe-tilt prior.
   Its current-frame tilt is fed forward (step 1 of the next frame); at a keyframe it becomes the
   keyframe tilt with the marginal covariance as the next windows' prior.

Before that, the initialisation with known scale (spec 9): a standstill start (image motion and IMU
both at rest for ``init.still_min_s``) gives gravity from the mean specific force and the gyro bias
from the mean rate, both re-estimated over the whole standstill while it lasts; otherwise the first
``init.window_s`` of 6-DOF stereo odometry (Bias-Eli-W, as CFO) feed :func:`stereo_imu_init` (gyro
bias, velocities, gravity, accelerometer bias with its prior).  The poses of the initialisation
window are held back and re-expressed in the gravity-aligned world frame W (z up, yaw of the first
camera arbitrary) once it is known, so the trajectory is one piece.  Where the IMU has a gap (or ends
before the images) the frame is tracked with the 6-DOF visual step and the interval is reported.

Frames: ``T_w_c`` is rectified cam0 in W; the body frame B is the IMU frame; ``R_ic`` = R_BC0 maps
camera vectors into the IMU frame.  Tilts are (roll, pitch) of R_WI in rad (ZYX, spec 1).
"""
from __future__ import annotations

import dataclasses
import time

import cv2
import numpy as np

from gevi_cli import estimators as est
from gevi_cli.estimators.preintegration import imu_segment, integrate_increments
from gevi_cli.frontend import FrontEnd
from gevi_cli.geometry import make_T
from gevi_cli.inertial.imu_stream import ImuStream
from gevi_cli.inertial.standstill import GRAVITY
from gevi_cli.pipelines.acc_bias import AccBiasTracker
from gevi_cli.pipelines.config import OdometryConfig
from gevi_cli.pipelines.inertial_init import (
    GEVI,
    INIT,
    STANDSTILL,
    VISUAL,
    FrameSample,
    InertialInitialisation,
    tilt_of,
    yaw_of,
)
from gevi_cli.pipelines.odometry import KeyframeOdometry, Matches
from gevi_cli.pipelines.pose6 import (
    converged_limit_px,
    opencv_pnp,
    reprojection_median_px,
    reverified,
    tracked_pose6,
)
from gevi_cli.pipelines.recent_motion import RecentMotion
from gevi_cli.pipelines.types import INERTIAL, OK
from gevi_cli.pipelines.verification import FivePointL1Verification, ThreePointVerification, TrackingFailure
from gevi_cli.pipelines.window_gravity import WindowGravity

#: at most this many BCDs per frame for the chi-square gate (_gated_bcd)
GATE_BCDS = 3

#: imu_states.csv columns (angles rad, biases rad/s and m/s^2, Sigma dimensionless unit-vector variance)
STATE_COLUMNS = ("index", "t_ns", "phase", "roll", "pitch", "yaw", "bgx", "bgy", "bgz", "bax", "bay", "baz",
                 "ba_std", "sigma_trace", "s_xx", "s_yy", "s_zz", "s_xy", "s_xz", "s_yz", "tilt_std",
                 "ransac_iters")


class GeviOdometry(InertialInitialisation, KeyframeOdometry):
    name = "gevi"
    world_is_cam0 = False
    state_file = "imu_states.csv"
    state_columns = STATE_COLUMNS

    def __init__(self, frontend: FrontEnd, cfg: OdometryConfig, imu: ImuStream, frame_period_s: float):
        super().__init__(frontend, cfg)
        self.imu = imu
        T_B_C = np.asarray(self.camera.T_B_C0, dtype=float)
        self.R_ic, self.p_ic = T_B_C[:3, :3], T_B_C[:3, 3]
        # rectified cam0 -> body and back (the poses are cam0's, the IMU's are the body's)
        self.T_B_C0, self.T_C0_B = T_B_C, np.linalg.inv(T_B_C)
        self.frame_period = float(frame_period_s)
        six_cfg = dataclasses.replace(cfg.verify, ransac="5pt")
        self.six_verify = FivePointL1Verification(six_cfg, self.camera)
        if cfg.verify.ransac == "3pt":
            self.gevi_verify = ThreePointVerification(cfg.verify, self.camera, self._levelling)
        else:
            self.gevi_verify = FivePointL1Verification(cfg.verify, self.camera)
        self.verification = self._verify
        self.phase = INIT
        self.mode = INIT  # how the current frame is tracked: INIT / GEVI / VISUAL
        self.b_g, self.b_a = np.zeros(3), np.zeros(3)
        self.bias_std = float("nan")  # posterior std of the in-flight horizontal b_a estimate (m/s^2)
        self.bias_updates: list[float] = []  # seconds since the first frame of each in-flight b_a adoption
        self.tilt = np.zeros(2)
        self.tilt_pred = np.zeros(2)
        self.tilt_cov = np.eye(2)
        self.kf_tilt, self.kf_tilt_cov = np.zeros(2), np.eye(2)
        self.lev = (np.eye(3), np.eye(3))  # levelling of keyframe and current frame, set per GEVI-mode frame
        self.Sigma = np.full((3, 3), np.nan)
        self.win: list[FrameSample] = []
        self.cur: FrameSample | None = None
        self.t_prev: int | None = None
        self.t_first: int | None = None
        self.first_kf_index: int | None = None
        self.T_first: np.ndarray | None = None  # pose of the first frame (in W once initialised)
        self.still = True  # the standstill that started the run is still going on
        self.moving_run = 0  # consecutive frames whose image motion says "moving"
        self.flow_ref = None  # features of the standstill test's reference frame (_image_flow_px)
        self.still_eval = None  # (frame index, _still_since_start's answer) of the last frame evaluated
        self.init_poses: list[tuple[int, int, np.ndarray]] = []  # (index, t_ns, T_w_c) in V, tracked ones
        self.next_init_try: int | None = None
        self.init_info: dict = {}
        self.gaps: list[dict] = []  # IMU gaps: {"first_index", "start_ns", "end_ns", "frames"}
        self.attitude = None  # AttitudeTrack of the IMU-only filter (fusion.mode = 4dof)
        self.bcd_ms = 0.0
        self._fold = None  # (keyframe index, frames folded, their composed gyro rotation, their seconds): _bcd
        self.innovations: list[tuple[int, np.ndarray]] = []  # (t_ns, a_dir - R_tilt(pred)^T e3) for Sigma's prior
        self.bias_poses: list[tuple[int, np.ndarray]] = []  # (t_ns, T_w_c) after the standstill, for b_a
        self.v_W = np.zeros(3)  # body velocity in W (m/s): from the visual track, carried by the IMU over losses
        # recent visually tracked body positions (velocity over IMU-only frames, acceleration compensation)
        self.motion = RecentMotion(cfg.fusion.acc_window_s, cfg.fusion.acc_order)
        # gravity in the body frame from the same frames and the preintegrated IMU (window_gravity.py)
        self.wgrav = WindowGravity(cfg.fusion.gravity_window_s) if cfg.fusion.gravity_window_s > 0 else None
        # the horizontal accelerometer bias from yaw changes (acc_bias.py); it reads the window gravity
        self.bias_track = AccBiasTracker(cfg.fusion.bias_window_s, cfg.init.ba_prior_sigma,
                                         walk=imu.noise.acc_random_walk) \
            if cfg.fusion.bias_window_s > 0 and self.wgrav is not None else None

    # --------------------------------------------------------------------------------- helpers
    def _levelling(self):
        """(L_k, L_c, sigma) of the frame being tracked (GEVI mode): the levelling rotations of the keyframe's
        and the predicted current roll/pitch, and the current normalized noise std."""
        return (*self.lev, float(np.sqrt(self.sigma2)))

    def _verify(self, z, q, p, rng):
        return (self.gevi_verify if self.mode == GEVI else self.six_verify)(z, q, p, rng)

    def _f_mean(self, t_ns: int) -> np.ndarray:
        """Mean specific force (m/s^2, body) over a frame period centred on ``t_ns`` (NaN: no samples)."""
        h = int(0.5 * self.frame_period * 1e9)
        _, _, a = self.imu.window(t_ns - h, t_ns + h)
        return a.mean(0) if len(a) else np.full(3, np.nan)

    def _acc_dir(self, t_ns: int, f_mean: np.ndarray, R_wb: np.ndarray | None = None) -> np.ndarray:
        """The gravity direction (``-R_wb^T g_W / g``, body frame) the gravity residual compares with at
        ``t_ns``: from the window of tracked frames when it has that frame (window_gravity.py), else the
        unit specific force, accelerometer bias removed and, given the body orientation ``R_wb``, the
        visually tracked body acceleration too."""
        if self.wgrav is not None and R_wb is not None:
            up = self.wgrav.up(t_ns)
            if up is not None:
                return up
        a = f_mean - self.b_a
        if R_wb is not None:
            a = a - R_wb.T @ self.motion.acceleration(t_ns)
        return a / np.linalg.norm(a)

    def _refresh_acc_dirs(self) -> None:
        """Re-read the acceleration of the BCD window's frames whose fit window has not yet slid to
        centred: the frames tracked since make it a smoother, unlagged estimate."""
        if self.motion.acc_window_ns <= 0 or not self.motion.t:
            return
        now = self.motion.t[-1]
        for s in self.win:
            if s.R_wb is not None and now - s.t_ns <= self.motion.acc_window_ns // 2 + int(self.frame_period * 1e9):
                s.acc_dir = self._acc_dir(s.t_ns, s.f_mean, s.R_wb)

    def _sample(self, index: int, t_ns: int, t_prev_ns: int | None) -> FrameSample:
        """IMU summary of frame ``index`` at ``t_ns`` (the gyro rotation since ``t_prev_ns``, NaN over a
        gap) with the current bias estimates."""
        rotvec, dt = np.zeros(3), 0.0
        if t_prev_ns is not None:
            fi = self.imu.interval(t_prev_ns, t_ns, self.b_g)
            rotvec, dt = fi.rotvec, (t_ns - t_prev_ns) * 1e-9
            if fi.gap:
                rotvec = np.full(3, np.nan)
        s = FrameSample(index, t_ns, t_prev_ns, None, rotvec, dt, np.zeros(2), self._f_mean(t_ns))
        # the orientation predicted from the last pose by the gyro (its tilt error is second order here)
        if self.phase != INIT and self.T_w_last is not None and np.all(np.isfinite(rotvec)):
            s.R_wb = self.T_w_last[:3, :3] @ self.R_ic.T @ s.gyro_rotation()
        if self.wgrav is not None and s.R_wb is not None and t_prev_ns is not None:
            up = self.wgrav.up(t_prev_ns)  # the last tracked frame's, carried over by the gyro
            if up is not None:
                s.acc_dir = s.gyro_rotation().T @ up
        if s.acc_dir is None:
            s.acc_dir = self._acc_dir(t_ns, s.f_mean, s.R_wb)
        return s

    # ------------------------------------------------------------------------------ main entry
    def track(self, frame):
        t_ns = int(frame.t_ns)
        self.cur = self._sample(self.index + 1, t_ns, self.t_prev)
        gap = self.t_prev is not None and not np.all(np.isfinite(self.cur.rotvec))
        gap = gap or not np.all(np.isfinite(self.cur.acc_dir))
        if self.phase == INIT:
            self.mode = INIT
        elif gap:
            self.mode = VISUAL
        else:
            self.mode = GEVI
            self.tilt_pred = np.array(est.tilt_angles(est.rtilt(*self.tilt) @ self.cur.gyro_rotation()))
            if self.attitude is not None:
                self.tilt_pred = self._filter_tilt(t_ns)
            # the frame's levelling rotations, for its verification and its pose step
            self.lev = (est.levelling(*self.kf_tilt, self.R_ic), est.levelling(*self.tilt_pred, self.R_ic))
        res = super().track(frame)
        if self.first_kf_index is None and res.keyframe:
            self.first_kf_index = res.index
        if self.t_first is None:
            self.t_first = t_ns
        self._note_gap(res, gap)
        if self.phase == INIT:
            # nothing is final before W is known: the window's poses are re-expressed at initialisation
            self.pending, res.final = res.final + self.pending, []
            if res.status == OK:
                self.init_poses.append((res.index, t_ns, res.T_w_c.copy()))
            self.online_held.append((res.index, res.T_w_c.copy()))  # in V: written once W is known
            res.online = []
            self._try_init(res)
        elif self.mode == GEVI and res.status == INERTIAL:
            self.tilt = tilt_of(res.T_w_c[:3, :3], self.R_ic)  # the gyro carried the attitude
        elif self.mode == GEVI and res.status != OK:
            self.tilt = self.tilt_pred  # the gyro carries the attitude over a lost frame
        elif self.mode == VISUAL:
            self.tilt = tilt_of(res.T_w_c[:3, :3], self.R_ic)
        if self.phase != INIT and self.still:
            self._update_standstill(res)
        if self.phase != INIT:
            if res.status != INERTIAL:
                # also at rest: the window gravity then spans the start of motion, which the standstill
                # test sees late (pool-easy_s1: 0.4 s, 0.2-0.44 m/s^2 read as gravity, 0.8 deg of pitch)
                self._update_velocity(res)
                if not self.still:  # at rest the later frames would not change the earlier frames' gravity
                    self._refresh_acc_dirs()
            if self.still:
                self.v_W = np.zeros(3)
            self._refine_acc_bias(res)
            self._track_acc_bias(res)
        self.cur.tilt = self.tilt.copy()
        if res.keyframe or self.kf is None:
            self._new_window(res)
        else:
            self.win.append(self.cur)
        res.extra = self._state_row(res)
        self.t_prev = t_ns
        return res

    def rotation_prior(self):
        """The gyro's rotation since the previous frame, in rectified-left camera coordinates
        (``R_cp = R_ic^T exp(rotvec)^T R_ic``); over an IMU gap the last step's, as CFO.  With
        ``frontend.derotate_prior`` "image" none: the front end's in-plane fit, as for CFO."""
        if self.cfg.frontend.derotate_prior == "image":
            return None  # the front end's in-plane fit (gevi_cli/configs/pool.yaml): pool-hard_s1 50 mm against 292 with the gyro's
        if self.cur is None or self.t_prev is None or not np.all(np.isfinite(self.cur.rotvec)):
            return super().rotation_prior()
        return self.R_ic.T @ self.cur.gyro_rotation().T @ self.R_ic

    def _bridge(self, t_ns: int):
        """A frame that cannot be tracked visually: at rest while the IMU shows the starting standstill,
        else IMU preintegration from the last pose and velocity (constant velocity where the IMU has a gap)."""
        if self.T_w_last is None:
            return super()._bridge(t_ns)
        if self.still and (self.phase != INIT or self.kf is None):
            return self.T_w_last.copy(), INERTIAL
        if self.phase == INIT or self.t_prev is None or not self.imu.covers(self.t_prev, t_ns):
            return super()._bridge(t_ns)
        g, a, dts = imu_segment(self.imu.t_ns, self.imu.gyro, self.imu.acc, self.t_prev, t_ns)
        pre = integrate_increments(g, a, dts, self.b_g, self.b_a)
        T_B_C = self.T_B_C0
        T_wb = self.T_w_last @ self.T_C0_B
        R, p, T = T_wb[:3, :3], T_wb[:3, 3], pre.dt
        g_W = np.array([0.0, 0.0, -GRAVITY])
        T_new = np.eye(4)
        T_new[:3, :3] = R @ pre.dR
        T_new[:3, 3] = p + self.v_W * T + 0.5 * g_W * T * T + R @ pre.dp
        self.v_W = self.v_W + g_W * T + R @ pre.dv
        return T_new @ T_B_C, INERTIAL

    def _update_velocity(self, res) -> None:
        """The tracked frame into the recent motion and the window gravity (whose answer becomes the
        frame's gravity direction); the velocity from a line fit to the last ~0.5 s, except at rest."""
        if res.status != OK:
            self.motion.reset()
            if self.wgrav is not None:
                self.wgrav.reset()
            return
        self._add_tracked(res.t_ns, res.T_w_c, self.t_prev)
        if self.wgrav is not None:
            up = self.wgrav.up(res.t_ns)
            if up is not None and self.cur is not None and self.cur.t_ns == res.t_ns:
                self.cur.acc_dir = up
        if self.still:
            return  # at rest: the velocity is zero, not the fit's
        v = self.motion.velocity()
        if v is not None:
            self.v_W = v

    def _add_tracked(self, t_ns: int, T_w_c: np.ndarray, chain_from: int | None) -> None:
        """A visually tracked frame (rectified cam0 pose ``T_w_c`` in W) for the recent-motion fit and the
        window gravity; the window chains it to its last frame by the preintegrated IMU when that frame
        is stamped ``chain_from`` and the IMU covers the interval, else starts a new history."""
        T_wb = T_w_c @ self.T_C0_B
        self.motion.add(t_ns, T_wb[:3, 3])
        w = self.wgrav
        if w is None:
            return
        pre = None
        if len(w) and chain_from is not None and int(w.t[-1]) == chain_from and self.imu.covers(chain_from, t_ns):
            g, a, dts = imu_segment(self.imu.t_ns, self.imu.gyro, self.imu.acc, chain_from, t_ns)
            pre = integrate_increments(g, a, dts, self.b_g, self.b_a)
        w.add(t_ns, T_wb[:3, 3], T_wb[:3, :3], pre)

    def _note_gap(self, res, gap: bool) -> None:
        if not gap or self.phase == INIT:
            return
        if self.gaps and self.gaps[-1]["last_index"] == res.index - 1:
            g = self.gaps[-1]
            g["last_index"], g["end_s"], g["frames"] = res.index, res.t_ns * 1e-9, g["frames"] + 1
        else:
            self.gaps.append({"first_index": res.index, "last_index": res.index, "start_s": res.t_ns * 1e-9,
                              "end_s": res.t_ns * 1e-9, "frames": 1})

    def _new_window(self, res) -> None:
        """The current frame starts the next BCD window (it is the new keyframe)."""
        i_prev = self.win[0].index if self.win else None  # the previous keyframe's frame
        self.win = [self.cur]
        if self.phase == INIT or self.kf is None:
            return
        floor = np.radians(self.cfg.fusion.kf_tilt_floor_deg) ** 2
        cov = self.tilt_cov if np.all(np.isfinite(self.tilt_cov)) else np.eye(2) * floor
        w, V = np.linalg.eigh(0.5 * (cov + cov.T))
        self.kf_tilt, self.kf_tilt_cov = self.tilt.copy(), (V * np.maximum(w, floor)) @ V.T
        T = self.kf.T_w_k
        if self.cfg.ba.enabled and res.status == OK:
            # The epipolar BA refined the keyframe with the whole window's images; its roll/pitch is the
            # better relative tilt, the BCD's the gravity-anchored one.  A complementary blend keeps both
            # (the BA's alone drifts where vision is weak; the BCD's alone follows sustained accelerations):
            # [PROPOSAL] gain ``fusion.kf_tilt_gravity_gain``, measured in docs/method.md.
            ba_tilt = tilt_of(T[:3, :3], self.R_ic)
            k = self.cfg.fusion.kf_tilt_gravity_gain
            self.kf_tilt = ba_tilt + k * np.array([est.wrap_angle(d) for d in self.tilt - ba_tilt])
        # keep R_WK exactly levelled by the keyframe tilt (the 4-DOF model's assumption)
        yaw = yaw_of(T[:3, :3] @ self.R_ic.T)
        R_before = T[:3, :3].copy()
        T[:3, :3] = est.rot_z(yaw) @ est.levelling(*self.kf_tilt, self.R_ic)
        # The keyframe's written pose is the one the next frames chain from.  The frames since the
        # previous keyframe (after the BA, their relative motion is the BA's) take the same correction
        # in proportion to their place in the window, so that it is not one step at the keyframe
        # [PROPOSAL]: applied as a step, the gravity re-levelling made the keyframe steps of pool-easy_s3
        # (60 s) 11x worse in rotation than the others (0.052 against 0.0045 deg) and GeVI's RPE 14 %
        # above CFO's.  What is tracked next is unchanged: only written poses between keyframes move.
        step = est.log_so3(T[:3, :3] @ R_before.T)
        span = res.index - i_prev if i_prev is not None else 0

        def written(i: int, P: np.ndarray) -> np.ndarray:
            if i == res.index:
                return T.copy()
            if span <= 0 or not i_prev < i < res.index:
                return P
            Q = P.copy()
            Q[:3, :3] = est.exp_so3(step * ((i - i_prev) / span)) @ P[:3, :3]
            return Q

        res.final = [(i, written(i, P)) for i, P in res.final]
        self.pending = [(i, written(i, P)) for i, P in self.pending]

    def _filter_tilt(self, t_ns: int) -> np.ndarray:
        a = self.attitude
        k = max(int(np.searchsorted(a.t_ns, t_ns, side="right")) - 1, 0)
        return np.array(est.tilt_angles(a.R_WI[k]))

    # ---------------------------------------------------------------------------- pose step
    def estimate_T_ck(self, m: Matches, frame) -> np.ndarray:
        if self.mode != GEVI:
            R, t, fallback = tracked_pose6(m.p, m.cov_unit * self.sigma2, m.q, self.cfg.pnp, self.sigma2, self.camera.f)
            self.fallbacks += int(fallback)
            return make_T(R, t)
        cov = m.cov_unit * self.sigma2
        L_k, L_c, _ = self._levelling()
        if self.cfg.fusion.mode == "bcd":
            self._note_innovation()
        R, t = self._gevi_pose(m, cov, L_k, L_c)
        f, pc = self.camera.f, self.cfg.pnp
        med = reprojection_median_px(R, t, m.p, m.q, f)
        if pc.reverify and not med <= converged_limit_px(pc, self.sigma2, f):
            # CFO's re-verification (pose6.reverified) with the GeVI step; the BCD's state (window tilts,
            # Sigma) is put back when the second pose is not kept
            saved = self._bcd_state()
            again = reverified(m.p, m.q, med, pc, self.sigma2, f,
                               lambda keep: self._gevi_pose(m.subset(keep), cov[keep], L_k, L_c))
            if again is None:
                self._restore_bcd_state(saved)
            else:
                (R, t), med = again
        if not np.isfinite(med) or med > pc.max_median_px:
            raise TrackingFailure(f"median reprojection error {med:.2f} px after the GeVI pose step")
        return make_T(R, t)

    def _bcd_state(self):
        """What a pose step changes besides its result: the tilts (current and window frames), Sigma."""
        return (self.tilt.copy(), np.array(self.tilt_cov, copy=True), np.array(self.Sigma, copy=True),
                [np.array(s.tilt, copy=True) for s in self.win])

    def _restore_bcd_state(self, saved) -> None:
        self.tilt, self.tilt_cov, self.Sigma, tilts = saved
        for s, tl in zip(self.win, tilts):
            s.tilt = tl

    def _gevi_pose(self, m: Matches, cov, L_k, L_c):
        """The 4-DOF step (6), then the BCD (8) or, with ``fusion.mode = 4dof``, the IMU's tilt as it is."""
        psi, t = self._pose4(m, cov, L_k, L_c)
        if self.cfg.fusion.mode == "bcd":
            return self._gated_bcd(m, cov, psi, t, L_k, L_c)
        self.tilt, self.tilt_cov = self.tilt_pred.copy(), np.full((2, 2), np.nan)
        return est.rot4(psi, L_k, L_c), t

    def _pose4(self, m: Matches, cov, L_k, L_c):
        """4-DOF BE (spec 6.2) + one epipolar GN step (6.3) -> (psi, t_ck).

        The linear 4-DOF model is degenerate for a *level* plane (a pool floor): with the vertical
        coordinate rho_3 = h of every point the same, x = (0, 0, 0, 0, -h) solves A x = b exactly (it
        maps every point to the camera centre), so with noise the estimate mixes the true and the
        spurious solution (measured: psi off by pi, all points behind the camera).  As for the 6-DOF
        step (pose6.estimate_pose6), when the median reprojection error exceeds ``pnp.fallback_sigmas``
        noise std, the GN step is redone from SQPnP projected on the 4-DOF model and the better kept.
        """
        f, pc = self.camera.f, self.cfg.pnp
        parallax_px = float(np.median(np.linalg.norm(m.q - m.z, axis=1))) * f
        use_gn = parallax_px >= self.cfg.verify.min_parallax_px  # below: left epipolar lines undefined (t ~ 0)

        def gn(psi, t):
            if not use_gn:
                return psi, t
            return est.pnp4_gn(psi, t, m.z, m.y, m.q, L_k, L_c, self.camera.R_rl, self.camera.t_rl)

        def err(psi, t):
            return reprojection_median_px(est.rot4(psi, L_k, L_c), t, m.p, m.q, f)

        best, e_best = None, np.inf
        try:
            best = gn(*est.pnp4_be(m.p, cov, m.q, L_k, L_c))
            e_best = err(*best)
        except est.EstimatorError:
            pass
        limit = max(pc.fallback_sigmas * np.sqrt(self.sigma2) * f, pc.fallback_min_px)
        if e_best > limit and pc.fallback_sigmas > 0:
            try:
                R6, t6 = opencv_pnp(m.p, m.q, cv2.SOLVEPNP_SQPNP, refine=False)
                M = L_c @ R6 @ L_k.T  # = Rz(psi) for an exact 4-DOF pose
                cand = gn(float(np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1])), t6)
                e2 = err(*cand)
                if e2 < e_best:
                    best, e_best = cand, e2
                    self.fallbacks += 1
            except (est.EstimatorError, cv2.error, TrackingFailure):
                pass
        if best is None:
            raise TrackingFailure("4-DOF PnP failed")
        return best

    def _gated_bcd(self, m: Matches, cov, psi, t, L_k, L_c):
        """The BCD on the matches whose reprojection residual its visual weights can explain.

        CFO's chi-square gate (``pnp.chi2_gate``, as in ``pose6._chi2_refit``):
        ``r^T Sigma_bar^-1 r`` is chi-square with 2 dof, and a match far beyond the gate is a wrong
        stereo depth, which the 2D-2D verification cannot see and the BCD's quadratic visual cost would
        follow [PROPOSAL; docs/method.md 9b].  Every match is tested at the BCD's pose and the BCD redone
        on those within the gate until the kept set stops changing, at most ``GATE_BCDS`` BCDs in all;
        where every match passes at the first pose (clean frames) it costs one test.  (Testing at the
        4-DOF pose first, a cheaper pose, flagged good matches there and cost 2.1 BCDs per frame on
        euroc_micro.)
        """
        gate = self.cfg.pnp.chi2_gate
        s2q = self.sigma2 if self.cfg.pnp.current_noise else 0.0
        keep = np.ones(len(m.p), dtype=bool)
        sub, cov_sub = m, cov
        for k in range(GATE_BCDS):
            R, t = self._bcd(sub, cov_sub, psi, t, L_k, L_c)
            if gate <= 0 or k + 1 == GATE_BCDS:
                break
            new = est.pnp6_whitened_sq(R, t, m.p, cov, m.q, s2q) <= gate
            if np.array_equal(new, keep) or new.sum() < self.cfg.pnp.min_points:
                break
            keep = new
            sub = m.subset(keep)
            cov_sub = cov[keep]
        return R, t

    def _note_innovation(self) -> None:
        """The current frame's innovation (its gravity direction against the gyro-predicted tilt) into
        the last ``fusion.sigma_memory_s`` seconds' list, Sigma's conjugate prior.  The window residuals
        are taken at the estimate, which an acceleration already pulled toward the specific force (they
        understate it); the innovations do not.  Measured on pool-easy_s1 (30 s): see docs/method.md."""
        inn = self.cur.acc_dir - est.rtilt(*self.tilt_pred).T @ np.array([0.0, 0.0, 1.0])
        mem = int(self.cfg.fusion.sigma_memory_s * 1e9)
        self.innovations = [x for x in self.innovations if self.cur.t_ns - x[0] < mem] + [(self.cur.t_ns, inn)]

    def _bcd(self, m: Matches, cov, psi, t, L_k, L_c):
        """One BCD (spec 8) from the 4-DOF pose ``(psi, t)`` of the levelling rotations ``L_k``, ``L_c``."""
        samples = self.win + [self.cur]
        links = [s.dt for s in samples[1:]]  # seconds of gyro integration per chain link
        cap = max(self.cfg.fusion.max_window_frames, 3)
        if len(samples) > cap:
            # a long window (slow motion, a standstill: one keyframe for seconds) costs O(K^3) per LM
            # step; the oldest frames after the keyframe are folded into one chain link (the gyro
            # rotations composed, the variance summed) and their gravity residuals dropped
            drop = samples[1:len(samples) - cap + 2]
            first = samples[len(samples) - cap + 2]
            # the folded prefix only grows within a window: its product is kept, not recomposed per frame
            # (the same products in the same order as composing them all again)
            key = samples[0].index
            if self._fold is None or self._fold[0] != key or self._fold[1] > len(drop):
                self._fold = (key, 0, np.eye(3), 0.0)
            _, k, R, dt = self._fold
            for s in drop[k:]:
                R = R @ est.exp_so3(s.rotvec)
                dt += s.dt
            self._fold = (key, len(drop), R, dt)
            R = R @ est.exp_so3(first.rotvec)
            merged = FrameSample(first.index, first.t_ns, samples[0].t_ns, first.acc_dir, est.log_so3(R),
                                 dt + first.dt, first.tilt)
            tail = samples[len(samples) - cap + 3:]
            samples = [samples[0], merged] + tail
            links = [merged.dt] + [s.dt for s in tail]
        depth = (m.p @ est.rot4(psi, L_k, L_c).T + t)[:, 2]
        front = depth > 0.5 * self.cfg.triangulation.min_depth_m
        if front.sum() < self.cfg.pnp.min_points:
            raise TrackingFailure(f"only {int(front.sum())} points in front of the camera after the 4-DOF step")
        m = m.subset(front)
        cov = cov[front]
        acc = np.array([s.acc_dir for s in samples])
        rot = np.array([s.rotvec for s in samples[1:]])
        noise = self.imu.noise
        fc = self.cfg.fusion
        # noise floor of Sigma_imu: the frame-mean white noise and the accelerometer-bias uncertainty (the
        # bias prior of spec 9.6: a standstill cannot observe b_a), so an unmodelled bias or a small
        # acceleration does not get the weight of pure white noise.  Measured (60 s, gain 1): pool-easy_s1
        # ATE 6.0 -> 4.6 mm, tilt 0.61 -> 0.43 deg; pool-hard_s2 63 -> 63 mm, 0.54 -> 0.60 deg.
        # ``--no-adaptive`` is spec 8's fixed-weight baseline, Sigma_imu = lambda_lo I at the accelerometer
        # noise floor (sigma_a / g)^2; the bias-prior part of the floor belongs to our adaptive estimate
        # (a fixed Sigma at the raised floor ties with it where the window gravity removes the
        # accelerations: docs/method.md 9b)
        lo = noise.acc_noise_density ** 2 / self.frame_period / GRAVITY ** 2
        if fc.adaptive:
            lo += (self.cfg.init.ba_prior_sigma / GRAVITY) ** 2
        tilts0 = np.array([self.kf_tilt] + [s.tilt for s in samples[1:-1]] + [self.tilt_pred])
        # Sigma's conjugate prior: the innovations of the last sigma_memory_s (_note_innovation)
        prior, dof = None, 0.0
        if int(fc.sigma_memory_s * 1e9) > 0:
            E = np.array([x[1] for x in self.innovations])
            prior, dof = E.T @ E / len(E) + lo * np.eye(3), float(len(E))
        window = est.FusionWindow(p=m.p, cov=cov, q=m.q, sigma2=self.sigma2, R_ic=self.R_ic, acc_dir=acc,
                                  gyro_inc=rot, gyro_var=noise.gyro_noise_density ** 2 * np.array(links),
                                  prior_mean=self.kf_tilt,
                                  prior_cov=self.kf_tilt_cov, psi0=psi, t0=t, lo=lo, hi=fc.sigma_hi ** 2,
                                  tilts0=tilts0, sigma_prior=prior, sigma_prior_dof=dof)
        t0 = time.perf_counter()
        try:
            state, Sigma, _ = est.bcd_refine(window, adaptive=fc.adaptive, max_iter=fc.max_iter, lm_iters=fc.lm_iters)
        except est.EstimatorError as err:
            raise TrackingFailure(f"BCD refinement: {err}") from None
        self.bcd_ms = (time.perf_counter() - t0) * 1e3
        self.tilt, self.tilt_cov, self.Sigma = state.tilts[-1].copy(), state.cov_last_tilt, Sigma
        for s, tl in zip(samples[1:-1], state.tilts[1:-1]):
            s.tilt = tl.copy()  # (a merged link's sample is a copy: the folded frames keep their tilts)
        return state.R_ck(self.R_ic), state.t

    # --------------------------------------------------------------------------------- output
    def _state_row(self, res) -> dict:
        phase = self.phase if self.phase == INIT else (res.status if res.status != OK else self.mode)
        if phase == GEVI and self.still:
            phase = STANDSTILL
        R_wi = res.T_w_c[:3, :3] @ self.R_ic.T
        S = self.Sigma
        tilt_std = float(np.sqrt(np.trace(self.tilt_cov) / 2)) if np.all(np.isfinite(self.tilt_cov)) else np.nan
        return {"index": res.index, "t_ns": res.t_ns, "phase": phase, "roll": float(self.tilt[0]),
                "pitch": float(self.tilt[1]), "yaw": yaw_of(R_wi), "bgx": self.b_g[0], "bgy": self.b_g[1],
                "bgz": self.b_g[2], "bax": self.b_a[0], "bay": self.b_a[1], "baz": self.b_a[2], "ba_std": self.bias_std,
                "sigma_trace": float(np.trace(S)), "s_xx": S[0, 0], "s_yy": S[1, 1], "s_zz": S[2, 2], "s_xy": S[0, 1],
                "s_xz": S[0, 2], "s_yz": S[1, 2], "tilt_std": tilt_std,
                "ransac_iters": getattr(self.gevi_verify, "iterations", 0) if self.mode == GEVI else 0}

    def summary(self) -> dict:
        """What status.json records about the IMU side of the run."""
        flight = {"updates": len(self.bias_updates), "first_at_s": self.bias_updates[0] if self.bias_updates else None,
                  "last_std": None if np.isnan(self.bias_std) else self.bias_std}
        return {"initialisation": self.init_info, "gyro_bias": self.b_g.tolist(), "acc_bias": self.b_a.tolist(),
                "acc_bias_in_flight": flight,
                "imu_gaps": self.gaps, "initialised": self.phase != INIT}
