"""The built-in sample is rendered once into the user cache, atomically."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli.simulate import sample as sample_mod
from gevi_cli.simulate.generate import SimulationConfig
from support import run_cli

TINY = SimulationConfig("pool-easy", seed=0, duration_s=1.5, rate_hz=4.0, resolution=(96, 54))


@pytest.fixture
def tiny_sample(monkeypatch, tmp_path):
    monkeypatch.setattr(sample_mod, "SAMPLE_CONFIG", TINY)
    monkeypatch.setenv("GEVI_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache"


def test_cache_dir_resolution(monkeypatch, tmp_path):
    monkeypatch.setenv("GEVI_CACHE_DIR", str(tmp_path / "a"))
    assert sample_mod.cache_dir() == tmp_path / "a"
    monkeypatch.delenv("GEVI_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert sample_mod.cache_dir() == tmp_path / "x" / "gevi"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "h"))
    assert sample_mod.cache_dir() == tmp_path / "h" / ".cache" / "gevi"


def test_sample_rendered_once_and_opens(tiny_sample, capsys):
    from gevi_cli.datasets import open_sequence
    from gevi_cli.simulate import sample_sequence

    path = sample_sequence(progress=False)
    assert path == tiny_sample / sample_mod.SAMPLE_NAME
    stamp = (path / "mav0" / "imu0" / "data.csv").stat().st_mtime_ns
    assert sample_sequence(progress=False) == path
    assert (path / "mav0" / "imu0" / "data.csv").stat().st_mtime_ns == stamp  # not re-rendered
    assert [p.name for p in tiny_sample.iterdir()] == [sample_mod.SAMPLE_NAME]  # no partial folders
    seq = open_sequence(path)
    assert len(seq) == 6 and seq.groundtruth is not None
    # still start: the first second is motionless
    gt = seq.groundtruth
    still = gt.t_ns - gt.t_ns[0] < 1_000_000_000
    assert np.ptp(gt.positions[still], axis=0).max() == 0.0
    code, out, err = run_cli(["simulate", "--sample", "-q"], capsys)
    assert code == 0 and out.strip() == str(path)


def test_interrupted_render_leaves_nothing(tiny_sample, monkeypatch):
    from gevi_cli.simulate.writers import euroc

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(euroc, "write_png", boom)
    with pytest.raises(KeyboardInterrupt):
        sample_mod.sample_sequence(progress=False)
    assert not any(tiny_sample.iterdir())


def test_default_sample_config_is_a_short_pool_easy_sequence():
    c = sample_mod.SAMPLE_CONFIG.resolved()
    assert c.preset == "pool-easy" and 12 <= c.duration_s <= 15 and 10 <= c.rate_hz <= 20
    assert c.resolution == (640, 360)
