"""One `gevi run`: resolve the configuration, open the input, build front end + odometry, then the one
run path (:func:`gevi_cli.run.pipeline.run_and_evaluate`, also :func:`gevi_cli.api.run`) with the run
folder as its sink; on top of it, the printing, the plots, the eval folders and the roll/pitch error.

Configuration precedence (later wins): dataclass defaults -> ``gevi_cli/configs/<kind>.yaml`` -> ``--config``
-> ``--set`` -> the shortcut options (``--pnp``, ``--no-ba``, ``--seed``).
"""
from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.pipelines.disparity_offset import describe_record


def config_dir() -> Path:
    """The per-kind YAMLs, package data of ``gevi_cli`` (``gevi_cli/configs/``): the same folder in a
    checkout, an editable install, a wheel and a ``--user`` install."""
    from importlib.resources import files

    return Path(str(files("gevi_cli") / "configs"))


KIND_CONFIG = {"euroc": "euroc.yaml", "pool": "pool.yaml", "kitti": "kitti.yaml", "ov2slam-tracks": "kitti-tracks.yaml",
               "rosbag": "euroc.yaml"}


@dataclass(frozen=True)
class RunRequest:
    sequence: str | None
    method: str | None = None  # None: gevi when the sequence has an IMU, else cfo
    start: int = 0
    max_frames: int | None = None
    stride: int = 1  # every stride-th frame (start and max_frames count strided frames); IMU and GT whole
    config_file: str | None = None
    sets: tuple = ()
    pnp: str | None = None
    no_ba: bool = False
    seed: int | None = None
    out: str | None = None
    results_root: str = "results"
    plots: bool = False
    quiet: bool = False
    kind: str | None = None
    groundtruth: str | None = None
    calib: str | None = None
    imu_calib: str | None = None
    topics: str | None = None
    cameras: str | None = None
    ransac: str | None = None
    no_adaptive: bool = False
    no_fusion: bool = False
    imu_time_offset: float | None = None


def is_track_export(path: Path) -> bool:
    from gevi_cli.datasets import track_export

    return path.is_dir() and track_export.detect(path)


def open_input(req: RunRequest):
    """(source, kind) for the request: an image Sequence or a TrackExport."""
    from gevi_cli.datasets.registry import sequence_kwargs
    from gevi_cli.datasets.strided import StridedSequence, check_stride

    if req.sequence is None:
        raise GeviError("gevi run", "give a SEQUENCE (dataset folder, bag or track export)")
    check_stride(req.stride)
    path = Path(req.sequence)
    if not path.exists():
        raise GeviError(path, "no such file or folder")
    if req.kind in (None, "ov2slam-tracks") and is_track_export(path):
        from gevi_cli.datasets.track_export import open_track_export

        if req.stride > 1:
            raise GeviError("--stride", f"{path} is a track export: its tracks were made at the full frame rate by "
                                        "the exporter's front end, so they cannot be strided; stride the images")
        if req.groundtruth is not None and not Path(req.groundtruth).is_file():
            raise GeviError("--gt", f"{req.groundtruth}: no such file")
        return open_track_export(path, req.calib, groundtruth=req.groundtruth), "ov2slam-tracks"
    from gevi_cli.datasets import open_sequence

    seq = open_sequence(path, kind=req.kind, **sequence_kwargs(req.groundtruth, req.calib, req.topics, req.cameras,
                                                             req.imu_calib))
    return (StridedSequence(seq, req.stride) if req.stride > 1 else seq), seq.kind


def frame_range(req: RunRequest, n: int) -> tuple[int, int]:
    """(start, stop) indices of the frames a run of ``req`` tracks, out of the ``n`` (strided) frames."""
    if n < 2:
        raise GeviError(req.sequence, f"holds {n} frame(s); odometry needs at least two")
    if req.start >= n:
        raise GeviError("--start", f"{req.start} is past the last frame ({n - 1})")
    stop = n if req.max_frames is None else min(n, req.start + req.max_frames)
    if stop - req.start < 2:
        raise GeviError("--max-frames", "odometry needs at least two frames")
    return req.start, stop


