"""The batch report folder: `gevi eval`'s tables and plots, a runtime table, report.md and report.html.

Layout (``OUT/report/``)::

    report.md, report.html   the summary (settings, run outcomes, every table, plots; the html is
                             self-contained: plots inline as base64 PNG)
    summary.md, tables/, runs.csv, metrics.json, settings.yaml   as written by `gevi eval`
                             (tables/<key>.md|.csv|.tex; posyaw_* tables; runtime.*)
    plots/                   per sequence trajectories/errors and the ATE bar chart (gevi eval's)
    results.json             per run: state, frames, ATE/RPE, scale (path and median step ratio); skipped
                             sequences (what `gevi regress` reads)

Tables use the code of :mod:`gevi_cli.evaluation.tables` (one formatter for `gevi eval` and batch).
"""
from __future__ import annotations

import base64
import html
import json
import re
import time
from pathlib import Path

from gevi_cli.batch.plan import deterministic
from gevi_cli.evaluation.tables import Cell, Table, render_markdown

#: timing.csv columns of the runtime table (ms per frame), in pipeline order
RUNTIME_STAGES = ("total", "read", "frontend", "verify", "noise", "pose", "keyframe", "ba")
#: the tables report.md shows first (the rest follow)
HEADLINE = ("ate_trans_rmse", "rpe_trans_rmse")


def runtime_table(runs, methods) -> Table:
    """Mean ms per frame of each stage, over every frame of every finished run of a method."""
    import pandas as pd

    cells, fps = {}, {}
    for m in methods:
        frames = []
        rates = []
        for r in runs:
            if r["method"] != m or r["state"] == "crashed":
                continue
            p = Path(r["run_dir"]) / "timing.csv"
            if p.is_file():
                frames.append(pd.read_csv(p))
            if r.get("elapsed_s"):
                rates.append(r["frames_done"] / r["elapsed_s"])
        if not frames:
            continue
        df = pd.concat(frames)
        for stage in RUNTIME_STAGES:
            col = f"{stage}_ms"
            if col in df:
                cells[(stage, m)] = Cell(values=[float(df[col].mean())], n_trials=1)
        fps[m] = sum(rates) / len(rates) if rates else float("nan")
    note = "frames/s (frames over wall time of the odometry, mean over runs): " + ", ".join(
        f"{m} {fps[m]:.1f}" for m in methods if m in fps)
    return Table("runtime", "Runtime per stage [ms per frame] — mean over every frame of every run", list(methods),
                 list(RUNTIME_STAGES), cells, note=note, average_row=False, row_label="stage")


#: the roll/pitch numbers `gevi run` writes into status.json for a stereo-inertial run: (key, title)
TILT_METRICS = (("tilt_rmse_deg", "Roll/pitch error RMSE [deg] — gravity direction, no alignment"),
                ("tilt_trend_deg_per_min", "Roll/pitch error trend [deg/min] — slope over 5 s windows after the "
                                           "initialisation (runs of 15 s or more)"))


def tilt_tables(runs, methods, sequences) -> list[Table]:
    """Per stereo-inertial method and sequence, the trials' roll/pitch RMSE and its trend (each run's
    ``tilt_*`` numbers, which :func:`~gevi_cli.batch.evaluate.evaluate_batch` took from its status.json)."""
    tables = []
    for key, title in TILT_METRICS:
        cells = {}
        for r in runs:
            if r["method"] not in methods or r["state"] == "crashed":
                continue
            v = r.get(key)
            cell = cells.setdefault((r["sequence"], r["method"]), Cell())
            cell.n_trials += 1
            if v is not None:
                cell.values.append(float(v))
                cell.n_lost += int(r["state"] == "lost-tracking")
        table = Table(key, title, list(methods), list(sequences), cells)
        if not table.is_empty():
            tables.append(table)
    return tables


def _online_tables(res, methods, sequences, settings) -> list[Table]:
    """ATE and RPE of the online trajectories (``eval: online``), keys prefixed ``online_``."""
    from gevi_cli.evaluation.report import build_tables

    if not res.online:
        return []
    out = []
    for t in build_tables(res.online, methods, sequences, settings):
        if t.key in HEADLINE:
            t.key, t.title = f"online_{t.key}", f"online: {t.title}"
            out.append(t)
    return out


