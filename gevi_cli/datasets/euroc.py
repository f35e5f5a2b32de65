"""EuRoC MAV ASL folders: ``mav0/{cam0,cam1,imu0,state_groundtruth_estimate0}``.

Layout per sensor: ``data.csv`` (``#timestamp [ns],...``) and ``sensor.yaml`` (``T_BS`` = sensor to
body, intrinsics ``[fu, fv, cu, cv]``, ``radial-tangential`` distortion).  Body = IMU frame.  Left and
right images are paired by timestamp; rows of ``data.csv`` without an image file are dropped and
counted (the real EuRoC-micro cam1 lists 99 rows for 95 files).
"""
from __future__ import annotations

import os
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from gevi_cli.datasets.calibration import PinholeCamera, StereoRig
from gevi_cli.datasets.registry import register
from gevi_cli.datasets.sequence import ImuData, Sequence, StereoFrame, pair_stereo
from gevi_cli.datasets.yamlio import load_yaml, matrix, require
from gevi_cli.errors import DataError, GeviError, LayoutError
from gevi_cli.trajectory import Trajectory, read_trajectory

_DISTORTION_NAMES = {
    "radial-tangential": "radtan", "radtan": "radtan", "plumb_bob": "radtan",
    "equidistant": "equidistant", "fisheye": "equidistant", "none": "none", "": "none",
}

#: Left/right stamps closer than this are one stereo pair (EuRoC pairs share the exact stamp).
DEFAULT_PAIR_TOLERANCE_NS = 1_000_000


def find_mav0(path: Path) -> Path | None:
    for candidate in (path / "mav0", path):
        if (candidate / "cam0").is_dir() and (candidate / "cam1").is_dir():
            return candidate
    return None


def camera_from_sensor_yaml(path: Path) -> PinholeCamera:
    """A :class:`PinholeCamera` from an EuRoC camera ``sensor.yaml``."""
    data = load_yaml(path)
    model = str(data.get("camera_model", "pinhole"))
    if model != "pinhole":
        raise DataError(path, f"camera_model '{model}' is not supported (only pinhole)")
    try:
        fu, fv, cu, cv = (float(v) for v in require(data, "intrinsics", path))
        width, height = (int(v) for v in require(data, "resolution", path))
    except (TypeError, ValueError):
        raise DataError(path, "'intrinsics' must be [fu, fv, cu, cv] and 'resolution' [width, height]") from None
    name = str(data.get("distortion_model", "none")).lower()
    if name not in _DISTORTION_NAMES:
        raise DataError(path, f"distortion_model '{name}' is not supported (radial-tangential, equidistant, none)")
    coeffs = tuple(float(c) for c in data.get("distortion_coefficients", []) or [])
    dist = _DISTORTION_NAMES[name]
    if dist != "none" and len(coeffs) != 4:
        raise DataError(path, f"{name} distortion needs 4 coefficients, got {len(coeffs)}")
    T_B_C = matrix(require(data, "T_BS", path), path, "T_BS")
    return PinholeCamera(width, height, fu, fv, cu, cv, dist, coeffs, T_B_C)


