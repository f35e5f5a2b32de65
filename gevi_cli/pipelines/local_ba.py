"""The epipolar local BA of a keyframe window (spec 10) and the checks its result must pass.

The window is the current keyframe K1 (stereo), the frames tracked against it and the new keyframe K2
(stereo).  Frames: ``T_kc`` is a frame's pose in K1's rectified-left camera (metres); observations are
normalized rectified-left (and right, for the keyframes) coordinates.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.geometry import invert_pose, make_T
from gevi_cli.observations import RectifiedStereo
from gevi_cli.pipelines.config import BA_MAX_ITER, BA_MAX_REPROJ_RATIO, BA_MAX_STEP_RATIO, BA_TOL, BAConfig
from gevi_cli.pipelines.keyframe import Keyframe
from gevi_cli.pipelines.pose6 import reprojection_median_px


@dataclass
class WindowFrame:
    """A frame tracked against the current keyframe: left observations and ``T_kc`` (frame in KF)."""

    index: int
    t_ns: int
    left: est.ImageObs
    T_kc: np.ndarray
    ok: bool


@dataclass
class WindowBA:
    """The outcome: ``T_k1_f`` the refined pose of each window frame in K1 by frame index (None: the BA
    failed or its result was not kept); ``rejected``: not kept by the reprojection cross-check."""

    T_k1_f: dict[int, np.ndarray] | None
    rejected: bool = False


def window_ba(kf: Keyframe, frames: list[WindowFrame], new: Keyframe, camera: RectifiedStereo, sigma: float,
              cfg: BAConfig, last_matches) -> WindowBA:
    """Spec 10 over (``kf``, ``frames``, ``new``; the last frame is ``new``'s) with the normalized noise
    std ``sigma``.  The result is kept when it is finite, does not raise the RMS by half, does not move the
    new keyframe by more than ``BA_MAX_STEP_RATIO`` of its distance (+5 cm), and, given the last frame's
    verified matches ``last_matches`` = (keyframe points, normalized pixels), does not make them
    reproject more than ``BA_MAX_REPROJ_RATIO`` times worse than the tracked pose did."""
    T_k = np.array([f.T_kc for f in frames])  # T_K1_Fk, last = the new keyframe
    obs = [kf.stereo_left, kf.stereo_right] + [f.left for f in frames[:-1]] + [new.stereo_left, new.stereo_right]
    window = est.BAWindow(obs[0], obs[1], obs[2:-2], obs[-2], obs[-1], T_k[:, :3, :3], T_k[:, :3, 3],
                          camera.R_rl, camera.t_rl, sigma=sigma)
    try:
        r = est.epipolar_local_ba(window, est.BAOptions(kernel=cfg.kernel, max_iter=BA_MAX_ITER,
                                                       delta=cfg.delta_sigmas * window.sigma,
                                                       tol=BA_TOL))
    except est.EstimatorError:
        return WindowBA(None)
    t_track, t_ba = T_k[-1, :3, 3], r.t[-1]
    span = np.linalg.norm(t_track)
    if (not np.all(np.isfinite(r.t)) or r.rms_final > r.rms_initial * 1.5
            or np.linalg.norm(t_ba - t_track) > BA_MAX_STEP_RATIO * span + 0.05):
        return WindowBA(None)
    if last_matches is not None:
        # Cross-check with the tracking cost: the BA (epipolar distances) must not make the keyframe
        # points reproject much worse in the new keyframe than the PnP pose did.  Windows whose
        # tracks are dominated by LK errors (fast motion blur) otherwise pull the poses off.
        p, q = last_matches
        f = camera.f
        T_ck_ba = invert_pose(make_T(r.R[-1], r.t[-1]))
        T_ck_tr = invert_pose(T_k[-1])
        e_ba = reprojection_median_px(T_ck_ba[:3, :3], T_ck_ba[:3, 3], p, q, f)
        e_tr = reprojection_median_px(T_ck_tr[:3, :3], T_ck_tr[:3, 3], p, q, f)
        if e_ba > BA_MAX_REPROJ_RATIO * e_tr + 0.05:
            return WindowBA(None, rejected=True)
    return WindowBA({f.index: make_T(r.R[i], r.t[i]) for i, f in enumerate(frames)})
