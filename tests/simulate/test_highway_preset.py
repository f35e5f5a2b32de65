"""The kitti-highway preset: 25-30 m/s on gentle curves, a road plane, only far structures; renderable
for 20 s (the scene reaches past where the car ends) and opened by the KITTI reader."""
from __future__ import annotations

import numpy as np

from gevi_cli.datasets import open_sequence
from gevi_cli.simulate.generate import SimulationConfig, build_sequence, simulate
from gevi_cli.simulate.presets import PRESETS, build_motion
from gevi_cli.simulate.scenes import build_scene


def test_highway_motion_speed_and_curvature():
    spec = PRESETS["kitti-highway"]
    for seed in (1, 2, 3):
        m = build_motion(spec, seed=seed, duration=20.0)
        s = m(np.arange(0.0, 20.0, 0.01))
        speed = np.linalg.norm(s.v_W, axis=1)
        assert 25.0 <= speed.min() and speed.max() <= 30.0
        assert np.abs(s.a_W[:, :2]).max() < 2.0  # highway curves: lateral acceleration well under 2 m/s^2


def test_highway_scene_is_a_road_plane_and_far_structures():
    spec = PRESETS["kitti-highway"]
    motion = build_motion(spec, seed=1, duration=20.0)
    scene = build_scene(spec, 1, motion, 20.0)
    ground = [p for p in scene.planes if p.name == "ground"]
    assert len(ground) == 1 and np.allclose(ground[0].origin, 0.0) and np.isinf(ground[0].size_u)
    far = [p for p in scene.planes if p.name != "ground"]
    x_end = motion(np.array([20.0])).p_W[0, 0]
    assert max(p.origin[0] for p in far) > x_end + 100.0  # structures ahead of the car to the end
    for p in far:  # every structure 35 m or more from the road centre line
        assert abs(p.origin[1] - motion.road(np.array([p.origin[0]]))[0][0]) >= 35.0 - 1e-9


def test_highway_renders_as_kitti(tmp_path):
    cfg = SimulationConfig("kitti-highway", seed=1, duration_s=1.0, rate_hz=10.0, resolution=(310, 94))
    path = simulate(cfg, tmp_path / "hw", "kitti", progress=False, workers=1)
    seq = open_sequence(path)
    assert seq.kind == "kitti" and len(seq) == 10
    gt = seq.groundtruth
    steps = np.linalg.norm(np.diff(gt.positions, axis=0), axis=1)
    assert np.all((steps > 2.5) & (steps < 3.0))  # 25-30 m/s at 10 Hz
    assert len(build_sequence(cfg).scene.planes) > 1
