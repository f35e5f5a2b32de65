"""Pyramidal Lucas-Kanade tracking with a forward-backward check (OpenCV ``calcOpticalFlowPyrLK``).

Pixels (u, v) of the images given (rectified in the front end); float64 in and out.

About pyramids: OpenCV's Python binding cannot pass a precomputed pyramid to
``calcOpticalFlowPyrLK`` -- its ``prevImg``/``nextImg`` accept one array only, and the list that
``cv2.buildOpticalFlowPyramid`` returns is refused (opencv/opencv#4777, still open; checked with
OpenCV 5.0).  So :func:`build_pyramid` returns a :class:`Pyramid` handle holding the checked base
image and the LK settings, made once per image and reused by the forward, backward and stereo calls;
OpenCV rebuilds the levels inside each call.  That price, measured as a one-point call: 0.27 ms at
752x480, 0.33 ms at 1226x370, per call (``track`` makes two calls, a keyframe's stereo two per
disparity hypothesis).  The levels themselves are available as :attr:`Pyramid.levels`, built on
demand with ``cv2.buildOpticalFlowPyramid``; nothing in the tracking path uses them.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np

from gevi_cli.frontend.config import FB_MAX_PX, LK_EPS, LK_ITERS, LK_LEVELS, LK_SCALE_STEP, FrontendConfig


@dataclass(frozen=True, eq=False)  # compared by identity: the image is an array
class Pyramid:
    """One image prepared for LK: ``image`` (contiguous uint8, level 0), ``window`` (px), ``max_level``."""

    image: np.ndarray
    window: int
    max_level: int

    @property
    def shape(self) -> tuple[int, int]:
        return self.image.shape

    @cached_property
    def levels(self) -> tuple[np.ndarray, ...]:
        """The images of levels 0..max_level (``cv2.buildOpticalFlowPyramid``, no derivatives)."""
        _, pyr = cv2.buildOpticalFlowPyramid(self.image, (self.window, self.window), self.max_level,
                                             withDerivatives=False)
        return tuple(pyr)


def build_pyramid(img: np.ndarray, cfg: FrontendConfig) -> Pyramid:
    """Handle for tracking from/into ``img`` (2-D uint8) with ``cfg.lk_window`` and ``LK_LEVELS``."""
    if img is None:
        raise ValueError("image is None (unreadable or missing)")
    img = np.asarray(img)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise ValueError(f"LK needs a 2-D uint8 image, got shape {img.shape} dtype {img.dtype}")
    return Pyramid(np.ascontiguousarray(img), int(cfg.lk_window), int(LK_LEVELS))


def lk_once(src: Pyramid, dst: Pyramid, uv: np.ndarray, guess: np.ndarray, cfg: FrontendConfig):
    """One OpenCV LK call (no checks): ``uv`` (n, 2) in ``src`` -> ``dst`` starting from ``guess``;
    returns the points (n, 2) float64 and OpenCV's status (n,) bool.  Float32 inside OpenCV."""
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, int(LK_ITERS), float(LK_EPS))
    out, status, _ = cv2.calcOpticalFlowPyrLK(
        src.image, dst.image, uv.astype(np.float32).reshape(-1, 1, 2), guess.astype(np.float32).reshape(-1, 1, 2),
        winSize=(src.window, src.window), maxLevel=src.max_level, criteria=criteria,
        flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
    return out.reshape(-1, 2).astype(np.float64), status.reshape(-1).astype(bool)


def in_image(uv: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(n,) True where pixel ``uv`` lies inside an image of ``shape`` (h, w): 0 <= u <= w-1, 0 <= v <= h-1."""
    h, w = shape
    return np.isfinite(uv).all(axis=1) & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)


def track_lk(pyr_prev: Pyramid, pyr_cur: Pyramid, uv_prev: np.ndarray, cfg: FrontendConfig,
             uv_guess: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Track pixels ``uv_prev`` (n, 2) of the previous image into the current one.

    Returns ``uv_cur`` (n, 2) float64 pixels (NaN where not ok) and ``ok`` (n,) bool: LK status in
    both directions, the result inside the image, and the forward-backward error
    ``|back(fwd(uv)) - uv| < FB_MAX_PX``.
    ``uv_guess`` (n, 2), default ``uv_prev``, is where the forward search starts.  The backward
    search starts at ``uv_cur`` moved back by the same prior displacement, so the check is as hard
    as the forward problem (starting it at ``uv_prev`` would let a wrong match pass trivially).
    """
    uv_prev = np.asarray(uv_prev, np.float64).reshape(-1, 2)
    n = len(uv_prev)
    if n == 0:
        return np.empty((0, 2)), np.zeros(0, bool)
    guess = uv_prev if uv_guess is None else np.asarray(uv_guess, np.float64).reshape(-1, 2)
    uv_cur, ok = lk_once(pyr_prev, pyr_cur, uv_prev, guess, cfg)
    ok &= in_image(uv_cur, pyr_cur.shape)
    idx = np.flatnonzero(ok)  # track back only what survived the forward pass
    if len(idx):
        start = uv_cur[idx] - (guess[idx] - uv_prev[idx])
        uv_back, ok_back = lk_once(pyr_cur, pyr_prev, uv_cur[idx], start, cfg)
        fb = np.linalg.norm(uv_back - uv_prev[idx], axis=1)
        ok[idx] = ok_back & (fb < FB_MAX_PX)
    uv_cur[~ok] = np.nan
    return uv_cur, ok


def track_lk_scaled(pyr_prev: Pyramid, pyr_cur: Pyramid, uv_prev: np.ndarray, cfg: FrontendConfig,
                    uv_guess: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`track_lk` for features whose patch changes size between the images by ``scale`` (n,).

    LK fits a translation of its window, so a patch that grew by 1.3x or more (a near point at a
    large forward step: a fast car, a low frame rate) no longer matches and is lost or lands on a
    look-alike.  The features are grouped by scale in steps of ``LK_SCALE_STEP`` (a factor); for
    each group other than the unit one the previous image is resized by the group's scale (an affine
    warp, the translation putting the group's features at their guesses on average) and the group is
    tracked from that image, so LK sees patches of the right size.  The unit group, a feature whose
    warped start falls outside the image and one whose scaled track fails get the plain
    :func:`track_lk` (one call for all of them; OpenCV's LK tracks each point on its own).
    """
    uv_prev = np.asarray(uv_prev, np.float64).reshape(-1, 2)
    guess = np.asarray(uv_guess, np.float64).reshape(-1, 2)
    n = len(uv_prev)
    uv, ok = np.full((n, 2), np.nan), np.zeros(n, bool)
    step = np.log(float(LK_SCALE_STEP))
    group = np.round(np.log(np.clip(np.asarray(scale, np.float64), 1e-3, 1e3)) / step)
    plain = ~np.isfinite(group) | (group == 0)
    h, w = pyr_cur.shape
    for g in np.unique(group[~plain]):
        members = np.flatnonzero(group == g)
        s = float(np.exp(g * step))
        t = np.median(guess[members] - s * uv_prev[members], axis=0)
        src = s * uv_prev[members] + t
        inside = in_image(src, (h, w))
        if inside.any():
            A = np.array([[s, 0.0, t[0]], [0.0, s, t[1]]])
            warped = build_pyramid(cv2.warpAffine(pyr_prev.image, A, (w, h), flags=cv2.INTER_LINEAR), cfg)
            uv_g, ok_g = track_lk(warped, pyr_cur, src[inside], cfg, guess[members[inside]])
            uv[members[inside]], ok[members[inside]] = uv_g, ok_g
        plain[members[~ok[members]]] = True
    idx = np.flatnonzero(plain)
    if len(idx):
        uv[idx], ok[idx] = track_lk(pyr_prev, pyr_cur, uv_prev[idx], cfg, guess[idx])
    return uv, ok
