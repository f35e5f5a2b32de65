"""The keyframe-relative odometry core shared by CurrentFeature Odometry and GeVI.

Data flow per frame (spec 2):  front end ``track`` -> match ids with the current keyframe ->
verification (pipeline's choice) -> noise variance -> pose of the keyframe in the current frame
``T_ck`` (pipeline's choice) -> keyframe rule -> at a new keyframe: epipolar local BA over the
previous keyframe, the frames between and the new keyframe (spec 10), then triangulation of the new
keyframe.  The trajectory is the chain of keyframe-relative poses.

Frames: ``T_w_c`` is the pose of rectified cam0 in the world frame W, which is the first keyframe's
rectified cam0; ``T_ck`` maps keyframe-left coordinates into current-left coordinates (metres).

The object holds state only (as KISS-ICP's ``register_frame``): no files, no clocks other than
per-stage timings, no printing; the run driver owns all of that.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.frontend import FrontEnd, Prediction
from gevi_cli.geometry import invert_pose, orthonormal_pose
from gevi_cli.pipelines.config import (
    FILL_POINTS,
    MIN_KF_POINTS,
    MIN_PNP_POINTS,
    NOISE_DEFAULT_PX,
    NOISE_MAX_PX,
    NOISE_MIN_PX,
    OdometryConfig,
)
from gevi_cli.pipelines.disparity_offset import DisparityOffset
from gevi_cli.pipelines.keyframe import Keyframe, make_keyframe
from gevi_cli.pipelines.local_ba import WindowFrame, window_ba
from gevi_cli.pipelines.types import BRIDGED, FINAL, OK, ONLINE, WORLD_FIRST_CAM0, FrameResult, PoseEvent, pose_events
from gevi_cli.pipelines.verification import TrackingFailure


@dataclass
class Matches:
    """Keyframe points seen in the current frame (all arrays aligned)."""

    ids: np.ndarray
    z: np.ndarray  # keyframe-left normalized
    y: np.ndarray  # keyframe-right normalized
    q: np.ndarray  # current-left normalized
    p: np.ndarray  # keyframe-left points (m)
    cov_unit: np.ndarray

    def subset(self, sel) -> "Matches":
        """The matches picked by ``sel`` (a mask or indices), every array alike."""
        return Matches(self.ids[sel], self.z[sel], self.y[sel], self.q[sel], self.p[sel], self.cov_unit[sel])


class KeyframeOdometry:
    """Base class; subclasses set ``self.verification`` and implement :meth:`estimate_T_ck`."""

    name = "odometry"
    state_columns: tuple = ()  # per-frame state in FrameResult.extra (GeVI: the IMU state)
    state_file = "states.csv"

    def __init__(self, frontend: FrontEnd, cfg: OdometryConfig):
        self.frontend = frontend
        self.camera = frontend.camera
        self.cfg = cfg
        self.kf: Keyframe | None = None
        self.window: list[WindowFrame] = []
        self.pending: list[tuple[int, np.ndarray]] = []  # (index, T_w_c) not final yet
        self.online_held: list[tuple[int, np.ndarray]] = []  # online poses held back (GeVI before its world)
        # what the frame being tracked releases: poses made final, and the online poses to hand out instead
        # of its own (None: its own), as (index, T_w_c); turned into PoseEvents at the end of track()
        self._final: list[tuple[int, np.ndarray]] = []
        self._online: list[tuple[int, np.ndarray]] | None = None
        self.index = -1
        self.sigma2 = (NOISE_DEFAULT_PX / self.camera.f) ** 2
        self.sigma2_valid = False
        self.T_w_last: np.ndarray | None = None
        self.velocity = np.eye(4)  # T_{prev,cur} of the last tracked step
        self.verification = None
        # RANSAC draws, seeded per frame from --seed: frame k draws from the seed's PCG64 stream advanced by
        # k * 2**64 steps, so its samples depend only on (seed, k), never on how many draws earlier frames
        # used. Re-positioning one generator costs ~3 us; a fresh default_rng per frame cost 13-55 us, more
        # than a clean frame's whole 3-point solve.
        self._bitgen = np.random.PCG64(cfg.run.seed)
        self._bitgen_start = self._bitgen.state
        self._rng = np.random.Generator(self._bitgen)
        self._last = None  # (p, q) of the last tracked frame's verified matches
        self._tail = None  # (frame, FrameResult) of the last frame, for the closing BA of finish()
        self.obs = None  # FeatureObs of the frame being tracked
        self._ba_longest = 0  # frames in the longest window bundle-adjusted so far
        self.ba_rejected = 0
        self.fallbacks = 0  # frames whose 6-DOF pose step started from SQPnP instead of Bias-Eli
        self.reacquired = 0  # frames tracked only after re-acquiring the keyframe's features by descriptor
        self._moving = False  # a step has been tracked: self.velocity is a measured motion
        self.disparity_offset = DisparityOffset() if cfg.triangulation.self_calibrate else None

    def frame_rng(self) -> np.random.Generator:
        """The generator for this frame's RANSAC draws, positioned at (seed, frame index)."""
        self._bitgen.state = self._bitgen_start
        self._bitgen.advance(self.index << 64)
        return self._rng

    # ------------------------------------------------------------------ to be provided by pipelines
    def estimate_T_ck(self, m: Matches, frame) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    # ------------------------------------------------------------------------------- main entry
    @property
    def world(self) -> str:
        """The world of the poses released now (:data:`~gevi_cli.pipelines.types.WORLD_FIRST_CAM0` here)."""
        return WORLD_FIRST_CAM0

    def track(self, frame) -> FrameResult:
        """Track one frame; never raises for tracking problems (they become ``bridged`` frames).  The
        poses it releases are the result's ``poses`` (its online pose, then those made final)."""
        self._final, self._online = [], None
        res = self._track(frame)
        online = self._online if self._online is not None else [(res.index, res.T_w_c)]
        res.poses = pose_events(ONLINE, online, self.world) + pose_events(FINAL, self._final, self.world)
        self._final, self._online = [], None
        return res

    def close(self, closing_ba: bool = False) -> list[PoseEvent]:
        """The poses still held, released: the pending ones made final (:meth:`_finish`), then the held
        online ones.  Call once, after the last frame (or on an interrupt / a crash, ``closing_ba`` False)."""
        final = self._finish(closing_ba)
        online, self.online_held = self.online_held, []
        return pose_events(FINAL, final, self.world) + pose_events(ONLINE, online, self.world)

    def _track(self, frame) -> FrameResult:
        """:meth:`track` without the release of the poses (subclasses extend this)."""
        self.index += 1
        timings: dict[str, float] = {}
        obs, predicted, topped_up = self._features(frame, timings)
        res = FrameResult(self.index, int(frame.t_ns), np.eye(4))
        T_ck, disp_px, left = self._pose_against_keyframe(frame, obs, predicted, topped_up, res, timings)
        if self.index == 0:
            res.T_w_c = np.eye(4)
        elif T_ck is not None:
            res.T_w_c = self.kf.T_w_k @ invert_pose(T_ck)
        else:
            res.T_w_c, res.status = self._bridge(res.t_ns)
        res.sigma_px = float(np.sqrt(self.sigma2) * self.camera.f)
        self._window_and_keyframe(frame, res, T_ck, disp_px, left, timings)
        self._remember_motion(res)
        res.timings = timings
        self._tail = (frame, res)
        return res

    def _features(self, frame, timings) -> tuple:
        """The front end's features of ``frame`` (topped up by re-acquisition when few keyframe points are
        left), the prediction they were tracked with, and whether they were topped up."""
        t0 = time.perf_counter()
        predicted = self.predicted_pixels()
        obs = self.frontend.track(frame, self.rotation_prior(), predicted)
        topped_up = False
        if predicted is not None and np.isin(obs.ids, self.kf.ids).sum() < self.cfg.keyframe.min_tracked:
            # few keyframe points left: those LK lost, searched for by descriptor near their predicted pixels
            again = self.frontend.reacquire(frame, predicted, keep_tracks=True)
            if again is not None and len(again) > len(obs):
                self.frontend.adopt(frame, again)
                obs, topped_up = again, True
        self.obs = obs  # the front end's features of this frame (ids, pixels), for what subclasses judge from them
        timings.update({f"fe_{k}": v for k, v in self.frontend.timings.items()})
        timings["frontend"] = time.perf_counter() - t0
        return obs, predicted, topped_up

    def _pose_against_keyframe(self, frame, obs, predicted, topped_up: bool, res: FrameResult, timings) -> tuple:
        """``(T_ck, mean image displacement px, the frame's left observations)``; ``T_ck`` None when the
        frame cannot be tracked.  After a failure the keyframe's features are re-acquired by descriptor
        and the pose step runs once more on them.  Fills the result's match counts and message."""
        q_all = self.camera.normalize(obs.uv)  # once per frame: matching and the BA window share it
        T_ck, failure, disp_px = None, "", 0.0
        if self.kf is not None:
            try:
                T_ck, n_match, n_in, disp_px = self._track_against_kf(obs.ids, q_all, frame, timings)
                res.n_matches, res.n_inliers = n_match, n_in
                res.message = "topped up by re-acquisition" if topped_up else ""
            except TrackingFailure as err:
                failure = str(err)
                t1 = time.perf_counter()
                again = self.frontend.reacquire(frame, predicted)
                timings["fe_reacquire"] = timings.get("fe_reacquire", 0.0) + time.perf_counter() - t1
                timings["frontend"] += time.perf_counter() - t1
                if again is not None:
                    # the keyframe's features found again by descriptor: the pose step once more on them
                    q_again = self.camera.normalize(again.uv)
                    try:
                        T_ck, n_match, n_in, disp_px = self._track_against_kf(again.ids, q_again, frame, timings)
                    except TrackingFailure as err2:
                        failure = f"{failure}; after re-acquisition: {err2}"
                    else:
                        res.n_matches, res.n_inliers = n_match, n_in
                        res.message, failure = f"re-acquired after: {failure}", ""
                        self.frontend.adopt(frame, again)
                        obs = self.obs = again
                        q_all = q_again
                        self.reacquired += 1
        elif self.index > 0:
            failure = "no keyframe to track against"
        if T_ck is None:
            res.message = failure
        return T_ck, disp_px, est.ImageObs(obs.ids, q_all)

    def _window_and_keyframe(self, frame, res: FrameResult, T_ck, disp_px: float, left, timings) -> None:
        """The frame into the window of the current keyframe; a new keyframe (with the local BA) when the
        source or the keyframe rule says so; the poses that can no longer change made final."""
        decision = self.frontend.keyframe_decision(frame)
        if decision is not None:
            res.kf_trigger = "source" if decision else ""
        elif self.kf is None:
            res.kf_trigger = "first"
        elif T_ck is None:
            res.kf_trigger = "untracked"
        else:
            res.kf_trigger = self._keyframe_rule(res, disp_px)
        decision = bool(res.kf_trigger)
        if self.kf is not None:
            # every tracked feature enters the BA (its robust kernel handles the outliers): measured,
            # verified-only observations gave KITTI 04 gray ATE 0.417 m instead of 0.349 m
            T_kc = invert_pose(T_ck) if T_ck is not None else invert_pose(self.kf.T_w_k) @ res.T_w_c
            self.window.append(WindowFrame(res.index, res.t_ns, left, T_kc, T_ck is not None))
        self.pending.append((res.index, res.T_w_c))
        if decision:
            t1 = time.perf_counter()
            self._insert_keyframe(frame, res, timings)
            timings["keyframe"] = time.perf_counter() - t1 - timings.get("ba", 0.0)
        elif not self.cfg.ba.enabled or self.kf is None:
            self._final, self.pending = self.pending, []

    def _remember_motion(self, res: FrameResult) -> None:
        """The last pose and, after a tracked step, the step as the constant-velocity motion; the bridge
        continues from the best pose known (after BA at a keyframe)."""
        T_now = self.kf.T_w_k if res.keyframe else res.T_w_c
        if self.T_w_last is not None and res.status == OK:
            # re-orthonormalised: bridged poses are products of velocities, rounding must not grow
            self.velocity = orthonormal_pose(invert_pose(self.T_w_last) @ T_now)
            self._moving = True
        self.T_w_last = T_now

    def predicted_pixels(self) -> Prediction | None:
        """Where the keyframe's points should appear in the frame about to be tracked (rectified-left
        pixels) and how much larger than in the previous frame, seen from the predicted pose: the last
        pose moved by the last tracked step (constant velocity), its rotation replaced by
        :meth:`rotation_prior` where that gives one (GeVI: the gyro's).  None before the first tracked
        step (no motion known yet) or without a keyframe."""
        if (not self.cfg.frontend.predict or self.kf is None or self.T_w_last is None or not self._moving
                or not len(self.kf)):
            return None
        step = self.velocity.copy()  # T_prev_cur
        R_cp = self.rotation_prior()
        if R_cp is not None:
            step[:3, :3] = R_cp.T
        T_pk = invert_pose(self.T_w_last) @ self.kf.T_w_k  # keyframe -> previous frame
        T_ck = invert_pose(step) @ T_pk  # keyframe -> predicted current frame
        pc = self.kf.p @ T_ck[:3, :3].T + T_ck[:3, 3]
        front = pc[:, 2] > self.cfg.triangulation.min_depth_m
        xy = pc[front, :2] / pc[front, 2:]
        uv = self.camera.intrinsics.pixels(xy)
        z_prev = self.kf.p[front] @ T_pk[2, :3] + T_pk[2, 3]
        return Prediction(self.kf.ids[front], uv, np.where(z_prev > 0, z_prev / pc[front, 2], 1.0))

    def rotation_prior(self) -> np.ndarray | None:
        """Predicted rotation ``R_cp`` (previous -> current rectified-left camera coordinates) of the
        frame about to be tracked, for the front end's rotation-compensated LK: the last step's
        rotation (constant angular velocity), when that step was tracked and at least half of its
        matches passed the pose's verification, and ``frontend.derotate_prior`` is "pose"; else None
        (the front end then predicts the rotation in the image plane from its own tracks).  The
        inlier test keeps a pose estimator that is going wrong from steering the tracks that feed
        it: with the prior always on, ``--pnp epnp`` on pool-hard_s1 drifted 5-10 deg per frame from
        frame 271 (inliers 27 of 60) and lost 69 frames."""
        last = self._tail[1] if self._tail is not None else None
        if (self.cfg.frontend.derotate_prior != "pose" or last is None or last.status != OK
                or last.n_inliers < 0.5 * max(last.n_matches, 1)):
            return None
        return self.velocity[:3, :3].T

    def _bridge(self, t_ns: int) -> tuple[np.ndarray, str]:
        """Pose of a frame that could not be tracked: constant velocity from the last pose (``bridged``)."""
        return (self.T_w_last if self.T_w_last is not None else np.eye(4)) @ self.velocity, BRIDGED

    def summary(self) -> dict:
        """What status.json records of the odometry's own state (a stereo odometry: nothing)."""
        return {}

    def _finish(self, closing_ba: bool = False) -> list[tuple[int, np.ndarray]]:
        """Poses still pending, made final.

        ``closing_ba`` (the sequence ended normally): the frames after the last keyframe close their
        window as if the last frame were a keyframe, so they get the epipolar BA too [PROPOSAL: the
        spec runs it at keyframe insertion only].  Without it the tail stays as tracked, and one bad
        tracked pose there stood out: a pool-easy render (10 s, seed 2, CFO) ended with three such
        frames, one 3 mm off, which tripled the sequence's RPE.  After an interrupt or a crash the tail
        is written as tracked (no BA on the way out).  The closing window may be no longer than the
        longest one the run already bundle-adjusted: a run with one keyframe (euroc_micro, at rest)
        would otherwise end with a 94-frame BA of a minute, for nothing (ATE 0.557 -> 0.563 mm)."""
        last = self._tail
        if (closing_ba and last is not None and self.cfg.ba.enabled and self.kf is not None and self.window
                and len(self.window) <= self._ba_longest
                and self.frontend.keyframe_decision(last[0]) is None  # exported tracks: their own keyframes only
                and self.window[-1].index == last[1].index and not last[1].keyframe and last[1].status == OK):
            frame, res = last
            self._final = []
            self._insert_keyframe(frame, res, {})
            out = self._final
        else:
            out = []
        out, self.pending = out + self.pending, []
        return out

    # --------------------------------------------------------------------------------- stages
    def _match(self, ids: np.ndarray, q_all: np.ndarray) -> Matches:
        kf = self.kf
        _, i_kf, i_obs = np.intersect1d(kf.ids, ids, assume_unique=True, return_indices=True)
        return Matches(kf.ids[i_kf], kf.z[i_kf], kf.y[i_kf], q_all[i_obs], kf.p[i_kf], kf.cov_unit[i_kf])

    def _update_sigma2(self, z: np.ndarray, q: np.ndarray) -> None:
        cfg = self.cfg.noise
        if cfg.method == "stereo":
            return  # estimated at keyframe insertion
        try:
            s2 = est.sigma2_symmetric(z, q) if cfg.method == "symmetric" else est.sigma2_onesided(q, z)
        except est.EstimatorError:
            return
        self._set_sigma2(s2)

    def _set_sigma2(self, s2: float) -> None:
        if not np.isfinite(s2) or s2 <= 0:
            return
        f = self.camera.f
        lo, hi = (NOISE_MIN_PX / f) ** 2, (NOISE_MAX_PX / f) ** 2
        self.sigma2 = float(np.clip(s2, lo, hi))
        self.sigma2_valid = True

    def _track_against_kf(self, ids, q_all, frame, timings):
        t0 = time.perf_counter()
        m = self._match(ids, q_all)
        n_match = len(m.ids)
        if n_match < MIN_PNP_POINTS:
            raise TrackingFailure(f"only {n_match} keyframe points tracked")
        keep = self.verification(m.z, m.q, m.p, self.frame_rng())
        m = m.subset(keep)
        t1 = time.perf_counter()
        timings["verify"] = t1 - t0
        if len(m.ids) < MIN_PNP_POINTS:
            raise TrackingFailure(f"only {len(m.ids)} of {n_match} matches pass verification")
        self._update_sigma2(m.z, m.q)
        t2 = time.perf_counter()
        timings["noise"] = t2 - t1
        T_ck = self.estimate_T_ck(m, frame)
        timings["pose"] = time.perf_counter() - t2
        if self.disparity_offset is not None:
            raw = (m.z[:, 0] - m.y[:, 0]) * self.camera.fx - self.kf.disparity_offset_px
            self.disparity_offset.observe(self.index, self.kf.index, m.z, m.q, raw, T_ck, self.camera.fx,
                                          self.camera.baseline)
        disp_px = float(np.mean(np.linalg.norm(m.q - m.z, axis=1))) * self.camera.f
        self._last = (m.p, m.q)
        return T_ck, n_match, len(m.ids), disp_px

    def _keyframe_rule(self, res: FrameResult, disp_px: float) -> str:
        """Why the tracked frame ``res`` becomes a keyframe ("": it does not): "inliers" (fewer verified
        matches than ``min_tracked_ratio`` of the keyframe's points or ``min_tracked``), "displacement" (the
        mean image displacement since the keyframe)."""
        k = self.cfg.keyframe
        if res.n_inliers < max(k.min_tracked_ratio * len(self.kf), k.min_tracked):
            return "inliers"
        return "displacement" if disp_px > k.max_mean_disp_px else ""

    def _insert_keyframe(self, frame, res: FrameResult, timings) -> None:
        cfg = self.cfg
        stereo = self.frontend.keyframe(frame)
        timings.update({f"fe_{k}": timings.get(f"fe_{k}", 0.0) + v
                        for k, v in self.frontend.timings.items()})
        new = make_keyframe(res.index, res.t_ns, res.T_w_c, stereo, self.camera, cfg.triangulation.min_depth_m,
                            cfg.triangulation.max_depth_m, cfg.triangulation.min_disparity_px,
                            FILL_POINTS, float(np.sqrt(self.sigma2) * self.camera.f),
                            self.disparity_offset.value if self.disparity_offset is not None else 0.0)
        if cfg.noise.method == "stereo" and len(new) >= 9:
            try:
                self._set_sigma2(est.sigma2_stereo(new.z, new.y, self.camera.R_rl, self.camera.t_rl))
            except est.EstimatorError:
                pass
        if self.kf is not None and cfg.ba.enabled and res.status == OK:
            t0 = time.perf_counter()
            T_w_new = self._local_ba(new)
            timings["ba"] = time.perf_counter() - t0
            if T_w_new is not None:
                new.T_w_k = T_w_new
        self._final, self.pending = self.pending, []
        if len(new) >= MIN_KF_POINTS:
            self.kf = new
            res.keyframe = True
            if self.disparity_offset is not None:
                self.disparity_offset.keyframe_made(new.index, new.disparity_offset_px)
        elif self.kf is None or res.status != OK:
            self.kf = None  # nothing to track against until a frame gives enough stereo points
        self.window = []

    def _local_ba(self, new: Keyframe) -> np.ndarray | None:
        """Spec 10 over (current KF, window frames, ``new``) when every window frame was tracked; updates
        the pending poses; the new keyframe's refined ``T_w_k`` or None (not run, failed, or not kept)."""
        kf, frames = self.kf, self.window
        if not frames or not all(f.ok for f in frames) or frames[-1].index != new.index:
            return None
        self._ba_longest = max(self._ba_longest, len(frames))
        out = window_ba(kf, frames, new, self.camera, float(np.sqrt(self.sigma2)), self.cfg.ba, self._last)
        self.ba_rejected += int(out.rejected)
        if out.T_k1_f is None:
            return None
        refined = {i: kf.T_w_k @ T for i, T in out.T_k1_f.items()}
        self.pending = [(i, refined.get(i, T)) for i, T in self.pending]
        return refined[new.index]
