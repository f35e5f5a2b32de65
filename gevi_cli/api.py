"""gevi as a library: run an odometry on a sequence and evaluate a trajectory, in memory.

    from gevi_cli.api import run, evaluate

    result = run("../shared/data/kitti06_head/dataset/sequences/06", method="cfo", stride=3)
    print(result.frames.status.value_counts(), result.evaluation.ate.trans_rmse)
    pair = evaluate(result.groundtruth, result.trajectory, align="se3")

``run`` resolves the configuration exactly as ``gevi run`` does (defaults -> the dataset kind's file
-> ``config`` -> ``sets``) and is :func:`gevi_cli.run.pipeline.run_and_evaluate`, the run path of
``gevi run`` and ``gevi batch``: the same odometry objects, driver and evaluation (of the primary
trajectory as written), with the output kept in memory; a run folder is one more sink
(:class:`gevi_cli.run.sinks.FolderSink`), which is what ``gevi run`` adds.  Poses: 4x4, metres; stamps in ns.
"""
from __future__ import annotations

from pathlib import Path

from gevi_cli.evaluation.evaluate import EvalSettings, PairResult
from gevi_cli.run.pipeline import RunResult
from gevi_cli.trajectory import Trajectory

__all__ = ["RunResult", "run", "evaluate"]


def run(sequence, method: str | None = None, config: str | None = None, sets=(), stride: int = 1, start: int = 0,
        max_frames: int | None = None, seed: int | None = None, groundtruth: str | None = None, sinks=(),
        progress: bool = False) -> RunResult:
    """Run ``method`` ("cfo" or "gevi"; default: gevi when the sequence has an IMU) on ``sequence`` (a
    dataset folder, bag or track export) and return the :class:`RunResult`.  ``config``: a YAML of
    overrides; ``sets``: ``"KEY=VALUE"`` strings (``gevi run --set``); ``stride``: every K-th frame;
    ``sinks``: more :class:`~gevi_cli.run.sinks.RunSink` objects to hand the output to as it is made.
    Raises :class:`gevi_cli.errors.GeviError` for unusable input (one line, as the CLI prints it).
    Runs with one BLAS/OpenCV thread, as ``gevi run`` (the caller's counts are put back on return)."""
    from gevi_cli.run.threads import one_thread

    with one_thread():
        return _run(sequence, method, config, sets, stride, start, max_frames, seed, groundtruth, sinks, progress)


def _run(sequence, method, config, sets, stride, start, max_frames, seed, groundtruth, sinks, progress) -> RunResult:
    from gevi_cli.run.folder import RunStatus
    from gevi_cli.run.pipeline import run_and_evaluate
    from gevi_cli.run.session import RunRequest, resolve

    req = RunRequest(sequence=str(sequence), method=method, start=start, max_frames=max_frames, stride=stride,
                     config_file=None if config is None else str(config), sets=tuple(sets), seed=seed, quiet=True,
                     groundtruth=None if groundtruth is None else str(groundtruth))
    resolved = resolve(req)
    status = RunStatus(method=resolved.req.method, stride=stride, sequence=resolved.source.name)
    return run_and_evaluate(resolved, status, sinks, progress=progress)


def evaluate(reference, estimate, align: str = "se3", delta: float = 1.0, unit: str = "frames",
             max_diff_s: float = 0.01, method: str = "estimate", sequence: str = "") -> PairResult:
    """ATE and RPE of ``estimate`` against ``reference``, the library call under ``gevi eval`` and
    ``gevi run`` (:func:`gevi_cli.evaluation.pair.evaluate_estimate`): ``reference`` a Trajectory, a
    trajectory file or a dataset folder (as ``gevi eval --gt``), ``estimate`` a Trajectory or a
    trajectory file (as ``gevi eval -e``); stamps associated within ``max_diff_s`` seconds, the estimate
    aligned by ``align`` (se3, sim3, posyaw, origin, none), RPE over ``delta`` frames (``unit``
    "frames") or metres ("m").  The PairResult holds ``ate``, ``rpe``, ``kitti``, ``scale`` (path and
    median step-length ratio, before alignment), ``alignment``, ``aligned`` and the ``association``; ``status`` "failed" with a ``reason`` when the two cannot be
    compared (a file without poses: "no valid poses").  Raises :class:`gevi_cli.errors.GeviError` for
    unusable input."""
    from gevi_cli.evaluation.pair import evaluate_estimate, evaluate_file, groundtruth, read_groundtruth

    settings = EvalSettings(align=align, max_diff_s=max_diff_s, rpe_delta=delta, rpe_unit=unit,
                            min_coverage=0.0).checked()
    ref = groundtruth(reference) if isinstance(reference, Trajectory) else read_groundtruth(reference)
    if isinstance(estimate, Trajectory):
        return evaluate_estimate(ref, estimate, settings, align, method=method, sequence=sequence)
    return evaluate_file(ref, Path(estimate), settings, align, method=method, sequence=sequence)
