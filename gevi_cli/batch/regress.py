"""`gevi regress`: a batch's ATE/RPE/frames tracked against committed expected values (the CI gate).

One-sided: a value *worse* than expected by more than its tolerance fails (ATE or RPE larger,
fewer frames tracked); a better one is reported.  Values compared are means over trials of the SE(3)
body-frame numbers in ``report/results.json``.

Tolerances (stated in the expected file, written by ``--write-expected``)::

    tol = max(k_std * std over trials, rel_floor * |expected|, abs_floor)

``std`` is the sample standard deviation over the trials (RANSAC seed k; render seed k where the
sequence says ``seed_per_trial``); the floors keep a run whose trials agree to the last bit (RANSAC on
clean data finds the same inliers whatever the seed) from failing on the last digit, e.g. another
BLAS on another machine.  Frames tracked: ``max(k_std * std, frames_rel_floor * frames, 1)`` frames.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from gevi_cli.errors import GeviError

METRICS = (("ate_m", "ATE"), ("rpe_m", "RPE"), ("frames_tracked", "frames tracked"))
DEFAULT_RULE = {"k_std": 3.0, "rel_floor": 0.10, "abs_floor_m": 1e-5, "frames_rel_floor": 0.02}


@dataclass
class Row:
    sequence: str
    method: str
    metric: str
    expected: float
    tol: float
    measured: float | None
    verdict: str  # ok / better / WORSE / FAILED


def measured_values(results_dir: Path) -> tuple[dict, list, dict]:
    """({(sequence, method): {metric: (mean, std, n)}}, skipped sequences, {(seq, method): failure})."""
    p = Path(results_dir) / "report" / "results.json"
    if not p.is_file():
        p = Path(results_dir) / "results.json"
    if not p.is_file():
        raise GeviError(results_dir, "no report/results.json: not a `gevi batch` results folder (or not finished)")
    try:
        doc = json.loads(p.read_text())
    except ValueError as exc:
        raise GeviError(p, f"not valid JSON: {exc}") from None
    groups: dict = {}
    failures: dict = {}
    for r in doc.get("runs", []):
        key = (r["sequence"], r["method"])
        g = groups.setdefault(key, {m: [] for m, _ in METRICS})
        if r["state"] == "crashed" or r.get("ate_m") is None:
            failures[key] = r.get("message") or r["state"]
            continue
        for m, _ in METRICS:
            if r.get(m) is not None:
                g[m].append(float(r[m]))
    out = {}
    for key, g in groups.items():
        out[key] = {}
        for m, vals in g.items():
            if vals:
                mean = sum(vals) / len(vals)
                std = math.sqrt(sum((v - mean) ** 2 for v in vals) / (len(vals) - 1)) if len(vals) > 1 else 0.0
                out[key][m] = (mean, std, len(vals))
    return out, doc.get("skipped", []), failures


def tolerance(metric: str, mean: float, std: float, rule: dict) -> float:
    if metric == "frames_tracked":
        return max(rule["k_std"] * std, rule["frames_rel_floor"] * mean, 1.0)
    return max(rule["k_std"] * std, rule["rel_floor"] * abs(mean), rule["abs_floor_m"])


HEADER = """\
# Expected results of `gevi batch {config}` for `gevi regress` (the CI gate).
# Written by `gevi regress RESULTS --write-expected FILE` from a real batch ({batch}, gevi {version}).
# Per (sequence, method): the mean over trials of ATE and RPE (SE(3), body frame, RPE over 1 frame;
# metres) and of the frames tracked, their spread over trials (std: sample standard deviation; trial k
# runs with RANSAC seed k, and with render seed k for a seed_per_trial sequence) and the tolerance
#     tol = max(k_std * std, rel_floor * expected, abs_floor_m)      (frames: max(k_std * std,
#                                                                     frames_rel_floor * expected, 1))
# with the rule below.  The gate is one-sided: measured > expected + tol (frames: < expected - tol)
# fails; measured < expected - tol is reported as better (update this file when that is on purpose).
"""


def write_expected(results_dir: Path, target: Path, rule: dict | None = None) -> Path:
    from gevi_cli import __version__

    rule = dict(DEFAULT_RULE, **(rule or {}))
    vals, skipped, failures = measured_values(results_dir)
    if failures:
        k, why = next(iter(failures.items()))
        raise GeviError(results_dir, f"{k[1]} on {k[0]} failed ({why}); expected values come from a batch whose runs "
                                     "all finished")
    entries: dict = {}
    for (seq, method), mv in sorted(vals.items()):
        e = entries.setdefault(seq, {})[method] = {}
        for m, _ in METRICS:
            if m in mv:
                mean, std, n = mv[m]
                e[m] = {"expected": float(f"{mean:.6g}"), "std": float(f"{std:.3g}"), "trials": n,
                        "tol": float(f"{tolerance(m, mean, std, rule):.3g}")}
    doc = json.loads((Path(results_dir) / "report" / "results.json").read_text())
    text = HEADER.format(config=Path(doc.get("config", "?")).name, batch=doc.get("batch", "?"), version=__version__)
    if skipped:
        text += "# Sequences skipped when this was measured: " + ", ".join(s["sequence"] for s in skipped) + "\n"
    text += yaml.safe_dump({"rule": rule, "entries": entries}, sort_keys=False)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(text)
    return target


def load_expected(path: Path) -> tuple[dict, dict]:
    if not Path(path).is_file():
        raise GeviError("--against", f"{path}: no such file")
    from gevi_cli.datasets.yamlio import load_yaml

    doc = load_yaml(Path(path), what="expected-values file")
    if not isinstance(doc.get("entries"), dict):
        raise GeviError(path, "expected keys rule: and entries: {sequence: {method: {metric: {expected, tol}}}}")
    for seq, methods in doc["entries"].items():
        for method, metrics in (methods or {}).items():
            for m, v in (metrics or {}).items():
                if m not in dict(METRICS) or not isinstance(v, dict) or not {"expected", "tol"} <= set(v):
                    raise GeviError(path, f"entries.{seq}.{method}.{m}: expected a metric "
                                          f"({', '.join(dict(METRICS))}) with expected: and tol:")
    return doc["entries"], doc.get("rule", {})


def compare(results_dir: Path, expected_path: Path) -> tuple[list, list]:
    """(rows, notes); rows hold a verdict per (sequence, method, metric)."""
    entries, _ = load_expected(expected_path)
    vals, skipped, failures = measured_values(results_dir)
    skipped_names = {s["sequence"]: s["reason"] for s in skipped}
    rows, notes = [], []
    for seq, methods in entries.items():
        if seq in skipped_names:
            notes.append(f"{seq}: left out, the batch skipped it ({skipped_names[seq]})")
            continue
        for method, metrics in methods.items():
            mv = vals.get((seq, method))
            for m, spec in metrics.items():
                exp, tol = float(spec["expected"]), float(spec["tol"])
                if (seq, method) in failures or mv is None or m not in mv:
                    why = failures.get((seq, method), "not in the batch")
                    rows.append(Row(seq, method, m, exp, tol, None, "FAILED"))
                    notes.append(f"{method} on {seq}: {why}")
                    continue
                got = mv[m][0]
                worse = got < exp - tol if m == "frames_tracked" else got > exp + tol
                better = got > exp + tol if m == "frames_tracked" else got < exp - tol
                rows.append(Row(seq, method, m, exp, tol, got, "WORSE" if worse else "better" if better else "ok"))
    for key in sorted(set(vals) - {(s, m) for s, ms in entries.items() for m in ms}):
        notes.append(f"{key[1]} on {key[0]}: no expected values (not gated)")
    return rows, notes


def render(rows: list) -> str:
    def f(x, metric):
        if x is None:
            return "—"
        return f"{x:.0f}" if metric == "frames_tracked" else f"{x * 1e3:.4g} mm"

    lines = ["| sequence | method | metric | expected | tolerance | measured | diff | verdict |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        diff = "—" if r.measured is None else (
            f"{r.measured - r.expected:+.0f}" if r.metric == "frames_tracked" else
            f"{100 * (r.measured - r.expected) / r.expected:+.1f} %" if r.expected else f"{r.measured - r.expected:+.3g}")
        label = dict(METRICS)[r.metric]
        lines.append(f"| {r.sequence} | {r.method} | {label} | {f(r.expected, r.metric)} | {f(r.tol, r.metric)} | "
                     f"{f(r.measured, r.metric)} | {diff} | {r.verdict} |")
    return "\n".join(lines)
