"""Writers produce layouts the dataset readers open; bag == folder; same seed -> identical bytes."""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from gevi_cli.datasets import open_sequence
from gevi_cli.geometry import invert_pose
from gevi_cli.simulate.generate import SimulationConfig, build_sequence, simulate
from support import run_cli

TINY = {
    # preset: (duration s, rate Hz, resolution, expected reader kind)
    "pool-easy": (2.0, 10.0, (160, 90), "pool"),
    "pool-hard": (2.0, 10.0, (160, 90), "pool"),
    "euroc-like": (1.5, 20.0, (188, 120), "euroc"),
    "kitti-like": (2.0, 10.0, (310, 94), "euroc"),
}


def _config(preset, seed=1, **kw):
    d, r, res, _ = TINY[preset]
    return SimulationConfig(preset, seed=seed, duration_s=d, rate_hz=r, resolution=res, **kw)


@pytest.fixture(scope="module")
def euroc_outputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim_euroc")
    return {p: simulate(_config(p), root / p, "euroc", progress=False, workers=1) for p in TINY}


@pytest.mark.parametrize("preset", sorted(TINY))
def test_readers_open_every_preset(preset, euroc_outputs):
    path = euroc_outputs[preset]
    cfg = _config(preset)
    sim = build_sequence(cfg)
    seq = open_sequence(path)
    assert seq.kind == TINY[preset][3]
    assert len(seq) == int(cfg.duration_s * cfg.rate_hz)
    np.testing.assert_array_equal(seq.stamps_ns, sim.frame_t_ns)
    assert seq.frame_rate_hz == pytest.approx(cfg.rate_hz, rel=1e-9)
    rig = seq.calibration
    assert rig.baseline == pytest.approx(sim.spec.baseline_m, abs=1e-9)
    np.testing.assert_allclose(rig.T_B_C0, sim.rig.T_B_C0, atol=1e-12)
    np.testing.assert_allclose(rig.T_B_C1, sim.rig.T_B_C1, atol=1e-12)
    assert not np.allclose(rig.T_B_C0, np.eye(4))  # camera-IMU extrinsic is not identity
    assert seq.imu.rate_hz == pytest.approx(200.0)
    assert seq.imu.gyro_noise_density == pytest.approx(1.6968e-4)
    np.testing.assert_array_equal(seq.imu.gyro, sim.imu.gyro)
    np.testing.assert_array_equal(seq.imu.acc, sim.imu.acc)
    gt = seq.groundtruth
    assert gt.frame == "body" and gt.t_ns[0] <= seq.stamps_ns[0] and gt.t_ns[-1] >= seq.stamps_ns[-1]
    np.testing.assert_allclose(gt.positions, sim.groundtruth.p_W, atol=1e-12)
    np.testing.assert_allclose(gt.rotations, sim.groundtruth.R_WB, atol=1e-12)
    frame = next(seq.frames())
    assert frame.left.dtype == np.uint8 and frame.left.shape == TINY[preset][2][::-1]
    assert frame.left.std() > 3.0  # not blank
    if preset.startswith("pool"):
        # mocap: marker poses map back to the body poses within the mocap noise
        T_B_M = seq.T_B_M
        np.testing.assert_allclose(T_B_M, sim.T_B_M, atol=1e-12)
        mocap_body = seq.mocap.with_sensor_frame(invert_pose(T_B_M), frame="body")
        idx = np.searchsorted(gt.t_ns, mocap_body.t_ns)
        assert np.abs(mocap_body.positions - gt.positions[idx]).max() < 0.005


def test_gevi_info_reports_rates_baseline_and_coverage(euroc_outputs, capsys):
    code, out, err = run_cli(["info", euroc_outputs["pool-easy"]], capsys)
    assert code == 0, err
    assert "20 stereo pairs at 10.0 Hz" in out
    assert "0.120 m" in out
    assert "IMU 200 Hz" in out
    assert "20 of 20 frames" in out
    code, out, err = run_cli(["info", euroc_outputs["euroc-like"]], capsys)
    assert code == 0 and "at 20.0 Hz" in out and "0.110 m" in out and "30 of 30 frames" in out


