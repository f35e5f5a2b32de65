"""The one run path: drive a resolved run's odometry into its sinks and evaluate its primary trajectory.

:func:`run_and_evaluate` is what :func:`gevi_cli.api.run` is, and what ``gevi run``
(:func:`gevi_cli.run.session.execute`: the run folder, the printing, the plots and the eval folders) and
``gevi batch`` (through ``execute``, per run) build on.  The evaluation is of the primary trajectory as
written (``status.primary``: the body TUM, or the KITTI rows when the ground truth is matched by frame
index), read back from the run folder when there is one, else written the same way to a temporary file, so the numbers do not depend on whether a folder was written.  Poses 4x4, metres; stamps ns.
"""
from __future__ import annotations

import tempfile
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.evaluation.evaluate import EvalSettings, PairResult
from gevi_cli.evaluation.pair import GroundTruth
from gevi_cli.run.folder import PRIMARY, PRIMARY_KITTI, RunStatus
from gevi_cli.trajectory import Trajectory


@dataclass
class Evaluation:
    """One alignment's evaluation of a run: its PairResult (``status`` failed with a ``reason`` when the
    pair could not be compared), or ``error``, the one-line reason it could not be evaluated at all."""

    align: str
    settings: EvalSettings
    result: PairResult | None = None
    error: str | None = None


@dataclass
class RunResult:
    """One run in memory.

    ``trajectory`` / ``trajectory_cam0``: the final (after-BA) poses of the body / rectified cam0 in the
    odometry's world (CFO: the first frame; GeVI: gravity-aligned once initialised); ``online``: the
    body poses as known when tracked.  ``frames``: one row per frame (status ok / bridged / inertial,
    keyframe, matches, inliers, noise std in px, message); ``timings``: ms per stage and frame;
    ``states``: GeVI's per-frame IMU state (None for CFO).  ``status``: what ``status.json`` holds.
    ``evaluation``: the primary trajectory against the sequence's ground truth, aligned by the config's
    ``run.align`` (None without a ground truth, or when it could not be evaluated); ``evaluations``: every
    alignment evaluated (a stereo-inertial run adds posyaw), ``truth`` the ground truth read; ``tilt``:
    GeVI's roll/pitch error against a gravity-aligned ground truth (deg; ``tilt_problem`` says why not);
    ``warnings``: every warning of the run, as ``gevi run`` prints them.
    """

    method: str
    sequence: str
    config: object  # OdometryConfig
    trajectory: Trajectory
    trajectory_cam0: Trajectory
    online: Trajectory
    frames: object  # pandas.DataFrame
    timings: object  # pandas.DataFrame
    states: object | None  # pandas.DataFrame
    status: RunStatus
    groundtruth: Trajectory | None
    evaluation: PairResult | None
    exit_code: int = 0  # 0 complete, 3 tracking lost on the way
    truth: GroundTruth | None = None
    truth_problem: str | None = None  # why the ground truth could not be read
    evaluations: list[Evaluation] = field(default_factory=list)
    tilt: dict | None = None  # GeVI: roll/pitch error of the primary trajectory (tilt_rmse_deg, tilt_max_deg, trend)
    tilt_problem: str | None = None  # GeVI: why roll/pitch were not evaluated
    warnings: list[str] = field(default_factory=list)  # every warning the run gave, the restart's included


def primary_file(resolved) -> str:
    """The run's primary trajectory: the KITTI rows when the ground truth is matched by frame index
    (KITTI ground truth without stamps), else the body TUM."""
    gt = resolved.source.groundtruth
    kitti_rows = resolved.kind in ("kitti", "ov2slam-tracks")
    return PRIMARY_KITTI if kitti_rows and gt is not None and gt.indexed else PRIMARY


def groundtruth_source(resolved):
    """What `gevi eval --gt` should read for this run (a file or the dataset folder), or None."""
    req = resolved.req
    if req.groundtruth:
        return req.groundtruth
    if resolved.source.groundtruth is not None:
        return req.sequence
    return None


def aligns(resolved) -> list[str]:
    """The config's alignment (SE(3): what every comparison across methods uses), and posyaw (4-DOF,
    gravity known) beside it for a stereo-inertial run."""
    align = resolved.cfg.run.align
    return [align] + (["posyaw"] if resolved.req.method == "gevi" and align != "posyaw" else [])


