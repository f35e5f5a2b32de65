"""Rotation-compensated LK: remove the predicted camera rotation before tracking, put it back after.

Why: OpenCV's LK fits a *translation* of a 21 px window.  When the image content also rotates, the
fitted translation is not the motion of the window's centre, and each feature is off by an amount
fixed by its own texture.  Tracked frame to frame, the error repeats with the same sign, so it
grows linearly with the frames since the keyframe.  On the pool-easy seed-2 render (a downward
camera yawing at up to ~20 deg/s) ``python scripts/track_bias.py RENDER --span 8`` reads 0.066 /
0.171 / 0.320 px RMS track error 1 / 4 / 8 frames after a keyframe, and 0.054 / 0.092 / 0.121 px
with ``--derotate``; a band-limited texture turned by 4 deg puts the 95th percentile of LK's error
at > 0.1 px, and < 0.05 px when derotated (tests/frontend/test_frontend.py).  The residual errors
that stay are perspective (slanted planes, depth edges): on the euroc-like render 0.43 -> 0.39 px
after 8 frames.

How: with ``R`` the rotation taking previous-camera coordinates into current-camera coordinates
(rectified left camera), the rotation alone moves a pixel ``x`` to ``H x`` with the infinite
homography ``H = K R K^-1``, exactly for every depth.  The current image is resampled at ``H x``
(bilinear) so that it shows the scene with the previous frame's orientation; LK then sees only the
translation's parallax, and each tracked pixel is mapped back by ``H``.  ``R`` is a *prediction*:
GeVI's gyro; CFO's last step, when that step's pose kept at least half of its matches
(``KeyframeOdometry.rotation_prior``); else the image rotation that best explains the last step's
tracks (:func:`fit_inplane`, about the optical axis only).  An error in the prediction only leaves
part of the rotation in, as without compensation.
"""
from __future__ import annotations

import cv2
import numpy as np


def rotation_homography(R_cp: np.ndarray, K: np.ndarray) -> np.ndarray:
    """``H = K R_cp K^-1``: previous pixel -> current pixel under the rotation ``R_cp`` alone."""
    return K @ np.asarray(R_cp, dtype=float) @ np.linalg.inv(K)


def derotate(img_cur: np.ndarray, H: np.ndarray) -> np.ndarray:
    """The current image seen with the previous orientation: ``out(x) = img_cur(H x)`` (bilinear;
    pixels from outside the image replicate its border, which the caller's in-image test rejects)."""
    h, w = img_cur.shape
    return cv2.warpPerspective(img_cur, H, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                               borderMode=cv2.BORDER_REPLICATE)


def fit_inplane(uv_prev: np.ndarray, uv_cur: np.ndarray, min_points: int = 8) -> tuple[np.ndarray, float] | None:
    """The image rotation and shift that best explain a step's tracks: ``(H, angle_deg)`` with
    ``uv_cur ~ H uv_prev``, ``H`` a rotation by ``angle`` about the tracks' centroid plus a shift (2-D
    least squares), refitted once without the pairs more than 3x the median residual away (moving
    objects, bad tracks).  Only the rotation *in the image plane*: a full 3-D rotation fitted to
    tracks also absorbs a sideways translation as a tilt, and warping by that tilt stretches the
    image (measured on pool-easy_s2, CFO: ATE 1.44 mm against 0.74 with the in-plane part only).
    None with fewer than ``min_points`` pairs."""
    keep = np.ones(len(uv_prev), dtype=bool)
    out = None
    for _ in range(2):
        if keep.sum() < min_points:
            return out
        mp, mc = uv_prev[keep].mean(0), uv_cur[keep].mean(0)
        a, b = uv_prev[keep] - mp, uv_cur[keep] - mc
        th = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b))
        c, s = np.cos(th), np.sin(th)
        H = np.array([[c, -s, mc[0] - (c * mp[0] - s * mp[1])], [s, c, mc[1] - (s * mp[0] + c * mp[1])], [0.0, 0.0, 1.0]])
        out = (H, float(np.degrees(abs(th))))
        r = np.linalg.norm(uv_cur - apply_homography(H, uv_prev), axis=1)
        keep = r <= 3.0 * np.median(r[keep]) + 1e-12
    return out


def apply_homography(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``H`` applied to pixels ``uv`` (n, 2)."""
    x = uv @ H[:2, :2].T + H[:2, 2]
    s = uv @ H[2, :2] + H[2, 2]
    return x / s[:, None]
