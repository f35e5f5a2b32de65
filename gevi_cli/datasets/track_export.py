"""OV2SLAM track exports: real front-end tracks and keyframe stereo matches, without images.

The CurrentFeature Odometry authors (Bias-Eliminated PnP, RA-L 2025) exported OV2SLAM's front end on
KITTI so that a back end can run without images.  An export is one folder holding

* ``ov2slam_pnp_data_seq*.txt``: per-frame tracks, **8 lines per frame**: left x, left y (pixels),
  X, Y, Z of the OV2SLAM map point (world; not used), scale (pyramid level), point id, outlier flag
  (0 = inlier as judged by OV2SLAM).  The 8 lines of a block have the same length.  Block k (0-based)
  is frame k+1: frame 0 has no block, it is the first keyframe.
* ``ov2slam_stereo_matches.txt``: keyframe stereo matches, **6 lines per keyframe**: keyframe frame
  index (one number), left x, left y, right x, right y (pixels), point ids (the ids of the tracks).

A frame's tracks are matched to the latest keyframe's stereo matches by id.  The export carries no
calibration: it comes from a KITTI ``calib.txt`` (``--calib FILE``) and the image size from
``image_size`` (default 1226x370, KITTI odometry sequences 04-10).  Frames are stamped at the
nominal KITTI rate (frame index times :data:`KITTI_NOMINAL_PERIOD_NS`, 10 Hz).

A :class:`TrackExport` is not an image :class:`~gevi_cli.datasets.sequence.Sequence` (its frames
hold observations, not images), so it is not in the dataset registry: open it with
:func:`open_track_export` and feed its :class:`TrackFrame` s to a back end through
:class:`gevi_cli.frontend.export.ExportFrontEnd`.

>>> export = open_track_export("ov2slam_data_kitti_04_gray", calib="gray_calib.txt")
>>> for frame in export.frames(): ...        # TrackFrame(index, t_ns, obs, outlier, stereo)
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Iterator

import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.kitti import read_calib
from gevi_cli.errors import DataError, GeviError, LayoutError
from gevi_cli.observations import FeatureObs, RectifiedStereo, StereoObs
from gevi_cli.trajectory import Trajectory, read_trajectory
from gevi_cli.trajectory.formats import read_text
from gevi_cli.trajectory.trajectory import KITTI_NOMINAL_PERIOD_NS

TRACKS_GLOB = "ov2slam_pnp_data_seq*.txt"
STEREO_NAME = "ov2slam_stereo_matches.txt"
#: Image size of KITTI odometry sequences 04-10 (00-02 are 1241x376, 03 is 1242x375).
KITTI_04_IMAGE_SIZE = (1226, 370)

_TRACK_LINES = ("left x", "left y", "map point X", "map point Y", "map point Z", "scale", "point id", "outlier flag")
_STEREO_LINES = ("keyframe id", "left x", "left y", "right x", "right y", "point id")


@dataclass(frozen=True)
class TrackFrame:
    """One frame of a track export.

    ``obs``: the tracked left-image features (ids int64, uv pixels); for frame 0 (no track block) the
    left points of its stereo matches.  ``outlier``: (n,) bool, OV2SLAM's outlier flag != 0 (all
    False for frame 0).  ``stereo``: the exported keyframe stereo matches when this frame is a
    keyframe of the export, else None.
    """

    index: int
    t_ns: int
    obs: FeatureObs
    outlier: np.ndarray
    stereo: StereoObs | None



def detect(path: str | Path) -> bool:
    """True for a folder holding ``ov2slam_pnp_data_seq*.txt`` and ``ov2slam_stereo_matches.txt``."""
    path = Path(path)
    return path.is_dir() and (path / STEREO_NAME).is_file() and any(p.is_file() for p in path.glob(TRACKS_GLOB))


# ----------------------------------------------------------------------------------------- parsing
def _read_rows(path: Path, lines_per_block: int, what: tuple[str, ...]) -> list[np.ndarray]:
    """Every line of ``path`` as a float64 array (blank trailing lines dropped), count checked."""
    text = read_text(path)  # UTF-8 (a BOM dropped); binary content is a DataError naming the file
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines:
        raise DataError(path, "is empty")
    if len(lines) % lines_per_block:
        raise DataError(f"{path}:{len(lines)}",
                        f"{len(lines)} lines is not a multiple of {lines_per_block} ({lines_per_block} lines per block: "
                        f"{', '.join(what)}); the file is truncated or has extra lines")
    rows = []
    for lineno, line in enumerate(lines, start=1):
        tokens = line.split()
        try:
            rows.append(np.array(tokens, dtype=np.float64))
        except ValueError:
            col, bad = next(((i, t) for i, t in enumerate(tokens, start=1) if not _is_float(t)), (1, tokens[0]))
            raise DataError(f"{path}:{lineno}",
                            f"value {col} {bad[:20]!r} is not a number (line {(lineno - 1) % lines_per_block + 1} of "
                            f"its block: {what[(lineno - 1) % lines_per_block]})") from None
    return rows


def _is_float(token: str) -> bool:
    try:
        float(token)
        return True
    except ValueError:
        return False


def _check_block(path: Path, first_line: int, block: list[np.ndarray], what: tuple[str, ...], skip: int = 0) -> int:
    """All lines of a block from ``skip`` on have the same length; returns it."""
    n = block[skip].size
    for j in range(skip + 1, len(block)):
        if block[j].size != n:
            raise DataError(f"{path}:{first_line + j}",
                            f"has {block[j].size} values but line {first_line + skip} of the same block has {n} "
                            f"(every line of a block lists the same points; this one is the {what[j]} line)")
    return n


def _finite(path: Path, first_line: int, block: list[np.ndarray], lines: tuple[int, ...], what: tuple[str, ...]):
    for j in lines:
        if not np.isfinite(block[j]).all():
            raise DataError(f"{path}:{first_line + j}", f"holds a non-finite {what[j]} value (nan or inf)")


def _ids(path: Path, lineno: int, values: np.ndarray) -> np.ndarray:
    if not np.isfinite(values).all() or (np.round(values) != values).any() or (np.abs(values) > 2.0**53).any():
        raise DataError(f"{path}:{lineno}", "point ids must be whole numbers (below 2^53)")
    ids = values.astype(np.int64)
    if len(np.unique(ids)) != len(ids):
        raise DataError(f"{path}:{lineno}", "lists a point id twice (ids must be unique within a frame)")
    return ids


def _read_tracks(path: Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    rows = _read_rows(path, 8, _TRACK_LINES)
    blocks = []
    for b in range(0, len(rows), 8):
        block, first = rows[b:b + 8], b + 1
        _check_block(path, first, block, _TRACK_LINES)
        _finite(path, first, block, (0, 1, 7), _TRACK_LINES)
        ids = _ids(path, first + 6, block[6])
        blocks.append((ids, np.column_stack([block[0], block[1]]), block[7] != 0))
    return blocks


def _read_stereo(path: Path, n_frames: int) -> dict[int, StereoObs]:
    rows = _read_rows(path, 6, _STEREO_LINES)
    out: dict[int, StereoObs] = {}
    last = -1
    for b in range(0, len(rows), 6):
        block, first = rows[b:b + 6], b + 1
        head = block[0]
        if head.size != 1 or not np.isfinite(head[0]) or head[0] != np.round(head[0]):
            raise DataError(f"{path}:{first}", f"the first line of a keyframe block must hold one frame index, "
                                               f"found {head.size} value(s)")
        kf = int(head[0])
        if kf <= last:
            raise DataError(f"{path}:{first}", f"keyframe {kf} is not after the previous keyframe {last} "
                                               f"(keyframe indices must increase)")
        if not 0 <= kf < n_frames:
            raise DataError(f"{path}:{first}", f"keyframe {kf} is outside the {n_frames} frames of the tracks file "
                                               f"(frames 0..{n_frames - 1})")
        _check_block(path, first, block, _STEREO_LINES, skip=1)
        _finite(path, first, block, (1, 2, 3, 4), _STEREO_LINES)
        ids = _ids(path, first + 5, block[5])
        out[kf] = StereoObs(ids, np.column_stack([block[1], block[2]]), np.column_stack([block[3], block[4]]))
        last = kf
    return out


# ----------------------------------------------------------------------------------------- camera
def camera_from_calib(calib: str | Path, colour: bool, image_size: tuple[int, int] = KITTI_04_IMAGE_SIZE,
                      warnings: list[str] | None = None) -> tuple[RectifiedStereo, tuple[str, str]]:
    """The rectified rig of a KITTI ``calib.txt`` and the rows ``(P_left, P_right)`` it came from.

    P2/P3 when ``colour`` and the file has both, else P0/P1 (a colour request without P2/P3 is noted
    in ``warnings``); P0 is always needed, it defines the body frame.

    KITTI writes ``P_i = K [I | t_i]`` with ``t_i = K^-1 P_i[:, 3]`` the position of cam0's origin in
    camera i's coordinates: ``X_ci = X_c0 + t_i``, i.e. ``T_Ci_C0 = [I | t_i]``.  The body frame of
    KITTI is cam0, so the left camera's pose in the body frame is ``T_B_C0 = inv(T_Cl_C0) = [I | -t_l]``.

    Numbers of ``cfo_kitti04/calib``: fx = 707.0912; colour ``P2[0, 3] = 46.88015`` px, so
    ``t_2 = (46.88015 / 707.0912, 0, 0) = (0.0663, 0, 0)`` m (the authors' ``T_20``) and
    ``T_B_C0`` translation = (-0.0663, 0, 0): cam2 sits 6.63 cm to the left (-x) of cam0.
    ``P3[0, 3] = -337.2825`` px gives the baseline ``(P2[0, 3] - P3[0, 3]) / fx = 0.5433`` m.  Gray:
    ``P1[0, 3] = -379.8145`` px, baseline 0.537150653 m, ``T_B_C0 = I``.
    """
    calib = Path(calib)
    if not calib.is_file():
        raise GeviError(calib, "no such calib file (pass a KITTI calib.txt with --calib FILE)")
    P = read_calib(calib)
    has_colour = "P2" in P and "P3" in P
    left, right = ("P2", "P3") if colour and has_colour else ("P0", "P1")
    if colour and not has_colour and warnings is not None:
        warnings.append(f"{calib}: no P2/P3 rows for this colour export; using the gray pair P0/P1")
    missing = [k for k in ("P0", left, right) if k not in P]
    if missing:
        raise DataError(calib, f"has no {', '.join(missing)} row(s); a KITTI calib.txt needs P0 and P1 "
                               f"(gray) or P0, P2 and P3 (colour), 12 numbers each")
    Pl, Pr = P[left], P[right]
    K = Pl[:, :3]
    if not np.allclose(Pr[:, :3], K, rtol=1e-6, atol=1e-6) or abs(K[0, 1]) > 1e-9 or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise DataError(calib, f"{left} and {right} are not a rectified pair (their K = P[:, :3] differ or are not pinhole)")
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    baseline = float((Pl[0, 3] - Pr[0, 3]) / fx)
    if baseline <= 0:
        raise DataError(calib, f"{right} is not to the right of {left} (baseline {baseline:.4f} m from P[0, 3] / fx)")
    t_l = np.linalg.solve(K, Pl[:, 3]) - np.linalg.solve(P["P0"][:, :3], P["P0"][:, 3])
    T_B_C0 = np.eye(4)
    T_B_C0[:3, 3] = 0.0 - t_l  # (no -0.0 for the gray pair)
    w, h = image_size
    return RectifiedStereo(Intrinsics(w, h, fx, fy, cx, cy), baseline, T_B_C0), (left, right)


# ----------------------------------------------------------------------------------------- reader
class TrackExport:
    """An OV2SLAM track export folder with its KITTI calibration (see the module docstring).

    ``name`` is the folder name; a ``_gray`` suffix means the grayscale pair (P0/P1), no suffix the
    colour pair (P2/P3 when the calib file has them).  ``groundtruth`` is a KITTI pose file of cam0
    (frame "cam0", indexed).  Colour exports estimate the cam2 trajectory; the CurrentFeature authors
    compare colour estimates with the cam0 ground truth *as they are* (ignoring the 6.63 cm cam2-cam0
    offset), while ``camera.T_B_C0`` holds that offset for an exact comparison.
    """

    kind = "ov2slam-tracks"

    @staticmethod
    def detect(path: str | Path) -> bool:
        return detect(path)

    def __init__(self, path: str | Path, calib: str | Path, groundtruth: str | Path | None = None,
                 image_size: tuple[int, int] = KITTI_04_IMAGE_SIZE):
        t0 = time.perf_counter()
        self.path = Path(path)
        self.warnings: list[str] = []
        self.imu_time_offset_s = 0.0  # no IMU
        if not self.path.is_dir():
            raise GeviError(self.path, "no such folder (expected an OV2SLAM track export folder)")
        tracks = sorted(p for p in self.path.glob(TRACKS_GLOB) if p.is_file())
        if not tracks:
            raise LayoutError(self.path, f"missing {TRACKS_GLOB} (the per-frame tracks of an OV2SLAM export)")
        if len(tracks) > 1:
            raise LayoutError(self.path, f"holds {len(tracks)} track files ({', '.join(p.name for p in tracks)}); "
                                         "expected one per export folder")
        self.tracks_path = tracks[0]
        self.stereo_path = self.path / STEREO_NAME
        if not self.stereo_path.is_file():
            raise LayoutError(self.path, f"missing {STEREO_NAME} (the keyframe stereo matches of an OV2SLAM export)")
        self.name = self.path.resolve().name
        self.calib_path = self.calibration_file = Path(calib)
        #: the rectified rig; ``pair`` names the calib rows it came from ("P0", "P1") or ("P2", "P3")
        self.camera, self.pair = camera_from_calib(self.calib_path, not self.name.endswith("_gray"), image_size,
                                                   self.warnings)
        #: True when the colour pair (cam2 left) is used
        self.colour = self.pair == ("P2", "P3")

        self._tracks = _read_tracks(self.tracks_path)
        n = len(self._tracks) + 1
        self._stereo = _read_stereo(self.stereo_path, n)
        if 0 not in self._stereo:
            raise DataError(self.stereo_path, "has no stereo matches for frame 0, the first keyframe of an export "
                                              "(its tracks file starts at frame 1)")
        self._stamps = np.arange(n, dtype=np.int64) * KITTI_NOMINAL_PERIOD_NS
        self._gt_path = Path(groundtruth) if groundtruth is not None else None
        w, h = self.camera.width, self.camera.height
        uv = np.concatenate([b[1] for b in self._tracks] + [s.uv_left for s in self._stereo.values()])
        outside = int(((uv[:, 0] < -0.5) | (uv[:, 0] > w - 0.5) | (uv[:, 1] < -0.5) | (uv[:, 1] > h - 0.5)).sum())
        if outside:
            self.warnings.append(f"{self.path}: {outside} observation(s) fall outside the {w}x{h} image "
                                 "(pass the sequence's image_size)")
        self.read_seconds = time.perf_counter() - t0

    # -------------------------------------------------------------------------------- metadata
    def __len__(self) -> int:
        return len(self._stamps)

    def __repr__(self) -> str:
        return (f"TrackExport({self.name!r}, {len(self)} frames, {len(self._stereo)} keyframes, "
                f"{'colour' if self.colour else 'gray'}, baseline {self.camera.baseline:.4f} m)")

    @property
    def stamps_ns(self) -> np.ndarray:
        """(n,) int64 nominal stamps: frame index times 0.1 s (the export has no times)."""
        return self._stamps

    @property
    def keyframe_ids(self) -> np.ndarray:
        """Frame indices of the exported keyframes, increasing (the first is 0)."""
        return np.array(sorted(self._stereo), dtype=np.int64)

    @property
    def imu(self) -> None:
        return None

    @cached_property
    def groundtruth(self) -> Trajectory | None:
        """The ``groundtruth`` file as cam0 poses on the export's stamps, or None when none was given."""
        if self._gt_path is None:
            return None
        gt = read_trajectory(self._gt_path, name="groundtruth", frame="cam0")
        if gt.indexed:
            if len(gt) != len(self):
                raise DataError(self._gt_path, f"has {len(gt)} poses but the export {self.name} has {len(self)} frames")
            gt = Trajectory(self._stamps, gt.positions, gt.quat_wxyz, frame="cam0", indexed=True, name="groundtruth",
                            meta=gt.meta)
        if self.colour:
            self.warnings.append("colour cameras: the ground truth is in the cam0 frame, the estimates in cam2 "
                                 "(the CurrentFeature authors compare them as they are)")
        return gt

    # -------------------------------------------------------------------------------- frames
    def frame(self, index: int) -> TrackFrame:
        """Frame ``index`` (0 <= index < len(self))."""
        if not 0 <= index < len(self):
            raise IndexError(f"frame {index} is outside 0..{len(self) - 1}")
        stereo = self._stereo.get(index)
        if index == 0:
            obs = FeatureObs(stereo.ids, stereo.uv_left)
            outlier = np.zeros(len(stereo), dtype=bool)
        else:
            ids, uv, outlier = self._tracks[index - 1]
            obs = FeatureObs(ids, uv)
        return TrackFrame(index, int(self._stamps[index]), obs, outlier, stereo)

    def frames(self, start: int | None = None, stop: int | None = None, step: int = 1) -> Iterator[TrackFrame]:
        """Iterate frames ``start:stop:step``."""
        for index in range(*slice(start, stop, step).indices(len(self))):
            yield self.frame(index)


def open_track_export(path: str | Path, calib: str | Path | None, groundtruth: str | Path | None = None,
                      **options) -> TrackExport:
    """Open an OV2SLAM track export; ``calib`` (a KITTI calib.txt) is required, the export has none."""
    path = Path(path)
    if not path.exists():
        raise GeviError(path, "no such file or folder")
    if not detect(path):
        raise LayoutError(path, f"not an OV2SLAM track export: expected a folder with {TRACKS_GLOB} and {STEREO_NAME}")
    if calib is None:
        raise LayoutError(path, "needs --calib FILE (a KITTI calib.txt): the track export holds no calibration")
    return TrackExport(path, calib, groundtruth=groundtruth, **options)


__all__ = ["TrackExport", "TrackFrame", "detect", "open_track_export", "camera_from_calib", "KITTI_04_IMAGE_SIZE"]
