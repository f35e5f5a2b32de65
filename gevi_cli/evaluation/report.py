"""The eval folder: tables (Markdown, CSV, LaTeX), ``metrics.json``, ``settings.yaml``, ``runs.csv``.

Layout (see docs/eval.md)::

    <out>/
      summary.md            every table, Markdown (what the console shows)
      tables/<key>.md|.csv|.tex
      tables/all.tex        every table, LaTeX
      runs.csv              one row per estimate (trial) with every scalar
      metrics.json          every number: settings, association, alignment, ATE, RPE, KITTI, scale per estimate,
                            tables
      settings.yaml         the settings and inputs used (re-run documentation)
      plots/                see gevi_cli.evaluation.plots
"""
from __future__ import annotations

import csv
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.evaluation.scale import MIN_STEP_M
from gevi_cli.evaluation.tables import Cell, Table, render_csv, render_latex, render_markdown


@dataclass(frozen=True)
class Metric:
    """One table of `gevi eval`: ``key`` (its file name), ``title``, ``unit`` and ``get``, the value of a
    PairResult (None or NaN: none).  ``target``: None when the lowest value is best (an error), else the
    ideal value (best = closest); ``note``: what the title says of the poses compared (None: the
    alignment of the results)."""

    key: str
    title: str
    unit: str
    get: Callable
    target: float | None = None
    note: str | None = None


#: the scale figures are read before alignment (gevi_cli.evaluation.scale), in the GT's sensor frame
_SCALE_NOTE = "associated poses in the GT's sensor frame, before alignment; best = closest to 1"

METRICS = [
    Metric("ate_trans_rmse", "ATE translation RMSE", "m", lambda r: r.ate and r.ate.trans_rmse),
    Metric("ate_rot_rmse", "ATE rotation RMSE", "deg", lambda r: r.ate and r.ate.rot_rmse_deg),
    Metric("rpe_trans_rmse", "RPE translation RMSE", "m", lambda r: r.rpe and r.rpe.trans_rmse),
    Metric("rpe_trans_mean", "RPE translation mean", "m", lambda r: r.rpe and r.rpe.trans_mean),
    Metric("rpe_rot_rmse", "RPE rotation RMSE", "deg", lambda r: r.rpe and r.rpe.rot_rmse_deg),
    Metric("rpe_rot_mean", "RPE rotation mean", "deg", lambda r: r.rpe and r.rpe.rot_mean_deg),
    Metric("scale_path_ratio", "Scale: path-length ratio", "est/GT", lambda r: r.scale and r.scale.path_ratio,
           target=1.0, note=_SCALE_NOTE),
    Metric("scale_step_ratio_median", f"Scale: median step-length ratio (GT steps >= {100 * MIN_STEP_M:g} cm)",
           "est/GT", lambda r: r.scale and r.scale.step_ratio_median, target=1.0, note=_SCALE_NOTE),
    Metric("kitti_t_err", "KITTI t_err (100-800 m segments)", "%", lambda r: r.kitti and r.kitti.t_err_pct),
    Metric("kitti_r_err", "KITTI r_err (100-800 m segments)", "deg/100 m", lambda r: r.kitti and r.kitti.r_err_deg_per_100m),
]
#: tables left out when no estimate has a value (no 100 m segment anywhere: short sequences)
OPTIONAL_TABLES = ("kitti_t_err", "kitti_r_err")


def _num(v):
    if v is None:
        return float("nan")
    return float(v)


def alignment_note(results, settings) -> str:
    by = {}
    for r in results:
        if r.align:
            by.setdefault(r.align, set()).add(r.method)
    n = "all poses" if settings.n_align is None or settings.n_align < 0 else f"first {settings.n_align} poses"
    if len(by) <= 1:
        a = next(iter(by), settings.align)
        return f"alignment: {a} ({n})"
    parts = [f"{a} ({', '.join(sorted(ms))})" for a, ms in sorted(by.items())]
    return f"alignment: {'; '.join(parts)} ({n})"


def jumps_note(results, settings) -> str:
    """What ``--allow-jumps`` did, for every table's note ("" when it was not given)."""
    if not settings.allow_jumps:
        return ""
    which = list(dict.fromkeys(f"{r.method}/{r.sequence}" for r in results if r.jumps))
    if not which:
        return "--allow-jumps: no input had a position jump"
    return f"--allow-jumps: position jumps read as written (possibly corrupt rows) in {', '.join(which)}"


def build_tables(results, methods, sequences, settings) -> list[Table]:
    note_align = alignment_note(results, settings)
    rpe_note = f"RPE delta {settings.rpe_delta:g} {settings.rpe_unit}"
    jumps = jumps_note(results, settings)
    tables = []
    for metric in METRICS:
        cells = {}
        for r in results:
            c = cells.setdefault((r.sequence, r.method), Cell())
            c.n_trials += 1
            v = _num(metric.get(r)) if r.ok else float("nan")
            if r.ok and not math.isnan(v):
                c.values.append(v)
                c.n_lost += bool(r.lost)
            elif r.ok:
                c.n_na += 1
            else:
                c.reasons.append(r.reason)
        key = metric.key
        t = Table(key, f"{metric.title} [{metric.unit}] — {metric.note or note_align}", list(methods),
                  list(sequences), cells, target=metric.target,
                  note="; ".join(filter(None, [rpe_note if key.startswith("rpe") else "", jumps])))
        if key in OPTIONAL_TABLES and t.is_empty():
            continue
        tables.append(t)
    return tables


