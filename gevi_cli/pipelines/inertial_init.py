"""GeVI's initialisation with known scale and its bias refinements (spec 9 [PROPOSAL]; docs/method.md 9b).

A mixin of :class:`~gevi_cli.pipelines.gevi.GeviOdometry`, kept apart so each module has one job:
detecting the starting standstill (images and IMU), initialising from it or from the first seconds of
stereo odometry, re-expressing the held-back poses in the gravity-aligned world, and the one-off
accelerometer-bias estimate after a standstill start.  It reads and writes the odometry's state.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.frontend.image_motion import fitted_flow_px
from gevi_cli.inertial.attitude import AttitudeFilterConfig, GravityAttitudeFilter, run_filter
from gevi_cli.inertial.standstill import GRAVITY, rest_limits_hold, tilt_from_specific_force
from gevi_cli.pipelines.types import OK

MIN_FLOW_FEATURES = 20
"""Fewest features tracked since the reference frame for the images to judge rest (``_image_flow_px``)."""

INIT, STANDSTILL, GEVI, VISUAL = "init", "standstill", "gevi", "visual"


@dataclass
class FrameSample:
    """IMU summary of one frame of the BCD window: unit bias-corrected specific force ``acc_dir``,
    gyro rotation vector ``rotvec`` from the previous frame (rad), ``dt`` (s), estimated ``tilt``."""

    index: int
    t_ns: int
    t_prev_ns: int | None
    acc_dir: np.ndarray
    rotvec: np.ndarray
    dt: float
    tilt: np.ndarray
    f_mean: np.ndarray | None = None  # mean specific force over the frame period, as measured (m/s^2)
    R_wb: np.ndarray | None = None  # body orientation the acceleration compensation used (None: none)
    _R: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)
    _R_of: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def gyro_rotation(self) -> np.ndarray:
        """``exp(rotvec)``, the gyro rotation from the previous frame (body), computed once per ``rotvec``:
        the sample, the tilt prediction, the front end's rotation prior use it in every frame."""
        if self._R_of is not self.rotvec:
            self._R, self._R_of = est.exp_so3(self.rotvec), self.rotvec
        return self._R


def tilt_of(R_wc: np.ndarray, R_ic: np.ndarray) -> np.ndarray:
    """(roll, pitch) of the body (IMU) for a camera orientation ``R_wc`` (rad)."""
    return np.array(est.tilt_angles(R_wc @ R_ic.T))


def yaw_of(R_wi: np.ndarray) -> float:
    """ZYX yaw of ``R_wi`` (rad)."""
    return float(np.arctan2(R_wi[1, 0], R_wi[0, 0]))


