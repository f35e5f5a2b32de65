"""Tables of one metric: rows = sequences (+ an average row), columns = methods.

A cell holds the values of every trial (run) of a method on a sequence:

* one trial: the value; ``failed`` when it failed (missing, no valid poses, low coverage);
* N trials: ``mean ± std`` (sample std, ddof=1) on the sequence row, and ``median (min, max)`` on an
  extra row below it; failed trials are left out and counted (``[k/N failed]``); all failed -> ``failed``.
* a trial that succeeded but has no value for the metric (a scale ratio of a sequence at rest) is left
  out and counted (``[k/N n/a]``); no value and no failure -> ``n/a``.

In each row the best value is **bold** and the second best is marked: Markdown and console ``_x_``,
LaTeX ``\\underline{x}`` (and ``\\textbf`` for the best).  Best is the lowest (an error) or, for a table
with a ``target`` (a scale ratio: 1), the closest to the target.
The average row is the mean over sequences of the per-sequence means; it is ``n/a`` for a method that
failed on some sequence (an average over a subset would not compare).
"""
from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Cell:
    """Values (one per successful trial) and the trial count of one (sequence, method)."""

    values: list = field(default_factory=list)
    n_trials: int = 0
    reasons: list = field(default_factory=list)
    n_lost: int = 0  # trials among the values whose run lost tracking (poses partly bridged)
    n_na: int = 0  # trials that succeeded but whose value is undefined (n/a: e.g. no motion to read a scale from)

    @property
    def n_ok(self) -> int:
        return len(self.values)

    @property
    def failed(self) -> bool:
        return self.n_ok == 0

    def stat(self, name: str) -> float:
        if not self.values:
            return float("nan")
        v = np.asarray(self.values, dtype=np.float64)
        if name == "mean":
            return float(v.mean())
        if name == "std":
            return float(v.std(ddof=1)) if len(v) > 1 else 0.0
        if name == "median":
            return float(np.median(v))
        if name == "min":
            return float(v.min())
        if name == "max":
            return float(v.max())
        raise KeyError(name)


@dataclass
class Table:
    """One metric over methods x sequences; ``title`` names metric, unit and alignment."""

    key: str
    title: str
    methods: list
    sequences: list
    cells: dict = field(default_factory=dict)  # (sequence, method) -> Cell
    note: str = ""
    average_row: bool = True  # False for tables whose rows are not sequences (a runtime table's stages)
    row_label: str = "sequence"  # header of the first column
    target: float | None = None  # None: the lowest value is best; else the closest to it (|v - target|)

    def cell(self, sequence: str, method: str) -> Cell:
        return self.cells.get((sequence, method), Cell())

    @property
    def has_trials(self) -> bool:
        return any(c.n_trials > 1 for c in self.cells.values())

    def is_empty(self) -> bool:
        return all(not c.values or all(math.isnan(x) for x in c.values) for c in self.cells.values())

    def average(self, method: str) -> float:
        means = [self.cell(s, method).stat("mean") for s in self.sequences]
        if not means or any(math.isnan(m) for m in means):
            return float("nan")
        return float(np.mean(means))

    def rows(self):
        """Yield (label, kind, {method: (text parts)}, {method: ranking value}) for rendering.

        kind is "mean" (plain or mean±std), "median" (median (min, max)) or "average".
        """
        trials = self.has_trials
        for s in self.sequences:
            yield s, "mean", {m: self.cell(s, m) for m in self.methods}
            if trials:
                yield f"{s} median (min, max)", "median", {m: self.cell(s, m) for m in self.methods}
        if self.average_row and (len(self.sequences) > 1 or not trials):
            yield "average", "average", {m: self.average(m) for m in self.methods}


def fmt(v: float) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "n/a"
    a = abs(v)
    if a >= 100:
        return f"{v:.1f}"
    if a >= 1:
        return f"{v:.3f}"
    if a >= 0.1 or a == 0:
        return f"{v:.4f}"
    # three significant digits below 0.1: sub-millimetre errors in metres stay readable (0.000712)
    return f"{v:.{2 - math.floor(math.log10(a))}f}"


def _fmt_like(v: float, ref: str) -> str:
    """``v`` with the decimals of ``ref``: a spread printed to the precision of its mean (the CSV
    tables hold the exact values)."""
    if v is None or math.isnan(v):
        return "n/a"
    decimals = len(ref.split(".")[1]) if "." in ref else 0
    return f"{v:.{decimals}f}"