def choose_method(req: RunRequest, source) -> tuple[str, str]:
    """(method, why): ``--method`` when given, else gevi with an IMU and cfo without."""
    if req.method:
        return req.method, "--method"
    imu = source.imu
    if imu is not None and len(imu) > 1:
        return "gevi", f"the sequence has an IMU ({len(imu)} samples); --method cfo for stereo only"
    return "cfo", "the sequence has no IMU"


#: the shortcut options: (RunRequest field, the option's name, the overrides it stands for given its value)
SHORTCUTS = (
    ("pnp", "--pnp", lambda v: {"pnp": {"method": v}}),
    ("no_ba", "--no-ba", lambda v: {"ba": {"enabled": False}}),
    ("seed", "--seed", lambda v: {"run": {"seed": v}}),
    ("ransac", "--ransac", lambda v: {"verify": {"ransac": v}}),
    ("no_adaptive", "--no-adaptive", lambda v: {"fusion": {"adaptive": False}}),
    ("no_fusion", "--no-fusion", lambda v: {"fusion": {"mode": "4dof"}}),
    ("imu_time_offset", "--imu-time-offset", lambda v: {"imu": {"time_offset_s": v}}),
)


def resolve_config(req: RunRequest, kind: str | None, method: str = "cfo"):
    """The effective :class:`OdometryConfig` and the list of files it came from.

    Every layer is checked as it is applied (:func:`gevi_cli.config.build`): unknown keys, types, domains,
    ordered pairs, and what does not apply to ``method`` or to input ``kind`` (None: not known yet, e.g. a
    batch method entry) unless it keeps its default.  Errors are one line naming the layer (file or option)."""
    from gevi_cli.config import build, load_yaml, parse_set, refuse_inapplicable
    from gevi_cli.pipelines.config import METHOD_DEFAULTS, OdometryConfig

    layers, sources = [], ["defaults"]
    if METHOD_DEFAULTS.get(method):
        layers.append((f"{method} defaults", METHOD_DEFAULTS[method], False))
        sources.append(f"{method} defaults")
    default = build(OdometryConfig, layers)  # what a setting that does not apply must keep
    if kind in KIND_CONFIG:
        kind_file = config_dir() / KIND_CONFIG[kind]
        if not kind_file.is_file():
            # a silent fallback to the defaults would run another method than the one documented
            raise GeviError(kind_file, f"the configuration for {kind} sequences is missing (broken installation?)")
        layers.append((str(kind_file), load_yaml(kind_file), False))
        sources.append(f"gevi_cli/configs/{kind_file.name}")
    own = build(OdometryConfig, layers)  # gevi's own configuration for this input, before the user's layers
    if req.config_file:
        layers.append((req.config_file, load_yaml(Path(req.config_file)), False))
        sources.append(req.config_file)
    if req.sets:
        layers.append(("--set", parse_set(req.sets), False))
        sources.append("--set")
    for name, flag, overrides in SHORTCUTS:
        value = getattr(req, name)
        if value is not None and value is not False:
            layers.append((flag, overrides(value), True))

    def check(cfg, where, is_flag):
        refuse_inapplicable(cfg, default, method, kind, where, is_flag, own)

    return build(OdometryConfig, layers, check), sources


