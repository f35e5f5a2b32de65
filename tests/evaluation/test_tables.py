"""Table rendering: best bold, second marked, trials as mean ± std and median (min, max), failed cells."""
import numpy as np

from gevi_cli.evaluation.tables import Cell, Table, render_csv, render_latex, render_markdown


def _table(trials=False):
    cells = {
        ("s1", "a"): Cell([1.0], 1), ("s1", "b"): Cell([2.0], 1), ("s1", "c"): Cell([3.0], 1),
        ("s2", "a"): Cell([0.5], 1), ("s2", "b"): Cell([], 1, ["missing"]), ("s2", "c"): Cell([0.25], 1),
    }
    if trials:
        cells[("s1", "a")] = Cell([1.0, 2.0, 4.0], 4, ["coverage"])
    return Table("ate", "ATE translation RMSE [m] — alignment: se3 (all poses)", ["a", "b", "c"], ["s1", "s2"], cells)


def _row(md, label):
    return [c.strip() for c in next(line for line in md.splitlines() if line.startswith(f"| {label} ")).strip("|").split("|")]


def test_markdown_marks_best_and_second_and_failed():
    md = render_markdown(_table())
    assert "alignment: se3" in md.splitlines()[0]
    assert _row(md, "s1") == ["s1", "**1.000**", "_2.000_", "3.000"]
    assert _row(md, "s2") == ["s2", "_0.5000_", "failed", "**0.2500**"]
    assert _row(md, "average") == ["average", "**0.7500**", "n/a", "_1.625_"]


def test_trials_mean_std_and_median_min_max():
    md = render_markdown(_table(trials=True))
    v = np.array([1.0, 2.0, 4.0])
    s1 = _row(md, "s1")
    assert s1[1] == f"_{v.mean():.3f} ± {v.std(ddof=1):.3f} [1/4 failed]_"  # 2.333 > 2.0 (b): second
    assert s1[2] == "**2.000**"
    med = _row(md, "s1 median (min, max)")
    assert med[1] == "**2.000 (1.000, 4.000) [1/4 failed]**" or med[1] == "_2.000 (1.000, 4.000) [1/4 failed]_"
    csv = render_csv(_table(trials=True))
    assert "s1,std," in csv and "s1,n_trials,4,1,1" in csv


def test_latex_marks():
    tex = render_latex(_table())
    assert "\\textbf{1.000}" in tex and "\\underline{2.000}" in tex and "\\toprule" in tex
    assert "se3" in tex


def test_ties_share_rank_and_single_method_unmarked():
    t = Table("x", "X", ["a", "b"], ["s"], {("s", "a"): Cell([1.0], 1), ("s", "b"): Cell([1.0], 1)})
    assert _row(render_markdown(t), "s") == ["s", "**1.000**", "**1.000**"]
    t = Table("x", "X", ["a"], ["s"], {("s", "a"): Cell([1.0], 1)})
    assert _row(render_markdown(t), "s") == ["s", "1.000"]


def test_lost_tracking_is_said_in_the_cell():
    t = _table()
    t.cells[("s1", "c")] = Cell([3.0], 1, n_lost=1)
    t.cells[("s2", "a")] = Cell([0.5, 0.7], 2, n_lost=1)
    md = render_markdown(t)
    assert _row(md, "s1")[3] == "3.000 [lost tracking]"
    assert _row(md, "s2")[1] == "_0.6000 ± 0.1414 [1/2 lost tracking]_"  # second after c (0.25)
