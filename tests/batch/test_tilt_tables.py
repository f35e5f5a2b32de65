"""The batch report's roll/pitch tables: each stereo-inertial run's numbers, per sequence and method."""
from __future__ import annotations

import pytest

from gevi_cli.batch.report import tilt_tables


def _run(tmp_path, method, sequence, trial, evaluation, state="ok"):
    """A run as evaluate_batch records it: its status.json's tilt_* numbers copied in."""
    return {"method": method, "sequence": sequence, "trial": trial, "state": state,
            **{k: v for k, v in evaluation.items() if k.startswith("tilt_")}}


def test_tilt_tables_collect_the_trials(tmp_path):
    runs = [_run(tmp_path, "gevi", "a", 1, {"tilt_rmse_deg": 0.4, "tilt_trend_deg_per_min": 0.01}),
            _run(tmp_path, "gevi", "a", 2, {"tilt_rmse_deg": 0.6, "tilt_trend_deg_per_min": None}),
            _run(tmp_path, "gevi", "b", 1, {"tilt_rmse_deg": 1.0}, state="lost-tracking"),
            _run(tmp_path, "gevi", "b", 2, {}, state="crashed"),
            _run(tmp_path, "cfo", "a", 1, {"ate_m": 1.0})]
    rmse, trend = tilt_tables(runs, ["gevi"], ["a", "b"])
    assert rmse.key == "tilt_rmse_deg" and trend.key == "tilt_trend_deg_per_min"
    a = rmse.cell("a", "gevi")
    assert a.values == pytest.approx([0.4, 0.6]) and a.n_trials == 2
    b = rmse.cell("b", "gevi")
    assert b.values == [1.0] and b.n_trials == 1 and b.n_lost == 1  # the crashed trial is not a trial here
    assert trend.cell("a", "gevi").values == [0.01] and trend.cell("a", "gevi").n_trials == 2
    assert "cfo" not in rmse.methods


def test_no_tilt_numbers_no_table(tmp_path):
    runs = [_run(tmp_path, "gevi", "a", 1, {"ate_m": 0.1})]
    assert tilt_tables(runs, ["gevi"], ["a"]) == []
