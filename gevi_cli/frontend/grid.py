"""Shi-Tomasi corners on a grid: at most one corner per cell, only in cells with no tracked feature.

Pixels of the (rectified) image; ``cell_px`` and ``quality*`` from
:class:`~gevi_cli.frontend.config.FrontendConfig`.  Fully vectorized, deterministic (ties go to the
first pixel in row-major order).
"""
from __future__ import annotations

import cv2
import numpy as np

from gevi_cli.frontend.config import BORDER_PX, MIN_DISTANCE_PX, FrontendConfig


class _Scratch:
    """Float32 buffers for the min-eigenvalue map, allocated once per image size.

    Why not ``cv2.cornerMinEigenVal``: it allocates a 3-channel float image per call (4.3 MB at
    752x480), and whether glibc serves that from fresh mmap pages depends on the process's malloc
    history -- measured 3.6 ms per call vs 0.6 ms once the heap is warm.  Owning the buffers makes
    the detector's cost independent of what ran before it.
    """

    def __init__(self, h: int, w: int, cell: int):
        self.h, self.w = h, w
        self.ny, self.nx = -(-h // cell), -(-w // cell)
        self.bufs = [np.empty((h, w), np.float32) for _ in range(5)]
        # score padded to whole cells; the padding never wins a cell
        self.padded = np.full((self.ny * cell, self.nx * cell), -np.inf, np.float32)


def min_eigen_map(img: np.ndarray, out: _Scratch) -> np.ndarray:
    """Shi-Tomasi score (2x the smaller eigenvalue of the 3x3-summed structure tensor, Sobel 3x3)
    of every pixel; same ranking as ``cv2.cornerMinEigenVal(img, 3)`` up to a constant factor."""
    ix, iy, a, b, c = out.bufs
    cv2.Sobel(img, cv2.CV_32F, 1, 0, dst=ix, ksize=3)
    cv2.Sobel(img, cv2.CV_32F, 0, 1, dst=iy, ksize=3)
    cv2.multiply(ix, ix, dst=a)
    cv2.multiply(iy, iy, dst=b)
    cv2.multiply(ix, iy, dst=c, scale=2.0)
    cv2.boxFilter(a, -1, (3, 3), dst=ix, normalize=False)   # ix <- sum Ix^2
    cv2.boxFilter(b, -1, (3, 3), dst=iy, normalize=False)   # iy <- sum Iy^2
    cv2.boxFilter(c, -1, (3, 3), dst=a, normalize=False)    # a  <- 2 sum IxIy
    # lambda_min * 2 = (Sxx + Syy) - sqrt((Sxx - Syy)^2 + (2 Sxy)^2)
    cv2.subtract(ix, iy, dst=b)
    cv2.magnitude(b, a, c)
    cv2.add(ix, iy, dst=b)
    cv2.subtract(b, c, dst=a)
    return a


def _reference_score(best: np.ndarray, percentile: float) -> float:
    """The corner strength that ``quality`` is relative to: the ``percentile`` of the finite cell maxima.

    Why not the single strongest corner: one high-contrast object (a marker, a calibration board on
    a feature-poor pool floor) is orders of magnitude stronger than the floor's texture -- pool-hard_s1
    frame 0: 1.3e6 against cell maxima of 2.6e3-5.3e3 -- and then the floor gets no corners at all,
    tracking rests on the few around the object and is lost when it leaves the view.  A percentile
    over cells lets one object move the threshold by one cell's worth, not the whole image's.
    """
    fin = best[np.isfinite(best)]
    if fin.size == 0:
        return -np.inf
    if percentile >= 100.0:
        return float(fin.max())
    return float(np.percentile(fin, percentile))


class GridDetector:
    """:func:`detect_grid` with its buffers kept between calls (one instance per front end)."""

    def __init__(self, cfg: FrontendConfig):
        self.cfg = cfg
        self._scratch: _Scratch | None = None

    def __call__(self, img: np.ndarray, occupied_uv: np.ndarray | None, mask: np.ndarray | None = None) -> np.ndarray:
        h, w = np.shape(img)[:2]
        s = self._scratch
        if s is None or (s.h, s.w) != (h, w):
            s = self._scratch = _Scratch(h, w, int(self.cfg.cell_px))
        return detect_grid(img, occupied_uv, self.cfg, mask, _scratch=s)


def detect_grid(img: np.ndarray, occupied_uv: np.ndarray | None, cfg: FrontendConfig,
                mask: np.ndarray | None = None, *, _scratch: _Scratch | None = None) -> np.ndarray:
    """New corners (n, 2) float64 pixels (u, v), at most one per ``cell_px`` cell, ordered by cell.

    A cell holding any point of ``occupied_uv`` (tracked features, pixels) gets no corner; nor does
    the ``BORDER_PX`` margin or where ``mask`` (optional, same size) is zero.  A candidate is dropped
    when a stronger candidate or an occupied point is closer than ``MIN_DISTANCE_PX``.  The quality
    level is relative to the strongest corner of the whole image (outside border and mask, occupied
    cells included), so the threshold does not depend on which cells happen to be tracked.
    "Strongest" is the ``quality_percentile`` of the cells' best scores (100: the single strongest
    corner), see :func:`_reference_score`.
    """
    img = np.ascontiguousarray(img)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise ValueError(f"detect_grid needs a 2-D uint8 image, got shape {img.shape} dtype {img.dtype}")
    h, w = img.shape
    cell, bd = int(cfg.cell_px), int(BORDER_PX)
    s = _scratch if _scratch is not None else _Scratch(h, w, cell)
    score = min_eigen_map(img, s)
    pad = s.padded
    view = pad[:h, :w]
    np.copyto(view, score)
    if bd > 0:
        view[:bd], view[h - bd:], view[:, :bd], view[:, w - bd:] = -np.inf, -np.inf, -np.inf, -np.inf
    if mask is not None:
        if mask.shape != img.shape:
            raise ValueError(f"mask shape {mask.shape} differs from image shape {img.shape}")
        view[np.asarray(mask) == 0] = -np.inf

    ny, nx = s.ny, s.nx
    blocks = pad.reshape(ny, cell, nx, cell).transpose(0, 2, 1, 3).reshape(ny, nx, cell * cell)
    arg = blocks.argmax(axis=2)
    best = np.take_along_axis(blocks, arg[..., None], axis=2)[..., 0]
    top = _reference_score(best, cfg.quality_percentile)
    if not np.isfinite(top) or top <= 0.0:
        return np.empty((0, 2))
    ok = best >= cfg.quality * top
    gy, gx = np.mgrid[0:ny, 0:nx]
    u = (gx * cell + arg % cell).astype(np.float64)
    v = (gy * cell + arg // cell).astype(np.float64)

    occ = np.empty((0, 2)) if occupied_uv is None else np.asarray(occupied_uv, np.float64).reshape(-1, 2)
    occ = occ[np.isfinite(occ).all(axis=1)]
    if len(occ):
        oc = np.clip(np.floor(occ[:, 0] / cell).astype(np.int64), 0, nx - 1)
        orow = np.clip(np.floor(occ[:, 1] / cell).astype(np.int64), 0, ny - 1)
        ok[orow, oc] = False

    r2 = float(MIN_DISTANCE_PX) ** 2
    if r2 > 0.0:
        # Only cells up to k away can hold a point closer than MIN_DISTANCE_PX (k = 1 for the defaults).
        k = int(np.ceil(MIN_DISTANCE_PX / cell))
        # candidate vs candidate: the weaker one goes (ties: the later cell)
        rank = np.where(ok, best, -np.inf)
        order = np.arange(ny * nx).reshape(ny, nx)
        drop = np.zeros_like(ok)
        for dy in range(-k, k + 1):
            for dx in range(-k, k + 1):
                if (dy == 0 and dx == 0) or abs(dy) >= ny or abs(dx) >= nx:
                    continue
                # destination cell (i, j), neighbour (i + dy, j + dx)
                ys, yd = slice(max(dy, 0), ny + min(dy, 0)), slice(max(-dy, 0), ny + min(-dy, 0))
                xs, xd = slice(max(dx, 0), nx + min(dx, 0)), slice(max(-dx, 0), nx + min(-dx, 0))
                near = (u[yd, xd] - u[ys, xs]) ** 2 + (v[yd, xd] - v[ys, xs]) ** 2 < r2
                stronger = (rank[ys, xs] > rank[yd, xd]) | (
                    (rank[ys, xs] == rank[yd, xd]) & (order[ys, xs] < order[yd, xd]))
                drop[yd, xd] |= near & stronger & ok[ys, xs]
        ok &= ~drop
        if len(occ):
            # occupied points vs the candidates in the (2k+1)^2 cells around each point
            dy, dx = np.mgrid[-k:k + 1, -k:k + 1]
            m = dy.size
            cy = (orow[:, None] + dy.ravel()).ravel()
            cx = (oc[:, None] + dx.ravel()).ravel()
            inside = (cy >= 0) & (cy < ny) & (cx >= 0) & (cx < nx)
            cy, cx = cy[inside], cx[inside]
            pu = np.repeat(occ[:, 0], m)[inside]
            pv = np.repeat(occ[:, 1], m)[inside]
            close = (u[cy, cx] - pu) ** 2 + (v[cy, cx] - pv) ** 2 < r2
            ok[cy[close], cx[close]] = False
    return np.column_stack([u[ok], v[ok]])
