"""The run folder contract: streamed poses survive Ctrl-C and crashes; gevi eval reads run folders."""
from __future__ import annotations

import json

import pytest

from support import run_cli


@pytest.fixture(scope="module")
def render(tmp_path_factory):
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    cfg = SimulationConfig("pool-easy", seed=4, duration_s=3.0, rate_hz=10.0, resolution=(376, 240))
    return simulate(cfg, tmp_path_factory.mktemp("render") / "pool-easy", "euroc", progress=False, workers=1)


def _rows(path):
    return [r for r in path.read_text().splitlines() if r and not r.startswith("#")]


@pytest.mark.parametrize("exc, state, code", [(KeyboardInterrupt, "interrupted", 130), (RuntimeError, "crashed", 1)])
def test_interrupt_or_crash_keeps_every_final_pose(render, tmp_path, monkeypatch, capsys, exc, state, code):
    from gevi_cli.pipelines.cfo import CurrentFeatureOdometry

    real = CurrentFeatureOdometry.track

    def track(self, frame):
        if self.index + 1 == 17:
            raise exc("stop here")
        return real(self, frame)

    monkeypatch.setattr(CurrentFeatureOdometry, "track", track)
    out = tmp_path / "run"
    from gevi_cli.cli import main

    with pytest.raises(BaseException) as info:
        main(["run", str(render), "--method", "cfo", "-o", str(out), "-q"])
    if exc is KeyboardInterrupt:
        assert isinstance(info.value, SystemExit) and info.value.code == code
    else:
        assert isinstance(info.value, RuntimeError)  # a bug, not a user error: the traceback is kept
    st = json.loads((out / "status.json").read_text())
    assert st["state"] == state and st["frames_done"] == 17
    # all 17 tracked frames are on disk, after-BA and online, whatever was still pending
    assert len(_rows(out / "traj_body.tum")) == 17
    assert len(_rows(out / "traj_online_body.tum")) == 17
    assert len(_rows(out / "timing.csv")) == 18  # header + 17


def test_eval_reads_a_results_tree_of_run_folders(render, tmp_path, capsys):
    root = tmp_path / "results"
    for _ in range(2):  # two timestamped runs = two trials, the `latest` link is not a third
        code, out, _ = run_cli(["run", render, "--method", "cfo", "--results-root", root, "-q", "--max-frames", "20"], capsys)
        assert code == 0
    seq_dir = root / "cfo" / "pool-easy"
    assert (seq_dir / "latest").is_symlink()
    runs = [p for p in seq_dir.iterdir() if not p.is_symlink()]
    assert len(runs) == 2
    code, out, err = run_cli(["eval", "--results", root, "--gt", f"pool-easy={render}", "-o", tmp_path / "ev"], capsys)
    assert code == 0, err
    assert out.count("cfo/pool-easy/") == 2 and "align se3 (config.yaml: align)" in out
    metrics = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    paths = {r["path"] for r in metrics["results"]}
    assert len(paths) == 2 and all(p.endswith("traj_body.tum") for p in paths)


def test_start_and_max_frames_count_frames(render, tmp_path, capsys):
    from gevi_cli.datasets import open_sequence
    from gevi_cli.trajectory import read_trajectory

    code, _, err = run_cli(["run", render, "--start", "10", "--max-frames", "15", "-o", tmp_path / "r", "-q"], capsys)
    assert code == 0, err
    est = read_trajectory(tmp_path / "r" / "traj_body.tum")
    stamps = open_sequence(render).stamps_ns
    assert list(est.t_ns) == list(stamps[10:25])
    code, _, err = run_cli(["run", render, "--start", "99", "-q", "-o", tmp_path / "x"], capsys)
    assert code == 2 and "--start" in err
