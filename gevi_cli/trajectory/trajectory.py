"""The one trajectory type of gevi.

A :class:`Trajectory` is a time series of rigid poses ``T_W_S`` (sensor frame S -> world frame W):
``p_W = R_W_S @ p_S + t_W_S``.  Stamps are int64 nanoseconds; positions metres; orientations unit
quaternions stored **w first**.  ``frame`` names the sensor frame S the poses describe ("body" = IMU
frame, "cam0" = left camera, or "unknown"), so the evaluator can bring estimates and ground truth into
the same frame before computing RPE.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

#: Nominal frame period used when a file has no stamps (KITTI): 10 Hz, the KITTI camera rate.
KITTI_NOMINAL_PERIOD_NS = 100_000_000

FRAMES = ("body", "cam0", "unknown")


@dataclass(frozen=True)
class Trajectory:
    """Poses ``T_W_S`` of one sensor frame over time.

    Attributes:
        t_ns: (n,) int64 stamps in nanoseconds, strictly increasing.
        positions: (n, 3) float64 ``t_W_S`` in metres.
        quat_wxyz: (n, 4) float64 unit quaternions of ``R_W_S``, w first.
        frame: which sensor frame S the poses describe ("body", "cam0" or "unknown").
        indexed: True when the file carried no stamps (KITTI): ``t_ns`` is then the frame index
            times :data:`KITTI_NOMINAL_PERIOD_NS` and association must be by index.
        name: a label (method name or file stem).
    """

    t_ns: np.ndarray
    positions: np.ndarray
    quat_wxyz: np.ndarray
    frame: str = "unknown"
    indexed: bool = False
    name: str = ""
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        t = np.ascontiguousarray(self.t_ns, dtype=np.int64).reshape(-1)
        p = np.ascontiguousarray(self.positions, dtype=np.float64).reshape(-1, 3)
        q = np.ascontiguousarray(self.quat_wxyz, dtype=np.float64).reshape(-1, 4)
        if not (len(t) == len(p) == len(q)):
            raise ValueError(f"stamps, positions and quaternions differ in length: {len(t)}, {len(p)}, {len(q)}")
        if self.frame not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, not {self.frame!r}")
        object.__setattr__(self, "t_ns", t)
        object.__setattr__(self, "positions", p)
        object.__setattr__(self, "quat_wxyz", q)

    # ----------------------------------------------------------------------------- constructors
    @classmethod
    def from_matrices(cls, t_ns, T, **kwargs) -> "Trajectory":
        """Build from (n, 4, 4) or (n, 3, 4) pose matrices ``T_W_S``."""
        T = np.asarray(T, dtype=np.float64)
        quat_xyzw = Rotation.from_matrix(T[:, :3, :3]).as_quat()
        return cls(t_ns, T[:, :3, 3], np.roll(quat_xyzw, 1, axis=1), **kwargs)

    @classmethod
    def from_rotations(cls, t_ns, R, positions, **kwargs) -> "Trajectory":
        quat_xyzw = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat()
        return cls(t_ns, positions, np.roll(quat_xyzw, 1, axis=1), **kwargs)

    # ------------------------------------------------------------------------------- accessors
    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def t_s(self) -> np.ndarray:
        """Stamps in seconds (float64; loses sub-microsecond precision at epoch times)."""
        return self.t_ns.astype(np.float64) * 1e-9

    @property
    def quat_xyzw(self) -> np.ndarray:
        return np.roll(self.quat_wxyz, -1, axis=1)

    @property
    def rotations(self) -> np.ndarray:
        """(n, 3, 3) rotation matrices ``R_W_S``."""
        return Rotation.from_quat(self.quat_xyzw).as_matrix()

    @property
    def matrices(self) -> np.ndarray:
        """(n, 4, 4) homogeneous poses ``T_W_S``."""
        T = np.tile(np.eye(4), (len(self), 1, 1))
        T[:, :3, :3] = self.rotations
        T[:, :3, 3] = self.positions
        return T

    @property
    def duration_s(self) -> float:
        return float(self.t_ns[-1] - self.t_ns[0]) * 1e-9 if len(self) > 1 else 0.0

    @property
    def path_length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.positions, axis=0), axis=1).sum()) if len(self) > 1 else 0.0

    # ------------------------------------------------------------------------------ operations
    def select(self, index) -> "Trajectory":
        """A sub-trajectory from a boolean mask, slice or index array."""
        return replace(self, t_ns=self.t_ns[index], positions=self.positions[index], quat_wxyz=self.quat_wxyz[index])

    def with_sensor_frame(self, T_S_N: np.ndarray, frame: str) -> "Trajectory":
        """Poses of another rigidly attached frame N: ``T_W_N = T_W_S @ T_S_N``.

        E.g. body poses -> cam0 poses with ``T_S_N = T_B_C0``; cam0 -> body with ``inv(T_B_C0)``.
        """
        T = self.matrices @ np.asarray(T_S_N, dtype=np.float64)
        return Trajectory.from_matrices(self.t_ns, T, frame=frame, indexed=self.indexed, name=self.name, meta=self.meta)
