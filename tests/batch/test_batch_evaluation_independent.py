"""The batch's own evaluation against an independent one (api.evaluate from the files, as `gevi eval`
reads them) on KITTI-layout rows (KITTI rows written, the ground truth stamped by times.txt), and after a
resume, when the batch evaluates the finished runs from their folders instead of taking the runs' own
evaluations."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow


def _rows(out):
    return {r["run_id"]: r for r in json.loads((out / "report" / "results.json").read_text())["runs"]}


def test_batch_kitti_rows_and_resumed_equal_an_independent_evaluation(tmp_path):
    from gevi_cli.api import evaluate
    from gevi_cli.batch.runner import run_batch
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    seq = simulate(SimulationConfig("kitti-like", seed=3, duration_s=3.0, resolution=(620, 188)),
                   tmp_path / "kl", "kitti", progress=False, workers=1)  # KITTI layout: sequences/00
    config = tmp_path / "one.yaml"
    config.write_text(f"name: one\nroot: .\ntrials: 1\nmethods: [cfo]\n"
                      f"sequences:\n  - name: kl\n    path: {seq}\n  - name: kl2\n    path: {seq}\n    stride: 2\n")
    out = tmp_path / "out"
    assert run_batch(config, out, jobs=1, echo=lambda *a, **k: None, progress=False) == 0
    first = _rows(out)
    assert len(first) == 2
    for row in first.values():
        run_dir = Path(row["run_dir"])
        status = json.loads((run_dir / "status.json").read_text())
        assert (run_dir / "traj_cam0_kitti.txt").is_file()
        ev = evaluate(seq, run_dir / status["primary"])  # the dataset folder as `gevi eval --gt` takes it
        assert (row["ate_m"], row["rpe_m"], row["path_ratio"]) == (ev.ate.trans_rmse, ev.rpe.trans_rmse,
                                                                   ev.scale.path_ratio)

    # a resumed batch (nothing to run) evaluates every run from its folder: the same numbers
    (out / "report").rename(tmp_path / "report_first")
    assert run_batch(config, out, jobs=1, echo=lambda *a, **k: None, progress=False) == 0
    again = _rows(out)
    for run_id, row in first.items():
        for key in ("ate_m", "rpe_m", "path_ratio", "step_ratio_median"):
            assert again[run_id][key] == row[key], (run_id, key)
