"""`gevi batch`: config -> plan -> renders -> runs (resumable) -> evaluation -> report; exit status.

Exit status: 0 every run ran to the end with tracking, 3 some run lost tracking or crashed (the
report lists them), 2 a bad config (raised before any run starts).
"""
from __future__ import annotations

import dataclasses
import json
import sys
import time
from pathlib import Path

from gevi_cli.batch.config import load_batch_config
from gevi_cli.batch.plan import baseline_runs, check_methods_fit, expand
from gevi_cli.batch.worker import read_marker


def default_out(cfg) -> Path:
    return Path(cfg.output) if cfg.output else Path("results") / "batch" / cfg.name


def select(cfg, sequences=None, trials=None):
    """Restrict ``cfg`` to some sequences (names) and/or override every method's trial count."""
    from gevi_cli.errors import GeviError

    if sequences:
        names = [n for item in sequences for n in item.split(",") if n]
        unknown = [n for n in names if n not in {s.name for s in cfg.sequences}]
        if unknown:
            raise GeviError("--sequences", f"no sequence {unknown[0]!r} in {cfg.path}; it has "
                                           f"{', '.join(s.name for s in cfg.sequences)}")
        cfg.sequences = [s for s in cfg.sequences if s.name in names]
    if trials:
        cfg.methods = [dataclasses.replace(m, trials=trials) for m in cfg.methods]
    return cfg


def prepare(config_path, out=None, echo=print, sequences=None, trials=None):
    """(cfg, out, specs with rendered sources, baseline runs, skipped) — every config check first."""
    cfg = select(load_batch_config(config_path), sequences, trials)
    check_methods_fit(cfg)
    baselines = baseline_runs(cfg)  # reads every baseline file: an unreadable one stops here
    out = Path(out) if out else default_out(cfg)
    skipped = [{"sequence": s.name, "reason": s.skip_reason} for s in cfg.sequences if s.skip_reason]
    for d in skipped:
        echo(f"gevi batch: skipping sequence {d['sequence']}: {d['reason']}")
    for b in cfg.baselines:
        if b.skip_reason:
            echo(f"gevi batch: skipping baseline {b.name}: {b.skip_reason}")
    specs = expand(cfg, out)
    return cfg, out, specs, baselines, skipped


def render_sources(cfg, specs, echo=print, progress=False):
    from gevi_cli.batch.renders import cache_root, ensure_rendered

    sims = [s.sim for s in specs if s.sim is not None]
    paths = ensure_rendered(sims, cache_root(cfg.cache), echo=echo, progress=progress) if sims else {}
    return [dataclasses.replace(s, source=paths[s.sim]) if s.sim is not None else s for s in specs]


def run_batch(config_path, out=None, *, jobs: int = 1, force: bool = False, executor: str = "local",
              scheduler: str | None = None, echo=print, progress: bool | None = None, sequences=None,
              trials: int | None = None) -> int:
    from gevi_cli.batch.evaluate import evaluate_batch
    from gevi_cli.batch.executors import execute_all
    from gevi_cli.batch.report import write_batch_report
    from gevi_cli.evaluation.evaluate import EvalSettings

    t0 = time.perf_counter()
    tty = sys.stderr.isatty() if progress is None else progress
    cfg, out, specs, baselines, skipped = prepare(config_path, out, echo, sequences, trials)
    specs = render_sources(cfg, specs, echo, progress=tty)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.yaml").write_text(Path(config_path).read_text())
    plan = {"config": str(Path(config_path).resolve()), "runs": [dataclasses.asdict(s) for s in specs]}
    (out / "batch.json").write_text(json.dumps(plan, indent=1, default=str) + "\n")
    todo = [s for s in specs if force or read_marker(s.run_dir) is None]
    if len(todo) < len(specs):
        echo(f"gevi batch: {len(specs) - len(todo)} of {len(specs)} runs already finished (--force redoes them)")
    echo(f"gevi batch: {len(todo)} run(s) to do on {executor}" + (f" x{jobs}" if executor == "local" else "")
         + f" -> {out}")
    evaluated = _dispatch(todo, executor, jobs, scheduler, echo, tty, execute_all)
    settings = EvalSettings(align="se3", n_align=-1, max_diff_s=cfg.eval.max_diff_s, rpe_delta=cfg.eval.rpe_delta,
                            rpe_unit="frames", min_coverage=cfg.eval.min_coverage, est_frame="same", kitti=True)
    res = evaluate_batch(specs, baselines, settings, {m.name for m in cfg.methods if m.method == "gevi"},
                         online=cfg.eval.online, evaluated=evaluated)
    report = write_batch_report(out / "report", cfg, specs, baselines, res, settings, skipped=skipped,
                                elapsed_s=time.perf_counter() - t0, executor=executor)
    bad = [r for r in res.runs if r["state"] != "ok"]
    for r in bad:
        echo(f"gevi batch: {r['run_id']}: {r['state']}: {r['message']}")
    echo(f"gevi batch: wrote {report} ({time.perf_counter() - t0:.1f} s)")
    return 3 if bad else 0


def _dispatch(todo, executor, jobs, scheduler, echo, tty, execute_all) -> dict:
    """Run ``todo``, showing runs done / failed / left and the time left (tqdm's estimate); returns each
    run's own evaluations by run id."""
    from tqdm import tqdm

    evaluated = {}
    if not todo:
        return evaluated
    n_bad, t0 = 0, time.perf_counter()
    bar = tqdm(total=len(todo), unit="run", disable=not tty, dynamic_ncols=True, desc="gevi batch")
    try:
        for k, (spec, done) in enumerate(execute_all(todo, executor, jobs, scheduler), 1):
            marker = done.marker
            evaluated[spec.run_id] = done.evaluations
            n_bad += marker["state"] != "ok"
            bar.update(1)
            bar.set_postfix_str(f"done {k - n_bad}, failed {n_bad}, left {len(todo) - k}")
            line = f"[{k}/{len(todo)}] {spec.run_id}: {marker['state']} ({marker['wall_s']:.1f} s)"
            if marker["state"] != "ok":
                line += f": {marker['message']}"
            if tty:
                bar.write(line)
            else:
                left = (time.perf_counter() - t0) / k * (len(todo) - k)
                echo(f"{line}; {len(todo) - k} left, about {left:.0f} s")
    finally:
        bar.close()
    return evaluated
