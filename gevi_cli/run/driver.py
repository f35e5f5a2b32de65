"""The run driver: sequence -> odometry -> run folder (streamed), timing, progress, status.

The odometry objects hold state only; this module owns I/O, clocks, the progress bar and the files
(see :mod:`gevi_cli.run.folder`).  Poses are written the moment they are final, so an interrupted or
crashed run leaves every pose it computed on disk, and ``status.json`` says how the run ended.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gevi_cli.errors import DataError
from gevi_cli.geometry import invert_pose
from gevi_cli.pipelines.types import BRIDGED, INERTIAL
from gevi_cli.run.folder import PoseStream, RunStatus, write_status

#: timing.csv columns (ms); the front-end sub-stages are part of "frontend" and "keyframe".
STAGES = ("read", "frontend", "fe_rectify", "fe_pyramid", "fe_derotate", "fe_lk", "fe_affine", "fe_detect", "fe_stereo", "fe_reacquire", "verify", "noise", "pose",
          "keyframe", "ba")


@dataclass
class RunOutcome:
    status: RunStatus
    exit_code: int  # 0 complete, 3 tracking lost on the way


def _read(source, i: int):
    try:
        return i, source._read_pair(i)
    except DataError as err:
        return i, err


def _frames(source, start: int, stop: int):
    """(index, frame or DataError) for indices start..stop-1; unreadable images do not stop a run.

    Image sequences are read one frame ahead in a thread: image decoding releases the GIL, so on a
    multi-core machine reading overlaps with tracking (the frames and their order are unchanged).
    """
    if hasattr(source, "_read_pair"):
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="gevi-read") as pool:
            ahead = pool.submit(_read, source, start) if start < stop else None
            for i in range(start, stop):
                item = ahead.result()
                ahead = pool.submit(_read, source, i + 1) if i + 1 < stop else None
                yield item
    else:
        for f in source.frames(start, stop):
            yield f.index, f


def run_odometry(source, odometry, run_dir: Path, status: RunStatus, *, T_B_C0: np.ndarray, start: int, stop: int,
                 kitti_rows: bool, progress: bool = True, warn=print) -> RunOutcome:
    """Track frames ``start:stop`` of ``source`` and stream the run folder ``run_dir``."""
    from tqdm import tqdm

    run_dir = Path(run_dir)
    # the world of a stereo odometry is its first cam0 (body trajectory: relative to the first body pose,
    # T_B0_B = T_BC T_C0_C T_CB); a stereo-inertial one has its own gravity-aligned world (T_W_B = T_W_C T_CB)
    T_C_B = invert_pose(T_B_C0)
    T_B_C = T_B_C0 if getattr(odometry, "world_is_cam0", True) else np.eye(4)
    online = PoseStream(run_dir / "traj_online_body.tum", "tum", "body")
    # the final (after-BA) poses go to every one of these; the frame decides body or cam0 poses
    finals = [PoseStream(run_dir / "traj_body.tum", "tum", "body"), PoseStream(run_dir / "traj_cam0.tum", "tum", "cam0")]
    if kitti_rows:
        finals += [PoseStream(run_dir / "traj_cam0_kitti.txt", "kitti", "cam0"),
                   PoseStream(run_dir / "traj_body_kitti.txt", "kitti", "body")]
    timing = open(run_dir / "timing.csv", "w", buffering=1)
    timing.write("index,t_ns,total_ms," + ",".join(f"{s}_ms" for s in STAGES) + "\n")
    frames_csv = open(run_dir / "frames.csv", "w", buffering=1)
    frames_csv.write("index,t_ns,status,keyframe,matches,inliers,sigma_px,message\n")
    state_cols = getattr(odometry, "state_columns", None)
    states_csv = None
    if state_cols:
        states_csv = open(run_dir / getattr(odometry, "state_file", "states.csv"), "w", buffering=1)
        states_csv.write(",".join(state_cols) + "\n")
    stamps: dict[int, int] = {}
    status.frames_total = stop - start
    t_run = time.perf_counter()
    lost_open = None

    def emit_final(items):
        for idx, T_w_c in items:
            poses = {"cam0": T_w_c, "body": T_B_C @ T_w_c @ T_C_B}
            for stream in finals:
                stream.append(stamps[idx], poses[stream.frame])

    def emit_online(items):
        for idx, T_w_c in items:
            online.append(stamps[idx], T_B_C @ T_w_c @ T_C_B)

    def flush(closing_ba: bool = False):
        """What the odometry still holds, written: pending poses made final, held online poses."""
        emit_final(odometry.finish(closing_ba=closing_ba))
        emit_online(odometry.release_online())

    def close_lost(end_t):
        nonlocal lost_open
        if lost_open is not None:
            i0, t0, reason, n = lost_open
            status.lost_intervals.append({"first_index": i0, "start_s": t0 * 1e-9, "end_s": end_t * 1e-9,
                                          "frames": n, "reason": reason})
            lost_open = None

    bar = tqdm(total=stop - start, unit="frame", disable=not progress, dynamic_ncols=True, leave=False)
    write_status(run_dir, status)
    try:
        frames = _frames(source, start, stop)
        while True:
            t_read = time.perf_counter()
            item = next(frames, None)
            if item is None:
                break
            index, frame = item
            t_read = time.perf_counter() - t_read
            if isinstance(frame, DataError):
                status.skipped_frames.append({"index": index, "reason": frame.one_line()})
                warn(f"frame {index} skipped: {frame.one_line()}")
                bar.update(1)
                continue
            t0 = time.perf_counter()
            res = odometry.track(frame)
            res.timings["read"] = t_read
            total = time.perf_counter() - t0 + t_read
            stamps[res.index] = res.t_ns
            emit_online(res.online if res.online is not None else [(res.index, res.T_w_c)])
            emit_final(res.final)
            timing.write(f"{index},{res.t_ns},{total * 1e3:.3f}," + ",".join(
                f"{res.timings.get(s, 0.0) * 1e3:.3f}" for s in STAGES) + "\n")
            msg = res.message.replace(",", ";").replace("\n", " ")
            frames_csv.write(f"{index},{res.t_ns},{res.status},{int(res.keyframe)},{res.n_matches},{res.n_inliers},"
                             f"{res.sigma_px:.4f},{msg}\n")
            if states_csv is not None and res.extra:
                states_csv.write(",".join(_fmt(res.extra.get(c, "")) for c in state_cols) + "\n")
            status.frames_done += 1
            status.keyframes += int(res.keyframe)
            if res.status == BRIDGED:
                status.bridged_frames.append(index)
                if lost_open is None:
                    lost_open = [index, res.t_ns, res.message, 0]
                lost_open[3] += 1
            else:
                status.frames_tracked += 1
                if res.status == INERTIAL:
                    status.inertial_frames.append(index)
                close_lost(res.t_ns)
            bar.update(1)
            if progress and status.frames_done % 10 == 0:
                bar.set_postfix_str(f"kf {status.keyframes} inl {res.n_inliers}")
            if status.frames_done % 50 == 0:
                status.elapsed_s = time.perf_counter() - t_run
                write_status(run_dir, status)
        if lost_open is not None:
            close_lost(max(stamps.values()) if stamps else 0)
        flush(closing_ba=True)
        status.state = "lost-tracking" if status.lost_intervals else "ok"
        if status.lost_intervals:
            status.message = (f"tracking lost {len(status.lost_intervals)} time(s); {len(status.bridged_frames)} "
                              "frame(s) bridged at constant velocity")
        elif status.frames_done < 2:
            status.state, status.message = "lost-tracking", f"only {status.frames_done} frame(s) could be read"
    except KeyboardInterrupt:
        flush()
        status.state, status.message = "interrupted", f"interrupted after {status.frames_done} frames"
        raise
    except Exception as exc:
        try:
            flush()
        except Exception:  # the state may be what broke; what was final is already on disk
            pass
        status.state, status.message = "crashed", f"{type(exc).__name__}: {exc}"
        raise
    finally:
        bar.close()
        for stream in [online] + finals:
            stream.close()
        timing.close()
        frames_csv.close()
        if states_csv is not None:
            states_csv.close()
        if hasattr(odometry, "summary"):
            status.imu = odometry.summary()
        status.elapsed_s = time.perf_counter() - t_run
        status.pose_fallbacks = int(getattr(odometry, "fallbacks", 0))
        write_status(run_dir, status)
    return RunOutcome(status, 0 if status.state == "ok" else 3)


def _fmt(v) -> str:
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.9g}"
    return str(v)
