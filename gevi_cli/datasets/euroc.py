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

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.datasets.kalibr import yaml_real, yaml_whole
from gevi_cli.datasets.registry import register
from gevi_cli.datasets.sequence import BODY_IS_IMU, ImuData, Sequence, StereoFrame, pair_stereo
from gevi_cli.datasets.yamlio import load_yaml, matrix, require
from gevi_cli.errors import DataError, LayoutError
from gevi_cli.trajectory import Trajectory, read_trajectory
from gevi_cli.trajectory.formats import _is_number, _looks_like_header, read_text

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


def camera_from_sensor_yaml(path: Path) -> tuple[Intrinsics, np.ndarray]:
    """The intrinsics and the pose ``T_BS`` (camera -> body, 4x4, metres) of an EuRoC camera ``sensor.yaml``."""
    data = load_yaml(path)
    model = str(data.get("camera_model", "pinhole"))
    if model != "pinhole":
        raise DataError(path, f"camera_model '{model}' is not supported (only pinhole)")
    try:
        fu, fv, cu, cv = (yaml_real(v) for v in require(data, "intrinsics", path))
        width, height = (yaml_whole(v) for v in require(data, "resolution", path))
    except (TypeError, ValueError):
        raise DataError(path, "'intrinsics' must be [fu, fv, cu, cv] and 'resolution' [width, height]") from None
    if not all(np.isfinite(v) for v in (fu, fv, cu, cv)) or fu <= 0 or fv <= 0:
        raise DataError(path, "'intrinsics' must be finite with fu, fv > 0")
    if width <= 0 or height <= 0:
        raise DataError(path, f"'resolution' must be positive, got [{width}, {height}]")
    name = str(data.get("distortion_model", "none")).lower()
    if name not in _DISTORTION_NAMES:
        raise DataError(path, f"distortion_model '{name}' is not supported (radial-tangential, equidistant, none)")
    try:
        coeffs = tuple(yaml_real(c) for c in (data.get("distortion_coefficients", []) or []))
    except (TypeError, ValueError):
        raise DataError(path, "'distortion_coefficients' must be a list of numbers") from None
    if not all(np.isfinite(c) for c in coeffs):
        raise DataError(path, "'distortion_coefficients' must be finite")
    dist = _DISTORTION_NAMES[name]
    if dist != "none" and len(coeffs) != 4:
        raise DataError(path, f"{name} distortion needs 4 coefficients, got {len(coeffs)}")
    T_B_C = matrix(require(data, "T_BS", path), path, "T_BS")
    return Intrinsics(width, height, fu, fv, cu, cv, dist, coeffs), T_B_C


def rig_from_sensor_yamls(folder: Path) -> StereoRig:
    """The stereo rig of an EuRoC ``mav0`` folder (``cam0/sensor.yaml`` and ``cam1/sensor.yaml``)."""
    (cam0, T_B_C0), (cam1, T_B_C1) = (camera_from_sensor_yaml(folder / cam / "sensor.yaml") for cam in ("cam0", "cam1"))
    return StereoRig(cam0, cam1, T_B_C0, T_B_C1)


def read_csv_rows(path: Path, what: str) -> list[tuple[int, list[str]]]:
    """``(line number, comma-separated tokens)`` of every data row of an EuRoC ``data.csv``.

    Skips blank lines and ``#`` comments (EuRoC's ``#timestamp [ns],...`` header) and a first line
    naming the columns without ``#``; takes a UTF-8 BOM, CRLF ends and spaces around commas.
    """
    text = read_text(path)
    rows: list[tuple[int, list[str]]] = []
    first = True
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        tokens = [t.strip() for t in line.split(",")]
        if first and _looks_like_header(tokens):
            first = False
            continue  # an unmarked header (timestamp,filename)
        first = False
        rows.append((lineno, tokens))
    if not rows:
        raise DataError(path, f"lists no {what}" + (" (the file is empty)" if not text.strip() else ""))
    return rows


def _stamp_ns(token: str, path: Path, lineno: int) -> int:
    """A whole-nanosecond stamp (EuRoC's unit), refused with its line otherwise."""
    if not token.isdigit() or not token.isascii() or int(token) > _MAX_NS:
        raise DataError(f"{path}:{lineno}", f"timestamp {token[:30]!r} is not a whole number of nanoseconds "
                                            "(EuRoC stamps are ns integers)")
    return int(token)


def _increasing(stamps: np.ndarray, path: Path, lines: list[int]) -> None:
    bad = np.diff(stamps) <= 0
    if bad.any():
        r = int(np.argmax(bad)) + 1
        what = "repeats" if stamps[r] == stamps[r - 1] else "is before"
        raise DataError(f"{path}:{lines[r]}", f"timestamp {stamps[r]} {what} the previous row's ({stamps[r - 1]}, "
                                              f"line {lines[r - 1]}); rows must be in time order, one per stamp")


#: int64 nanoseconds end at 9.22e18.
_MAX_NS = 9_000_000_000_000_000_000


