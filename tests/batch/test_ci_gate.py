"""The CI gate: `gevi batch configs/batch/ci.yaml` then `gevi regress` against the committed values.

No wall-clock budget here (it failed a passing batch at 308 s on a loaded 2-core machine): the batch
prints its own time, and per-frame speed is scripts/bench_pipeline.py's, against a floor measured in
the same run."""
from __future__ import annotations

import subprocess
import sys

import pytest

from support import REPO, SHARED_DATA


@pytest.mark.slow
def test_ci_batch_passes_the_regression_gate(tmp_path):
    out = tmp_path / "ci"
    gevi = [sys.executable, "-m", "gevi_cli.cli"]
    batch = subprocess.run(gevi + ["batch", "configs/batch/ci.yaml", "-o", str(out), "--jobs", "2"], cwd=REPO,
                           capture_output=True, text=True, check=False)
    assert batch.returncode == 0, batch.stdout[-3000:] + batch.stderr[-3000:]
    if not SHARED_DATA.is_dir():
        assert "skipping sequence euroc_micro" in batch.stdout
    gate = subprocess.run(gevi + ["regress", str(out), "--against", "tests/regression/expected.yaml"], cwd=REPO,
                          capture_output=True, text=True, check=False)
    print(gate.stdout)
    assert gate.returncode == 0, gate.stdout + gate.stderr
    assert "| pool-easy-10s | gevi | ATE |" in gate.stdout and "0 worse than expected" in gate.stdout
    if not SHARED_DATA.is_dir():
        assert "left out, the batch skipped it" in gate.stdout
