"""Where a run's output goes as the driver makes it: the run folder's files, or memory.

The driver (:mod:`gevi_cli.run.driver`) hands every sink the same events, in order: a final pose
(``final``: rectified cam0 and body pose of a frame whose pose will not change any more), an online
pose (``online``: body pose as known when tracked), a frame's outcome (``frame``), the status now and
then (``status``), and ``close`` once.  ``restart``: the run begins again from its first frame (the driver's
restart with a self-calibrated stereo pair); what was handed on so far is superseded.  Stamps in ns; poses 4x4, world frame of the odometry.
"""
from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.pipelines.types import FrameResult
from gevi_cli.run.folder import PoseStream, RunStatus, write_status
from gevi_cli.trajectory import Trajectory

#: per-frame stages (ms in timing.csv); the front-end sub-stages are part of "frontend" and "keyframe".
STAGES = ("read", "frontend", "fe_rectify", "fe_pyramid", "fe_derotate", "fe_lk", "fe_affine", "fe_detect", "fe_stereo",
          "fe_reacquire", "verify", "noise", "pose", "keyframe", "ba")

#: frames.csv columns
FRAME_COLUMNS = ("index", "t_ns", "status", "keyframe", "matches", "inliers", "sigma_px", "kf_trigger", "message")


class RunSink(Protocol):
    def final(self, t_ns: int, T_cam0: np.ndarray, T_body: np.ndarray) -> None: ...

    def online(self, t_ns: int, T_body: np.ndarray) -> None: ...

    def frame(self, index: int, res: FrameResult, total_s: float) -> None: ...

    def status(self, status: RunStatus) -> None: ...

    def restart(self) -> None: ...

    def close(self, status: RunStatus) -> None: ...


SINK_METHODS = ("final", "online", "frame", "status", "restart", "close")


def check_sink(sink) -> None:
    """A sink handed to a run has every :class:`RunSink` method (a restart calls ``restart``, on data where the
    disparity offset is found): a one-line GeviError before the first frame, not an AttributeError mid-run."""
    missing = [m for m in SINK_METHODS if not callable(getattr(sink, m, None))]
    if missing:
        raise GeviError("sinks", f"{type(sink).__name__} lacks {', '.join(missing)} (a RunSink has "
                                 f"{', '.join(SINK_METHODS)})")


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.9g}"
    return str(v)


class FolderSink:
    """The run folder's streamed files (:mod:`gevi_cli.run.folder`): every row flushed when written, so a
    crash or Ctrl-C loses nothing computed.  ``state_columns``: the odometry's per-frame state columns
    (``res.extra``), written to ``state_file``."""

    def __init__(self, run_dir: Path, kitti_rows: bool, state_columns=None, state_file: str = "states.csv"):
        self.run_dir = Path(run_dir)
        self._kitti_rows, self._state_file = kitti_rows, state_file
        self._state_cols = list(state_columns) if state_columns else None
        self._open()

    def _open(self):
        """(Re)create the streamed files, each with its header only."""
        kitti_rows, state_file = self._kitti_rows, self._state_file
        self._online = PoseStream(self.run_dir / "traj_online_body.tum", "tum", "body")
        self._finals = [PoseStream(self.run_dir / "traj_body.tum", "tum", "body"),
                        PoseStream(self.run_dir / "traj_cam0.tum", "tum", "cam0")]
        if kitti_rows:
            self._finals += [PoseStream(self.run_dir / "traj_cam0_kitti.txt", "kitti", "cam0"),
                             PoseStream(self.run_dir / "traj_body_kitti.txt", "kitti", "body")]
        self._timing = open(self.run_dir / "timing.csv", "w", buffering=1)
        self._timing.write("index,t_ns,total_ms," + ",".join(f"{s}_ms" for s in STAGES) + "\n")
        self._frames = open(self.run_dir / "frames.csv", "w", buffering=1)
        self._frames.write(",".join(FRAME_COLUMNS) + "\n")
        self._states = None
        if self._state_cols:
            self._states = open(self.run_dir / state_file, "w", buffering=1)
            self._states.write(",".join(self._state_cols) + "\n")

    def final(self, t_ns, T_cam0, T_body):
        poses = {"cam0": T_cam0, "body": T_body}
        for stream in self._finals:
            stream.append(t_ns, poses[stream.frame])

    def online(self, t_ns, T_body):
        self._online.append(t_ns, T_body)

    def frame(self, index, res, total_s):
        self._timing.write(f"{index},{res.t_ns},{total_s * 1e3:.3f}," + ",".join(
            f"{res.timings.get(s, 0.0) * 1e3:.3f}" for s in STAGES) + "\n")
        msg = res.message.replace(",", ";").replace("\n", " ")
        self._frames.write(f"{index},{res.t_ns},{res.status},{int(res.keyframe)},{res.n_matches},{res.n_inliers},"
                           f"{res.sigma_px:.4f},{res.kf_trigger},{msg}\n")
        if self._states is not None and res.extra:
            self._states.write(",".join(_fmt(res.extra.get(c, "")) for c in self._state_cols) + "\n")

    def status(self, status):
        write_status(self.run_dir, status)

    def restart(self):
        self._close_files()
        self._open()

    def _close_files(self):
        for stream in [self._online] + self._finals:
            stream.close()
        for fh in (self._timing, self._frames, self._states):
            if fh is not None:
                fh.close()

    def close(self, status):
        self._close_files()
        write_status(self.run_dir, status)


class MemorySink:
    """The same output kept in memory (:func:`gevi_cli.api.run`)."""

    def __init__(self):
        self.restart()

    def restart(self):
        self.final_rows: list[tuple[int, np.ndarray, np.ndarray]] = []
        self.online_rows: list[tuple[int, np.ndarray]] = []
        self.frame_rows: list[tuple] = []
        self.timing_rows: list[tuple] = []
        self.state_rows: list[dict] = []

    def final(self, t_ns, T_cam0, T_body):
        self.final_rows.append((int(t_ns), np.array(T_cam0, dtype=float), np.array(T_body, dtype=float)))

    def online(self, t_ns, T_body):
        self.online_rows.append((int(t_ns), np.array(T_body, dtype=float)))

    def frame(self, index, res, total_s):
        self.frame_rows.append((index, res.t_ns, res.status, int(res.keyframe), res.n_matches, res.n_inliers,
                                res.sigma_px, res.kf_trigger, res.message))
        self.timing_rows.append((index, res.t_ns, total_s * 1e3) + tuple(res.timings.get(s, 0.0) * 1e3 for s in STAGES))
        if res.extra:
            self.state_rows.append(dict(res.extra))

    def status(self, status):
        pass

    def close(self, status):
        pass

    def trajectory(self, frame: str = "body") -> Trajectory:
        """The final poses (``frame`` "body" or "cam0"), in stamp order."""
        return _trajectory(self.final_rows, 2 if frame == "body" else 1, frame)

    def online_trajectory(self) -> Trajectory:
        """The online (as tracked) body poses, in stamp order."""
        return _trajectory(self.online_rows, 1, "body")


def _trajectory(rows, k: int, frame: str) -> Trajectory:
    rows = sorted(rows, key=lambda r: r[0])
    t = np.array([r[0] for r in rows], dtype=np.int64)
    return Trajectory.from_matrices(t, np.array([r[k] for r in rows]).reshape(-1, 4, 4), frame=frame)