def read_image_list(folder: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """(stamps_ns, file paths, rows without a file) from ``<cam>/data.csv`` and ``<cam>/data/``.

    Rows are ``<timestamp ns>,<filename>``; stamps must strictly increase (an unsorted or repeated
    row is refused with its line, not reordered).
    """
    csv = folder / "data.csv"
    if not csv.is_file():
        raise LayoutError(folder, "missing data.csv (expected '#timestamp [ns],filename' rows)")
    rows = read_csv_rows(csv, "images")
    stamps, files, lines = [], [], []
    for lineno, tokens in rows:
        if len(tokens) != 2 or not tokens[1]:
            raise DataError(f"{csv}:{lineno}", f"expected '<timestamp ns>,<filename>', found {len(tokens)} column(s)")
        stamps.append(_stamp_ns(tokens[0], csv, lineno))
        files.append(tokens[1])
        lines.append(lineno)
    stamps = np.array(stamps, dtype=np.int64)
    _increasing(stamps, csv, lines)
    files = np.array(files, dtype=str)
    data_dir = folder / "data"
    present = set(os.listdir(data_dir)) if data_dir.is_dir() else set()
    exists = np.fromiter((f in present for f in files), dtype=bool, count=len(files))
    paths = np.array([str(data_dir / f) for f in files[exists]], dtype=object)
    return stamps[exists], paths, int((~exists).sum())


def read_imu(folder: Path) -> ImuData:
    """``imu0/data.csv`` (ns, gyro xyz rad/s, acc xyz m/s^2) and the noise model of ``sensor.yaml``.

    Every row has the first row's column count (at least 7; later columns are ignored), finite
    values, and a stamp after the previous row's; a row that does not is refused with its line.
    """
    csv = folder / "data.csv"
    if not csv.is_file():
        raise LayoutError(folder, "missing data.csv")
    rows = read_csv_rows(csv, "IMU rows")
    width = len(rows[0][1])
    if width < 7:
        raise DataError(f"{csv}:{rows[0][0]}", f"has {width} columns; expected 7 (timestamp, gyro xyz, acc xyz)")
    stamps = np.empty(len(rows), dtype=np.int64)
    values = np.empty((len(rows), 6))
    lines = []
    for i, (lineno, tokens) in enumerate(rows):
        if len(tokens) != width:
            raise DataError(f"{csv}:{lineno}", f"has {len(tokens)} columns, expected {width} like the first row")
        stamps[i] = _stamp_ns(tokens[0], csv, lineno)
        try:
            values[i] = [float(t) for t in tokens[1:7]]
        except ValueError:
            bad = next(c for c, t in enumerate(tokens[1:7], start=2) if not _is_number(t))
            raise DataError(f"{csv}:{lineno}", f"column {bad} is not a number: {tokens[bad - 1][:30]!r}") from None
        if not np.isfinite(values[i]).all():
            raise DataError(f"{csv}:{lineno}", "contains a non-finite value (nan or inf)")
        lines.append(lineno)
    _increasing(stamps, csv, lines)
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
                noise[field] = _noise_value(data[key], yaml_path, key)
    return ImuData(stamps, values[:, 0:3].copy(), values[:, 3:6].copy(), **noise)


def _noise_value(value, path: Path, key: str) -> float:
    try:
        value = yaml_real(value)
    except (TypeError, ValueError):
        raise DataError(path, f"'{key}' is not a number") from None
    if not np.isfinite(value) or value < 0:
        raise DataError(path, f"'{key}' must be a finite non-negative number")
    return value


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
        self._rig = rig_from_sensor_yamls(mav0)
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
            self._groundtruth_source = self._gt_override
            return gt
        csv = self.mav0 / "state_groundtruth_estimate0" / "data.csv"
        found = csv if csv.is_file() else self._groundtruth_beside()
        if found is not None:
            gt = read_trajectory(found, name="groundtruth", frame="body")
            self.warnings.extend(gt.meta["warnings"])
            self._groundtruth_source = found
            return gt
        return self._fallback_groundtruth()

    @property
    def reference_in_imu_frame(self) -> str:
        """EuRoC's ground truth (and a render's, and a pool sequence's converted motion capture) is the pose of
        the body frame, which is the IMU's; a file given with --gt may be anything."""
        return "" if self._gt_override is not None else BODY_IS_IMU

    def _groundtruth_beside(self) -> Path | None:
        """The one body-pose file in a ``groundtruth/`` folder next to ``mav0/`` (TUM or EuRoC CSV), as copies
        of EuRoC sequences often carry it; None when there is none or several (a warning names them)."""
        folder = self.mav0.parent / "groundtruth"
        files = sorted(p for p in folder.glob("*") if p.suffix in (".txt", ".csv", ".tum")) if folder.is_dir() else []
        if len(files) > 1:
            self.warnings.append(f"{folder}: {len(files)} trajectory files ({', '.join(p.name for p in files)}); "
                                 "none taken as the ground truth (pass --gt FILE)")
        return files[0] if len(files) == 1 else None

    def _fallback_groundtruth(self) -> Trajectory | None:
        self.warnings.append(f"{self.mav0 / 'state_groundtruth_estimate0' / 'data.csv'}: missing, and no "
                             f"single file in {self.mav0.parent / 'groundtruth'}/; no ground truth (pass --gt FILE)")
        return None

    # ----------------------------------------------------------------------------------- images
    def read_pair(self, index: int) -> StereoFrame:
        return StereoFrame(int(self._stamps[index]), _imread_gray(self._left[index]), _imread_gray(self._right[index]))


def _imread_gray(path: str) -> np.ndarray:
    image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise DataError(path, "cannot be read as an image (missing, truncated or not an image)")
    return image


@staticmethod
def _detect(path: Path) -> bool:
    return path.is_dir() and find_mav0(path) is not None


EurocSequence.detect = _detect
