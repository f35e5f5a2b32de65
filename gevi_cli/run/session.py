"""One `gevi run`: resolve the configuration, open the input, build front end + odometry, drive the
run into its folder, evaluate it with the code of `gevi eval`, and print the result.

Configuration precedence (later wins): dataclass defaults -> ``configs/<kind>.yaml`` -> ``--config``
-> ``--set`` -> the shortcut options (``--pnp``, ``--no-ba``, ``--seed``).
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

from gevi_cli.errors import GeviError

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"
KIND_CONFIG = {"euroc": "euroc.yaml", "pool": "pool.yaml", "kitti": "kitti.yaml", "ov2slam-tracks": "kitti-tracks.yaml",
               "rosbag": "euroc.yaml"}


@dataclass(frozen=True)
class RunRequest:
    sequence: str | None
    method: str = "cfo"
    start: int = 0
    max_frames: int | None = None
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


def _is_export(path: Path) -> bool:
    from gevi_cli.datasets import track_export

    return path.is_dir() and track_export.detect(path)


def open_input(req: RunRequest):
    """(source, kind) for the request: an image Sequence or a TrackExport."""
    from gevi_cli.commands.options import sequence_kwargs

    if req.sequence is None:
        raise GeviError("gevi run", "give a SEQUENCE (dataset folder, bag or track export)")
    path = Path(req.sequence)
    if not path.exists():
        raise GeviError(path, "no such file or folder")
    if req.kind in (None, "ov2slam-tracks") and _is_export(path):
        from gevi_cli.datasets.track_export import open_track_export

        if req.groundtruth is not None and not Path(req.groundtruth).is_file():
            raise GeviError("--gt", f"{req.groundtruth}: no such file")
        return open_track_export(path, req.calib, groundtruth=req.groundtruth), "ov2slam-tracks"
    from gevi_cli.datasets import open_sequence

    seq = open_sequence(path, kind=req.kind, **sequence_kwargs(req.groundtruth, req.calib, req.topics, req.cameras,
                                                             req.imu_calib))
    return seq, seq.kind


def resolve_config(req: RunRequest, kind: str | None):
    """The effective :class:`OdometryConfig` and the list of files it came from."""
    from gevi_cli.config import load_yaml, override, parse_set
    from gevi_cli.pipelines.config import OdometryConfig

    cfg, sources = OdometryConfig(), ["defaults"]
    kind_file = CONFIG_DIR / KIND_CONFIG.get(kind or "", "")
    if kind and kind_file.is_file():
        cfg = override(cfg, load_yaml(kind_file), str(kind_file))
        sources.append(f"configs/{kind_file.name}")
    if req.config_file:
        cfg = override(cfg, load_yaml(Path(req.config_file)), req.config_file)
        sources.append(req.config_file)
    if req.sets:
        cfg = override(cfg, parse_set(req.sets), "--set")
        sources.append("--set")
    shortcuts = {}
    if req.pnp:
        shortcuts.setdefault("pnp", {})["method"] = req.pnp
    if req.no_ba:
        shortcuts.setdefault("ba", {})["enabled"] = False
    if req.seed is not None:
        shortcuts.setdefault("run", {})["seed"] = req.seed
    if shortcuts:
        cfg = override(cfg, shortcuts, "options")
    return cfg.validate(), sources


def dump_config(req: RunRequest) -> str:
    from gevi_cli.config import flat_items

    kind = None
    if req.sequence is not None:
        _, kind = open_input(req)
    cfg, sources = resolve_config(req, kind)
    lines = [f"# effective configuration ({' -> '.join(sources)}); set any key with --set KEY=VALUE"]
    for key, value, help_text in flat_items(cfg):
        v = "true" if value is True else "false" if value is False else value
        lines.append(f"{key}={v}" + (f"    # {help_text}" if help_text else ""))
    return "\n".join(lines)


def build(source, kind: str, cfg, method: str):
    """(front end, odometry) for ``source``."""
    from gevi_cli.pipelines.cfo import CurrentFeatureOdometry

    if kind == "ov2slam-tracks":
        from gevi_cli.frontend.export import ExportFrontEnd

        frontend = ExportFrontEnd(source, use_outlier_flags=cfg.verify.use_export_flags)
    else:
        from gevi_cli.frontend.image_frontend import ImageFrontEnd

        frontend = ImageFrontEnd(source.calibration, cfg.frontend)
    if method == "cfo":
        return frontend, CurrentFeatureOdometry(frontend, cfg)
    raise GeviError("--method", f"unknown method {method!r}")


def _gt_source(req: RunRequest, source):
    """What `gevi eval --gt` should read for this run (a file or the dataset folder), or None."""
    if req.groundtruth:
        return req.groundtruth
    if getattr(source, "groundtruth", None) is not None:
        return req.sequence
    return None


def execute(req: RunRequest, echo=print) -> int:
    """Run and evaluate; returns the exit status (0 complete, 3 tracking lost)."""
    import dataclasses

    import cv2
    import numpy as np
    import yaml

    from gevi_cli import __version__
    from gevi_cli.run.driver import run_odometry
    from gevi_cli.run.folder import PRIMARY, PRIMARY_KITTI, RunStatus, make_run_dir

    t_start = time.perf_counter()
    cv2.setNumThreads(1)
    source, kind = open_input(req)
    cfg, sources = resolve_config(req, kind)
    n = len(source)
    if n < 2:
        raise GeviError(req.sequence, f"holds {n} frame(s); odometry needs at least two")
    if req.start >= n:
        raise GeviError("--start", f"{req.start} is past the last frame ({n - 1})")
    stop = n if req.max_frames is None else min(n, req.start + req.max_frames)
    if stop - req.start < 2:
        raise GeviError("--max-frames", "odometry needs at least two frames")
    for w in getattr(source, "warnings", []):
        echo(f"gevi: warning: {w}", err=True)
    frontend, odometry = build(source, kind, cfg, req.method)
    seq_name = source.name
    run_dir = make_run_dir(req.out, Path(req.results_root), req.method, seq_name)
    config_doc = {"method": req.method, "sequence": str(req.sequence), "kind": kind, "sensor": "stereo",
                  "align": cfg.run.align, "frames": [req.start, stop], "sources": sources,
                  **dataclasses.asdict(cfg)}
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config_doc, sort_keys=False))
    kitti_rows = kind in ("kitti", "ov2slam-tracks")
    # KITTI ground truth without stamps is matched by frame index: then the KITTI rows are primary
    gt_traj = getattr(source, "groundtruth", None)
    indexed_gt = kitti_rows and gt_traj is not None and gt_traj.indexed
    status = RunStatus(method=req.method, primary=PRIMARY_KITTI if indexed_gt else PRIMARY, sequence=seq_name, gevi_version=__version__,
                       command=" ".join(["gevi"] + sys.argv[1:]), started=time.strftime("%Y-%m-%dT%H:%M:%S%z"))
    echo(f"gevi run: {req.method} on {seq_name} ({kind}), frames {req.start}..{stop - 1} -> {run_dir}")

    def warn(msg):
        echo(f"gevi: warning: {msg}", err=True)

    outcome = run_odometry(source, odometry, run_dir, status, T_B_C0=np.asarray(frontend.camera.T_B_C0),
                           start=req.start, stop=stop, kitti_rows=kitti_rows,
                           progress=not req.quiet and sys.stderr.isatty(), warn=warn)
    st = outcome.status
    fps = st.frames_done / st.elapsed_s if st.elapsed_s > 0 else float("nan")
    echo(f"{st.frames_tracked}/{st.frames_done} frames tracked, {st.keyframes} keyframes, "
         f"{st.elapsed_s:.2f} s ({fps:.1f} frames/s)")
    t0_s = int(source.stamps_ns[req.start]) * 1e-9
    for iv in st.lost_intervals[:5]:
        echo(f"tracking lost at {iv['start_s'] - t0_s:.3f} s (frame {iv['first_index']}, {iv['frames']} frame(s) bridged): "
             f"{iv['reason']}")
    if len(st.lost_intervals) > 5:
        echo(f"... and {len(st.lost_intervals) - 5} more loss(es); see status.json and frames.csv")
    gt = _gt_source(req, source)
    if gt is not None:
        _evaluate(run_dir, req, cfg, gt, seq_name, st, echo)
    else:
        echo("no ground truth: not evaluated (give --gt FILE)")
    from gevi_cli.run.folder import write_status

    write_status(run_dir, st)
    echo(f"wrote {run_dir} ({time.perf_counter() - t_start:.1f} s)")
    if st.state != "ok":
        echo(f"gevi run: {st.state}: {st.message}", err=True)
    return outcome.exit_code


def _evaluate(run_dir: Path, req: RunRequest, cfg, gt, seq_name: str, status, echo) -> None:
    """`gevi eval --gt GT -e METHOD=RUN/traj_body.tum` into RUN/eval (the same code path)."""
    from gevi_cli.evaluation.runner import run_eval

    try:
        results, tables, _ = run_eval(
            gt_opts=[str(gt)], estimates=[f"{req.method}={run_dir / status.primary}"], results_root=None, gt_root=None,
            sequence_name=seq_name, align=cfg.run.align, n_align=-1, max_diff=0.01, t_offset=0.0,
            rpe_delta=cfg.run.rpe_delta, rpe_unit="frames", min_coverage=0.0, est_frame="same", gt_frame="body",
            t_b_c0=None, kitti=True, plots=req.plots, out=str(run_dir / "eval"), overwrite=True, keep_going=True,
            quiet=True, echo=lambda *a, **k: None)  # the run prints its own one-line summary
    except GeviError as err:  # the run is complete on disk; an unusable evaluation must not hide it
        status.evaluation = {"failed": err.one_line()}
        echo(f"evaluation failed: {err.one_line()}")
        return
    r = results[0]
    if r.ok and r.ate is not None:
        rpe = r.rpe.trans_rmse if r.rpe is not None else float("nan")
        status.evaluation = {"align": r.align, "ate_m": r.ate.trans_rmse, "rpe_m": rpe,
                             "ate_rot_deg": getattr(r.ate, "rot_rmse_deg", None), "matched": r.association.n_matched}
        echo(f"ATE {_metres(r.ate.trans_rmse)}, RPE {_metres(rpe)} ({r.align.upper()}, body frame, RPE over "
             f"{cfg.run.rpe_delta:g} frame; {r.association.summary()})")
    else:
        status.evaluation = {"failed": r.reason}
        echo(f"evaluation failed: {r.reason}")
    for w in r.warnings:
        echo(f"gevi: warning: {w}", err=True)


def _metres(x: float) -> str:
    """Metres with 4 significant digits below 10 cm (sub-millimetre runs stay readable)."""
    return f"{x:.4f} m" if not x < 0.1 else f"{x:.4g} m"
