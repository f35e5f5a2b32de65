"""GeVI: gravity-enhanced stereo visual-inertial odometry ("GeVI-SLAM", spec 2, 6-9).

Per frame, on top of :class:`~gevi_cli.pipelines.odometry.KeyframeOdometry` (front end, keyframes,
triangulation from the current keyframe only, noise variance, bridging, run-driver contract):

1. IMU: the gyro rotation since the previous frame (bias-corrected) predicts the current roll/pitch
   from the last estimate: ``tilt_c = tilt(R_tilt(tilt_prev) dR)`` (yaw-invariant, spec 8.1.3).
2. Verification: upright 3-point RANSAC with the levelling rotations ``L_k``, ``L_c`` (spec 7).
3. 4-DOF bias-eliminated estimate of (psi, t_ck) (spec 6.2) and one Gauss-Newton step on the
   point-to-epipolar-line distances in both keyframe images (spec 6.3): :mod:`.pose4`.
4. 6-DOF refinement with the jointly estimated gravity-prior covariance, by block coordinate descent
   (spec 8) over the frames since the keyframe: :mod:`.tilt_window`.  Its current-frame tilt is fed
   forward (step 1 of the next frame); at a keyframe it becomes the keyframe tilt with the marginal
   covariance as the next windows' prior.

Before that, the initialisation with known scale (spec 9, :mod:`.inertial_init`): from a standstill
(images and IMU at rest for ``init.still_min_s``) or from the first ``init.window_s`` of 6-DOF stereo
odometry (Bias-Eli-W, as CFO).  The poses of the initialisation window are held back and re-expressed in
the gravity-aligned world frame W (z up, yaw of the first camera arbitrary) once it is known, so the
trajectory is one piece.  Where the IMU has a gap (or ends before the images) the frame is tracked with
the 6-DOF visual step and the interval is reported.

The parts, each with one job: :class:`~.inertial_init.Initialisation` (the start and the standstill),
:class:`~.inertial_state.ImuBiases` (the bias estimates), :class:`~.body_motion.BodyMotion` (per-frame
IMU summaries, recent motion, window gravity, IMU propagation), :class:`~.tilt_window.TiltWindow` (the
roll/pitch state and the BCD), :class:`~.acc_bias.InFlightBias` (the horizontal b_a in flight) and
the two verifications.  Each frame's plan (:class:`FramePlan`) is decided from the IMU before the images.

Frames: ``T_w_c`` is rectified cam0 in W; the body frame B is the IMU frame; ``R_ic`` = R_BC0 maps
camera vectors into the IMU frame.  Tilts are (roll, pitch) of R_WI in rad (ZYX, spec 1).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.frontend import FrontEnd
from gevi_cli.geometry import make_T
from gevi_cli.inertial.attitude import AttitudeFilterConfig, GravityAttitudeFilter, run_filter
from gevi_cli.inertial.imu_stream import ImuStream
from gevi_cli.inertial.standstill import GRAVITY
from gevi_cli.pipelines.acc_bias import AccBiasTracker, InFlightBias
from gevi_cli.pipelines.body_motion import BodyMotion
from gevi_cli.pipelines.config import BA_PRIOR_SIGMA, BIAS_MAX_STD, MAX_MEDIAN_PX, OdometryConfig
from gevi_cli.pipelines.inertial_init import Initialisation, Start
from gevi_cli.pipelines.inertial_state import FrameSample, ImuBiases, tilt_of, yaw_of
from gevi_cli.pipelines.odometry import KeyframeOdometry, Matches
from gevi_cli.pipelines.pose4 import pose4
from gevi_cli.pipelines.pose6 import converged_limit_px, reprojection_median_px, reverified, tracked_pose6
from gevi_cli.pipelines.tilt_window import TiltWindow
from gevi_cli.pipelines.types import INERTIAL, OK, WORLD_GRAVITY, WORLD_PROVISIONAL
from gevi_cli.pipelines.verification import FivePointL1Verification, ThreePointVerification, TrackingFailure

#: how a frame is tracked: before W is known; the GeVI steps; the 6-DOF visual step over an IMU gap.
#: STANDSTILL labels GEVI frames of the starting standstill in imu_states.csv.
INIT, GEVI, VISUAL, STANDSTILL = "init", "gevi", "visual", "standstill"

#: imu_states.csv columns (angles rad, biases rad/s and m/s^2, Sigma dimensionless unit-vector variance)
STATE_COLUMNS = ("index", "t_ns", "phase", "roll", "pitch", "yaw", "bgx", "bgy", "bgz", "bax", "bay", "baz",
                 "ba_std", "sigma_trace", "s_xx", "s_yy", "s_zz", "s_xy", "s_xz", "s_yz", "tilt_std",
                 "ransac_iters")


@dataclass
class FramePlan:
    """How the frame being tracked is tracked, decided from the IMU before its images are looked at.

    ``sample``: its IMU summary; ``mode``: INIT / GEVI / VISUAL; in GEVI mode ``tilt_pred``, the
    gyro-predicted roll/pitch (rad), and ``levelling``, the rotations (L_k, L_c) that level the keyframe
    and the current camera for the verification and the pose step."""

    sample: FrameSample
    mode: str
    tilt_pred: np.ndarray | None = None
    levelling: tuple[np.ndarray, np.ndarray] | None = None


class GeviOdometry(KeyframeOdometry):
    name = "gevi"
    state_file = "imu_states.csv"
    state_columns = STATE_COLUMNS

    def __init__(self, frontend: FrontEnd, cfg: OdometryConfig, imu: ImuStream, frame_period_s: float):
        super().__init__(frontend, cfg)
        self.imu = imu
        T_B_C = np.asarray(self.camera.T_B_C0, dtype=float)
        self.R_ic, self.p_ic = T_B_C[:3, :3], T_B_C[:3, 3]
        self.biases = ImuBiases()
        self.start = Initialisation(cfg.init, imu, self.R_ic, self.p_ic)
        self.body = BodyMotion(imu, self.biases, T_B_C, frame_period_s, cfg.fusion)
        self.tilts = TiltWindow(cfg, imu.noise, frame_period_s, self.R_ic)
        # the horizontal accelerometer bias from yaw changes (acc_bias.py); it reads the window gravity
        tracker = AccBiasTracker(cfg.fusion.bias_window_s, BA_PRIOR_SIGMA, walk=imu.noise.acc_random_walk) \
            if cfg.fusion.bias_window_s > 0 and self.body.gravity is not None else None
        self.in_flight = InFlightBias(tracker, BIAS_MAX_STD)
        self.six_verify = FivePointL1Verification(dataclasses.replace(cfg.verify, ransac="5pt"), self.camera)
        if cfg.verify.ransac == "3pt":
            self.gevi_verify = ThreePointVerification(cfg.verify, self.camera, self._levelling)
        else:
            self.gevi_verify = FivePointL1Verification(cfg.verify, self.camera)
        self.verification = self._verify
        self.attitude = None  # AttitudeTrack of the IMU-only filter (fusion.mode = 4dof)
        self.plan: FramePlan | None = None
        self.t_prev: int | None = None
        self.gaps: list[dict] = []  # IMU gaps: {"first_index", "last_index", "start_s", "end_s", "frames"}

    # ------------------------------------------------------------------------------ main entry
    @property
    def world(self) -> str:
        """WORLD_GRAVITY once the initialisation answered; before, WORLD_PROVISIONAL (V: the first cam0)."""
        return WORLD_GRAVITY if self.start.done else WORLD_PROVISIONAL

    def _track(self, frame):
        t_ns = int(frame.t_ns)
        plan = self.plan = self._plan(t_ns)
        res = super()._track(frame)
        self.start.note_frame(res)
        self._note_gap(res, plan.mode == VISUAL)
        if not self.start.done:
            self._hold_until_start(res)
        elif plan.mode == VISUAL or res.status == INERTIAL:
            self.tilts.tilt = tilt_of(res.T_w_c[:3, :3], self.R_ic)  # the gyro carried the attitude, or vision
        elif plan.mode == GEVI and res.status != OK:
            self.tilts.tilt = plan.tilt_pred  # the gyro carries the attitude over a lost frame
        if self.start.done:
            self._update_inertial(res)
        plan.sample.tilt = self.tilts.tilt.copy()
        if res.keyframe or self.kf is None:
            self._new_window(res)
        else:
            self.tilts.append(plan.sample)
        res.extra = self._state_row(res)
        self.t_prev = t_ns
        return res

    def _plan(self, t_ns: int) -> FramePlan:
        """The frame's IMU summary and mode; in GEVI mode the predicted tilt and the levelling rotations."""
        R_w_last = self.T_w_last[:3, :3] if self.start.done and self.T_w_last is not None else None
        sample = self.body.sample(self.index + 1, t_ns, self.t_prev, R_w_last)
        if not self.start.done:
            return FramePlan(sample, INIT)
        if not sample.has_imu:
            return FramePlan(sample, VISUAL)
        tilt_pred = np.array(est.tilt_angles(est.rtilt(*self.tilts.tilt) @ sample.gyro_rotation()))
        if self.attitude is not None:
            tilt_pred = self._filter_tilt(t_ns)
        lev = (est.levelling(*self.tilts.kf_tilt, self.R_ic), est.levelling(*tilt_pred, self.R_ic))
        return FramePlan(sample, GEVI, tilt_pred, lev)

    def _hold_until_start(self, res) -> None:
        """Before W is known nothing is final and nothing is written: the poses are held in V (the first
        keyframe's rectified cam0) and re-expressed in W when the initialisation answers."""
        self.pending, self._final = self._final + self.pending, []
        self.online_held.append((res.index, res.T_w_c.copy()))
        self._online = []
        start = self.start.try_start(res, self.obs)
        if start is not None:
            self._enter_world(res, start)

    def _update_inertial(self, res) -> None:
        """After a frame in W: the standstill's gyro bias, the motion and window gravity, the biases."""
        still = self.start.still
        if still:
            b_g = self.start.standstill_gyro_bias(res, self.obs)
            still = self.start.still
            if b_g is not None:
                self.biases.b_g = b_g
        if res.status != INERTIAL:
            # also at rest: the window gravity then spans the start of motion, which the standstill test sees late
            self.body.update(res, self.t_prev, self.plan.sample, still)
            if not still:  # at rest the later frames would not change the earlier frames' gravity
                self.body.refresh_acc_dirs(self.tilts.samples)
        if still:
            self.body.v_W = np.zeros(3)
        self.biases.b_a = self.start.refined_acc_bias(res, self.biases.b_g, self.biases.b_a, self.tilts.tilt)
        self._track_acc_bias(res)

    # ------------------------------------------------------------------------- hooks of the core
    def _levelling(self):
        """(L_k, L_c, sigma) of the frame being tracked (GEVI mode): the levelling rotations of the keyframe's
        and the predicted current roll/pitch, and the current normalized noise std."""
        return (*self.plan.levelling, float(np.sqrt(self.sigma2)))

    def _verify(self, z, q, p, rng):
        return (self.gevi_verify if self.plan.mode == GEVI else self.six_verify)(z, q, p, rng)

    def rotation_prior(self):
        """The gyro's rotation since the previous frame, in rectified-left camera coordinates
        (``R_cp = R_ic^T exp(rotvec)^T R_ic``); over an IMU gap the last step's, as CFO.  With
        ``frontend.derotate_prior`` "image" none: the front end's in-plane fit, as for CFO."""
        if self.cfg.frontend.derotate_prior == "image":
            return None  # the front end's in-plane fit (gevi_cli/configs/pool.yaml)
        if self.plan is None or self.t_prev is None or not np.all(np.isfinite(self.plan.sample.rotvec)):
            return super().rotation_prior()
        return self.R_ic.T @ self.plan.sample.gyro_rotation().T @ self.R_ic

    def _bridge(self, t_ns: int):
        """A frame that cannot be tracked visually: at rest while the IMU shows the starting standstill,
        else IMU preintegration from the last pose and velocity (constant velocity where the IMU has a gap)."""
        if self.T_w_last is None:
            return super()._bridge(t_ns)
        if self.start.still and (self.start.done or self.kf is None):
            return self.T_w_last.copy(), INERTIAL
        if not self.start.done or self.t_prev is None or not self.imu.covers(self.t_prev, t_ns):
            return super()._bridge(t_ns)
        return self.body.propagate(self.T_w_last, self.t_prev, t_ns), INERTIAL

    # ---------------------------------------------------------------------------- pose step
    def estimate_T_ck(self, m: Matches, frame) -> np.ndarray:
        if self.plan.mode != GEVI:
            R, t, fallback = tracked_pose6(m.p, m.cov_unit * self.sigma2, m.q, self.cfg.pnp, self.sigma2, self.camera.f)
            self.fallbacks += int(fallback)
            return make_T(R, t)
        cov = m.cov_unit * self.sigma2
        if self.cfg.fusion.mode == "bcd":
            self.tilts.note_innovation(self.plan.sample, self.plan.tilt_pred)
        R, t = self._gevi_pose(m, cov)
        f, pc = self.camera.f, self.cfg.pnp
        med = reprojection_median_px(R, t, m.p, m.q, f)
        if not med <= converged_limit_px(pc, self.sigma2, f):
            # CFO's re-verification (pose6.reverified) with the GeVI step; the tilt state is put back when
            # the second pose is not kept
            saved = self.tilts.saved()
            again = reverified(m.p, m.q, med, pc, self.sigma2, f, lambda keep: self._gevi_pose(m.subset(keep), cov[keep]))
            if again is None:
                self.tilts.restore(saved)
            else:
                (R, t), med = again
        if not np.isfinite(med) or med > MAX_MEDIAN_PX:
            raise TrackingFailure(f"median reprojection error {med:.2f} px after the GeVI pose step")
        return make_T(R, t)

    def _gevi_pose(self, m: Matches, cov):
        """The 4-DOF step (6), then the BCD (8) or, with ``fusion.mode = 4dof``, the IMU's tilt as it is."""
        L_k, L_c = self.plan.levelling
        (psi, t), fallback = pose4(m, cov, L_k, L_c, self.camera, self.cfg, self.sigma2)
        self.fallbacks += int(fallback)
        if self.cfg.fusion.mode == "bcd":
            return self.tilts.refine(m, cov, psi, t, L_k, L_c, self.sigma2, self.plan.sample, self.plan.tilt_pred)
        self.tilts.tilt, self.tilts.tilt_cov = self.plan.tilt_pred.copy(), np.full((2, 2), np.nan)
        return est.rot4(psi, L_k, L_c), t

    # ------------------------------------------------------------------------- the start
    def _enter_world(self, res, start: Start) -> None:
        """The initialisation answered: its biases adopted, everything held in V re-expressed in the
        gravity-aligned W, the held poses final, the tilt state and the motion histories started."""
        if start.b_g is not None:
            self.biases.b_g = start.b_g
        if start.b_a is not None:
            self.biases.b_a = start.b_a
        T_WV = np.eye(4)
        T_WV[:3, :3] = start.R_WV
        self.pending = [(i, T_WV @ T) for i, T in self.pending]
        res.T_w_c = T_WV @ res.T_w_c
        self._online, self.online_held = [(i, T_WV @ T) for i, T in self.online_held], []
        if self.kf is not None:
            self.kf.T_w_k = T_WV @ self.kf.T_w_k
        if self.T_w_last is not None:
            self.T_w_last = T_WV @ self.T_w_last
        poses = dict(self.pending)
        s0 = (BA_PRIOR_SIGMA / GRAVITY) ** 2  # the bias/tilt ambiguity floor (spec 9.6)
        kf_tilt = tilt_of(self.kf.T_w_k[:3, :3], self.R_ic) if self.kf is not None else None
        self.tilts.reset_tilts(tilt_of(res.T_w_c[:3, :3], self.R_ic), kf_tilt, s0)
        # the window since the keyframe, re-summarised with the biases now known
        cur = self.plan.sample
        for s in self.tilts.samples + [cur]:
            fs = self.body.sample(s.index, s.t_ns, s.t_prev_ns, None)
            s.acc_dir, s.rotvec = fs.acc_dir, fs.rotvec
            if s.index in poses and s is not cur:
                s.tilt = tilt_of(poses[s.index][:3, :3], self.R_ic)
        self.body.seed(self.start.held, T_WV, res.index)
        if self.cfg.fusion.mode == "4dof":
            self._start_attitude_filter(res.t_ns)
        if not self.cfg.ba.enabled:
            self._final, self.pending = self.pending, []

    def _start_attitude_filter(self, t_ns: int) -> None:
        """``fusion.mode = 4dof``: roll/pitch from the IMU alone, the gravity-prior filter run over the rest."""
        ts, g, a = self.imu.window(t_ns, int(self.imu.t_ns[-1]))
        R0 = est.rtilt(*self.tilts.tilt)
        f = GravityAttitudeFilter(R0, self.biases.b_g, self.imu.noise, self.imu.dt_nominal, AttitudeFilterConfig(),
                                  b_a=self.biases.b_a)
        self.attitude = run_filter(f, ts, g, a)

    def _filter_tilt(self, t_ns: int) -> np.ndarray:
        a = self.attitude
        k = max(int(np.searchsorted(a.t_ns, t_ns, side="right")) - 1, 0)
        return np.array(est.tilt_angles(a.R_WI[k]))

    # ---------------------------------------------------------------------------- keyframes
    def _new_window(self, res) -> None:
        """The current frame starts the next BCD window (it is the new keyframe); in W, the keyframe tilt
        is taken and the keyframe re-levelled by it."""
        i_prev = self.tilts.restart(self.plan.sample)  # the previous keyframe's frame
        if not self.start.done or self.kf is None:
            return
        self.tilts.take_keyframe_tilt()
        T = self.kf.T_w_k
        if self.cfg.ba.enabled and res.status == OK:
            # The epipolar BA refined the keyframe with the whole window's images; its roll/pitch is the
            # better relative tilt, the BCD's the gravity-anchored one.  A complementary blend keeps both
            # (the BA's alone drifts where vision is weak; the BCD's alone follows sustained accelerations):
            # the gravity-anchored BCD tilt, written as the BA's plus the wrapped difference.
            ba_tilt = tilt_of(T[:3, :3], self.R_ic)
            self.tilts.kf_tilt = ba_tilt + np.array([est.wrap_angle(d) for d in self.tilts.tilt - ba_tilt])
        # keep R_WK exactly levelled by the keyframe tilt (the 4-DOF model's assumption)
        yaw = yaw_of(T[:3, :3] @ self.R_ic.T)
        R_before = T[:3, :3].copy()
        T[:3, :3] = est.rot_z(yaw) @ est.levelling(*self.tilts.kf_tilt, self.R_ic)
        # The keyframe's written pose is the one the next frames chain from.  The frames since the
        # previous keyframe (after the BA, their relative motion is the BA's) take the same correction
        # in proportion to their place in the window, so that it is not one step at the keyframe
        # [PROPOSAL].  What is tracked next is unchanged: only written poses between keyframes move.
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

        self._final = [(i, written(i, P)) for i, P in self._final]
        self.pending = [(i, written(i, P)) for i, P in self.pending]

    # ------------------------------------------------------------------------------ biases
    def _track_acc_bias(self, res) -> None:
        """The horizontal accelerometer bias in flight (acc_bias.py), from the visually tracked frames in motion."""
        if self.in_flight.tracker is None or self.start.still:
            return
        wg = self.body.gravity
        up = wg.up(res.t_ns) if res.status == OK and len(wg) else None
        self.biases.b_a = self.in_flight.observe(res.t_ns, up, self.plan.sample.rotvec, self.t_prev, res.keyframe,
                                                 self.biases.b_a, (res.t_ns - self.start.t_first) * 1e-9)

    def _note_gap(self, res, gap: bool) -> None:
        if not gap:
            return
        if self.gaps and self.gaps[-1]["last_index"] == res.index - 1:
            g = self.gaps[-1]
            g["last_index"], g["end_s"], g["frames"] = res.index, res.t_ns * 1e-9, g["frames"] + 1
        else:
            self.gaps.append({"first_index": res.index, "last_index": res.index, "start_s": res.t_ns * 1e-9,
                              "end_s": res.t_ns * 1e-9, "frames": 1})

    # --------------------------------------------------------------------------------- output
    def _state_row(self, res) -> dict:
        mode = self.plan.mode
        phase = INIT if not self.start.done else (res.status if res.status != OK else mode)
        if phase == GEVI and self.start.still:
            phase = STANDSTILL
        R_wi = res.T_w_c[:3, :3] @ self.R_ic.T
        tw, b_g, b_a = self.tilts, self.biases.b_g, self.biases.b_a
        S = tw.Sigma
        tilt_std = float(np.sqrt(np.trace(tw.tilt_cov) / 2)) if np.all(np.isfinite(tw.tilt_cov)) else np.nan
        return {"index": res.index, "t_ns": res.t_ns, "phase": phase, "roll": float(tw.tilt[0]),
                "pitch": float(tw.tilt[1]), "yaw": yaw_of(R_wi), "bgx": b_g[0], "bgy": b_g[1],
                "bgz": b_g[2], "bax": b_a[0], "bay": b_a[1], "baz": b_a[2], "ba_std": self.in_flight.std,
                "sigma_trace": float(np.trace(S)), "s_xx": S[0, 0], "s_yy": S[1, 1], "s_zz": S[2, 2], "s_xy": S[0, 1],
                "s_xz": S[0, 2], "s_yz": S[1, 2], "tilt_std": tilt_std,
                "ransac_iters": self.gevi_verify.iterations if mode == GEVI else 0}

    def summary(self) -> dict:
        """What status.json records about the IMU side of the run."""
        fl = self.in_flight
        flight = {"updates": len(fl.updates), "first_at_s": fl.updates[0] if fl.updates else None,
                  "last_std": None if np.isnan(fl.std) else fl.std}
        return {"initialisation": self.start.info, "gyro_bias": self.biases.b_g.tolist(),
                "acc_bias": self.biases.b_a.tolist(), "acc_bias_in_flight": flight,
                "imu_gaps": self.gaps, "initialised": self.start.done}
