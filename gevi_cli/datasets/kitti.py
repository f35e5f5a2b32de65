"""KITTI odometry sequences: ``sequences/XX/{image_0,image_1 | image_2,image_3}, calib.txt, times.txt``.

Images are rectified (no distortion).  ``calib.txt`` gives projection matrices ``P0..P3`` of the
rectified cameras, ``P_i = K [I | t_i]`` with ``t_i`` the offset from rectified cam0 to camera i.
KITTI has no IMU, so the body frame is **cam0** (``T_B_C0 = I``), which is also the frame of the
ground truth ``poses/XX.txt`` (looked up at ``../../poses/XX.txt`` relative to the sequence folder, or
next to it).  Option ``cameras="gray"`` (default when image_0 exists) or ``"color"``.
"""
from __future__ import annotations

import re
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.datasets.registry import register
from gevi_cli.datasets.sequence import Sequence, StereoFrame
from gevi_cli.errors import DataError, GeviError, LayoutError
from gevi_cli.trajectory import Trajectory, read_trajectory
from gevi_cli.trajectory.formats import read_text
from gevi_cli.trajectory.stamps import decimal_strings_to_ns

_CAMERAS = {"gray": ("image_0", "image_1", "P0", "P1"), "color": ("image_2", "image_3", "P2", "P3")}


