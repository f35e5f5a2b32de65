"""The stereo rig of the simulator and the rays its renderer casts.

Cameras are :class:`~gevi_cli.camera.Intrinsics` with a radial-tangential ("radtan", EuRoC
"radial-tangential") lens, coefficients (k1, k2, p1, p2), all zero for an ideal pinhole.
Camera frame (docs/method.md section 1): x right, y down, z forward (optical axis).  Pixel
coordinates: the centre of the top-left pixel is (0, 0); pixel (u, v) covers
[u - 0.5, u + 0.5] x [v - 0.5, v + 0.5].
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.geometry import invert_pose


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
    x, y = camera.undistort_normalized((uu - camera.cx) / camera.fx, (vv - camera.cy) / camera.fy)
    rays = np.stack([x, y, np.ones_like(x)], axis=-1)
    return rays / np.linalg.norm(rays, axis=-1, keepdims=True)


@dataclass(frozen=True)
class RenderRig:
    """Two cameras rigidly mounted on the body (= IMU) frame B.

    Attributes:
        cam0, cam1: intrinsics of the left and right camera.
        T_B_C0, T_B_C1: 4x4 camera -> body transforms (``X_B = T_B_C X_C``), as EuRoC's ``T_BS``.
    """

    cam0: Intrinsics
    cam1: Intrinsics
    T_B_C0: np.ndarray = field(repr=False)
    T_B_C1: np.ndarray = field(repr=False)

    @property
    def T_C1_C0(self) -> np.ndarray:
        """Left -> right camera transform (``X_C1 = T_C1_C0 X_C0``)."""
        return invert_pose(self.T_B_C1) @ self.T_B_C0

    @property
    def baseline_m(self) -> float:
        return float(np.linalg.norm(self.T_C1_C0[:3, 3]))

    def cameras(self):
        return [(self.cam0, self.T_B_C0), (self.cam1, self.T_B_C1)]

    def to_stereo_rig(self):
        """The same rig as the dataset layer's :class:`~gevi_cli.datasets.calibration.StereoRig`
        (what the readers will return for the written sequence)."""
        from gevi_cli.datasets.calibration import StereoRig

        def as_read(cam: Intrinsics) -> Intrinsics:  # an all-zero radtan lens is read back as "none"
            return cam if cam.has_distortion else replace(cam, distortion_model="none", distortion=())

        return StereoRig(as_read(self.cam0), as_read(self.cam1), self.T_B_C0, self.T_B_C1)
