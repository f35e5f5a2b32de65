"""Calibration of a stereo rig with an IMU: typed, frozen, with rectification derived once.

Frames: ``B`` = body = IMU frame; ``C0``/``C1`` = left/right camera (x right, y down, z forward).
``T_B_C0`` maps left-camera coordinates into the body frame (the EuRoC ``T_BS`` of cam0).
Intrinsics (:class:`~gevi_cli.camera.Intrinsics`) are in pixels; translations in metres.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.geometry import invert_pose


@dataclass(frozen=True)
class Rectification:
    """Stereo rectification computed once by OpenCV (``stereoRectify`` + ``initUndistortRectifyMap``).

    ``R0``/``R1`` rotate each original camera frame into its rectified frame; ``K`` is the shared
    rectified intrinsic matrix (pixels); ``baseline`` in metres; the maps remap raw images into
    rectified ones with ``cv2.remap``.
    """

    R0: np.ndarray
    R1: np.ndarray
    P0: np.ndarray
    P1: np.ndarray
    K: np.ndarray
    baseline: float
    size: tuple[int, int]
    map0: tuple[np.ndarray, np.ndarray]
    map1: tuple[np.ndarray, np.ndarray]

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (
            cv2.remap(left, *self.map0, interpolation=cv2.INTER_LINEAR),
            cv2.remap(right, *self.map1, interpolation=cv2.INTER_LINEAR),
        )


@dataclass(frozen=True)
class StereoRig:
    """Left (cam0) and right (cam1) camera: their intrinsics and body-frame extrinsics.

    ``T_B_C0``/``T_B_C1`` (4x4, metres) map left/right camera coordinates into the body frame
    (``X_B = T_B_C X_C``, EuRoC's ``T_BS``).
    """

    cam0: Intrinsics
    cam1: Intrinsics
    T_B_C0: np.ndarray = field(compare=False)
    T_B_C1: np.ndarray = field(compare=False)

    def __post_init__(self):
        for name in ("T_B_C0", "T_B_C1"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64).reshape(4, 4))

    @cached_property
    def T_C1_C0(self) -> np.ndarray:
        """Left -> right camera: ``X_R = R_rl X_L + t_rl`` (spec section 1)."""
        return invert_pose(self.T_B_C1) @ self.T_B_C0

    @property
    def R_rl(self) -> np.ndarray:
        return self.T_C1_C0[:3, :3]

    @property
    def t_rl(self) -> np.ndarray:
        return self.T_C1_C0[:3, 3]

    @property
    def baseline(self) -> float:
        """Distance between the two optical centres (metres)."""
        return float(np.linalg.norm(self.t_rl))

    @cached_property
    def rectification(self) -> Rectification:
        size = self.cam0.resolution
        R, t = self.R_rl, self.t_rl.reshape(3, 1)
        # OpenCV wants contiguous float64 R and t: R_rl is a view into T_C1_C0 and cv2.fisheye's reshape
        # refuses non-contiguous input ("the matrix is not continuous").
        R, t = np.ascontiguousarray(R, dtype=np.float64), np.ascontiguousarray(t, dtype=np.float64)
        if self.cam0.distortion_model == "equidistant":
            R0, R1, _, _, _ = cv2.fisheye.stereoRectify(
                self.cam0.K, self.cam0.dist_coeffs, self.cam1.K, self.cam1.dist_coeffs, size, R, t,
                flags=cv2.CALIB_ZERO_DISPARITY, newImageSize=size, balance=0.0, fov_scale=1.0,
            )
            # Our choice of the rectified camera, not OpenCV's: its new-camera estimate fits the whole
            # distorted border of a wide lens into the image (T265: focal 37 px from 285 px), which
            # throws away the resolution the tracker needs.  We keep the lens's own focal (the smaller
            # of the two cameras', so neither is upsampled) and the image centre as principal point:
            # the rectified view is the central field of 2*atan(w/2f) (T265: 112 deg horizontally).
            f = float(min(self.cam0.fx, self.cam0.fy, self.cam1.fx, self.cam1.fy))
            K_rect = np.array([[f, 0.0, (size[0] - 1) / 2.0], [0.0, f, (size[1] - 1) / 2.0], [0.0, 0.0, 1.0]])
            P0 = np.hstack([K_rect, np.zeros((3, 1))])
            P1 = P0.copy()
            P1[0, 3] = -f * float(np.linalg.norm(t))
            init = cv2.fisheye.initUndistortRectifyMap
        else:
            R0, R1, P0, P1, _, _, _ = cv2.stereoRectify(
                self.cam0.K, self.cam0.dist_coeffs, self.cam1.K, self.cam1.dist_coeffs, size, R, t,
                flags=cv2.CALIB_ZERO_DISPARITY, alpha=0,
            )
            init = cv2.initUndistortRectifyMap
        map0 = init(self.cam0.K, self.cam0.dist_coeffs, R0, P0, size, cv2.CV_32FC1)
        map1 = init(self.cam1.K, self.cam1.dist_coeffs, R1, P1, self.cam1.resolution, cv2.CV_32FC1)
        K = P0[:3, :3].copy()
        return Rectification(R0, R1, P0, P1, K, float(-P1[0, 3] / P1[0, 0]), size, tuple(map0), tuple(map1))

    def summary(self) -> str:
        c0 = self.cam0
        return (
            f"{c0.width}x{c0.height}, fx {c0.fx:.3f} fy {c0.fy:.3f} cx {c0.cx:.3f} cy {c0.cy:.3f}, "
            f"distortion {c0.distortion_model}, baseline {self.baseline:.3f} m"
        )
