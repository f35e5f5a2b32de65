"""An IMU-only EuRoC ASL folder: ``mav0/imu0`` (+ ``state_groundtruth_estimate0``), no cameras.

What ``gevi simulate mav`` writes and what ``gevi imu`` reads like the IMU of a full EuRoC folder:
the same ``imu0`` reader (noise model from ``sensor.yaml`` where it states one) and the same
ground-truth rule (``--gt`` FILE, else ``state_groundtruth_estimate0/data.csv``; body = IMU frame).
"""
from __future__ import annotations

from functools import cached_property
from pathlib import Path

from gevi_cli.datasets.euroc import read_imu
from gevi_cli.datasets.sequence import BODY_IS_IMU
from gevi_cli.errors import LayoutError
from gevi_cli.trajectory import read_trajectory


class EurocImu:
    """``imu`` (:class:`~gevi_cli.datasets.sequence.ImuData`) and ``groundtruth`` (body poses or None)."""

    kind = "euroc-imu"
    imu_time_offset_s = 0.0  # no camera clock: the IMU's own stamps

    def __init__(self, path: Path, groundtruth=None):
        path = Path(path)
        self.mav0 = next((c for c in (path / "mav0", path) if (c / "imu0" / "data.csv").is_file()), None)
        if self.mav0 is None:
            raise LayoutError(path, "no mav0/imu0/data.csv: not an EuRoC IMU folder")
        self.name = (self.mav0.parent if self.mav0.name == "mav0" else self.mav0).resolve().name
        self.warnings: list[str] = []
        self._gt = Path(groundtruth) if groundtruth is not None else None

    @cached_property
    def imu(self):
        return read_imu(self.mav0 / "imu0")

    @property
    def reference_in_imu_frame(self) -> str:
        """The ground truth of an IMU-only EuRoC folder (gevi simulate mav) is the body (IMU) frame's pose."""
        return "" if self._gt is not None else BODY_IS_IMU

    @cached_property
    def groundtruth(self):
        csv = self._gt or self.mav0 / "state_groundtruth_estimate0" / "data.csv"
        if not csv.is_file():
            return None
        gt = read_trajectory(csv, name="groundtruth", frame="body")
        self.warnings.extend(gt.meta["warnings"])
        return gt