def _tables(res, methods, sequences, inertial, settings):
    from gevi_cli.evaluation.report import build_tables

    se3 = build_tables(res.se3, methods, sequences, settings)
    for t in se3:
        t.title = t.title.replace("— alignment:", "— SE(3), body frame; alignment:")
    posyaw = []
    imethods = [m for m in methods if m in inertial]
    if imethods and res.posyaw:
        for t in build_tables(res.posyaw, imethods, sequences, settings):
            if t.key.startswith(("kitti", "scale_")):
                continue  # the scale figures do not depend on the alignment: the SE(3) tables hold them
            t.key = f"posyaw_{t.key}"
            t.title = f"posyaw (4-DOF, gravity known): {t.title}"
            posyaw.append(t)
    return se3, posyaw


def write_batch_report(report_dir: Path, cfg, specs, baselines, res, settings, *, skipped, elapsed_s: float,
                       executor: str) -> Path:
    """Write the report folder; returns the path of report.md."""
    from gevi_cli import __version__
    from gevi_cli.evaluation.report import write_report

    report_dir.mkdir(parents=True, exist_ok=True)
    methods = [m.name for m in cfg.methods] + list(dict.fromkeys(b.name for b in baselines))
    sequences = [s.name for s in cfg.sequences if not s.skip_reason]
    inertial = {m.name for m in cfg.methods if m.method == "gevi"}
    se3, posyaw = _tables(res, methods, sequences, inertial, settings)
    runtime = runtime_table(res.runs, [m.name for m in cfg.methods])
    tilt = tilt_tables(res.runs, [m.name for m in cfg.methods if m.name in inertial], sequences)
    online = _online_tables(res, [m.name for m in cfg.methods], sequences, settings)
    tables = se3 + posyaw + tilt + online + [runtime]
    seq_info = {s: {"poses": len(g), "span_s": g.duration_s, "path_length_m": g.path_length_m}
                for s, g in res.gts.items()}
    inputs = {"config": str(cfg.path), "runs": {s.run_id: s.run_dir for s in specs},
              "baselines": {f"{b.name}/{b.sequence}" + (f"/{b.trial}" if b.trial else ""): b.path
                            for b in baselines}}
    write_report(report_dir, tables, res.se3 + res.posyaw, seq_info, settings, inputs)
    plots = []
    if cfg.eval.plots:
        from gevi_cli.evaluation.plots import plot_sequence, plot_summary

        pdir = report_dir / "plots"
        for s in sequences:
            if s in res.gts:
                plots += plot_sequence(pdir, s, res.gts[s], [r for r in res.se3 if r.sequence == s])
        ate = next((t for t in se3 if t.key == "ate_trans_rmse"), None)
        if ate is not None and not ate.is_empty():
            plots += plot_summary(pdir, ate)
    pngs = [p for p in plots if p.suffix == ".png"]
    results_doc = {"batch": cfg.name, "config": str(cfg.path), "gevi_version": __version__,
                   "runs": _clean(res.runs), "skipped": skipped,
                   "baselines": [{"name": b.name, "sequence": b.sequence, "trial": b.trial, "state": b.state,
                                  "reason": b.reason}
                                 for b in baselines],
                   "cells": _cells(se3)}
    (report_dir / "results.json").write_text(json.dumps(results_doc, indent=1) + "\n")
    md = _markdown(cfg, specs, baselines, res, se3, posyaw + tilt, online, runtime, skipped, pngs, report_dir,
                   elapsed_s, executor, __version__)
    (report_dir / "report.md").write_text(md)
    (report_dir / "report.html").write_text(markdown_to_html(md, report_dir, f"gevi batch: {cfg.name}"))
    return report_dir / "report.md"


def _clean(runs):
    out = []
    for r in runs:
        d = {k: v for k, v in r.items() if k != "run_dir"}
        d["run_dir"] = str(r["run_dir"])
        out.append(d)
    return out


def _cells(tables):
    """{table key: {sequence: {method: {mean, std, n_ok, n_trials}}}} for regress."""
    out = {}
    for t in tables:
        d = out.setdefault(t.key, {})
        for (s, m), c in t.cells.items():
            d.setdefault(s, {})[m] = {"mean": None if c.failed else c.stat("mean"),
                                      "std": None if c.failed else c.stat("std"), "n_ok": c.n_ok,
                                      "n_trials": c.n_trials, "reasons": c.reasons}
    return out


