"""The CI gate: `gevi batch configs/batch/ci.yaml` then `gevi regress` against the committed values."""
from __future__ import annotations

import subprocess
import sys
import time

from support import REPO, SHARED_DATA


def test_ci_batch_passes_the_regression_gate(tmp_path):
    out = tmp_path / "ci"
    gevi = [sys.executable, "-m", "gevi_cli.cli"]
    t0 = time.perf_counter()
    batch = subprocess.run(gevi + ["batch", "configs/batch/ci.yaml", "-o", str(out), "--jobs", "2"], cwd=REPO,
                           capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    assert batch.returncode == 0, batch.stdout[-3000:] + batch.stderr[-3000:]
    assert wall < 300, f"the CI batch took {wall:.0f} s (budget 5 min)"
    if not SHARED_DATA.is_dir():
        assert "skipping sequence euroc_micro" in batch.stdout
    gate = subprocess.run(gevi + ["regress", str(out), "--against", "tests/regression/expected.yaml"], cwd=REPO,
                          capture_output=True, text=True, check=False)
    print(gate.stdout)
    assert gate.returncode == 0, gate.stdout + gate.stderr
    assert "| pool-easy-10s | gevi | ATE |" in gate.stdout and "0 worse than expected" in gate.stdout
    if not SHARED_DATA.is_dir():
        assert "left out, the batch skipped it" in gate.stdout
