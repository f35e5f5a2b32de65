"""What every dataset reader returns: a :class:`Sequence` and its typed pieces.

Stamps are int64 nanoseconds; images uint8 grayscale; IMU in the body (= IMU) frame, gyro rad/s,
accelerometer m/s^2 (specific force).  Ground truth is a :class:`~gevi_cli.trajectory.Trajectory`
of body poses ``T_W_B`` unless its ``frame`` says otherwise (KITTI: cam0 = body).
"""
from __future__ import annotations

import abc
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.trajectory import Trajectory


@dataclass(frozen=True)
class StereoFrame:
    """One synchronised stereo pair; ``t_ns`` is the left image stamp (ns)."""

    t_ns: int
    left: np.ndarray
    right: np.ndarray


@dataclass(frozen=True)
class ImuData:
    """IMU samples in the body frame with the continuous-time noise parameters of the calibration.

    Noise densities: gyro rad/s/sqrt(Hz), accel m/s^2/sqrt(Hz); random walks: rad/s^2/sqrt(Hz),
    m/s^3/sqrt(Hz).  ``None`` where the calibration does not give them.
    """

    t_ns: np.ndarray
    gyro: np.ndarray
    acc: np.ndarray
    gyro_noise_density: float | None = None
    gyro_random_walk: float | None = None
    acc_noise_density: float | None = None
    acc_random_walk: float | None = None

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def rate_hz(self) -> float:
        return rate_hz(self.t_ns)

    @property
    def duration_s(self) -> float:
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9 if len(self) > 1 else 0.0

    def between(self, t0_ns: int, t1_ns: int) -> "ImuData":
        """Samples with ``t0_ns <= t <= t1_ns``."""
        i0, i1 = np.searchsorted(self.t_ns, [t0_ns, t1_ns], side="left")
        i1 = np.searchsorted(self.t_ns, t1_ns, side="right")
        return ImuData(self.t_ns[i0:i1], self.gyro[i0:i1], self.acc[i0:i1], self.gyro_noise_density,
                       self.gyro_random_walk, self.acc_noise_density, self.acc_random_walk)


#: an interval of a sampled stream (an IMU, a reference trajectory) longer than this many median sample periods
#: is a gap (gevi info, gevi imu, the bag inventory; gevi run's default of imu.max_gap_factor)
GAP_FACTOR = 5.0

#: why a reader's own ground truth needs no rotation into the IMU frame (Sequence.reference_in_imu_frame)
BODY_IS_IMU = "the dataset's ground truth is the body (IMU) frame's pose"


def rate_hz(t_ns: np.ndarray) -> float:
    """Nominal rate from the median sample period (robust to dropped frames)."""
    if len(t_ns) < 2:
        return 0.0
    return float(1e9 / np.median(np.diff(t_ns)))


class Sequence(abc.ABC):
    """A recorded stereo(-inertial) sequence, opened by one of the registered readers.

    Implementations read metadata eagerly (stamps, calibration, IMU, ground truth) and images lazily:
    they set ``_name``, ``_rig`` (the :class:`StereoRig`) and ``_stamps`` in ``__init__`` and
    implement ``read_pair``.
    """

    kind: str = ""
    #: camera-IMU time shift from the calibration (Kalibr ``timeshift_cam_imu``: t_imu = t_cam + shift), s
    imu_time_offset_s: float = 0.0
    #: the calibration file the camera model came from when it is not part of the dataset (a bag's --calib)
    calibration_file: Path | None = None
    #: the dataset folder or file the reader opened (readers set it in ``__init__``)
    path: Path

    def __init__(self):
        self.warnings: list[str] = []

    # Readers set these three in __init__; the properties are the public, read-only view.
    _name: str
    _rig: StereoRig
    _stamps: np.ndarray

    @property
    def name(self) -> str:
        return self._name

    @property
    def calibration(self) -> StereoRig:
        return self._rig

    @property
    def stamps_ns(self) -> np.ndarray:
        """(n,) int64 stamps of the stereo pairs, increasing."""
        return self._stamps

    @abc.abstractmethod
    def read_pair(self, index: int) -> StereoFrame:
        """Load stereo pair ``index`` (0 <= index < len(self))."""

    @property
    def imu(self) -> ImuData | None:
        return None

    @property
    def groundtruth(self) -> Trajectory | None:
        return None

    @property
    def reference_in_imu_frame(self) -> str:
        """Why the dataset's ground truth is the IMU's own pose (``gevi imu`` then estimates only its clock
        offset); "" when that is not known (a file given with --gt, a motion-capture marker body)."""
        return ""

    @property
    def groundtruth_source(self) -> Path | None:
        """The file :attr:`groundtruth` was read from (None: none, or not from one file)."""
        return getattr(self, "_groundtruth_source", None)

    def __len__(self) -> int:
        return len(self.stamps_ns)

    def frames(self, start: int | None = None, stop: int | None = None, step: int = 1) -> Iterator[StereoFrame]:
        """Lazily iterate stereo pairs ``start:stop:step`` (indices into :attr:`stamps_ns`)."""
        for index in range(*slice(start, stop, step).indices(len(self))):
            yield self.read_pair(index)

    @property
    def frame_rate_hz(self) -> float:
        return rate_hz(self.stamps_ns)

    @property
    def duration_s(self) -> float:
        s = self.stamps_ns
        return float(s[-1] - s[0]) * 1e-9 if len(s) > 1 else 0.0


def pair_by_stamp(left_ns: np.ndarray, right_ns: np.ndarray, tolerance_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices (i_left, i_right) of left/right stamps that are mutual nearest neighbours within tolerance.

    Both inputs sorted.  Pairing by time (never by row index) survives dropped frames on either side.
    """
    if len(left_ns) == 0 or len(right_ns) == 0:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    j = np.searchsorted(right_ns, left_ns)
    j0 = np.clip(j - 1, 0, len(right_ns) - 1)
    j1 = np.clip(j, 0, len(right_ns) - 1)
    best = np.where(np.abs(right_ns[j0] - left_ns) <= np.abs(right_ns[j1] - left_ns), j0, j1)
    ok = np.abs(right_ns[best] - left_ns) <= tolerance_ns
    i_left = np.nonzero(ok)[0]
    i_right = best[ok]
    # keep one left per right (mutual nearest): first occurrence wins
    _, first = np.unique(i_right, return_index=True)
    return i_left[first], i_right[first]


def pair_stereo(left_ns: np.ndarray, right_ns: np.ndarray, tolerance_ns: int, names: tuple[str, str],
                where, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pair_by_stamp` for a reader: unpaired images are counted into ``warnings`` (per camera
    ``names``), and no pair at all is a :class:`~gevi_cli.errors.DataError` at ``where``."""
    from gevi_cli.errors import DataError

    i0, i1 = pair_by_stamp(left_ns, right_ns, tolerance_ns)
    for name, n, used in ((names[0], len(left_ns), len(i0)), (names[1], len(right_ns), len(i1))):
        if n - used:
            warnings.append(f"{name}: {n - used} image(s) without a partner within "
                            f"{tolerance_ns / 1e6:g} ms in the other camera; ignored")
    if len(i0) == 0:
        raise DataError(where, f"no stereo pairs: {names[0]} and {names[1]} share no stamps within "
                               f"{tolerance_ns / 1e6:g} ms")
    return i0, i1
