"""GeVI's initialisation with known scale and its bias refinements (spec 9 [PROPOSAL]; docs/method.md).

A small state machine, :class:`Initialisation`: it watches the first frames (tracked in the provisional
frame V, the first keyframe's rectified cam0) for a standstill (images and IMU at rest), and answers with
a :class:`Start` (gravity, hence W, and the biases) from the standstill or from the first seconds of
stereo odometry.  After a standstill start it also keeps the gyro bias at the standstill's mean rate
while the standstill lasts, and estimates the accelerometer bias once from the first seconds of motion.
It holds no poses of the odometry: re-expressing them in W is the odometry's job.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.frontend.image_motion import fitted_flow_px
from gevi_cli.inertial.imu_stream import ImuStream
from gevi_cli.inertial.standstill import (
    GRAVITY,
    STILL_MAX_ACC_STD,
    STILL_MAX_GRAVITY_ERR,
    STILL_MAX_GYRO_STD,
    rest_limits_hold,
    tilt_from_specific_force,
)
from gevi_cli.pipelines.config import (
    BA_PRIOR_SIGMA,
    INIT_STRIDE,
    MAX_WINDOW_S,
    POSE_SIGMA_M,
    STILL_LAG_S,
    STILL_MAX_FLOW_PX,
    STILL_PERSIST,
    InitConfig,
)
from gevi_cli.pipelines.types import OK

MIN_FLOW_FEATURES = 20
"""Fewest features tracked since the reference frame for the images to judge rest (``_image_flow_px``)."""


@dataclass
class Start:
    """The initialisation's answer: ``R_WV`` rotates the provisional frame V into the gravity-aligned W;
    ``b_g`` (rad/s) / ``b_a`` (m/s^2) are the biases it estimated (None: it estimated none)."""

    R_WV: np.ndarray
    b_g: np.ndarray | None = None
    b_a: np.ndarray | None = None


class Initialisation:
    """Initialisation state machine of GeVI (not started -> ``done``); see the module docstring.

    ``still``: the standstill that started the run is still going on; ``info``: what status.json records
    of the initialisation; ``t_first``: stamp of the first frame (ns)."""

    def __init__(self, cfg: InitConfig, imu: ImuStream, R_ic: np.ndarray, p_ic: np.ndarray):
        self.cfg = cfg
        self.imu = imu
        self.R_ic, self.p_ic = R_ic, p_ic
        self.done = False
        self.still = True
        self.info: dict = {}
        self.t_first: int | None = None
        self.held: list[tuple[int, int, np.ndarray]] = []  # (index, t_ns, T_v_c) of the frames tracked in V
        self._first_kf_index: int | None = None
        self._next_try: int | None = None
        self._moving_run = 0  # consecutive frames whose image motion says "moving"
        self._flow_ref = None  # features of the standstill test's reference frame (_image_flow_px)
        self._still_eval = None  # (frame index, _still_since_start's answer) of the last frame evaluated
        self._bias_poses: list[tuple[int, np.ndarray]] = []  # (t_ns, T_w_c) after the standstill, for b_a

    def note_frame(self, res) -> None:
        """Every frame: the first stamp and the first keyframe (the standstill test's references)."""
        if self._first_kf_index is None and res.keyframe:
            self._first_kf_index = res.index
        if self.t_first is None:
            self.t_first = res.t_ns

    # ------------------------------------------------------------------------------- the start
    def try_start(self, res, obs) -> Start | None:
        """A frame before the start (``res.T_w_c`` in V, ``obs`` its features): a :class:`Start` when the
        standstill has lasted ``still_min_s`` or, after motion began, ``window_s`` of poses are held."""
        if res.status == OK:
            self.held.append((res.index, res.t_ns, res.T_w_c.copy()))
        ic = self.cfg
        elapsed = (res.t_ns - self.t_first) * 1e-9
        start = None
        if self.still:
            rest, (ts, g, a) = self._still_since_start(res, obs)
            if not rest:
                self.still = False
            elif elapsed >= ic.still_min_s and len(ts) >= 2:
                start = self._from_standstill(res, ts, g, a)
        if start is None and not self.still and elapsed >= ic.window_s:
            if self._next_try is not None and res.index < self._next_try:
                return None
            start = self._from_motion(res, elapsed)
        self.done = start is not None
        return start

    def _from_standstill(self, res, ts, g, a) -> Start:
        roll, pitch = tilt_from_specific_force(a.mean(0))
        # V = the first frame's rectified cam0, which is where the platform still is
        R_WV = est.levelling(roll, pitch, self.R_ic) @ res.T_w_c[:3, :3].T
        self.info = {"method": "standstill", "at_s": (res.t_ns - self.t_first) * 1e-9,
                     "standstill_s": (ts[-1] - ts[0]) * 1e-9}
        return Start(R_WV, b_g=g.mean(0))

    def _from_motion(self, res, elapsed: float) -> Start | None:
        poses = self.held[::INIT_STRIDE]
        try:
            r = self._stereo_imu_init([p[1] for p in poses], [p[2] for p in poses])
        except est.EstimatorError as err:
            if elapsed + 0.5 < MAX_WINDOW_S:
                self._next_try = res.index + INIT_STRIDE * 5
                self.info = {"failed_attempt": str(err)}
                return None
            # last resort: gravity from the mean specific force (zero mean acceleration assumed)
            _, g, a = self.imu.window(self.t_first, res.t_ns)
            roll, pitch = tilt_from_specific_force(a.mean(0))
            R_WV = est.levelling(roll, pitch, self.R_ic) @ self.held[0][2][:3, :3].T
            self.info = {"method": "mean-specific-force (stereo-IMU init failed: " + str(err) + ")", "at_s": elapsed}
            return Start(R_WV)
        self.info = {"method": "stereo-imu", "at_s": elapsed, "poses": len(poses),
                     "gravity_norm_linear": r.gravity_norm_linear, "rms_rot": r.rms_rot}
        return Start(r.R_WV, b_g=r.b_g.copy(), b_a=r.b_a.copy())

    def _stereo_imu_init(self, t_ns: list[int], T_w_c: list[np.ndarray], b_g0: np.ndarray | None = None):
        """Spec 9's stereo-IMU initialisation over the rectified-cam0 poses ``T_w_c`` stamped ``t_ns`` (from
        the gyro bias ``b_g0``, default 0); raises EstimatorError."""
        opts = est.InitOptions(ba_prior_sigma=BA_PRIOR_SIGMA, acc_noise_density=self.imu.noise.acc_noise_density,
                               pose_pos_sigma=POSE_SIGMA_M, b_g0=b_g0)
        return est.stereo_imu_init(np.array(t_ns, dtype=np.int64), np.array([T[:3, :3] for T in T_w_c]),
                                   np.array([T[:3, 3] for T in T_w_c]), self.imu.t_ns, self.imu.gyro, self.imu.acc,
                                   self.R_ic, self.p_ic, opts)

    # ----------------------------------------------------------------------------- the standstill
    def standstill_gyro_bias(self, res, obs) -> np.ndarray | None:
        """While the starting standstill lasts, the gyro bias: the mean rate over all of it (rad/s).
        None once it is over (``still`` becomes False)."""
        rest, (ts, g, a) = self._still_since_start(res, obs)
        if not (rest and len(ts) >= 2):
            self.still = False
            return None
        # the end of a standstill is seen late (a smooth start of motion stays below the image and IMU
        # limits for a while), so the last ``STILL_LAG_S`` do not enter the bias [PROPOSAL]
        i0, i1 = self.imu.span(self.t_first, int(ts[-1]) - int(STILL_LAG_S * 1e9))
        if (self.imu.t_ns[i1 - 1] - ts[0] if i1 - i0 >= 2 else 0) < int(0.5 * self.cfg.still_min_s * 1e9):
            i1 = i0 + len(ts)
        self.info["standstill_s"] = (ts[-1] - ts[0]) * 1e-9
        return self.imu.moments.gyro_mean(i0, i1)

    def _images_at_rest(self, obs) -> bool:
        """The images say the platform is at rest: the image motion since the reference frame
        (``_image_flow_px``) stays within ``STILL_MAX_FLOW_PX``, or exceeds it on fewer than
        ``STILL_PERSIST`` consecutive frames.

        The flow is measured on the images themselves, not through the poses: on a turbid start the
        chained poses of a keyframe every frame read pixels of motion at rest, and a moving-start
        initialisation at rest takes a wrong gyro bias.  A real start of motion grows monotonically and
        is caught ``STILL_PERSIST - 1`` frames later, well inside ``still_min_s``."""
        moved = self._image_flow_px(obs) > STILL_MAX_FLOW_PX
        self._moving_run = self._moving_run + 1 if moved else 0
        return self._moving_run < STILL_PERSIST

    def _image_flow_px(self, obs) -> float:
        """Image motion (px) since the reference frame: :func:`~gevi_cli.frontend.image_motion.fitted_flow_px`
        over this frame's features ``obs`` tracked since the reference.  The reference is the first frame
        with features after the first keyframe; when fewer than ``MIN_FLOW_FEATURES`` of its features are
        left, this frame becomes the reference (if it has that many).  0 (the images say nothing, the IMU
        decides) before any keyframe, on a new reference, and with too few features.

        Fitted, because LK-chained features random-walk at rest while a motion moves them together;
        re-referenced, because abstaining once the first frame's features are gone left the end of the
        standstill to the IMU's looser limits.  A new reference forgets the motion before it: a start
        of motion outgrows the limit within one reference's life, a slower creep does not."""
        if obs is None or self._first_kf_index is None:
            return 0.0
        ref = self._flow_ref
        if ref is not None:
            common, i0, i1 = np.intersect1d(ref.ids, obs.ids, assume_unique=True, return_indices=True)
        if ref is None or len(common) < MIN_FLOW_FEATURES:
            if len(obs.ids) >= MIN_FLOW_FEATURES:
                self._flow_ref = obs
            return 0.0
        return fitted_flow_px(ref.uv[i0], obs.uv[i1])

    def _still_since_start(self, res, obs):
        """(images and IMU at rest since the first frame, the IMU samples (t, gyro, acc) since then).

        Evaluated once per frame: the frame that starts from the standstill asks again right after
        (``try_start``, then ``standstill_gyro_bias``), and the images' "moving" counter counts it once."""
        if self._still_eval is not None and self._still_eval[0] == res.index:
            return self._still_eval[1]
        i0, i1 = self.imu.span(self.t_first, res.t_ns)
        ts, g, a = self.imu.t_ns[i0:i1], self.imu.gyro[i0:i1], self.imu.acc[i0:i1]
        # (the statistics from the stream's prefix sums: this window grows with the standstill)
        rest = self._images_at_rest(obs) and (len(ts) < 2 or rest_limits_hold(
            *self.imu.moments.window(i0, i1), STILL_MAX_GYRO_STD, STILL_MAX_ACC_STD, STILL_MAX_GRAVITY_ERR))
        self._still_eval = (res.index, (rest, (ts, g, a)))
        return rest, (ts, g, a)

    # --------------------------------------------------------------------- b_a after a standstill
    def refined_acc_bias(self, res, b_g: np.ndarray, b_a: np.ndarray, tilt: np.ndarray) -> np.ndarray:
        """After a standstill start, the accelerometer bias (unobservable at rest, m/s^2) estimated once
        from the first ``init.window_s`` of continuously tracked motion: the stereo-IMU initialisation
        (spec 9) over those frames' poses in W, of which only the component of b_a along gravity is
        adopted (W, the tilts ``tilt`` and the gyro bias ``b_g`` of the standstill stay) [PROPOSAL].
        Returns ``b_a`` unchanged until then, when rejected, and after."""
        ic = self.cfg
        if self.still or self.info.get("method") != "standstill" \
                or "acc_bias_refined" in self.info:
            return b_a
        if res.status != OK:
            # *visually tracked* motion: IMU-carried poses would feed the bias back into itself
            self._bias_poses = []
            return b_a
        self._bias_poses.append((res.t_ns, res.T_w_c.copy()))
        if not self._bias_poses or (self._bias_poses[-1][0] - self._bias_poses[0][0]) * 1e-9 < ic.window_s:
            return b_a
        poses = self._bias_poses[::INIT_STRIDE]
        try:
            r = self._stereo_imu_init([p[0] for p in poses], [p[1] for p in poses], b_g0=b_g)
        except est.EstimatorError as err:
            self.info["acc_bias_refined"] = f"failed: {err}"
            return b_a
        angle = float(np.arccos(np.clip(-r.gravity_V[2] / np.linalg.norm(r.gravity_V), -1.0, 1.0)))
        info = {"at_s": (res.t_ns - self.t_first) * 1e-9, "b_a": r.b_a.tolist(), "gravity_angle_deg": np.degrees(angle)}
        # consistency with the standstill: the bias may move gravity by at most the bias/tilt ambiguity
        # (3 prior sigma / g) and must itself be plausible under its prior
        limit = 3.0 * BA_PRIOR_SIGMA
        if angle > limit / GRAVITY or np.linalg.norm(r.b_a) > limit:
            info["rejected"] = f"inconsistent with the standstill (limit {limit:g} m/s^2)"
        else:
            # only the component along gravity: the standstill's W already holds the horizontal bias as a
            # tilt (b_h / g, spec 9.6), which a few seconds of motion cannot tell apart from it
            up = est.rtilt(*tilt).T @ np.array([0.0, 0.0, 1.0])  # body up (IMU frame)
            b_a = b_a + up * float(up @ (r.b_a - b_a))
            info["adopted"] = b_a.tolist()
        self.info["acc_bias_refined"] = info
        return b_a
