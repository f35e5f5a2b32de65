"""A keyframe of the CurrentFeature-style back ends: its stereo matches triangulated with covariance.

Only the *current* keyframe's points are used for tracking (no map, spec 2): when a new keyframe is
inserted the previous points are dropped, so pose errors and point errors stay independent.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.observations import RectifiedStereo, StereoObs

FILL_SIGMAS = 3.0
"""A point that fills a keyframe beyond its far gate needs a disparity this many standard deviations
above zero."""


@dataclass
class Keyframe:
    """``index`` frame index; ``T_w_k`` pose of its rectified cam0 in the world (4x4).

    ``ids``/``z``/``p``/``cov_unit`` describe the points that passed the depth gate: normalized left
    coordinates ``z`` (n, 2), points ``p`` (n, 3) in keyframe-left coordinates (m) and their
    covariance per unit image variance ``cov_unit`` (n, 3, 3; multiply by sigma^2 in normalized
    units).  ``stereo`` keeps all matches (normalized) for the local BA.
    """

    index: int
    t_ns: int
    T_w_k: np.ndarray
    ids: np.ndarray
    z: np.ndarray
    y: np.ndarray
    p: np.ndarray
    cov_unit: np.ndarray
    stereo_left: est.ImageObs
    stereo_right: est.ImageObs
    disparity_offset_px: float = 0.0  # added to every measured disparity (pipelines.disparity_offset)

    def __len__(self) -> int:
        return len(self.ids)


def make_keyframe(index: int, t_ns: int, T_w_k: np.ndarray, stereo: StereoObs, camera: RectifiedStereo,
                  min_depth_m: float, max_depth_m: float, min_disparity_px: float = 0.0,
                  fill_points: int = 0, sigma_px: float = 0.0, disparity_offset_px: float = 0.0) -> Keyframe:
    """Triangulate ``stereo`` (spec 4) and keep the points inside the depth gate and with at least
    ``min_disparity_px`` of disparity.  When fewer than ``fill_points`` (the pipeline: ``FILL_POINTS``) pass, the points beyond that
    far gate are kept too (ORB-SLAM's stereo keyframes take far points while they have fewer than 100
    near ones), so that a scene whose texture is all far away (a highway, open water) still has points
    to track; their covariance carries their depth uncertainty.  A filling point's disparity must
    differ from zero by :data:`FILL_SIGMAS` standard deviations of a disparity, ``sqrt(2) sigma_px``
    (two noisy pixels; ``sigma_px`` the image noise std, px): nearer to zero its depth is unbounded.
    ``disparity_offset_px``: the pair's estimated disparity offset, added to every disparity (the right
    pixels moved left by it) before anything else, so the points and the BA's right observations agree."""
    ids = np.asarray(stereo.ids, dtype=np.int64)
    z = camera.normalize(stereo.uv_left)
    uv_right = np.asarray(stereo.uv_right, dtype=np.float64)
    if disparity_offset_px:
        uv_right = uv_right - np.array([disparity_offset_px, 0.0])
    y = camera.normalize(uv_right)
    disparity = np.asarray(stereo.disparity, dtype=np.float64) + disparity_offset_px
    depth = camera.depth_from_disparity(disparity)
    keep = (depth >= min_depth_m) & (depth <= max_depth_m) & np.isfinite(depth)
    keep &= disparity >= min_disparity_px
    if keep.sum() < fill_points:
        floor = max(FILL_SIGMAS * np.sqrt(2.0) * sigma_px, 0.01)
        far = np.flatnonzero(~keep & (depth >= min_depth_m) & (disparity >= floor))  # beyond the far gate
        keep[far] = True
    if keep.sum() >= 3:
        # a match refined along the rectified row has y2 = z2 exactly: one measurement, not two
        tied = z[keep, 1] == y[keep, 1]
        p, cov_unit = est.triangulate(z[keep], y[keep], camera.R_rl, camera.t_rl, 1.0, tied_rows=tied)
    else:
        p, cov_unit = np.empty((0, 3)), np.empty((0, 3, 3))
    return Keyframe(index, t_ns, np.asarray(T_w_k, dtype=np.float64), ids[keep], z[keep], y[keep], p, cov_unit,
                    est.ImageObs(ids, z), est.ImageObs(ids, y), float(disparity_offset_px))