def run_and_evaluate(resolved, status: RunStatus, sinks=(), *, pipeline=None, run_dir: Path | None = None,
                     progress: bool = False, warn=None) -> RunResult:
    """Run ``resolved`` (:func:`gevi_cli.run.session.resolve`) into memory and ``sinks``, then evaluate it.

    ``pipeline``: a factory of the run's (front end, odometry), called again for a fresh odometry when the
    run restarts with the stereo disparity offset; or one (front end, odometry) pair, which cannot be
    rebuilt, so an offset found on the way applies from the next keyframe on, without a restart; None: the
    stock ones.  Each sink must have :class:`~gevi_cli.run.sinks.RunSink`'s methods (checked before the
    first frame).  ``run_dir``: the folder a :class:`~gevi_cli.run.sinks.FolderSink` among ``sinks``
    writes, whose primary trajectory (chosen here, ``status.primary``) is then the one evaluated.
    Exceptions of the odometry propagate (the sinks are closed first, the status says "crashed"); an
    unusable ground truth or evaluation is recorded in the result instead."""
    import pandas as pd

    from gevi_cli.run.assemble import pipeline_factory
    from gevi_cli.run.driver import run_odometry
    from gevi_cli.run.sinks import FRAME_COLUMNS, STAGES, MemorySink, check_sink

    for sink in sinks:
        check_sink(sink)
    given, warnings = warn, []

    def warn(msg):
        warnings.append(msg)
        if given is not None:
            given(msg)

    source, method = resolved.source, resolved.req.method
    if pipeline is None:
        pipeline = pipeline_factory(resolved, warn)
    if callable(pipeline):
        frontend, odometry = pipeline()
        rebuild = lambda: pipeline()[1]  # noqa: E731
    else:
        (frontend, odometry), rebuild = pipeline, None
    status.primary = primary_file(resolved)
    memory = MemorySink()
    outcome = run_odometry(source, odometry, status, [memory, *sinks], T_B_C0=np.asarray(frontend.camera.T_B_C0),
                           start=resolved.start, stop=resolved.stop, progress=progress, warn=warn, rebuild=rebuild)
    frames = pd.DataFrame(memory.frame_rows, columns=list(FRAME_COLUMNS))
    timings = pd.DataFrame(memory.timing_rows, columns=["index", "t_ns", "total"] + list(STAGES))
    states = pd.DataFrame(memory.state_rows) if memory.state_rows else None
    est = memory.trajectory("body")
    result = RunResult(method, source.name, resolved.cfg, est, memory.trajectory("cam0"), memory.online_trajectory(),
                       frames, timings, states, outcome.status, source.groundtruth, None, outcome.exit_code)
    result.warnings = warnings
    gt = groundtruth_source(resolved)
    if gt is not None:
        _evaluate(result, resolved, gt, memory, outcome.status.primary, run_dir)
    return result


def _evaluate(result: RunResult, resolved, gt, memory, primary: str, run_dir: Path | None) -> None:
    """Fill ``result``'s evaluations: the primary trajectory against the ground truth ``gt``."""
    from gevi_cli.evaluation.pair import evaluate_file, read_groundtruth

    try:
        result.truth = read_groundtruth(gt)
    except GeviError as err:  # the run is complete; an unusable ground truth must not hide it
        result.truth_problem = err.one_line()
        result.evaluations = [Evaluation(a, _settings(resolved, a), error=result.truth_problem)
                              for a in aligns(resolved)]
        return
    result.groundtruth = result.truth.trajectory
    method, seq = resolved.req.method, resolved.source.name
    with _primary_path(memory, primary, run_dir) as path:
        for align in aligns(resolved):
            ev = Evaluation(align, _settings(resolved, align))
            try:
                ev.result = evaluate_file(result.truth, path, ev.settings, align, method=method, sequence=seq,
                                          keep_going=True)
            except GeviError as err:
                ev.error = err.one_line()
            if run_dir is None and ev.result is not None:
                ev.result.path = None  # the file was only the format's round trip
            result.evaluations.append(ev)
        if method == "gevi":
            result.tilt, result.tilt_problem = _tilt(result, path)
    first = result.evaluations[0]
    result.evaluation = first.result if first.error is None else None


def _tilt(result: RunResult, path: Path) -> tuple[dict | None, str | None]:
    """GeVI's roll/pitch error of the primary trajectory ``path`` against the run's gravity-aligned ground truth
    (no alignment): ``({tilt_rmse_deg, tilt_max_deg, tilt_trend_deg_per_min}, None)`` or ``(None, why not)``."""
    from gevi_cli.evaluation.tilt import tilt_errors
    from gevi_cli.trajectory import read_trajectory

    imu = result.status.imu or {}
    if imu and not imu.get("initialised", True):
        return None, ("the run ended before the stereo-IMU initialisation (its world is the first camera frame, "
                      "not gravity-aligned)")
    try:
        te = tilt_errors(read_trajectory(path, frame="body"), result.truth.trajectory)
    except GeviError as err:
        return None, err.one_line()
    if len(te.err_deg) == 0:
        return None, None
    # whether roll/pitch drift: the slope over every 5 s window after the initialisation (None: too short a run)
    at_s = (imu.get("initialisation") or {}).get("at_s") or 0.0
    trend = te.trend_deg_per_min(int(te.t_ns[0]) + int(round(at_s * 1e9)))
    return {"tilt_rmse_deg": te.rmse_deg, "tilt_max_deg": float(te.err_deg.max()),
            "tilt_trend_deg_per_min": trend if np.isfinite(trend) else None}, None


def _settings(resolved, align: str) -> EvalSettings:
    return EvalSettings(align=align, rpe_delta=resolved.cfg.run.rpe_delta, min_coverage=0.0).checked()


@contextmanager
def _primary_path(memory, primary: str, run_dir: Path | None):
    """The primary trajectory's file: the run folder's, or (no folder) the poses kept in ``memory`` written
    the same way to a temporary file, so that they read back as the folder's would (a KITTI row keeps ~1e-6
    of its matrix, and the KITTI metric re-reads the rows as written)."""
    if run_dir is not None:
        yield Path(run_dir) / primary
        return
    from gevi_cli.trajectory.formats import write_trajectory

    with tempfile.TemporaryDirectory(prefix="gevi-") as tmp:
        path = Path(tmp) / primary
        traj = memory.trajectory("body")
        if len(traj):
            write_trajectory(traj, path, "kitti" if primary == PRIMARY_KITTI else "tum")
        else:
            path.write_text("")
        yield path
