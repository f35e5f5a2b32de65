"""One small batch shared by every batch test (session scope): a 5 s pool-easy render (10 Hz,
376x240; rendered once into a test cache), GeVI (two trials) and CFO (deterministic: one run), with ``--jobs 2``; the
online trajectories evaluated too."""
from __future__ import annotations

from pathlib import Path

import pytest

SMALL_CONFIG = """\
name: small
trials: 2
cache: {cache}
eval: {{online: true}}
methods:
  - gevi
  - cfo
sequences:
  - name: pool-easy-5s
    simulate: {{preset: pool-easy, seed: 3, duration: 5, rate: 10, resolution: 376x240}}
"""


@pytest.fixture(scope="session")
def small_config(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("batch_config")
    p = d / "small.yaml"
    p.write_text(SMALL_CONFIG.format(cache=d / "cache"))
    return p


@pytest.fixture(scope="session")
def small_batch(small_config, tmp_path_factory):
    """(results folder, exit status, printed lines) of the small batch with --jobs 2."""
    from gevi_cli.batch.runner import run_batch

    out = tmp_path_factory.mktemp("batch_jobs2") / "out"
    lines = []
    code = run_batch(small_config, out, jobs=2, echo=lines.append, progress=False)
    return out, code, lines