def _markdown(cfg, specs, baselines, res, se3, posyaw, online, runtime, skipped, pngs, report_dir, elapsed_s,
              executor, version) -> str:
    states = {}
    for r in res.runs:
        states[r["state"]] = states.get(r["state"], 0) + 1
    not_run = len(specs) - len(res.runs)
    counts = ", ".join(f"{n} {s}" for s, n in sorted(states.items())) + (f", {not_run} not run" if not_run else "")
    worker_s = sum(r.get("wall_s", 0.0) for r in res.runs)
    intro = (f"Config `{cfg.path.name}`, gevi {version}, {time.strftime('%Y-%m-%d %H:%M %Z')}; {len(specs)} runs "
             f"({counts}) taking {worker_s:.0f} s of worker time; this invocation {elapsed_s:.0f} s ({executor}).")
    rules = ("Every comparison across methods: SE(3) alignment over all poses, body frame, RPE over consecutive "
             f"frames (delta {cfg.eval.rpe_delta:g} frame); estimates covering less than "
             f"{100 * cfg.eval.min_coverage:g} % of the ground-truth time span are `failed`. Trials: mean ± std and "
             "median (min, max); trial k runs with `--seed k` (GeVI's 3-point RANSAC; CFO's 5-point RANSAC, "
             "OpenCV's, keeps a seed of its own, so its trials differ only by a `seed_per_trial` render). **Bold** "
             "best, _italic_ second. `failed`: the run broke (crashed, no trajectory, or too little coverage); "
             "`n/a`: never run; `[k/N lost tracking]`: k of "
             "the N trials lost tracking and bridged the frames they could not track (constant velocity; the IMU "
             "for gevi), so their numbers are not those of a run that tracked throughout.")
    import sys

    command = " ".join(["gevi"] + sys.argv[1:]) if Path(sys.argv[0]).name in ("gevi", "cli.py") else ""
    L = [f"# gevi batch: {cfg.name}", "", intro + (f" Command: `{command}`." if command else ""), "", rules, ""]
    L += ["## Settings", "", "| method | `gevi run` options | trials |", "|---|---|---|"]
    L += [f"| {m.name} | `{' '.join(m.args)}` | {m.trials} |" for m in cfg.methods]
    once = [m.name for m in cfg.methods if m.trials > 1 and deterministic(m.method)]
    if once:
        L += ["", f"{', '.join(once)}: deterministic (CFO takes no seed; OpenCV's 5-point RANSAC keeps its own), so "
                  "it ran once per sequence, not once per trial, except on `seed_per_trial` renders."]
    L += ["", "| sequence | source | methods |", "|---|---|---|"]
    for s in cfg.sequences:
        if s.sim is not None:
            opts = {k: v for k, v in s.sim.__dict__.items() if v not in (None, (), False) or k in ("seed",)}
            src = "render " + ", ".join(f"{k}={v}" for k, v in opts.items())
            if s.seed_per_trial:
                src += " (seed = trial)"
        else:
            src = f"`{_short(s.path, cfg.root)}`" + (f", max_frames {s.inputs.max_frames}" if s.inputs.max_frames else "")
        src += f", stride {s.inputs.stride}" if s.inputs.stride > 1 else ""
        note = f" — skipped: {s.skip_reason}" if s.skip_reason else ""
        L.append(f"| {s.name} | {src}{note} | {', '.join(s.methods) if s.methods else 'all'} |")
    if cfg.baselines:
        L += ["", "| baseline | trajectories | format | frame | T_B_C0 |", "|---|---|---|---|---|"]
        for b in cfg.baselines:
            T = b.T_B_C0 if isinstance(b.T_B_C0, str) else "4x4 in the config"
            T = _short(T, cfg.root) if isinstance(T, str) and "/" in T else T
            files = "/" + (b.files[0] if len(b.files) == 1 else "{" + ",".join(b.files) + "}") if b.files else ""
            stamps = " (stamped with the sequence's frame times)" if b.stamps else ""
            L.append(f"| {b.name} | `{_short(b.path, cfg.root)}{files}`{stamps}"
                     f"{' — skipped: ' + b.skip_reason if b.skip_reason else ''} | {b.fmt} | {b.frame} | {T} |")
    if skipped:
        L += ["", "Skipped sequences: " + "; ".join(f"{d['sequence']} ({d['reason']})" for d in skipped) + "."]
    bad = [r for r in res.runs if r["state"] != "ok"]
    if bad:
        L += ["", "## Runs that lost tracking or crashed", "", "| run | state | message |", "|---|---|---|"]
        L += [f"| {r['run_id']} | {r['state']} | {r['message'].replace('|', '/')} |" for r in bad]
    failed = [r for r in res.se3 if not r.ok]
    if failed:
        L += ["", "Failed cells: " + "; ".join(f"{r.method} on {r.sequence}{' ' + r.trial if r.trial else ''}: "
                                               f"{r.reason}" for r in failed) + "."]
    if res.problems:
        L += ["", "Not evaluated: " + "; ".join(res.problems) + "."]
    calibrated = [r for r in res.runs if r.get("disparity_offset_px")]
    if calibrated:
        L += ["", "## Beyond the published methods", "",
              "These runs corrected the stereo pair's disparity offset found by the self-calibration (docs/method.md "
              "4; `--set triangulation.self_calibrate=false` runs without it), from the frame given (0: the run restarted with it, and its online "
              "trajectory is then not causal):", "", "| run | offset applied [px] | from frame |", "|---|---|---|"]
        L += [f"| {r['run_id']} | {r['disparity_offset_px']:+.3f} | {r['disparity_offset_from_frame']} |"
              for r in calibrated]
    order = sorted(se3, key=lambda t: (t.key not in HEADLINE, HEADLINE.index(t.key) if t.key in HEADLINE else 0))
    L += ["", "## Accuracy (SE(3), body frame)", ""] + [render_markdown(t) for t in order]
    if posyaw:
        L += ["## Stereo-inertial methods: posyaw alignment, roll/pitch against gravity", ""]
        L += [render_markdown(t) for t in posyaw if "rot_mean" not in t.key]
    if online:
        L += ["## Online trajectories (as tracked, before the BA of their window), SE(3)", ""]
        restarted = [r["run_id"] for r in res.runs if not r.get("online_causal", True)]
        if restarted:
            L += ["Not causal (restarted with the disparity offset found later in the run): "
                  + ", ".join(restarted) + ".", ""]
        L += [render_markdown(t) for t in online]
    L += ["## Runtime", "", render_markdown(runtime)]
    if pngs:
        L += ["## Plots", ""] + [f"![{p.stem}]({p.relative_to(report_dir)})" for p in pngs] + [""]
    L += [("Every table also as CSV and LaTeX in `tables/`; every number in `metrics.json`; per run in "
           "`results.json` and `runs.csv`."), ""]
    return "\n".join(L)


