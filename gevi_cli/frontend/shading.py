"""Illumination shading removal: the image minus its local mean, before detection, LK and stereo.

Pixels of the rectified image; ``size_px`` is the side (odd, px) of the local-mean kernel.

Why: an underwater vehicle carries its own lamps, so the light falls off across the image (hot spot,
vignetting, attenuation with range) while the floor's own texture is faint.  That shading is fixed
to the *camera*, not to the scene: in consecutive frames it stays where it was and pulls LK towards
zero motion, and between the two cameras of the rig it differs, so the coarse pyramid levels of the
stereo LK align shading instead of texture.  Measured on pool-hard_s1 (`gevi simulate pool-hard
--seed 1`), frame 100, 346 corners, 41 px window: 10 stereo matches pass the row and
forward-backward checks on the raw images, 263-280 after subtracting a Gaussian local mean of
sigma 5-20 px.  ``gevi_cli/configs/pool.yaml`` uses 61 px: a larger kernel keeps more of the floor's
mid-frequency texture but leaves more of a narrow light spot (the residual grows as size^2 over the
spot's width^2; tests/frontend/test_underwater.py), and on KITTI-like scenes with large image motion
the removal costs LK its coarse-level capture range, so it is off by default (docs/method.md,
"Lamp-lit floors").  The local mean is OpenCV's stack blur (0.5 ms at 752x480 for a 61 px kernel,
against 4 ms for the Gaussian it approximates); the result is offset to 128 and saturated to uint8,
which keeps LK's integer image path.
"""
from __future__ import annotations

import cv2
import numpy as np


def remove_shading(img: np.ndarray, size_px: int) -> np.ndarray:
    """``img - local_mean(img) + 128`` (uint8, saturating); ``size_px <= 1`` returns ``img`` as is."""
    size = int(size_px)
    if size <= 1:
        return img
    size |= 1  # stack blur needs an odd kernel
    mean = cv2.stackBlur(img, (size, size))
    return cv2.addWeighted(img, 1.0, mean, -1.0, 128.0)
