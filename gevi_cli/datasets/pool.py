"""Pool-style underwater sequences: the EuRoC ASL layout plus motion capture.

``mav0/mocap0/data.csv`` holds poses ``T_W_M`` of the marker body M (``#timestamp [ns], p_x, p_y,
p_z, q_w, q_x, q_y, q_z``) and ``mav0/mocap0/sensor.yaml`` its ``T_BS`` = ``T_B_M`` (marker to body).
Body poses follow as ``T_W_B = T_W_M @ inv(T_B_M)``.  When
``state_groundtruth_estimate0/data.csv`` is present it stays the ground truth; otherwise the
converted motion capture is.
"""
from __future__ import annotations

from functools import cached_property
from pathlib import Path

import numpy as np

from gevi_cli.datasets.euroc import EurocSequence, find_mav0
from gevi_cli.datasets.registry import register
from gevi_cli.datasets.yamlio import load_yaml, matrix
from gevi_cli.errors import LayoutError
from gevi_cli.geometry import invert_pose
from gevi_cli.trajectory import Trajectory, read_trajectory


@register("pool")
class PoolSequence(EurocSequence):
    """EuRoC ASL folder with ``mav0/mocap0`` (see module docstring)."""

    @staticmethod
    def detect(path: Path) -> bool:
        mav0 = find_mav0(path) if path.is_dir() else None
        return mav0 is not None and (mav0 / "mocap0" / "data.csv").is_file()

    @cached_property
    def T_B_M(self) -> np.ndarray:
        """Marker body -> IMU body (4x4)."""
        yaml_path = self.mav0 / "mocap0" / "sensor.yaml"
        if not yaml_path.is_file():
            raise LayoutError(self.mav0 / "mocap0", "missing sensor.yaml with T_BS (marker to body transform)")
        return matrix(load_yaml(yaml_path).get("T_BS"), yaml_path, "T_BS")

    @cached_property
    def mocap(self) -> Trajectory:
        """Marker poses ``T_W_M`` as recorded."""
        marker = read_trajectory(self.mav0 / "mocap0" / "data.csv", name="mocap")
        self.warnings.extend(marker.meta["warnings"])
        return marker

    def _fallback_groundtruth(self) -> Trajectory:
        return self.mocap.with_sensor_frame(invert_pose(self.T_B_M), frame="body")