def dump_config(req: RunRequest) -> str:
    """Every setting: its effective value, then its type, default, valid domain and help."""
    from gevi_cli.config import describe, show

    if req.sequence is not None:
        source, kind = open_input(req)
        method, _ = choose_method(req, source)
        what = method
    else:  # what `gevi run` without a SEQUENCE runs: the built-in pool sample (stereo-IMU), not rendered here
        kind, method = "pool", req.method or "gevi"
        what = f"{method} on the built-in pool-easy sample (gevi run without a SEQUENCE)"
    cfg, sources = resolve_config(req, kind, method)
    lines = [f"# effective configuration for {what} ({' -> '.join(sources)}); set any key with --set KEY=VALUE",
             "# KEY=VALUE    # type in its domain (default DEFAULT) [where it applies]: what it does"]
    for key, value, typ, default, dom, help_text in describe(cfg):
        lines.append(f"{key}={show(value)}    # {typ} in {dom} (default {show(default)}) {help_text}")
    return "\n".join(lines)


@dataclass(frozen=True)
class Resolved:
    """A run request resolved against its input: the request with its method chosen (and why), the
    opened source and its kind, the effective configuration and where it came from, the frame range."""

    req: RunRequest
    source: object
    kind: str
    why: str
    cfg: object
    sources: list
    start: int
    stop: int


def resolve(req: RunRequest) -> Resolved:
    """Open the input, choose the method, resolve the configuration and the frame range (one-line errors)."""
    source, kind = open_input(req)
    method, why = choose_method(req, source)
    req = dataclasses.replace(req, method=method)
    cfg, sources = resolve_config(req, kind, method)
    start, stop = frame_range(req, len(source))
    return Resolved(req, source, kind, why, cfg, sources, start, stop)


def execute(req: RunRequest, echo=print) -> int:
    """`gevi run`: :func:`run_in_folder`; returns the exit status (0 complete, 3 tracking lost)."""
    return run_in_folder(req, echo).exit_code


def run_in_folder(req: RunRequest, echo=print):
    """Run and evaluate into a run folder, printing as `gevi run` does; returns the
    :class:`~gevi_cli.run.pipeline.RunResult`.  One BLAS/OpenCV thread throughout
    (:func:`gevi_cli.run.threads.one_thread`)."""
    from gevi_cli.run.threads import one_thread

    with one_thread():
        return _execute(req, echo)


