"""The run driver: sequence -> odometry -> sinks (the run folder, memory), timing, progress, status.

The odometry objects hold state only; this module owns the reading, the clocks and the progress bar,
and hands each pose the odometry releases (its PoseEvents, :mod:`gevi_cli.pipelines.types`) to the
sinks (:mod:`gevi_cli.run.sinks`) the moment it is released, so an interrupted or crashed run leaves
every pose it computed in its folder, and ``status.json`` says how it ended.

When the odometry's stereo self-calibration first finds the pair's disparity offset
(:mod:`gevi_cli.pipelines.disparity_offset`), every keyframe so far was made without it: the driver
restarts the run once from its first frame with a fresh odometry (``rebuild``) carrying the estimate, and
the sinks start over (``restart``), so the run's output is made with one calibration throughout.  The
restart happens only within the first keyframes (:data:`~gevi_cli.pipelines.disparity_offset.RESTART_MAX_KEYFRAMES`);
an offset found later applies from the next keyframe on.  ``status.json`` then describes the second pass
(``elapsed_s`` and frames as in ``timing.csv``), with the first pass's frames and time in ``first_pass``.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from gevi_cli.errors import DataError
from gevi_cli.pipelines.types import BRIDGED, FINAL, INERTIAL, Odometry
from gevi_cli.run.folder import RunStatus


@dataclass
class RunOutcome:
    status: RunStatus
    exit_code: int  # 0 complete, 3 tracking lost on the way


def _read(source, i: int):
    try:
        return i, source.read_pair(i)
    except DataError as err:
        return i, err


def _frames(source, start: int, stop: int):
    """(index, frame or DataError) for indices start..stop-1; unreadable images do not stop a run.

    Image sequences are read one frame ahead in a thread: image decoding releases the GIL, so on a
    multi-core machine reading overlaps with tracking (the frames and their order are unchanged).
    """
    if hasattr(source, "read_pair"):
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


def run_odometry(source, odometry: Odometry, status: RunStatus, sinks, *, T_B_C0: np.ndarray, start: int, stop: int,
                 progress: bool = True, warn=print, rebuild: Callable[[], Odometry] | None = None) -> RunOutcome:
    """Track frames ``start:stop`` of ``source``, handing every pose and frame to each of ``sinks``
    (:mod:`gevi_cli.run.sinks`) the moment it is made.  ``rebuild``: a fresh odometry like ``odometry``,
    for the restart with the disparity offset found on the way (None: no restart)."""
    from tqdm import tqdm

    stamps: dict[int, int] = {}
    status.frames_total = stop - start
    t_run = time.perf_counter()
    lost_open = None

    def emit(events):
        """PoseEvents to the sinks: the cam0 pose in its world and the body pose (PoseEvent.body)."""
        for ev in events:
            T_body = ev.body(T_B_C0)
            for sink in sinks:
                if ev.kind == FINAL:
                    sink.final(stamps[ev.index], ev.T, T_body)
                else:
                    sink.online(stamps[ev.index], T_body)

    def flush(closing_ba: bool = False):
        """What the odometry still holds, handed on (``Odometry.close``)."""
        emit(odometry.close(closing_ba=closing_ba))

    def close_lost(end_t):
        nonlocal lost_open
        if lost_open is not None:
            i0, t0, reason, n = lost_open
            status.lost_intervals.append({"first_index": i0, "start_s": t0 * 1e-9, "end_s": end_t * 1e-9,
                                          "frames": n, "reason": reason})
            lost_open = None

    def restart_calibrated():
        """A fresh odometry carrying the disparity offset just found, and the run begun again."""
        nonlocal odometry, frames, lost_open, t_run
        found = odometry.disparity_offset
        est = found.found
        warn(f"stereo disparity offset {est.value_px:.2f} +- {est.total_sigma_px:.2f} px found after "
             f"{status.frames_done + 1} frames: restarting from the first frame with the corrected pair")
        frames.close()
        odometry = rebuild()
        odometry.disparity_offset = found.carried()
        now = time.perf_counter()
        status.first_pass = {"frames": status.frames_done + 1, "elapsed_s": now - t_run}
        status.online_causal = False
        t_run = now
        status.frames_done = status.frames_tracked = status.keyframes = 0
        for name in ("lost_intervals", "bridged_frames", "inertial_frames", "skipped_frames"):
            getattr(status, name).clear()
        stamps.clear()
        lost_open = None
        bar.reset()
        for sink in sinks:
            sink.restart()
            sink.status(status)
        frames = _frames(source, start, stop)

    announced = False  # the offset found without a restart was reported
    bar = tqdm(total=stop - start, unit="frame", disable=not progress, dynamic_ncols=True, leave=False)
    for sink in sinks:
        sink.status(status)
    frames = _frames(source, start, stop)
    try:
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
            offset = odometry.disparity_offset
            if rebuild is not None and offset is not None and offset.calls_for_restart:
                restart_calibrated()
                continue
            if offset is not None and offset.found is not None and not offset.restarted and not announced:
                est = offset.found
                why = "past the first keyframes" if rebuild is not None else "the odometry cannot be rebuilt"
                warn(f"stereo disparity offset {est.value_px:.2f} +- {est.total_sigma_px:.2f} px found at frame "
                     f"{offset.found_at_frame}: applied from the next keyframe on, without a restart ({why})")
                announced = True
            res.timings["read"] = t_read
            total = time.perf_counter() - t0 + t_read
            stamps[res.index] = res.t_ns
            emit(res.poses)
            for sink in sinks:
                sink.frame(index, res, total)
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
                for sink in sinks:
                    sink.status(status)
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
        except Exception:  # the state may be what broke; what was final is already handed on
            pass
        status.state, status.message = "crashed", f"{type(exc).__name__}: {exc}"
        raise
    finally:
        bar.close()
        status.imu = odometry.summary()
        status.elapsed_s = time.perf_counter() - t_run
        status.pose_fallbacks = int(odometry.fallbacks)
        if odometry.disparity_offset is not None:
            status.disparity_offset = odometry.disparity_offset.record()
        for sink in sinks:
            sink.close(status)
    return RunOutcome(status, 0 if status.state == "ok" else 3)
