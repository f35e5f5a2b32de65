"""Left -> right matching on a rectified pair: LK from each left feature, checked both ways.

Pixels of the rectified images; ``disparity = u_L - u_R`` (px, > 0 for points in front), depth
``Z = fx * b / disparity`` (m).  A match must be forward-backward consistent (``FB_MAX_PX``), lie on
the left feature's row (``STEREO_ROW_MAX_PX``) and have its depth inside
``[min_depth_m, max_depth_m]``, i.e. ``fx b / max_depth_m <= d <= fx b / min_depth_m``.

Search strategy (why a disparity ladder): LK converges from about +-30-40 px around the true
disparity (measured on KITTI 06 frame 0, 21 px window, 3 levels: of 190 matchable points 186
converge when started 30 px short of it, 179 from 40 px short, 183 from 40 px beyond, 154 from
60 px beyond), but KITTI disparities reach about 100 px and EuRoC's 96 px at the 0.5 m gate.  So LK
first starts from ``disparity_prior`` (the median disparity of the previous keyframe; 0 on the
first) and the points that fail are retried from hypotheses ``step_px`` apart.  Measured with
``python scripts/bench_frontend.py`` on KITTI 06 keyframes 0, 5, .., 45, default config, "correct"
= within 1 px of an OpenCV SGBM disparity; per keyframe: zero start 193 matches / 154 correct (26
of them with d > 40 px), prior start 201 / 160 (29), ladder 211 / 167 (35); SGBM disagrees with
9.4 %, 9.9 %, 10.4 % of the matches.  The ladder finds the most correct matches, the gain being the
near points, so it is kept.  Its cost is the retries of the points that fail everywhere: about 1.8x
the single try per KITTI keyframe (~300 points; 3.8 -> 7.0 ms and 6.8 -> 12.6 ms in two runs) and
1.4x on euroc_micro, where all three find the same matches (no d > 40 px in that scene).
"""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np

from gevi_cli.frontend.config import (
    FB_MAX_PX,
    LK_EPS,
    STEREO_MAX_DEPTH_M,
    STEREO_MIN_DEPTH_M,
    STEREO_ROW_MAX_PX,
    FrontendConfig,
)
from gevi_cli.frontend.klt import Pyramid, in_image, lk_once
from gevi_cli.observations import RectifiedStereo

STEP_PX = 40.0
"""Spacing of the disparity hypotheses (px): about the LK capture range measured above."""

RUNGS = 3
"""Hypotheses tried per point at most (the prior, then the ladder)."""

ROW_ITERS = 10
"""Iterations of the 1-D refinement on the row (:func:`refine_on_row`).  Measured on a kitti-like render
(101 keyframes, ~220 matches each): 130 / 36 / 10 / 5 features still moving after 1 / 2 / 3 / 4
iterations, 1.8 after 10, and 1.3 of those still after 30 (then dropped as not converged, keeping the
2-D match); the iterations past 10 ran for one or two features at a time and cost ~2 ms per keyframe."""


def disparity_gate(camera: RectifiedStereo, cfg: FrontendConfig) -> tuple[float, float]:
    """Accepted disparities (px): ``[fx b / max_depth_m, fx b / min_depth_m]``."""
    fb = camera.fx * camera.baseline
    return fb / STEREO_MAX_DEPTH_M, fb / STEREO_MIN_DEPTH_M


def hypotheses(prior: float, d_max: float, step_px: float = STEP_PX, rungs: int = RUNGS) -> list[float]:
    """Start disparities: ``prior``, then ``prior + step``, ``prior - step``, ``prior + 2 step``, ...
    kept inside ``[0, d_max]``; at most ``rungs``."""
    prior = float(np.clip(prior, 0.0, d_max))
    out = [prior]
    k = 1
    while len(out) < rungs and k * step_px <= d_max:
        for cand in (prior + k * step_px, prior - k * step_px):
            if 0.0 <= cand <= d_max and len(out) < rungs:
                out.append(cand)
        k += 1
    return out


