"""One resolver for the shared data (gevi_cli/shared_data.py): $GEVI_SHARED_DATA, else ../shared/data next
to the repository; batch configs' ``../shared/data/...`` paths follow it (issue 35)."""
from __future__ import annotations

from pathlib import Path

import support
from gevi_cli import shared_data
from gevi_cli.batch.config import load_batch_config

CONFIG = """\
name: t
root: .
methods: [cfo]
sequences:
  - name: real
    path: ../shared/data/seq
    gt: ../shared/data/seq/gt.txt
    optional: true
  - name: local
    path: data/seq
    optional: true
"""


def test_default_is_next_to_the_repository(monkeypatch):
    monkeypatch.delenv(shared_data.ENV, raising=False)
    assert shared_data.shared_data_dir() == Path(shared_data.__file__).resolve().parents[2] / "shared" / "data"
    assert shared_data.redirect("../shared/data/euroc_micro") is None  # resolved as written


def test_tests_use_the_same_resolver():
    assert support.SHARED_DATA == shared_data.shared_data_dir()


def test_batch_config_paths_follow_the_variable(tmp_path, monkeypatch):
    elsewhere = tmp_path / "elsewhere" / "data"
    (elsewhere / "seq").mkdir(parents=True)
    (elsewhere / "seq" / "gt.txt").write_text("0 0 0 0 0 0 0 1\n")
    cfg_dir = tmp_path / "repo"
    cfg_dir.mkdir()
    (cfg_dir / "b.yaml").write_text(CONFIG)
    monkeypatch.setenv(shared_data.ENV, str(elsewhere))
    real, local = load_batch_config(cfg_dir / "b.yaml").sequences
    assert (real.path, real.inputs.gt, real.skip_reason) == (str(elsewhere / "seq"), str(elsewhere / "seq" / "gt.txt"), "")
    assert local.path == str(cfg_dir / "data" / "seq") and local.skip_reason  # other relative paths: as before
    monkeypatch.delenv(shared_data.ENV)
    real, _ = load_batch_config(cfg_dir / "b.yaml").sequences
    assert real.path == str(cfg_dir / "../shared/data/seq") and "is absent" in real.skip_reason
