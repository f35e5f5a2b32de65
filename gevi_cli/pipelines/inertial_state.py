"""What GeVI's parts share on the IMU side: the per-frame IMU summary, the bias estimates, tilt and yaw.

Frames: the body frame B is the IMU frame; ``R_ic`` = R_BC0 maps rectified-cam0 vectors into it.
Tilts are (roll, pitch) of R_WB in rad (ZYX, spec 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli import estimators as est


@dataclass
class ImuBiases:
    """The current gyro (rad/s) and accelerometer (m/s^2) bias estimates, body frame; one object shared by
    the parts that correct the IMU with them (their owner replaces the arrays, never edits them)."""

    b_g: np.ndarray = field(default_factory=lambda: np.zeros(3))
    b_a: np.ndarray = field(default_factory=lambda: np.zeros(3))


@dataclass
class FrameSample:
    """IMU summary of one frame of the BCD window: unit bias-corrected specific force ``acc_dir``,
    gyro rotation vector ``rotvec`` from the previous frame (rad), ``dt`` (s), estimated ``tilt``."""

    index: int
    t_ns: int
    t_prev_ns: int | None
    acc_dir: np.ndarray
    rotvec: np.ndarray
    dt: float
    tilt: np.ndarray
    f_mean: np.ndarray | None = None  # mean specific force over the frame period, as measured (m/s^2)
    R_wb: np.ndarray | None = None  # body orientation the acceleration compensation used (None: none)
    _R: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)
    _R_of: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def gyro_rotation(self) -> np.ndarray:
        """``exp(rotvec)``, the gyro rotation from the previous frame (body), computed once per ``rotvec``:
        the sample, the tilt prediction, the front end's rotation prior use it in every frame."""
        if self._R_of is not self.rotvec:
            self._R, self._R_of = est.exp_so3(self.rotvec), self.rotvec
        return self._R

    @property
    def has_imu(self) -> bool:
        """The IMU covers the frame: a finite gyro rotation and gravity direction (not an IMU gap)."""
        return bool(np.all(np.isfinite(self.rotvec)) and np.all(np.isfinite(self.acc_dir)))


def tilt_of(R_wc: np.ndarray, R_ic: np.ndarray) -> np.ndarray:
    """(roll, pitch) of the body (IMU) for a camera orientation ``R_wc`` (rad)."""
    return np.array(est.tilt_angles(R_wc @ R_ic.T))


def yaw_of(R_wi: np.ndarray) -> float:
    """ZYX yaw of ``R_wi`` (rad)."""
    return float(np.arctan2(R_wi[1, 0], R_wi[0, 0]))
