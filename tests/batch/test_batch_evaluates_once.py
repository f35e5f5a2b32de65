"""gevi batch evaluates each run once: it takes the evaluation the run's own run path made
(run/pipeline.run_and_evaluate, through the worker), and evaluates a run itself only when it has none
(a run finished by an earlier invocation of a resumed batch) -- with the same numbers."""
from __future__ import annotations

import json


def test_the_batch_takes_each_runs_own_evaluation(pool_render, tmp_path, monkeypatch):
    from gevi_cli.batch.runner import run_batch
    from gevi_cli.evaluation import evaluate, pair  # pair: the run's evaluation, bound to the real evaluate_pair

    calls = []
    real = evaluate.evaluate_pair

    def counted(*args, **kwargs):
        calls.append(kwargs.get("method"))
        return real(*args, **kwargs)

    assert pair.evaluate_pair is real
    monkeypatch.setattr(evaluate, "evaluate_pair", counted)  # what the batch's own evaluation calls
    config = tmp_path / "one.yaml"
    config.write_text(f"name: one\nroot: .\ntrials: 1\nmethods: [gevi]\n"
                      f"sequences:\n  - name: pool\n    path: {pool_render}\n    max_frames: 30\n")
    results = tmp_path / "out" / "report" / "results.json"
    assert run_batch(config, tmp_path / "out", jobs=1, echo=lambda *a, **k: None, progress=False) == 0
    assert calls == []  # se3 and posyaw both taken from the run
    first = json.loads(results.read_text())

    # resumed: the run is finished on disk, not run again, so the batch evaluates it from its folder
    assert run_batch(config, tmp_path / "out", jobs=1, echo=lambda *a, **k: None, progress=False) == 0
    assert calls == ["gevi", "gevi"]
    again = json.loads(results.read_text())
    keys = ("ate_m", "rpe_m", "path_ratio", "step_ratio_median")
    assert [first["runs"][0][k] for k in keys] == [again["runs"][0][k] for k in keys]
    assert first["cells"] == again["cells"]
