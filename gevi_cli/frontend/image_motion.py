"""How far the image moved between two frames, judged from features tracked in both.

Pixels (rectified).  Used by GeVI's standstill test (``pipelines/inertial_init.py``).
"""
from __future__ import annotations

import cv2
import numpy as np


def fitted_flow_px(uv0: np.ndarray, uv1: np.ndarray, percentile: float = 90.0) -> float:
    """The ``percentile`` over the features of the displacement (px) that a similarity transform
    (rotation, scale, translation) fitted to all pairs ``uv0`` -> ``uv1`` (n, 2) predicts at ``uv0``;
    0.0 for fewer than 3 pairs or a degenerate fit.

    The fit is OpenCV's ``estimateAffinePartial2D`` with least median of squares (no threshold to
    tune; up to half the pairs may be wrong tracks), seeded so that the same inputs give the same
    answer.  Why fitted, not each feature's own displacement: features chained by LK random-walk,
    independently of each other, while a motion of the camera moves them together; the fit averages
    the walk down by about sqrt(n) (see docs/method.md, "Standstill").
    """
    uv0 = np.asarray(uv0, np.float32).reshape(-1, 2)
    uv1 = np.asarray(uv1, np.float32).reshape(-1, 2)
    if len(uv0) < 3 or len(uv0) != len(uv1):
        return 0.0
    cv2.setRNGSeed(0)
    M, _ = cv2.estimateAffinePartial2D(uv0, uv1, method=cv2.LMEDS)
    if M is None:
        return 0.0
    moved = uv0.astype(np.float64) @ M[:, :2].T + M[:, 2] - uv0
    return _percentile(np.linalg.norm(moved, axis=1), percentile)


def _percentile(x: np.ndarray, percentile: float) -> float:
    """``np.percentile(x, percentile)`` (linear interpolation) from the two order statistics it needs:
    a partial sort instead of np.percentile's general machinery (~40 us of this per-frame test)."""
    pos = (len(x) - 1) * (percentile / 100.0)
    lo = int(np.floor(pos))
    hi = min(lo + 1, len(x) - 1)
    a, b = np.partition(x, [lo, hi])[[lo, hi]]
    t = pos - lo
    # numpy's lerp: exact at both ends
    return float(b - (b - a) * (1.0 - t) if t >= 0.5 else a + (b - a) * t)