def _execute(req: RunRequest, echo):
    import yaml

    from gevi_cli import __version__
    from gevi_cli.run.assemble import make_pipeline, pipeline_factory
    from gevi_cli.run.folder import RunStatus, make_run_dir
    from gevi_cli.run.pipeline import primary_file, run_and_evaluate
    from gevi_cli.run.sinks import FolderSink

    t_start = time.perf_counter()
    if req.sequence is None:
        from gevi_cli.simulate.sample import sample_path, sample_sequence

        if not sample_path().exists():
            echo("gevi run: no SEQUENCE given; rendering the built-in pool-easy sample (once, about a minute)")
        req = dataclasses.replace(req, sequence=str(sample_sequence(progress=not req.quiet and sys.stderr.isatty())))
    resolved = resolve(req)
    req, source, kind, cfg, sources, stop = (resolved.req, resolved.source, resolved.kind, resolved.cfg,
                                             resolved.sources, resolved.stop)
    method = req.method
    for w in source.warnings:
        echo(f"gevi: warning: {w}", err=True)
    def warn(msg):
        echo(f"gevi: warning: {msg}", err=True)

    echo(f"gevi run: method {method} ({resolved.why})")
    frontend, odometry = make_pipeline(resolved, warn)
    # read (and check) the ground truth before the run folder exists: a KITTI --gt whose rows do not match
    # the sequence's times.txt is refused in one line without leaving an empty run behind
    primary = primary_file(resolved)
    seq_name = source.name
    run_dir = make_run_dir(req.out, Path(req.results_root), req.method, seq_name)
    sensor = "stereo-inertial" if method == "gevi" else "stereo"
    config_doc = {"method": req.method, "sequence": str(req.sequence), "kind": kind, "sensor": sensor,
                  "align": cfg.run.align, "stride": req.stride, "frames": [req.start, stop], "sources": sources,
                  **dataclasses.asdict(cfg)}
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config_doc, sort_keys=False))
    kitti_rows = kind in ("kitti", "ov2slam-tracks")
    status = RunStatus(method=req.method, stride=req.stride, primary=primary, sequence=seq_name,
                       gevi_version=__version__,
                       command=" ".join(["gevi"] + sys.argv[1:]), started=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    strided = f" at stride {req.stride} (original frames {req.start * req.stride}..{(stop - 1) * req.stride})" \
        if req.stride > 1 else ""
    echo(f"gevi run: {req.method} on {seq_name} ({kind}), frames {req.start}..{stop - 1}{strided} -> {run_dir}")

    folder = FolderSink(run_dir, kitti_rows, odometry.state_columns, odometry.state_file)
    result = run_and_evaluate(resolved, status, [folder], pipeline=pipeline_factory(resolved, first=(frontend, odometry)),
                              run_dir=run_dir, progress=not req.quiet and sys.stderr.isatty(), warn=warn)
    st = result.status
    fps = st.frames_done / st.elapsed_s if st.elapsed_s > 0 else float("nan")
    echo(f"{st.frames_tracked}/{st.frames_done} frames tracked, {st.keyframes} keyframes, "
         f"{st.elapsed_s:.2f} s ({fps:.1f} frames/s)")
    if st.first_pass:
        echo(f"before that, a first pass of {st.first_pass['frames']} frames in {st.first_pass['elapsed_s']:.2f} s "
             "(status.json first_pass); traj_online_body.tum is not causal after the restart")
    if st.disparity_offset:
        echo(f"stereo disparity offset: {describe_record(st.disparity_offset)}")
        # what ran beyond the configuration: the offset the self-calibration applied (status.json has its evidence)
        rec = st.disparity_offset
        config_doc["self_calibration"] = {"disparity_offset_px": rec["applied_px"],
                                          "applied_from_frame": rec["applied_from_frame"], "restarted": rec["restarted"]}
        (run_dir / "config.yaml").write_text(yaml.safe_dump(config_doc, sort_keys=False))
    t0_s = int(source.stamps_ns[req.start]) * 1e-9
    for iv in st.lost_intervals[:5]:
        echo(f"tracking lost at {iv['start_s'] - t0_s:.3f} s (frame {iv['first_index']}, {iv['frames']} frame(s) bridged): "
             f"{iv['reason']}")
    if st.inertial_frames:
        first = st.inertial_frames[0]
        echo(f"vision could not track {len(st.inertial_frames)} frame(s) (first: frame {first}); they were carried by "
             "the IMU alone (status.json inertial_frames, frames.csv)")
    if len(st.lost_intervals) > 5:
        echo(f"... and {len(st.lost_intervals) - 5} more loss(es); see status.json and frames.csv")
    if method == "gevi" and (run_dir / "imu_states.csv").is_file():
        from gevi_cli.evaluation.plots import plot_imu_states

        plot_imu_states(run_dir / "imu_states.csv", run_dir / "imu_states.png")
    pair = None
    if result.evaluations:
        if req.groundtruth is None and source.groundtruth_source is not None:
            echo(f"ground truth: {source.groundtruth_source} (the sequence's own; --gt FILE for another)")
        pair = _write_evaluation(run_dir, req, cfg, result, seq_name, st, echo)
    else:
        echo("no ground truth: not evaluated (give --gt FILE)")
    from gevi_cli.run.folder import write_status, write_trajectory_png

    write_trajectory_png(run_dir, st, kind, pair)
    write_status(run_dir, st)
    echo(f"wrote {run_dir} ({time.perf_counter() - t_start:.1f} s)")
    if st.state != "ok":
        echo(f"gevi run: {st.state}: {st.message}", err=True)
    return result


def _write_evaluation(run_dir: Path, req: RunRequest, cfg, result, seq_name: str, status, echo):
    """The run's evaluations (:func:`gevi_cli.run.pipeline.run_and_evaluate`) into RUN/eval (the primary
    alignment) and RUN/eval/<align> (posyaw beside SE(3) for a stereo-inertial run), the status.json
    entries and the printed lines; then the roll/pitch error of a stereo-inertial run.
    Returns the primary alignment's PairResult (None when the evaluation failed)."""
    status.evaluation = {}
    primary = None
    for k, ev in enumerate(result.evaluations):
        out = run_dir / "eval" if k == 0 else run_dir / "eval" / ev.align
        if ev.error is not None:
            entry, pair = _failed(ev.error, echo)
        else:
            entry, pair = _write_one(run_dir, req, cfg, result.truth, seq_name, status, ev, out, echo)
        if k == 0:
            status.evaluation.update(entry)
            primary = pair
        else:
            status.evaluation[ev.align] = entry
    if req.method == "gevi":
        _print_tilt(result, status, echo)
    return primary


def _print_tilt(result, status, echo) -> None:
    """GeVI's roll/pitch error as the run path evaluated it (``RunResult.tilt``), printed and into status.json."""
    problem = result.truth_problem or result.tilt_problem
    if result.tilt is None:
        if problem is not None:
            echo(f"roll/pitch not evaluated: {problem}")
        return
    status.evaluation.update(result.tilt)
    trend = result.tilt["tilt_trend_deg_per_min"]
    trend_txt = f", trend {trend:+.3f} deg/min over 5 s windows" if trend is not None else ""
    echo(f"roll/pitch error {result.tilt['tilt_rmse_deg']:.3f} deg RMSE, {result.tilt['tilt_max_deg']:.3f} deg max"
         f"{trend_txt} (gravity direction, no alignment; needs a gravity-aligned ground truth)")


def _failed(why: str, echo):
    echo(f"evaluation failed: {why}")
    return {"failed": why}, None


def _write_one(run_dir: Path, req: RunRequest, cfg, truth, seq_name: str, status, ev, out: Path, echo):
    """(the status.json evaluation entries, the PairResult or None when it failed) of one alignment's
    evaluation ``ev`` of the run's primary trajectory against ``truth``, with its eval folder ``out``."""
    from gevi_cli.evaluation.report import build_tables
    from gevi_cli.evaluation.runner import eval_inputs, write_eval_folder

    r, settings = ev.result, ev.settings
    try:
        tables = build_tables([r], [req.method], [seq_name], settings)
        inputs = eval_inputs({seq_name: truth.path}, {f"{req.method}/{seq_name}": run_dir / status.primary})
        write_eval_folder(out, tables, [r], {seq_name: truth}, settings, inputs, req.plots)
    except GeviError as err:  # the run is complete on disk; an unusable evaluation must not hide it
        return _failed(err.one_line(), echo)
    for w in r.warnings:
        echo(f"gevi: warning: {w}", err=True)
    if not (r.ok and r.ate is not None):
        return _failed(r.reason, echo)
    rpe = r.rpe.trans_rmse if r.rpe is not None else float("nan")
    ratio = r.scale.path_ratio  # before alignment: the estimate's path over the ground truth's (n/a at rest)
    echo(f"ATE {_metres(r.ate.trans_rmse)}, RPE {_metres(rpe)}, path-length ratio "
         f"{'n/a' if np.isnan(ratio) else f'{ratio:.3f}'} est/GT ({r.align.upper()}, body frame, RPE over "
         f"{cfg.run.rpe_delta:g} frame; {r.association.summary()})")
    return {"align": r.align, "ate_m": r.ate.trans_rmse, "rpe_m": rpe,
            "ate_rot_deg": getattr(r.ate, "rot_rmse_deg", None), "matched": r.association.n_matched,
            "path_ratio": None if np.isnan(ratio) else ratio}, r


def _metres(x: float) -> str:
    """Metres with 4 significant digits below 10 cm (sub-millimetre runs stay readable)."""
    return f"{x:.4f} m" if not x < 0.1 else f"{x:.4g} m"