def read_image_list(folder: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """(stamps_ns, file paths, rows without a file) from ``<cam>/data.csv`` and ``<cam>/data/``."""
    csv = folder / "data.csv"
    if not csv.is_file():
        raise LayoutError(folder, "missing data.csv (expected '#timestamp [ns],filename' rows)")
    try:
        table = pd.read_csv(csv, header=None, comment="#", names=["t", "file"], dtype={"t": np.int64, "file": str},
                            skipinitialspace=True)
    except (ValueError, pd.errors.ParserError) as err:
        raise DataError(csv, f"cannot parse rows as '<timestamp ns>,<filename>' ({err})") from None
    if table.empty:
        raise DataError(csv, "lists no images")
    order = np.argsort(table["t"].to_numpy(), kind="stable")
    stamps = table["t"].to_numpy()[order]
    files = table["file"].to_numpy().astype(str)[order]
    data_dir = folder / "data"
    present = set(os.listdir(data_dir)) if data_dir.is_dir() else set()
    exists = np.fromiter((f in present for f in files), dtype=bool, count=len(files))
    paths = np.array([str(data_dir / f) for f in files[exists]], dtype=object)
    return stamps[exists], paths, int((~exists).sum())


def read_imu(folder: Path) -> ImuData:
    """``imu0/data.csv`` (ns, gyro xyz rad/s, acc xyz m/s^2) and the noise model of ``sensor.yaml``."""
    csv = folder / "data.csv"
    try:
        table = pd.read_csv(csv, header=None, comment="#", dtype=np.float64, skipinitialspace=True)
        stamps = pd.read_csv(csv, header=None, comment="#", usecols=[0], dtype=np.int64).to_numpy()[:, 0]
    except FileNotFoundError:
        raise LayoutError(folder, "missing data.csv") from None
    except (ValueError, pd.errors.ParserError) as err:
        raise DataError(csv, f"cannot parse IMU rows ({err})") from None
    if table.shape[1] < 7:
        raise DataError(csv, f"has {table.shape[1]} columns; expected 7 (timestamp, gyro xyz, acc xyz)")
    values = table.to_numpy()[:, 1:7]
    bad = ~np.isfinite(values).all(axis=1)
    if bad.any():
        raise DataError(f"{csv}", f"data row {int(np.argmax(bad)) + 1} contains a non-finite value")
    if (np.diff(stamps) <= 0).any():
        raise DataError(csv, f"timestamps not increasing at data row {int(np.argmax(np.diff(stamps) <= 0)) + 2}")
    noise = {}
    yaml_path = folder / "sensor.yaml"
    if yaml_path.is_file():
        data = load_yaml(yaml_path)
        T_BS = matrix(data["T_BS"], yaml_path, "T_BS") if "T_BS" in data else np.eye(4)
        if not np.allclose(T_BS, np.eye(4), atol=1e-9):
            raise DataError(yaml_path, "imu0 T_BS is not identity; gevi defines the body frame as the IMU frame")
        for key, field in (("gyroscope_noise_density", "gyro_noise_density"), ("gyroscope_random_walk", "gyro_random_walk"),
                           ("accelerometer_noise_density", "acc_noise_density"), ("accelerometer_random_walk", "acc_random_walk")):
            if key in data:
                noise[field] = float(data[key])
    return ImuData(stamps, values[:, 0:3].copy(), values[:, 3:6].copy(), **noise)


@register("euroc")
class EurocSequence(Sequence):
    """An EuRoC ASL folder (the folder holding ``mav0/``, or ``mav0`` itself)."""

    def __init__(self, path: Path, groundtruth: str | Path | None = None,
                 pair_tolerance_ns: int = DEFAULT_PAIR_TOLERANCE_NS):
        super().__init__()
        self.path = Path(path)
        mav0 = find_mav0(self.path)
        if mav0 is None:
            raise LayoutError(self.path, "no mav0/cam0 and mav0/cam1 folders: not an EuRoC ASL folder")
        self.mav0 = mav0
        self._name = (mav0.parent if mav0.name == "mav0" else mav0).resolve().name
        for cam in ("cam0", "cam1"):
            if not (mav0 / cam / "sensor.yaml").is_file():
                raise LayoutError(mav0 / cam, "missing sensor.yaml (camera calibration)")
        self._rig = StereoRig(camera_from_sensor_yaml(mav0 / "cam0" / "sensor.yaml"),
                              camera_from_sensor_yaml(mav0 / "cam1" / "sensor.yaml"))
        t0, f0, missing0 = read_image_list(mav0 / "cam0")
        t1, f1, missing1 = read_image_list(mav0 / "cam1")
        for cam, missing in (("cam0", missing0), ("cam1", missing1)):
            if missing:
                self.warnings.append(f"{mav0 / cam / 'data.csv'}: {missing} row(s) have no image file; ignored")
        i0, i1 = pair_stereo(t0, t1, pair_tolerance_ns, (str(mav0 / "cam0"), str(mav0 / "cam1")), mav0, self.warnings)
        self._stamps = t0[i0]
        self._left = f0[i0]
        self._right = f1[i1]
        self._gt_override = Path(groundtruth) if groundtruth is not None else None

    # --------------------------------------------------------------------------------- metadata
    @cached_property
    def imu(self) -> ImuData | None:
        folder = self.mav0 / "imu0"
        if not (folder / "data.csv").is_file():
            return None
        return read_imu(folder)

    @cached_property
    def groundtruth(self) -> Trajectory | None:
        if self._gt_override is not None:
            gt = read_trajectory(self._gt_override, name="groundtruth", frame="body")
            self.warnings.extend(gt.meta["warnings"])
            return gt
        csv = self.mav0 / "state_groundtruth_estimate0" / "data.csv"
        if csv.is_file():
            gt = read_trajectory(csv, name="groundtruth", frame="body")
            self.warnings.extend(gt.meta["warnings"])
            return gt
        return self._fallback_groundtruth()

    def _fallback_groundtruth(self) -> Trajectory | None:
        self.warnings.append(f"{self.mav0 / 'state_groundtruth_estimate0' / 'data.csv'}: missing; "
                             "no ground truth (pass --groundtruth FILE)")
        return None

    # ----------------------------------------------------------------------------------- images
    def _read_pair(self, index: int) -> StereoFrame:
        return StereoFrame(int(self._stamps[index]), _imread_gray(self._left[index]), _imread_gray(self._right[index]))


def _imread_gray(path: str) -> np.ndarray:
    image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise DataError(path, "cannot be read as an image (missing, truncated or not an image)")
    return image


def _check_groundtruth_option(path) -> None:
    if path is not None and not Path(path).is_file():
        raise GeviError("--groundtruth", f"{path}: no such file")


@staticmethod
def _detect(path: Path) -> bool:
    return path.is_dir() and find_mav0(path) is not None


EurocSequence.detect = _detect