def _short(p: str, root: Path) -> str:
    """``p`` relative to the config's root (how the config wrote it; no machine-specific prefix)."""
    import os

    return os.path.relpath(p, root) if Path(p).is_absolute() else str(p)


# -------------------------------------------------------------------------------------- html
def _inline(text: str) -> str:
    t = html.escape(text)
    t = re.sub(r"`([^`]+)`", r"<code>\1</code>", t)
    t = re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", t)
    t = re.sub(r"(?<![\w])_([^_|]+?)_(?![\w])", r"<i>\1</i>", t)
    return t


def markdown_to_html(md: str, base: Path, title: str) -> str:
    """The report's Markdown (headings, paragraphs, tables, images) as one self-contained HTML page."""
    style = ("body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}"
             "td:first-child,th:first-child{text-align:left}img{max-width:100%}")
    head = f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
    out = [f"{head}<style>{style}</style></head><body>"]
    lines = md.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].startswith("|"):
                rows.append([c.strip() for c in lines[i].strip().strip("|").split("|")])
                i += 1
            body = [r for r in rows[1:] if not all(set(c) <= set("-: ") for c in r)]
            out.append("<table><tr>" + "".join(f"<th>{_inline(c)}</th>" for c in rows[0]) + "</tr>")
            out += ["<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in body]
            out.append("</table>")
            continue
        m = re.match(r"(#+) (.*)", line)
        img = re.match(r"!\[([^\]]*)\]\(([^)]+)\)", line)
        if m:
            n = len(m.group(1))
            out.append(f"<h{n}>{_inline(m.group(2))}</h{n}>")
        elif img:
            p = base / img.group(2)
            if p.is_file():
                data = base64.b64encode(p.read_bytes()).decode()
                out.append(f"<p><img alt='{html.escape(img.group(1))}' src='data:image/png;base64,{data}'></p>")
        elif line.strip():
            out.append(f"<p>{_inline(line)}</p>")
        i += 1
    out.append("</body></html>")
    return "\n".join(out)


