"""The kitti-highway render (27 m/s, texture mostly 35 m to kilometres away) tracked at every frame by CFO."""
from __future__ import annotations

import json

import pytest

from support import run_cli

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def highway(tmp_path_factory):
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    cfg = SimulationConfig("kitti-highway", seed=1, duration_s=10.0, distortion=False)  # real.yaml's kitti-highway-10s
    return simulate(cfg, tmp_path_factory.mktemp("highway") / "seq", "kitti", progress=False)


def _status(highway, tmp_path, capsys, *args):
    code, _, err = run_cli(["run", highway, "--method", "cfo", "-q", "-o", tmp_path / "run", *args], capsys)
    return code, json.loads((tmp_path / "run" / "status.json").read_text())


def test_far_points_fill_a_keyframe_short_of_near_ones(highway, tmp_path, capsys):
    """Every frame tracked, and the pose on the road: 2.7 m per frame, so an ATE under one frame's step
    means no frame was carried by the constant-velocity bridge."""
    code, status = _status(highway, tmp_path, capsys)
    assert code == 0
    assert status["frames_tracked"] == status["frames_done"] == 100
    assert status["evaluation"]["ate_m"] < 2.7


def test_without_the_far_points_the_highway_is_lost(highway, tmp_path, capsys):
    """The same render with stereo capped at 100 m and no filling (the gate of a plain stereo odometry):
    keyframes run out of points (ten-odd near ones) and frames are bridged."""
    code, status = _status(highway, tmp_path, capsys, "--set", "frontend.max_depth_m=100",
                           "--set", "triangulation.fill_points=0")
    assert status["frames_tracked"] < status["frames_done"]