def choose_out_dir(out: str | None, default_name: str, overwrite: bool) -> tuple[Path, str | None]:
    """The eval folder; never silently overwrites (returns a notice when a default name was taken)."""
    if out:
        p = Path(out)
        if p.exists() and (not p.is_dir() or any(p.iterdir())) and not overwrite:
            raise GeviError("--out", f"{p} exists and is not empty; choose another folder or pass --overwrite")
        return p, None
    base = Path("eval") / default_name
    p, k = base, 1
    while p.exists() and (not p.is_dir() or any(p.iterdir())):
        k += 1
        p = Path(f"{base}-{k}")
    notice = f"{base} exists; writing to {p}" if p != base else None
    return p, notice


def default_name(sequences, methods, results_root: str | None) -> str:
    if results_root:
        base = Path(results_root).resolve().name
    else:
        seq = "+".join(sequences[:3]) + ("+more" if len(sequences) > 3 else "")
        base = f"{seq}_{'-'.join(methods[:4])}" + ("-more" if len(methods) > 4 else "")
    return re.sub(r"[^A-Za-z0-9._+-]+", "_", base)[:80] or "eval"


def _table_json(t: Table) -> dict:
    d = {}
    for s in t.sequences:
        d[s] = {}
        for m in t.methods:
            c = t.cell(s, m)
            d[s][m] = {k: (None if math.isnan(c.stat(k)) else c.stat(k)) for k in ("mean", "std", "median", "min", "max")}
            d[s][m].update({"n_ok": c.n_ok, "n_na": c.n_na, "n_trials": c.n_trials,
                            "values": list(map(float, c.values))})
    d["average"] = {m: (None if math.isnan(t.average(m)) else t.average(m)) for m in t.methods}
    return {"title": t.title, "note": t.note, "cells": d}


def _clean(o):
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return None if math.isnan(float(o)) else float(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    return o


def _scalars(prefix: str, result) -> dict:
    """``{prefix_name: value}`` of the scalar entries of a result's ``as_dict()`` (none for None)."""
    if result is None:
        return {}
    return {f"{prefix}_{k}": v for k, v in result.as_dict().items() if not isinstance(v, (dict, str))}


def write_report(out: Path, tables, results, sequences_info: dict, settings, inputs: dict) -> list[Path]:
    """Write everything but plots into ``out``; return the written files."""
    from gevi_cli import __version__
    from gevi_cli.evaluation.evo_compat import EVO_VERSION

    out.mkdir(parents=True, exist_ok=True)
    tdir = out / "tables"
    tdir.mkdir(exist_ok=True)
    written = []
    md_all, tex_all = [], []
    for t in tables:
        md, tex, cs = render_markdown(t), render_latex(t), render_csv(t)
        for ext, text in (("md", md), ("tex", tex), ("csv", cs)):
            p = tdir / f"{t.key}.{ext}"
            p.write_text(text)
            written.append(p)
        md_all.append(md)
        tex_all.append(tex)
    failed = [f"- {r.method}/{r.sequence}" + (f"/{r.trial}" if r.trial else "") + f": {r.reason}"
              for r in results if not r.ok]
    why = ["## Failed cells\n\n" + "\n".join(failed) + "\n"] if failed else []
    (out / "summary.md").write_text("# gevi eval\n\n" + "\n".join(md_all + why))
    (tdir / "all.tex").write_text("% requires \\usepackage{booktabs}\n" + "\n".join(tex_all))
    written += [out / "summary.md", tdir / "all.tex"]

    rows = []
    for r in results:
        row = {"method": r.method, "sequence": r.sequence, "trial": r.trial, "status": r.status, "reason": r.reason,
               "align": r.align, "path": r.path}
        if r.association is not None:
            row.update(matched=r.association.n_matched, est_poses=r.association.n_est,
                       coverage_pct=100 * r.association.coverage)
        for key, val in (("ate", r.ate), ("rpe", r.rpe), ("kitti", r.kitti)):
            row.update(_scalars(key, val))
        if r.alignment is not None:
            row["align_scale"] = r.alignment.scale
        row.update(_scalars("scale", r.scale))  # after the columns runs.csv had before it
        rows.append(row)
    keys = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    with open(out / "runs.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for row in rows:
            w.writerow(row)
    written.append(out / "runs.csv")

    metrics = {"gevi_version": __version__, "evo_version": EVO_VERSION, "settings": settings.as_dict(),
               "sequences": sequences_info, "results": [r.as_dict() for r in results],
               "tables": {t.key: _table_json(t) for t in tables}}
    (out / "metrics.json").write_text(json.dumps(_clean(metrics), indent=1))
    import yaml

    (out / "settings.yaml").write_text(yaml.safe_dump(_clean({"settings": settings.as_dict(), "inputs": inputs}),
                                                      sort_keys=False))
    written += [out / "metrics.json", out / "settings.yaml"]
    return written