class InertialInitialisation:
    """Initialisation state machine of GeVI (phase INIT -> GEVI); see the module docstring."""

    def _try_init(self, res) -> None:
        ic = self.cfg.init
        t_ns = res.t_ns
        elapsed = (t_ns - self.t_first) * 1e-9
        if self.still:
            rest, (ts, g, a) = self._still_since_start(res)
            if not rest:
                self.still = False
            elif elapsed >= ic.still_min_s and len(ts) >= 2:
                self._initialise_standstill(res, ts, g, a)
                return
        if not self.still and elapsed >= ic.window_s:
            if self.next_init_try is not None and res.index < self.next_init_try:
                return
            self._initialise_moving(res, elapsed)

    def _initialise_standstill(self, res, ts, g, a) -> None:
        self.b_g = g.mean(0)
        roll, pitch = tilt_from_specific_force(a.mean(0))
        # V = the first frame's rectified cam0, which is where the platform still is
        R_WV = est.levelling(roll, pitch, self.R_ic) @ res.T_w_c[:3, :3].T
        self.init_info = {"method": "standstill", "at_s": (res.t_ns - self.t_first) * 1e-9,
                          "standstill_s": (ts[-1] - ts[0]) * 1e-9}
        self._enter_tracking(res, R_WV)

    def _initialise_moving(self, res, elapsed: float) -> None:
        ic = self.cfg.init
        poses = self.init_poses[::max(ic.stride, 1)]
        opts = est.InitOptions(ba_prior_sigma=ic.ba_prior_sigma, acc_noise_density=self.imu.noise.acc_noise_density,
                               pose_pos_sigma=ic.pose_sigma_m)
        try:
            r = est.stereo_imu_init(np.array([p[1] for p in poses], dtype=np.int64),
                                    np.array([p[2][:3, :3] for p in poses]), np.array([p[2][:3, 3] for p in poses]),
                                    self.imu.t_ns, self.imu.gyro, self.imu.acc, self.R_ic, self.p_ic, opts)
        except est.EstimatorError as err:
            if elapsed + 0.5 < ic.max_window_s:
                self.next_init_try = res.index + max(ic.stride, 1) * 5
                self.init_info = {"failed_attempt": str(err)}
                return
            # last resort: gravity from the mean specific force (zero mean acceleration assumed)
            _, g, a = self.imu.window(self.t_first, res.t_ns)
            roll, pitch = tilt_from_specific_force(a.mean(0))
            R_WV = est.levelling(roll, pitch, self.R_ic) @ self.init_poses[0][2][:3, :3].T
            self.init_info = {"method": "mean-specific-force (stereo-IMU init failed: " + str(err) + ")",
                              "at_s": elapsed}
            self._enter_tracking(res, R_WV)
            return
        self.b_g, self.b_a = r.b_g.copy(), r.b_a.copy()
        self.init_info = {"method": "stereo-imu", "at_s": elapsed, "poses": len(poses),
                          "gravity_norm_linear": r.gravity_norm_linear, "rms_rot": r.rms_rot}
        self._enter_tracking(res, r.R_WV)

    def _enter_tracking(self, res, R_WV: np.ndarray) -> None:
        """Re-express everything held in V in the gravity-aligned W; the held poses become final."""
        T_WV = np.eye(4)
        T_WV[:3, :3] = R_WV
        self.pending = [(i, T_WV @ T) for i, T in self.pending]
        res.T_w_c = T_WV @ res.T_w_c
        res.online, self.online_held = [(i, T_WV @ T) for i, T in self.online_held], []
        if self.kf is not None:
            self.kf.T_w_k = T_WV @ self.kf.T_w_k
        if self.T_w_last is not None:
            self.T_w_last = T_WV @ self.T_w_last
        poses = dict(self.pending)
        self.T_first = self.pending[0][1].copy() if self.pending else res.T_w_c.copy()
        self.tilt = tilt_of(res.T_w_c[:3, :3], self.R_ic)
        s0 = (self.cfg.init.ba_prior_sigma / GRAVITY) ** 2  # the bias/tilt ambiguity floor (spec 9.6)
        self.tilt_cov = np.eye(2) * s0
        if self.kf is not None:
            self.kf_tilt = tilt_of(self.kf.T_w_k[:3, :3], self.R_ic)
            self.kf_tilt_cov = np.eye(2) * s0
        # the window since the keyframe, re-summarised with the biases now known
        for s in self.win + [self.cur]:
            fs = self._sample(s.index, s.t_ns, s.t_prev_ns)
            s.acc_dir, s.rotvec = fs.acc_dir, fs.rotvec
            if s.index in poses and s is not self.cur:
                s.tilt = tilt_of(poses[s.index][:3, :3], self.R_ic)
        self.phase = GEVI
        self._seed_motion(T_WV, res.index)
        if self.cfg.fusion.mode == "4dof":
            self._start_attitude_filter(res.t_ns)
        if not self.cfg.ba.enabled:
            res.final, self.pending = self.pending, []

    def _seed_motion(self, T_WV: np.ndarray, index: int) -> None:
        """Give the recent-motion fit and the window gravity the held-back frames of the initialisation
        window, in W and preintegrated with the biases now known, so that both answer from the first
        frame after the initialisation instead of a window length later (the frame ``index`` itself is
        added by ``_update_velocity``).  A standstill start is declared over late; without these frames
        the start of motion in between was read from the bare specific force."""
        prev = None
        for i, t_ns, T_vc in self.init_poses:
            if i >= index:
                break
            self._add_tracked(t_ns, T_WV @ T_vc, prev[1] if prev is not None and prev[0] == i - 1 else None)
            prev = (i, t_ns)

    def _start_attitude_filter(self, t_ns: int) -> None:
        ts, g, a = self.imu.window(t_ns, int(self.imu.t_ns[-1]))
        R0 = est.rtilt(*self.tilt)
        f = GravityAttitudeFilter(R0, self.b_g, self.imu.noise, self.imu.dt_nominal, AttitudeFilterConfig(),
                                  b_a=self.b_a)
        self.attitude = run_filter(f, ts, g, a)

    def _images_at_rest(self, res) -> bool:
        """The images say the platform is at rest: the image motion since the reference frame
        (``_image_flow_px``) stays within ``init.still_max_flow_px``, or exceeds it on fewer than
        ``init.still_persist`` consecutive frames.

        The flow is measured on the images themselves, not through the poses: on a turbid start
        (pool-hard_s3, 27 keyframe points, a keyframe every frame) the chained poses read 3.8 px of
        motion at rest by frame 1, the standstill was missed, and the moving-start initialisation at
        rest took a gyro bias 6.6e-3 rad/s off (tilt 11 deg after 60 s).  EuRoC's MAV at rest jitters by
        up to 1.2 px (0.15 deg).  A real start of motion grows monotonically and is caught
        ``still_persist - 1`` frames later, well inside ``still_min_s``."""
        moved = self._image_flow_px() > self.cfg.init.still_max_flow_px
        self.moving_run = self.moving_run + 1 if moved else 0
        return self.moving_run < max(self.cfg.init.still_persist, 1)

    def _image_flow_px(self) -> float:
        """Image motion (px) since the reference frame: :func:`~gevi_cli.frontend.image_motion.fitted_flow_px`
        over this frame's features tracked since the reference.  The reference is the first frame with
        features after the first keyframe; when fewer than ``MIN_FLOW_FEATURES`` of its features are
        left, this frame becomes the reference (if it has that many).  0 (the images say nothing, the
        IMU decides) before any keyframe, on a new reference, and with too few features.

        Why fitted and re-referenced (docs/method.md, "Standstill"): LK-chained features random-walk,
        on a faint floor by 3-5 px within 0.5 s at rest (pool-hard_s1), while a motion moves them
        together; below 20 features the fit's own noise reached 3 px.  Abstaining once the first
        frame's features are gone left the end of the standstill to the IMU's loose limits, which let
        pool-hard_s1's smooth start of motion pass as rest for 0.9 s (1e-2 rad/s of yaw rate went into
        the gyro bias).  A new reference forgets the motion before it: a start of motion outgrows the
        limit within one reference's life, a creep slower than ``still_max_flow_px`` per reference
        does not."""
        obs = self.obs
        if obs is None or self.first_kf_index is None:
            return 0.0
        ref = self.flow_ref
        if ref is not None:
            common, i0, i1 = np.intersect1d(ref.ids, obs.ids, assume_unique=True, return_indices=True)
        if ref is None or len(common) < MIN_FLOW_FEATURES:
            if len(obs.ids) >= MIN_FLOW_FEATURES:
                self.flow_ref = obs
            return 0.0
        return fitted_flow_px(ref.uv[i0], obs.uv[i1])

    def _still_since_start(self, res):
        """(images and IMU at rest since the first frame, the IMU samples (t, gyro, acc) since then).

        Evaluated once per frame: the frame that initialises from the standstill asks again right after
        (``_try_init``, then ``_update_standstill``), and the images' "moving" counter must count it once."""
        if self.still_eval is not None and self.still_eval[0] == res.index:
            return self.still_eval[1]
        ic = self.cfg.init
        i0, i1 = self.imu.span(self.t_first, res.t_ns)
        ts, g, a = self.imu.t_ns[i0:i1], self.imu.gyro[i0:i1], self.imu.acc[i0:i1]
        # (the statistics from the stream's prefix sums: this window grows with the standstill)
        rest = self._images_at_rest(res) and (len(ts) < 2 or rest_limits_hold(
            *self.imu.moments.window(i0, i1), ic.still_max_gyro_std, ic.still_max_acc_std, ic.still_max_gravity_err))
        self.still_eval = (res.index, (rest, (ts, g, a)))
        return rest, (ts, g, a)

    def _update_standstill(self, res) -> None:
        """While the starting standstill lasts, the gyro bias is the mean rate over all of it."""
        rest, (ts, g, a) = self._still_since_start(res)
        if rest and len(ts) >= 2:
            # the end of a standstill is seen late (a smooth start of motion stays below the image and
            # IMU limits for a while), so the last ``init.still_lag_s`` do not enter the bias [PROPOSAL]:
            # pool-hard_s3 (yaw ramping up from rest) was called still for 1.8 s, 0.8 s longer than it
            # was, and its gyro bias came out 4.5e-3 rad/s off in z with them
            i0, i1 = self.imu.span(self.t_first, int(ts[-1]) - int(self.cfg.init.still_lag_s * 1e9))
            if (self.imu.t_ns[i1 - 1] - ts[0] if i1 - i0 >= 2 else 0) < int(0.5 * self.cfg.init.still_min_s * 1e9):
                i1 = i0 + len(ts)
            self.b_g = self.imu.moments.gyro_mean(i0, i1)
            self.init_info["standstill_s"] = (ts[-1] - ts[0]) * 1e-9
        else:
            self.still = False

    def _refine_acc_bias(self, res) -> None:
        """After a standstill start, the accelerometer bias (unobservable at rest) is estimated once from
        the first ``init.window_s`` of continuously tracked motion: the stereo-IMU initialisation (spec 9)
        over those frames' poses in W, of which only b_a is adopted (W, the tilts and the gyro bias of the standstill stay).
        [PROPOSAL]; measured in docs/method.md 9b."""
        ic = self.cfg.init
        if not ic.refine_acc_bias or self.still or self.init_info.get("method") != "standstill" \
                or "acc_bias_refined" in self.init_info:
            return
        if res.status != OK:
            # 2 s of *visually tracked* motion: IMU-carried poses would feed the bias back into itself
            # (measured on pool-hard_s1, 30 s: ATE 0.26 m -> 0.93 m when they were allowed)
            self.bias_poses = []
            return
        self.bias_poses.append((res.t_ns, res.T_w_c.copy()))
        if not self.bias_poses or (self.bias_poses[-1][0] - self.bias_poses[0][0]) * 1e-9 < ic.window_s:
            return
        poses = self.bias_poses[::max(ic.stride, 1)]
        opts = est.InitOptions(ba_prior_sigma=ic.ba_prior_sigma, acc_noise_density=self.imu.noise.acc_noise_density,
                               pose_pos_sigma=ic.pose_sigma_m, b_g0=self.b_g)
        try:
            r = est.stereo_imu_init(np.array([p[0] for p in poses], dtype=np.int64),
                                    np.array([p[1][:3, :3] for p in poses]), np.array([p[1][:3, 3] for p in poses]),
                                    self.imu.t_ns, self.imu.gyro, self.imu.acc, self.R_ic, self.p_ic, opts)
        except est.EstimatorError as err:
            self.init_info["acc_bias_refined"] = f"failed: {err}"
            return
        angle = float(np.arccos(np.clip(-r.gravity_V[2] / np.linalg.norm(r.gravity_V), -1.0, 1.0)))
        info = {"at_s": (res.t_ns - self.t_first) * 1e-9, "b_a": r.b_a.tolist(), "gravity_angle_deg": np.degrees(angle)}
        # consistency with the standstill: the bias may move gravity by at most the bias/tilt ambiguity
        # (3 prior sigma / g) and must itself be plausible under its prior
        limit = 3.0 * ic.ba_prior_sigma
        if angle > limit / GRAVITY or np.linalg.norm(r.b_a) > limit:
            info["rejected"] = f"inconsistent with the standstill (limit {limit:g} m/s^2)"
        else:
            # Only the component along gravity is adopted [PROPOSAL]: the standstill's W already holds the
            # horizontal bias as a tilt (b_h / g, spec 9.6), and 2 s of motion with a few degrees of yaw
            # cannot tell them apart, so a horizontal b_a from this window re-counts it without the tilt
            # the same solution came with.  Measured on the 60 s pool renders (docs/method.md 9b): the
            # horizontal part was 0.009-0.037 m/s^2 off the true bias, as far as the prior's zero was
            # (0.012-0.031), and moved by 0.015 m/s^2 between runs that differed in the last digits; the
            # vertical part was within 0.006 m/s^2.
            up = est.rtilt(*self.tilt).T @ np.array([0.0, 0.0, 1.0])  # body up (IMU frame)
            self.b_a = self.b_a + up * float(up @ (r.b_a - self.b_a))
            info["adopted"] = self.b_a.tolist()
        self.init_info["acc_bias_refined"] = info

    def _track_acc_bias(self, res) -> None:
        """The horizontal accelerometer bias in flight (acc_bias.py): each visually tracked frame's window
        gravity into the tracker, chained by the gyro to the frame before when that one is in it too;
        at keyframes the estimate is adopted when its posterior std is below ``fusion.bias_max_std``
        [PROPOSAL]."""
        bt = self.bias_track
        if bt is None or self.still or self.phase == INIT:
            return
        up = self.wgrav.up(res.t_ns) if res.status == OK and len(self.wgrav) else None
        if up is None:
            bt.reset()
            return
        chained = len(bt) and self.t_prev is not None and int(bt.t[-1]) == self.t_prev
        bt.add(res.t_ns, self.cur.rotvec if chained else None, up, self.b_a)
        if not res.keyframe:
            return
        sol = bt.solve(self.b_a)
        if sol is None:
            return
        b, std = sol
        self.bias_std = std
        if std < self.cfg.fusion.bias_max_std:
            self.b_a = b
            self.bias_updates.append((res.t_ns - self.t_first) * 1e-9)