def _cell_text(kind: str, c) -> tuple[str, float]:
    """(text without marks, value used for ranking)."""
    if kind == "average":
        return fmt(c), c
    if c.n_trials == 0:  # never run (e.g. a baseline that does not exist for this sequence)
        return "n/a", float("nan")
    n_failed = c.n_trials - c.n_ok - c.n_na
    failed_note = f" [{n_failed}/{c.n_trials} failed]" if n_failed else ""
    if c.failed:
        return ("n/a" + failed_note if c.n_na else "failed"), float("nan")
    if c.n_na:
        failed_note += f" [{c.n_na}/{c.n_trials} n/a]"
    if c.n_lost:  # a number, but not one of a run that tracked throughout: say so in the cell
        failed_note += f" [{c.n_lost}/{c.n_trials} lost tracking]" if c.n_trials > 1 else " [lost tracking]"
    if kind == "median":
        if c.n_trials <= 1:
            return fmt(c.stat("median")) + failed_note, c.stat("median")
        return f"{fmt(c.stat('median'))} ({fmt(c.stat('min'))}, {fmt(c.stat('max'))}){failed_note}", c.stat("median")
    if c.n_trials > 1:
        mean = fmt(c.stat("mean"))
        return f"{mean} ± {_fmt_like(c.stat('std'), mean)}{failed_note}", c.stat("mean")
    return fmt(c.stat("mean")) + failed_note, c.stat("mean")


def _ranks(values: dict) -> dict:
    """method -> 1 (best), 2 (second) or 0; lowest is best, NaN never ranked, ties share the rank."""
    finite = sorted({v for v in values.values() if not math.isnan(v)})
    out = {}
    for m, v in values.items():
        if math.isnan(v) or len(values) < 2:
            out[m] = 0
        elif v == finite[0]:
            out[m] = 1
        elif len(finite) > 1 and v == finite[1]:
            out[m] = 2
        else:
            out[m] = 0
    return out


MARKS = {
    "markdown": ("**{}**", "_{}_"),
    "latex": ("\\textbf{{{}}}", "\\underline{{{}}}"),
    "console": ("**{}**", "_{}_"),
}


def _grid(table: Table, style: str) -> list[list[str]]:
    best, second = MARKS[style]
    grid = [[table.row_label] + list(table.methods)]
    for label, kind, cells in table.rows():
        texts, vals = {}, {}
        for m, c in cells.items():
            texts[m], vals[m] = _cell_text(kind, c)
        if table.target is not None:
            vals = {m: abs(v - table.target) for m, v in vals.items()}
        ranks = _ranks(vals)
        row = [label]
        for m in table.methods:
            t = texts[m]
            if style == "latex":
                t = t.replace("±", "$\\pm$").replace("_", "\\_")
            if ranks[m] == 1:
                t = best.format(t)
            elif ranks[m] == 2:
                t = second.format(t)
            row.append(t)
        grid.append(row)
    return grid


def render_markdown(table: Table, console: bool = False) -> str:
    """GitHub Markdown table (bold best, ``_second_``); ``console`` uses ``*best*`` and ``second'``."""
    grid = _grid(table, "console" if console else "markdown")
    widths = [max(len(r[i]) for r in grid) for i in range(len(grid[0]))]
    lines = [f"### {table.title}" if not console else table.title]
    if table.note:
        lines.append(table.note if console else f"_{table.note}_")
    if not console:
        lines.append("")
    for k, r in enumerate(grid):
        lines.append("| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |")
        if k == 0:
            lines.append("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    return "\n".join(lines) + "\n"


def render_latex(table: Table) -> str:
    grid = _grid(table, "latex")
    esc = lambda s: s.replace("_", "\\_").replace("%", "\\%")  # noqa: E731
    cols = "l" + "r" * len(table.methods)
    out = ["% " + table.title, "\\begin{tabular}{" + cols + "}", "\\toprule",
           " & ".join(esc(c) for c in grid[0]) + " \\\\", "\\midrule"]
    for r in grid[1:]:
        if r[0] == "average":
            out.append("\\midrule")
        out.append(" & ".join([esc(r[0])] + r[1:]) + " \\\\")
    out += ["\\bottomrule", "\\end{tabular}"]
    caption = esc(table.title + (f" ({table.note})" if table.note else ""))
    return "\\begin{table}[t]\n\\centering\n\\caption{" + caption + "}\n" + "\n".join(out) + "\n\\end{table}\n"


def render_csv(table: Table) -> str:
    """Plain numbers: one row per (sequence, statistic); columns = methods (empty = failed)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["sequence", "statistic"] + list(table.methods))
    stats = ["mean", "std", "median", "min", "max"] if table.has_trials else ["value"]

    def num(v):
        return "" if v is None or math.isnan(v) else repr(float(v))

    for s in table.sequences:
        for st in stats:
            w.writerow([s, st] + [num(table.cell(s, m).stat("mean" if st == "value" else st)) for m in table.methods])
        if table.has_trials:
            w.writerow([s, "n_ok"] + [table.cell(s, m).n_ok for m in table.methods])
            w.writerow([s, "n_trials"] + [table.cell(s, m).n_trials for m in table.methods])
    if table.average_row:
        w.writerow(["average", "mean"] + [num(table.average(m)) for m in table.methods])
    return buf.getvalue()
