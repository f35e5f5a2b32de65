"""The run folder: the unit ``gevi eval``, ``gevi batch`` and ``gevi regress`` read.

Layout (``results/<method>/<sequence>/<timestamp>/`` by default, ``latest`` links the newest; a
``--stride K`` run's sequence is ``<sequence>_strideK``, its frame indices count strided frames)::

    status.json            state (running / ok / lost-tracking / interrupted / crashed), the primary
                           trajectory file and its frame, lost intervals, bridged frames, version, command
    config.yaml            the effective configuration (with ``align:`` for gevi eval --align auto)
    traj_body.tum          after-BA trajectory, body frame (primary)    } streamed pose by pose as they
    traj_cam0.tum          after-BA trajectory, rectified cam0 frame    } become final, so a crash or
    traj_cam0_kitti.txt    the same as KITTI rows (KITTI sequences)     } Ctrl-C loses nothing computed
    traj_body_kitti.txt    body frame as KITTI rows (KITTI sequences; the primary there, because KITTI
                           ground truth has no stamps and is matched by frame index)
    traj_online_body.tum   the online (tracking-time) trajectory, body frame
    frames.csv             per frame: status, keyframe, matches, inliers, noise std
    timing.csv             per frame: ms per stage
    trajectory.png         a small top view: the estimate over the ground truth where there is one
    eval/                  gevi eval's report against the ground truth, when there is one

Every pose file is flushed after each row.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.trajectory import Trajectory
from gevi_cli.trajectory.formats import format_header, format_rows

PRIMARY = "traj_body.tum"
PRIMARY_KITTI = "traj_body_kitti.txt"


class PoseStream:
    """Append poses to a trajectory file, one flushed row at a time (``fmt``: tum / kitti)."""

    def __init__(self, path: Path, fmt: str, frame: str):
        self.path, self.fmt, self.frame = Path(path), fmt, frame
        self._fh = open(self.path, "w", buffering=1)
        header = format_header(fmt)
        if header:
            self._fh.write(header + "\n")
        self.count = 0

    def append(self, t_ns: int, T: np.ndarray) -> None:
        traj = Trajectory.from_matrices(np.array([t_ns]), T[None], frame=self.frame)
        self._fh.write(format_rows(traj, self.fmt)[0] + "\n")
        self._fh.flush()
        self.count += 1

    def close(self) -> None:
        if not self._fh.closed:
            os.fsync(self._fh.fileno())
            self._fh.close()


@dataclass
class RunStatus:
    """What ``status.json`` holds."""

    state: str = "running"
    method: str = ""
    sequence: str = ""
    stride: int = 1  # `gevi run --stride`: frame j of the run is frame stride * j of the sequence
    primary: str = PRIMARY
    frame: str = "body"
    frames_total: int = 0
    frames_done: int = 0
    frames_tracked: int = 0
    keyframes: int = 0
    pose_fallbacks: int = 0  # frames whose pose step started from SQPnP (coplanar points)
    # the stereo pair's disparity offset (pipelines.disparity_offset.DisparityOffset.record): the estimate with
    # its uncertainty, the value applied and from which frame, whether the run restarted; {}: self-calibration off
    disparity_offset: dict = field(default_factory=dict)
    # a run restarted with the offset: the first pass's frames and wall time (s); {}: no restart.  The rest of
    # this file, timing.csv and the trajectories describe the second pass
    first_pass: dict = field(default_factory=dict)
    # the online trajectory is causal (each pose from the frames up to it); False after a restart, whose frames
    # were re-tracked with an offset found from frames after them
    online_causal: bool = True
    lost_intervals: list = field(default_factory=list)  # {"start_s", "end_s", "frames", "first_index", "reason"}
    bridged_frames: list = field(default_factory=list)  # frame indices bridged at constant velocity
    inertial_frames: list = field(default_factory=list)  # GeVI: not tracked visually, carried by the IMU alone
    skipped_frames: list = field(default_factory=list)  # unreadable frames: {"index", "reason"}
    message: str = ""
    gevi_version: str = ""
    command: str = ""
    started: str = ""
    elapsed_s: float = 0.0
    evaluation: dict = field(default_factory=dict)
    imu: dict = field(default_factory=dict)  # stereo-inertial runs: initialisation, biases, IMU gaps


def make_run_dir(out: str | None, results_root: Path, method: str, sequence: str) -> Path:
    """``-o DIR`` or ``results/<method>/<sequence>/<timestamp>/`` with a ``latest`` link next to it."""
    if out:
        d = Path(out)
        d.mkdir(parents=True, exist_ok=True)
        return d
    base = results_root / method / sequence
    base.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    d, k = base / stamp, 1
    while d.exists():
        k += 1
        d = base / f"{stamp}-{k}"
    d.mkdir()
    latest = base / "latest"
    try:
        if latest.is_symlink() or latest.exists():
            latest.unlink()
        latest.symlink_to(d.name)
    except OSError:  # filesystems without symlinks: the timestamped folder is still complete
        pass
    return d


def write_status(run_dir: Path, status: RunStatus) -> None:
    tmp = run_dir / "status.json.tmp"
    tmp.write_text(json.dumps(status.__dict__, indent=2, default=str) + "\n")
    os.replace(tmp, run_dir / "status.json")


def read_status(run_dir: Path) -> dict | None:
    p = Path(run_dir) / "status.json"
    if not p.is_file():
        return None
    try:
        data = json.loads(p.read_text())
    except ValueError:
        return None
    return data if isinstance(data, dict) else None


TRAJECTORY_PNG = "trajectory.png"


def run_world(status: RunStatus, kind: str | None) -> str | None:
    """The world of the run's body trajectory (a key of :data:`gevi_cli.evaluation.plots.WORLDS`, or None).

    GeVI's world is gravity-aligned, z up, once its stereo-IMU initialisation happened (before, it is
    the first cam0 frame).  A stereo odometry's (CFO) is the first body frame: on KITTI the body is cam0,
    a level car camera (x right, y down, z forward); elsewhere its attitude is unknown.
    """
    if status.method == "gevi":
        return "z-up" if (status.imu or {}).get("initialised", True) else "camera"
    return "camera-level" if kind in ("kitti", "ov2slam-tracks") else None


def write_trajectory_png(run_dir: Path, status: RunStatus, kind: str | None, pair=None) -> Path | None:
    """``trajectory.png``: a small top view of the run (metres), in the plane perpendicular to gravity
    where the world is known to be gravity-aligned.  ``pair``: the evaluation's PairResult, whose
    aligned estimate is drawn over the matched ground truth in the ground truth's world; without one,
    the primary trajectory alone in the run's world.  None when the run wrote no pose.  Cost
    (scripts/bench_run_png.py): 40-70 ms to draw, plus 0.3 s importing matplotlib where the run has
    not (a CFO run; GeVI's imu_states.png imports it anyway)."""
    from gevi_cli.evaluation.plots import plot_run_trajectory, world_of
    from gevi_cli.trajectory import read_trajectory

    run_dir = Path(run_dir)
    title = f"{status.method} on {status.sequence}"
    if pair is not None and getattr(pair, "aligned", None) is not None:
        gt = pair.association.gt
        return plot_run_trajectory(run_dir / TRAJECTORY_PNG, pair.aligned.positions, gt.positions, world_of(gt),
                                   f"{title} ({pair.align}-aligned) over ground truth")
    try:
        est = read_trajectory(run_dir / status.primary, frame="body")
    except GeviError:  # no or an unreadable primary: no picture (status.json says why)
        return None
    if len(est) == 0:
        return None
    return plot_run_trajectory(run_dir / TRAJECTORY_PNG, est.positions, None, run_world(status, kind), title)
