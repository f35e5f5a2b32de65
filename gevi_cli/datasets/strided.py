"""Every K-th stereo pair of a sequence (``gevi run --stride K``): the same recording at 1/K of its
frame rate, i.e. K times the motion between consecutive frames.

Frame ``j`` of the strided sequence is frame ``K * j`` of the original, with its original stamp
(int64 ns).  The IMU (body frame, every sample), the calibration and the ground truth (stamped body
or cam0 poses) are the original's, whole: the ground truth is matched to the strided frames by stamp.
"""
from __future__ import annotations

from typing import Iterator

from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.datasets.sequence import ImuData, Sequence, StereoFrame
from gevi_cli.errors import GeviError
from gevi_cli.trajectory import Trajectory


def check_stride(stride: int, where: str = "--stride") -> int:
    """``stride`` as a whole number >= 1, else a one-line :class:`GeviError` at ``where``."""
    if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
        raise GeviError(where, f"must be a whole number >= 1 (1 = every frame), got {stride!r}")
    return stride


def stride_suffix(stride: int) -> str:
    """What a strided run adds to its sequence name (and so to its default run folder): ``_stride3``."""
    return f"_stride{stride}" if stride > 1 else ""


class StridedSequence(Sequence):
    """Frames ``0, K, 2K, ...`` of ``inner`` (see module docstring); named ``<inner name>_stride<K>``.

    Its ``path``, ``calibration_file`` and the attributes a reader adds beyond :class:`Sequence` are the
    inner sequence's.
    """

    path = property(lambda self: self.inner.path)
    calibration_file = property(lambda self: self.inner.calibration_file)

    def __init__(self, inner: Sequence, stride: int):
        super().__init__()
        self.inner = inner
        self.stride = check_stride(stride)
        self.kind = inner.kind
        self.imu_time_offset_s = inner.imu_time_offset_s
        self.warnings = inner.warnings  # shared: the inner reader appends to it lazily (ground truth, IMU)
        self._name = inner.name + stride_suffix(stride)
        self._rig: StereoRig = inner.calibration
        self._stamps = inner.stamps_ns[::stride]

    def __getattr__(self, name: str):
        if name == "inner":  # not set yet (unpickling): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def read_pair(self, index: int) -> StereoFrame:
        return self.inner.read_pair(self.stride * index)

    def frames(self, start: int | None = None, stop: int | None = None, step: int = 1) -> Iterator[StereoFrame]:
        """The inner reader's own iteration (a bag streams in one pass) over the strided indices."""
        selected = range(*slice(start, stop, step).indices(len(self)))
        if len(selected) == 0:
            return iter(())
        k = self.stride
        return self.inner.frames(k * selected.start, k * selected[-1] + 1, k * selected.step)

    @property
    def imu(self) -> ImuData | None:
        return self.inner.imu

    @property
    def groundtruth(self) -> Trajectory | None:
        return self.inner.groundtruth