def test_kitti_layout(tmp_path, capsys):
    cfg = _config("kitti-like")
    path = simulate(cfg, tmp_path / "k", "kitti", progress=False, workers=1)
    assert path == tmp_path / "k" / "sequences" / "00"
    for name in ("image_0/000000.png", "image_1/000019.png", "calib.txt", "times.txt"):
        assert (path / name).is_file()
    assert (tmp_path / "k" / "poses" / "00.txt").is_file()
    calib = (path / "calib.txt").read_text().splitlines()
    assert [line.split(":")[0] for line in calib] == ["P0", "P1", "P2", "P3", "Tr"]
    assert all(len(line.split()) == 13 for line in calib)
    P1 = np.array(calib[1].split()[1:], float).reshape(3, 4)
    assert P1[0, 3] == pytest.approx(-P1[0, 0] * 0.54, rel=1e-12)
    assert (path / "times.txt").read_text().splitlines()[:2] == ["0.000000e+00", "1.000000e-01"]
    seq = open_sequence(path)
    assert seq.kind == "kitti" and len(seq) == 20
    assert seq.calibration.baseline == pytest.approx(0.54, abs=1e-9)
    assert seq.calibration.cam0.distortion_model == "none"
    sim = build_sequence(SimulationConfig("kitti-like", seed=1, duration_s=2.0, rate_hz=10.0, resolution=(310, 94),
                                          distortion=False))
    T = sim.camera_poses(sim.frame_t_ns, 0)
    rel = invert_pose(T[0]) @ T
    np.testing.assert_allclose(seq.groundtruth.positions, rel[:, :3, 3], atol=1e-6)
    speed = np.linalg.norm(np.diff(rel[:, :3, 3], axis=0), axis=1) * 10.0
    assert 7.0 < speed.mean() < 13.0  # car at ~10 m/s
    code, out, _ = run_cli(["info", path], capsys)
    assert code == 0 and "0.540 m" in out and "20 of 20 frames" in out


@pytest.mark.parametrize("preset", ["pool-easy", "euroc-like"])
def test_bag_reads_back_identical_to_folder(preset, tmp_path, euroc_outputs, capsys):
    bag = simulate(_config(preset), tmp_path / "b", "bag", progress=False, workers=1)
    assert bag == tmp_path / "b" / f"{preset}.bag"
    assert (tmp_path / "b" / f"{preset}_camchain.yaml").is_file() and (tmp_path / "b" / f"{preset}_imu.yaml").is_file()
    folder = open_sequence(euroc_outputs[preset])
    seq = open_sequence(bag)
    assert seq.kind == "rosbag"
    np.testing.assert_array_equal(seq.stamps_ns, folder.stamps_ns)
    for a, b in zip(seq.frames(), folder.frames()):
        assert a.t_ns == b.t_ns
        np.testing.assert_array_equal(a.left, b.left)
        np.testing.assert_array_equal(a.right, b.right)
    np.testing.assert_array_equal(seq.imu.t_ns, folder.imu.t_ns)
    np.testing.assert_array_equal(seq.imu.gyro, folder.imu.gyro)
    np.testing.assert_array_equal(seq.imu.acc, folder.imu.acc)
    assert seq.imu.acc_random_walk == folder.imu.acc_random_walk
    np.testing.assert_array_equal(seq.groundtruth.t_ns, folder.groundtruth.t_ns)
    np.testing.assert_allclose(seq.groundtruth.positions, folder.groundtruth.positions, atol=1e-12)
    np.testing.assert_allclose(seq.groundtruth.rotations, folder.groundtruth.rotations, atol=1e-12)
    rb, rf = seq.calibration, folder.calibration
    for cb, cf in ((rb.cam0, rf.cam0), (rb.cam1, rf.cam1)):
        assert (cb.width, cb.height, cb.fx, cb.fy, cb.cx, cb.cy) == (cf.width, cf.height, cf.fx, cf.fy, cf.cx, cf.cy)
        np.testing.assert_allclose(cb.distortion, cf.distortion)
    np.testing.assert_allclose(rb.T_B_C0, rf.T_B_C0, atol=1e-12)
    np.testing.assert_allclose(rb.T_B_C1, rf.T_B_C1, atol=1e-12)
    code, out, _ = run_cli(["info", bag], capsys)
    assert code == 0 and "GT coverage" in out