def read_calib(path: Path) -> dict[str, np.ndarray]:
    """The ``P0..P3`` (3x4) matrices of a KITTI ``calib.txt`` (``Pi: 12 numbers`` per line).

    Other ``key: values`` lines (``Tr:``, ``calib_time:``) are ignored; a ``P`` row with a
    non-number, a non-finite value, other than 12 numbers, or given twice is refused with its line.
    """
    if not path.is_file():
        raise LayoutError(path.parent, "missing calib.txt")
    out = {}
    for lineno, line in enumerate(read_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        key, colon, rest = line.partition(":")
        key = key.strip()
        if not colon or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", key):
            raise DataError(f"{path}:{lineno}", f"is not a 'key: values' line (KITTI calib.txt rows are "
                                                f"'P0: 12 numbers'): {line.strip()[:40]!r}")
        if key not in _P_KEYS:
            continue
        try:
            values = np.array(rest.split(), dtype=np.float64)
        except ValueError:
            raise DataError(f"{path}:{lineno}", f"'{key}' holds a non-number") from None
        if values.size != 12:
            raise DataError(f"{path}:{lineno}", f"'{key}' has {values.size} numbers, expected 12")
        if not np.isfinite(values).all():
            raise DataError(f"{path}:{lineno}", f"'{key}' holds a non-finite value (nan or inf)")
        if key in out:
            raise DataError(f"{path}:{lineno}", f"'{key}' is given twice")
        out[key] = values.reshape(3, 4)
    return out


_P_KEYS = ("P0", "P1", "P2", "P3")


def read_times(path: Path) -> np.ndarray:
    """The stamps of ``times.txt`` (one time in seconds per line) as exact int64 ns.

    Blank lines are skipped; a line that is not one finite number, or a time not after the
    previous line's, is refused with its line.
    """
    if not path.is_file():
        raise LayoutError(path.parent, "missing times.txt")
    stamps, lines = [], []
    for lineno, line in enumerate(read_text(path).splitlines(), start=1):
        tokens = line.split()
        if not tokens:
            continue
        if len(tokens) != 1:
            raise DataError(f"{path}:{lineno}", f"holds {len(tokens)} values; expected one time in seconds per line")
        try:
            stamps.append(int(decimal_strings_to_ns(tokens, 1_000_000_000)[0]))
        except ValueError:
            raise DataError(f"{path}:{lineno}", f"{tokens[0][:30]!r} is not a finite time in seconds") from None
        lines.append(lineno)
    if not stamps:
        raise DataError(path, "lists no times (expected one time in seconds per frame)")
    stamps = np.array(stamps, dtype=np.int64)
    bad = np.diff(stamps) <= 0
    if bad.any():
        r = int(np.argmax(bad)) + 1
        raise DataError(f"{path}:{lines[r]}", f"time {stamps[r] * 1e-9:.9g} s is not after the previous line's "
                                              f"({stamps[r - 1] * 1e-9:.9g} s); times must increase, one per frame")
    return stamps


def _camera_from_P(P: np.ndarray, P_ref: np.ndarray, width: int, height: int) -> tuple[Intrinsics, np.ndarray]:
    """The intrinsics and the pose ``T_B_C`` (camera -> body = rectified cam0 of ``P_ref``) of a KITTI row ``P``."""
    K = P[:, :3]
    # P = K [I | t]: t = K^-1 P[:, 3] is the position of rectified cam0's origin in this camera.
    t_i = np.linalg.solve(K, P[:, 3]) - np.linalg.solve(P_ref[:, :3], P_ref[:, 3])
    T_B_C = np.eye(4)
    T_B_C[:3, 3] = -t_i
    return Intrinsics(width, height, K[0, 0], K[1, 1], K[0, 2], K[1, 2]), T_B_C


def _single_sequence(path: Path) -> Path:
    """A KITTI root (``dataset/`` with ``sequences/XX``) holding one sequence stands for that sequence."""
    sequences = path / "sequences"
    if sequences.is_dir():
        children = [c for c in sequences.iterdir() if c.is_dir()]
        if len(children) == 1:
            return children[0]
    return path


@register("kitti")
class KittiSequence(Sequence):
    """One KITTI odometry sequence folder (``.../sequences/XX``)."""

    @staticmethod
    def detect(path: Path) -> bool:
        path = _single_sequence(path)
        return path.is_dir() and (path / "calib.txt").is_file() and (path / "times.txt").is_file() and (
            (path / "image_0").is_dir() or (path / "image_2").is_dir())

    def __init__(self, path: Path, groundtruth: str | Path | None = None, cameras: str | None = None):
        super().__init__()
        self.path = _single_sequence(Path(path))
        self._name = self.path.resolve().name
        if cameras is None:
            cameras = "gray" if (self.path / "image_0").is_dir() else "color"
        if cameras not in _CAMERAS:
            raise GeviError("--cameras", f"choose gray or color, not {cameras!r}")
        left_dir, right_dir, P_left, P_right = _CAMERAS[cameras]
        self.cameras = cameras
        for folder in (left_dir, right_dir):
            if not (self.path / folder).is_dir():
                raise LayoutError(self.path, f"missing {folder}/ for the {cameras} stereo pair")
        self._stamps = read_times(self.path / "times.txt")
        names = [f"{i:06d}.png" for i in range(len(self._stamps))]
        self._left = [str(self.path / left_dir / n) for n in names]
        self._right = [str(self.path / right_dir / n) for n in names]
        have = sum(Path(p).is_file() for p in self._left[:1] + self._left[-1:])
        if have < 2:
            raise LayoutError(self.path / left_dir, f"expected {len(names)} images 000000.png..{names[-1]} (one per line of times.txt)")
        calib = read_calib(self.path / "calib.txt")
        if P_left not in calib or P_right not in calib or "P0" not in calib:
            raise DataError(self.path / "calib.txt", f"needs P0, {P_left} and {P_right}")
        probe = cv2.imread(self._left[0], cv2.IMREAD_GRAYSCALE)
        if probe is None:
            raise DataError(self._left[0], "cannot be read as an image")
        h, w = probe.shape
        (cam0, T_B_C0), (cam1, T_B_C1) = (_camera_from_P(calib[P], calib["P0"], w, h) for P in (P_left, P_right))
        self._rig = StereoRig(cam0, cam1, T_B_C0, T_B_C1)
        self._gt_override = Path(groundtruth) if groundtruth is not None else None

    def _gt_path(self) -> Path | None:
        if self._gt_override is not None:
            return self._gt_override
        seq = self.path.resolve()
        for candidate in (seq.parent.parent / "poses" / f"{seq.name}.txt", seq / "poses.txt", seq / "poses" / f"{seq.name}.txt"):
            if candidate.is_file():
                return candidate
        return None

    @cached_property
    def groundtruth(self) -> Trajectory | None:
        path = self._gt_path()
        if path is None:
            self.warnings.append(f"{self.path}: no ground truth found at ../../poses/{self.name}.txt (pass --groundtruth FILE)")
            return None
        gt = read_trajectory(path, name="groundtruth", frame="cam0")
        if gt.indexed:
            if len(gt) != len(self._stamps):
                raise DataError(path, f"has {len(gt)} poses but times.txt lists {len(self._stamps)} frames")
            gt = Trajectory(self._stamps, gt.positions, gt.quat_wxyz, frame="cam0", name="groundtruth", meta=gt.meta)
        if self.cameras == "color":
            self.warnings.append("colour cameras: ground truth is in the cam0 frame; estimates are converted with T_B_C0")
        return gt

    def read_pair(self, index: int) -> StereoFrame:
        left = cv2.imread(self._left[index], cv2.IMREAD_GRAYSCALE)
        right = cv2.imread(self._right[index], cv2.IMREAD_GRAYSCALE)
        for image, path in ((left, self._left[index]), (right, self._right[index])):
            if image is None:
                raise DataError(path, "cannot be read as an image (missing or truncated)")
        return StereoFrame(int(self._stamps[index]), left, right)