def match_gain(pyr_left: Pyramid, pyr_right: Pyramid) -> Pyramid:
    """The right image scaled to the left image's mean brightness (saturating uint8).

    Why: LK compares raw intensities, and the two cameras' exposure/gain differ (EuRoC V1_01
    frame 0: mean 149 left vs 133 right).  Measured on euroc_micro frames 0, 10, .., 40 (default
    config): 52 stereo matches per frame without this, 82 with it; KITTI 06 unchanged (215 vs 214).
    """
    m_l, m_r = float(cv2.mean(pyr_left.image)[0]), float(cv2.mean(pyr_right.image)[0])
    if m_r <= 0.0 or abs(m_l / m_r - 1.0) < 0.01:
        return pyr_right
    return replace(pyr_right, image=cv2.convertScaleAbs(pyr_right.image, alpha=m_l / m_r))


def _patches(img: np.ndarray, u: np.ndarray, v: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Bilinear samples (n, m) float64 of ``img`` at ``(u + ox, v + oy)`` for the m ``offsets`` (m, 2)."""
    uu = (u[:, None] + offsets[None, :, 0]).astype(np.float32)
    vv = (v[:, None] + offsets[None, :, 1]).astype(np.float32)
    return cv2.remap(img, uu, vv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE).astype(np.float64)


def refine_on_row(pyr_left: Pyramid, pyr_right: Pyramid, uv_left: np.ndarray, d0: np.ndarray,
                  cfg: FrontendConfig) -> tuple[np.ndarray, np.ndarray]:
    """Disparities (n,) of ``uv_left`` (n, 2) by a 1-D Lucas-Kanade along the rectified row, from ``d0``.

    Level 0, the ``lk_window`` square, the right patch taken on the left feature's row: the model
    is ``L(u, v) = a R(u - d, v) + c`` (gain ``a`` and offset ``c`` fitted in closed form each
    iteration), solved inverse-compositionally (the left patch's horizontal Scharr gradient, as
    OpenCV's LK uses the template's), steps clipped to 1 px, :data:`ROW_ITERS` iterations, ``LK_EPS`` as LK.
    Returns ``d`` and ``ok``: converged, with horizontal texture, and within ``STEREO_ROW_MAX_PX``
    of ``d0`` (the 2-D solution may slide that far along an oblique edge, no farther).

    Why (docs/method.md, "Real images"): on KITTI 06 the vertical component of the 2-D LK solution
    is not zero (mean -0.16 px, std 0.47 px, a ``x y`` pattern of up to 0.8 px in the corners) and
    it drags the horizontal one along oblique edges; the 2-D disparities read 0.37 % below this
    1-D estimate and SGBM's, whereas on a render (exact rectification) the two agree.
    """
    n = len(uv_left)
    d = np.asarray(d0, np.float64).copy()
    if n == 0:
        return d, np.zeros(0, bool)
    half = pyr_left.window // 2
    ax = np.arange(-half, half + 1, dtype=np.float64)
    offsets = np.stack(np.meshgrid(ax, ax), -1).reshape(-1, 2)
    u, v = uv_left[:, 0], uv_left[:, 1]
    left = pyr_left.image.astype(np.float32)
    tpl = _patches(left, u, v, offsets)
    tpl -= tpl.mean(axis=1, keepdims=True)
    grad = _patches(cv2.Scharr(left, cv2.CV_32F, 1, 0, scale=1.0 / 32.0), u, v, offsets)
    grad -= grad.mean(axis=1, keepdims=True)
    hess = np.einsum("ij,ij->i", grad, grad)
    textured = hess > 1e-6 * grad.shape[1]
    right = pyr_right.image.astype(np.float32)
    active = np.flatnonzero(textured)
    for _ in range(ROW_ITERS):
        if len(active) == 0:
            break
        img = _patches(right, u[active] - d[active], v[active], offsets)
        img -= img.mean(axis=1, keepdims=True)
        gain = np.einsum("ij,ij->i", img, tpl[active]) / np.maximum(np.einsum("ij,ij->i", img, img), 1e-12)
        res = gain[:, None] * img - tpl[active]
        step = np.clip(np.einsum("ij,ij->i", grad[active], res) / hess[active], -1.0, 1.0)
        d[active] += step
        active = active[np.abs(step) >= LK_EPS]
    ok = textured & np.isfinite(d) & (np.abs(d - d0) < STEREO_ROW_MAX_PX)
    ok[active] = False  # not converged within ROW_ITERS
    return d, ok


def match_stereo(pyr_left: Pyramid, pyr_right: Pyramid, uv_left: np.ndarray, camera: RectifiedStereo,
                 cfg: FrontendConfig, disparity_prior: float | None = None, step_px: float = STEP_PX,
                 rungs: int = RUNGS, gain: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Right-image pixels (n, 2) of the left features ``uv_left`` (n, 2) and ``ok`` (n,) bool.

    ``uv_right`` is NaN where ``ok`` is False.  ``disparity_prior`` (px) is where the search starts
    (default 0); failures are retried from the :func:`hypotheses` ladder (``rungs=1``: prior only).
    ``gain``: compensate the global brightness difference first (:func:`match_gain`).
    With ``cfg.stereo_refine`` the accepted matches are refined on the row (:func:`refine_on_row`):
    ``uv_right = (u_L - d, v_L)``; where the refinement fails the 2-D match stays.
    """
    uv_left = np.asarray(uv_left, np.float64).reshape(-1, 2)
    n = len(uv_left)
    uv_right = np.full((n, 2), np.nan)
    ok = np.zeros(n, bool)
    if n == 0:
        return uv_right, ok
    if gain:
        pyr_right = match_gain(pyr_left, pyr_right)
    d_lo, d_hi = disparity_gate(camera, cfg)
    for d0 in hypotheses(0.0 if disparity_prior is None else disparity_prior, d_hi, step_px, rungs):
        todo = np.flatnonzero(~ok)
        if len(todo) == 0:
            break
        shift = np.array([d0, 0.0])
        src = uv_left[todo]
        fwd, good = lk_once(pyr_left, pyr_right, src, src - shift, cfg)
        d = src[:, 0] - fwd[:, 0]
        good &= in_image(fwd, pyr_right.shape)
        good &= (np.abs(fwd[:, 1] - src[:, 1]) < STEREO_ROW_MAX_PX) & (d >= d_lo) & (d <= d_hi)
        idx = np.flatnonzero(good)
        if len(idx):
            # backward from the match, started symmetrically (shifted back by the same hypothesis)
            back, ok_back = lk_once(pyr_right, pyr_left, fwd[idx], fwd[idx] + shift, cfg)
            fb_ok = ok_back & (np.linalg.norm(back - src[idx], axis=1) < FB_MAX_PX)
            acc = todo[idx[fb_ok]]
            uv_right[acc] = fwd[idx[fb_ok]]
            ok[acc] = True
    if cfg.stereo_refine and ok.any():
        k = np.flatnonzero(ok)
        d, good = refine_on_row(pyr_left, pyr_right, uv_left[k], uv_left[k, 0] - uv_right[k, 0], cfg)
        good &= (d >= d_lo) & (d <= d_hi)
        # a failed refinement (weak horizontal texture: it did not converge or slid off) keeps the 2-D
        # match: dropping those 3 % cost pool-hard_s1 (60 s, a turbid floor) 52 more IMU-only frames
        # and its ATE went from 0.44 to 1.03 m; kitti06_head: RPE 0.0112 m against 0.0109 m
        uv_right[k[good]] = np.column_stack([uv_left[k[good], 0] - d[good], uv_left[k[good], 1]])
    return uv_right, ok
