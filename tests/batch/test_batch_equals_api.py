"""A batch run's numbers are api.run's on the same input, to the bit: the batch runs `gevi run`'s
code per run (batch/worker.run_one -> run/session.execute) and evaluates the run's primary trajectory
as written, which api.run evaluates the same way (ATE, RPE and the scale ratios before alignment)."""
from __future__ import annotations

import json


def test_batch_run_numbers_equal_api_run(pool_render, tmp_path):
    from gevi_cli.api import run
    from gevi_cli.batch.runner import run_batch

    config = tmp_path / "one.yaml"
    config.write_text(f"name: one\nroot: .\ntrials: 1\nmethods: [gevi]\n"
                      f"sequences:\n  - name: pool\n    path: {pool_render}\n")
    code = run_batch(config, tmp_path / "out", jobs=1, echo=lambda *a, **k: None, progress=False)
    assert code == 0
    (row,) = json.loads((tmp_path / "out" / "report" / "results.json").read_text())["runs"]

    ev = run(pool_render, method="gevi").evaluation
    assert (row["ate_m"], row["rpe_m"], row["path_ratio"], row["step_ratio_median"]) == (
        ev.ate.trans_rmse, ev.rpe.trans_rmse, ev.scale.path_ratio, ev.scale.step_ratio_median)
