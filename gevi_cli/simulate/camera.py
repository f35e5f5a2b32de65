"""The simulator's cameras and the rays its renderer casts.

The rig is the dataset layer's :class:`~gevi_cli.datasets.calibration.StereoRig`; its cameras are :class:`~gevi_cli.camera.Intrinsics` with a radial-tangential ("radtan", EuRoC
"radial-tangential") lens, coefficients (k1, k2, p1, p2), all zero for an ideal pinhole.
Camera frame (docs/method.md section 1): x right, y down, z forward (optical axis).  Pixel
coordinates: the centre of the top-left pixel is (0, 0); pixel (u, v) covers
[u - 0.5, u + 0.5] x [v - 0.5, v + 0.5].
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.calibration import StereoRig


def pixel_rays(camera: Intrinsics, supersample: int = 1) -> np.ndarray:
    """Unit ray directions (camera frame) through the sub-pixel sample centres of ``camera``.

    Returns (H*s, W*s, 3) float64 for ``s = supersample``; sample (r, c) lies at pixel coordinates
    ``u = (c + 0.5)/s - 0.5``, ``v = (r + 0.5)/s - 0.5``, so averaging s x s blocks gives a box
    filter centred on each pixel.
    """
    s = int(supersample)
    u = (np.arange(camera.width * s) + 0.5) / s - 0.5
    v = (np.arange(camera.height * s) + 0.5) / s - 0.5
    uu, vv = np.meshgrid(u, v)
    xy = camera.normalize(np.column_stack([uu.ravel(), vv.ravel()])).reshape(uu.shape + (2,))
    x, y = camera.undistort_normalized(xy[..., 0], xy[..., 1])
    rays = np.stack([x, y, np.ones_like(x)], axis=-1)
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


def as_read(rig: StereoRig) -> StereoRig:
    """The rig as the dataset readers return it for a written sequence: an all-zero radtan lens is "none"."""

    def read(cam: Intrinsics) -> Intrinsics:
        return cam if cam.has_distortion else replace(cam, distortion_model="none", distortion=())

    return StereoRig(read(rig.cam0), read(rig.cam1), rig.T_B_C0, rig.T_B_C1)
