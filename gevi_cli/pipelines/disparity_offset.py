"""Online self-calibration of the rectified stereo pair's disparity offset.

A rectified pair whose two principal points (or rectifications) disagree by ``delta`` pixels along the
rows measures every disparity ``delta`` short: ``d = fx b / Z - delta``.  Near points barely notice,
far ones do (at 7 px of disparity, 0.8 px is 11 % of depth), and a stereo odometry that trusts far
points reads every step too long.  The two-view geometry of a tracked frame sees it without knowing the
scale: triangulated from the keyframe and the current frame with the tracked rotation and translation
direction, the points' inverse depths ``1 / Z_mono`` are the true ones times an unknown factor, so the
stereo disparities lie on the line ``d = k / Z_mono - delta``.  The intercept is the offset.

Each tracked step gives one robust line fit (Huber IRLS); a step counts when its intercept is well
determined: its points reach far enough that zero disparity is not an extrapolation
(:data:`MAX_EXTRAPOLATION`) and the intercept's standard error is below :data:`MAX_STEP_SE_PX`.  The estimate is the median of the counted steps
once there are :data:`MIN_STEPS` of them and it reaches :data:`MIN_OFFSET_PX`, else 0.  The keyframes made
before the estimate existed carry the offset; the run driver therefore restarts the run once, from its first
frame, when the estimate first becomes known (:attr:`DisparityOffset.calls_for_restart`), carrying the steps
seen so far (:meth:`DisparityOffset.carried`).  Frames: keyframe-left normalized coordinates, disparities in
pixels of the rectified images.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MIN_PARALLAX_DEG = 0.3
"""A point enters a step's fit when its two rays (keyframe, current frame) differ by at least this."""

MIN_POINTS = 20
"""A step's fit needs this many points with that parallax."""

MAX_STEP_SE_PX = 0.25
"""A step counts when the standard error of its intercept is below this (px)."""

MAX_EXTRAPOLATION = 1.0
"""A step counts only when its points reach within this many spans of zero disparity: the 10th
percentile of their disparities at most this times the 10-90 % spread.  The intercept is read at zero
disparity; from a pool floor at 45-57 px it is an extrapolation of six spans, where any error of the
line's slope becomes an offset (a pool-easy render, exact rectification, read -0.4 to -0.6 px)."""

MIN_STEPS = 5
"""The estimate is 0 until this many steps have counted."""

MIN_OFFSET_PX = 0.25
"""An offset is corrected only when its estimate is at least this (px).  On pairs whose calibration
holds the estimate reads a little above zero: 0.015-0.03 px on the kitti-like and kitti-highway renders
(exact rectification), 0.12 px on the real KITTI 06 head, where correcting by it cost ATE 20 -> 63 mm
(a fixed 0.05 px: 44 mm).  Chosen on those, not on the sequence it is for (the real KITTI 01 head reads
0.73 px)."""

HUBER_K = 1.5
"""Huber threshold of the line fit, in robust standard deviations of its residuals."""


def two_view_inverse_depth(z: np.ndarray, q: np.ndarray, R_ck: np.ndarray, t_ck: np.ndarray):
    """``(inverse depth in the keyframe up to the length of t_ck (n,), parallax in degrees (n,))`` of the
    matches ``z`` (keyframe-left) -> ``q`` (current-left), normalized, for the pose ``T_ck``.  The
    inverse depth is NaN where the point does not lie in front along its ray."""
    rk = np.column_stack([z, np.ones(len(z))]) @ R_ck.T  # keyframe rays in the current frame
    rc = np.column_stack([q, np.ones(len(q))])
    a = np.cross(rc, rk)
    b = -np.cross(rc, np.broadcast_to(t_ck, rc.shape))
    lam = np.einsum("ij,ij->i", a, b) / np.maximum(np.einsum("ij,ij->i", a, a), 1e-300)
    cos = np.einsum("ij,ij->i", rk, rc) / (np.linalg.norm(rk, axis=1) * np.linalg.norm(rc, axis=1))
    parallax = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    inv = np.where(lam > 0, 1.0 / np.where(lam > 0, lam, 1.0), np.nan)
    return inv, parallax


