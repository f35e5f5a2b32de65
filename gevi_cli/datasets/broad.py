"""A trial of BROAD (Laidig et al., "BROAD - A Benchmark for Robust Inertial Orientation Estimation",
Data 6(7):72, 2021) in its MATLAB ``.mat`` form: what ``gevi imu`` and ``gevi info`` read.

Fields used (``scipy.io.loadmat(..., squeeze_me=True)``): ``imu_gyr`` (N, 3) rad/s and ``imu_acc``
(N, 3) m/s^2 in the IMU frame; ``opt_quat`` (N, 4, w x y z) the orientation of the IMU in an ENU
frame (z up) from optical motion capture, already synchronised and aligned to the IMU by the
dataset's authors, NaN where the markers were occluded; ``movement`` (N, bool) the samples the
benchmark scores; ``sampling_rate`` (Hz).  The samples are equally spaced: sample ``k`` is stamped
``round(k / sampling_rate * 1e9)`` ns.  ``opt_pos`` (m) gives the positions where present.
"""
from __future__ import annotations

from functools import cached_property
from pathlib import Path

import numpy as np

from gevi_cli.datasets.sequence import ImuData
from gevi_cli.errors import DataError, GeviError

#: the fields a trial must have, with the number of columns of each (None: a vector)
REQUIRED = {"imu_gyr": 3, "imu_acc": 3, "opt_quat": 4, "movement": None, "sampling_rate": 0}


def is_broad_mat(path: Path) -> bool:
    """A ``.mat`` file (BROAD's MATLAB form); its content is checked when it is read."""
    return Path(path).is_file() and Path(path).suffix.lower() == ".mat"


class BroadTrial:
    """``imu`` (:class:`~gevi_cli.datasets.sequence.ImuData`, IMU frame), ``groundtruth`` (IMU poses in
    ENU where the optical reference is valid), ``movement`` (N, bool) and ``scored_t_ns`` (the stamps of
    the movement samples with a valid reference: what the benchmark's RMSE is over)."""

    kind = "broad"
    imu_time_offset_s = 0.0
    reference_aligned = True  # synchronised and aligned to the IMU by the dataset's authors

    def __init__(self, path: Path):
        self.path = Path(path)
        self.name = self.path.stem
        self.warnings: list[str] = []
        if not self.path.is_file():
            raise GeviError(self.path, "no such file")
        from scipy.io import loadmat

        try:
            mat = loadmat(self.path, squeeze_me=True)
        except Exception as err:  # scipy raises ValueError / MatReadError / OSError on a non-MATLAB file
            raise DataError(self.path, f"not a readable MATLAB .mat file ({type(err).__name__}: {err})") from err
        self.fields = {k: _field(self.path, mat, k, cols) for k, cols in REQUIRED.items()}
        n = len(self.fields["imu_gyr"])
        for key in ("imu_acc", "opt_quat", "movement"):
            if len(self.fields[key]) != n:
                raise DataError(self.path, f"field '{key}' has {len(self.fields[key])} samples, 'imu_gyr' has {n}")
        rate = float(self.fields["sampling_rate"])
        if not np.isfinite(rate) or rate <= 0:
            raise DataError(self.path, f"field 'sampling_rate' is {rate}, not a positive rate in Hz")
        if n < 2:
            raise DataError(self.path, f"field 'imu_gyr' has {n} sample(s); at least 2 are needed")
        for key in ("imu_gyr", "imu_acc"):
            if not np.all(np.isfinite(self.fields[key])):
                raise DataError(self.path, f"field '{key}' contains NaN or inf")
        self.rate_hz = rate
        self.t_ns = np.round(np.arange(n) / rate * 1e9).astype(np.int64)
        self.movement = self.fields["movement"].astype(bool)
        self.info = str(mat.get("info", "")).strip()
        pos = mat.get("opt_pos")
        self._pos = np.asarray(pos, dtype=float) if pos is not None and np.shape(pos) == (n, 3) else np.zeros((n, 3))

    @cached_property
    def imu(self) -> ImuData:
        return ImuData(self.t_ns, np.ascontiguousarray(self.fields["imu_gyr"], dtype=float),
                       np.ascontiguousarray(self.fields["imu_acc"], dtype=float))

    @cached_property
    def valid(self) -> np.ndarray:
        """(N,) bool: samples whose optical reference is a finite, non-zero quaternion."""
        q = self.fields["opt_quat"]
        return np.all(np.isfinite(q), axis=1) & (np.linalg.norm(np.nan_to_num(q), axis=1) > 0.5)

    @cached_property
    def groundtruth(self):
        """The optical reference as a Trajectory of IMU poses (ENU world, z up) at the valid samples."""
        from gevi_cli.trajectory import Trajectory

        v = self.valid
        q = self.fields["opt_quat"][v]
        traj = Trajectory(self.t_ns[v], np.nan_to_num(self._pos[v]), q / np.linalg.norm(q, axis=1, keepdims=True),
                          frame="body", name="groundtruth")
        traj.meta.update({"path": str(self.path), "format": "broad", "warnings": []})
        return traj

    @property
    def scored_t_ns(self) -> np.ndarray:
        """Stamps (ns) of the samples BROAD scores: movement phases with a valid reference."""
        return self.t_ns[self.movement & self.valid]

    @property
    def duration_s(self) -> float:
        return float(self.t_ns[-1]) * 1e-9


def _field(path: Path, mat: dict, key: str, cols: int | None) -> np.ndarray:
    """``mat[key]`` as an array of the expected shape: (N, cols), (N,) for None, a scalar for 0."""
    if key not in mat:
        raise DataError(path, f"no field '{key}': not a BROAD trial (needs {', '.join(REQUIRED)})")
    try:
        a = np.asarray(mat[key], dtype=float)
    except (TypeError, ValueError) as err:
        raise DataError(path, f"field '{key}' is not numeric") from err
    want = "a number" if cols == 0 else "a vector of N samples" if cols is None else f"N x {cols}"
    if (cols == 0 and a.size != 1) or (cols is None and a.ndim != 1) or (cols and (a.ndim != 2 or a.shape[1] != cols)):
        raise DataError(path, f"field '{key}' has shape {a.shape}, expected {want}")
    return a.reshape(()) if cols == 0 else a