def _digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("fmt", ["euroc", "bag"])
def test_same_seed_gives_identical_bytes(fmt, tmp_path):
    cfg = SimulationConfig("pool-hard", seed=5, duration_s=1.0, rate_hz=5.0, resolution=(96, 64))
    a = simulate(cfg, tmp_path / "a", fmt, progress=False, workers=1)
    b = simulate(cfg, tmp_path / "b", fmt, progress=False, workers=2)
    da, db = _digest(tmp_path / "a"), _digest(tmp_path / "b")
    assert da == db and len(da) >= 4
    assert a.relative_to(tmp_path / "a") == b.relative_to(tmp_path / "b")
    c = simulate(SimulationConfig("pool-hard", seed=6, duration_s=1.0, rate_hz=5.0, resolution=(96, 64)),
                 tmp_path / "c", fmt, progress=False, workers=1)
    assert _digest(tmp_path / "c") != da and c.exists()
    assert not list(tmp_path.glob(".*partial*"))


def test_cli_user_errors(tmp_path, capsys):
    code, _, err = run_cli(["simulate", "no-such-preset", tmp_path / "x"], capsys)
    assert code == 2 and "unknown preset" in err and len(err.strip().splitlines()) == 1
    code, _, err = run_cli(["simulate", "pool-easy", tmp_path / "x", "--resolution", "640by360"], capsys)
    assert code == 2 and "--resolution" in err
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("x")
    code, _, err = run_cli(["simulate", "pool-easy", tmp_path / "full"], capsys)
    assert code == 2 and "--overwrite" in err
    code, _, err = run_cli(["simulate", "pool-easy", tmp_path / "full", "--overwrite"], capsys)
    assert code == 2 and "refusing" in err and (tmp_path / "full" / "keep.txt").exists()


def test_cli_renders_and_overwrites(tmp_path, capsys):
    args = ["simulate", "pool-hard", tmp_path / "o", "--duration", "0.5", "--rate", "4", "--resolution", "64x48",
            "--seed", "3", "-q", "--no-imu-noise"]
    code, out, err = run_cli(args, capsys)
    assert code == 0, err
    assert out.strip() == str(tmp_path / "o")
    desc = (tmp_path / "o" / "simulation.yaml").read_text()
    assert "preset: pool-hard" in desc and "seed: 3" in desc
    code, _, err = run_cli(args, capsys)
    assert code == 2 and "--overwrite" in err
    code, _, err = run_cli(args + ["--overwrite"], capsys)
    assert code == 0, err
    seq = open_sequence(tmp_path / "o")
    assert len(seq) == 2 and np.all(seq.imu.gyro == build_sequence(
        SimulationConfig("pool-hard", seed=3, duration_s=0.5, rate_hz=4, resolution=(64, 48))).imu.gyro_true)


@pytest.mark.parametrize("extra", [{}, {"a_max": 0.15, "moving_start": True, "distortion": False, "image_noise": False}])
def test_config_from_its_simulation_yaml_rebuilds_the_same_sequence(extra):
    """``SimulationConfig.from_description`` inverts ``description``: through the YAML text the
    written ``simulation.yaml`` holds, the resolved config is equal and the trajectory the same."""
    import yaml

    from gevi_cli.simulate.imu import ImuParams

    cfg = _config("pool-easy", seed=3, imu=ImuParams(acc_random_walk=5e-3), **extra)
    seq = build_sequence(cfg)
    back = SimulationConfig.from_description(yaml.safe_load(yaml.safe_dump(seq.description("euroc"))))
    assert back.resolved() == cfg.resolved()
    again = build_sequence(back)
    t = seq.frame_t_ns
    assert np.array_equal(again.frame_t_ns, t)
    assert np.array_equal(again.body_state(t).T_WB, seq.body_state(t).T_WB)


def test_config_from_a_broken_description_is_one_value_error():
    with pytest.raises(ValueError, match="not a gevi simulate description"):
        SimulationConfig.from_description({"preset": "pool-easy", "seed": 1})