def step_offset(inv_depth: np.ndarray, disparity_px: np.ndarray) -> tuple[float, float]:
    """``(delta px, its standard error px)`` of the line ``d = k inv - delta`` through the points, by
    Huber IRLS; ``(nan, inf)`` when the fit is degenerate."""
    X = np.column_stack([inv_depth, np.ones(len(inv_depth))])
    w = np.ones(len(inv_depth))
    coef = np.full(2, np.nan)
    for _ in range(20):
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(X * sw[:, None], disparity_px * sw, rcond=None)
        r = disparity_px - X @ coef
        scale = 1.4826 * np.median(np.abs(r)) + 1e-12
        w_new = np.minimum(1.0, HUBER_K * scale / np.maximum(np.abs(r), 1e-12))
        if np.allclose(w_new, w, atol=1e-6):
            break
        w = w_new
    r = disparity_px - X @ coef
    n = len(r)
    N = (X * w[:, None]).T @ X
    if n <= 2 or np.linalg.cond(N) > 1e12:
        return float("nan"), float("inf")
    s2 = float(np.sum(w * r**2) / max(np.sum(w) - 2.0, 1.0))
    se = float(np.sqrt(s2 * np.linalg.inv(N)[1, 1]))
    return float(-coef[1]), se


@dataclass
class DisparityOffset:
    """The running estimate; :attr:`value` (px) is what the next keyframe's disparities are raised by.
    ``observed_through``: the frames up to this index were observed by an earlier pass of the run (their
    steps are in ``steps``) and are not observed again; -1 in a run's first pass."""

    steps: list[float] = field(default_factory=list)
    observed_through: int = -1

    def observe(self, index: int, z: np.ndarray, q: np.ndarray, raw_disparity_px: np.ndarray,
                T_ck: np.ndarray) -> None:
        """One tracked step of frame ``index``: keyframe-left ``z`` and current-left ``q`` (normalized), the
        keyframe's raw (uncorrected) stereo disparities of those points (px) and the tracked pose ``T_ck``."""
        if index <= self.observed_through:
            return
        t = T_ck[:3, 3]
        if not np.linalg.norm(t) > 0:
            return
        inv, parallax = two_view_inverse_depth(z, q, T_ck[:3, :3], t)
        ok = np.isfinite(inv) & (parallax >= MIN_PARALLAX_DEG) & np.isfinite(raw_disparity_px)
        if ok.sum() < MIN_POINTS:
            return
        d10, d90 = np.percentile(raw_disparity_px[ok], [10, 90])
        if d10 > MAX_EXTRAPOLATION * (d90 - d10):
            return
        delta, se = step_offset(inv[ok], raw_disparity_px[ok])
        if np.isfinite(delta) and se < MAX_STEP_SE_PX:
            self.steps.append(delta)

    @property
    def value(self) -> float:
        """The offset (px): the median of the counted steps; 0 before :data:`MIN_STEPS` of them or while its
        size is under :data:`MIN_OFFSET_PX`."""
        if len(self.steps) < MIN_STEPS:
            return 0.0
        delta = float(np.median(self.steps))
        return delta if abs(delta) >= MIN_OFFSET_PX else 0.0

    @property
    def calls_for_restart(self) -> bool:
        """The offset has just become known in the run's first pass, so every keyframe so far was made
        without it: the run is better restarted from its first frame with it."""
        return self.observed_through < 0 and self.value != 0.0

    def carried(self, through: int) -> DisparityOffset:
        """The estimate for a restarted run: the steps seen so far, frames up to ``through`` observed."""
        return DisparityOffset(steps=list(self.steps), observed_through=through)
