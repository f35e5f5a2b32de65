"""Trajectory pictures in the right plane (issue 35): the plane perpendicular to gravity where the world
is gravity-aligned, else the two axes of largest extent; and every `gevi run` folder has trajectory.png."""
from __future__ import annotations

import json

import numpy as np
import pytest

from gevi_cli.evaluation.plots import view_of, world_of
from gevi_cli.run.folder import RunStatus, run_world, write_trajectory_png
from gevi_cli.trajectory import Trajectory, read_trajectory, write_trajectory
from support import run_cli, shared_path


def _car_in_kitti_camera_frame(n=51) -> np.ndarray:
    """kitti06_head's shape: 60 m forward (z), the road 1.2 m downhill (y down) and 1.0 m to the left (x)."""
    s = np.linspace(0.0, 1.0, n)
    return np.column_stack([-1.0 * s**2, 1.2 * s, 60.0 * s])


def test_kitti_camera_frame_is_seen_from_above_in_x_z():
    p = _car_in_kitti_camera_frame()
    v = view_of(p, "camera-level")
    assert v.top == (0, 2) and v.normal == 1 and v.normal_down  # the road: x right, z forward; y (down) is up/down
    assert (v.labels[0], v.labels[2], v.labels[1]) == ("x [m] (right)", "z [m] (forward)", "y [m] (down)")
    # by extent alone this trajectory would be seen from the side (y 1.2 m > x 1.0 m)
    assert view_of(p, None).top == (1, 2)


def test_gravity_aligned_world_is_seen_in_x_y_even_when_it_climbs_more_than_it_strays():
    t = np.linspace(0.0, 1.0, 100)
    p = np.column_stack([4.0 * t, 0.3 * np.sin(6 * t), 2.0 * t])  # z-up: 2 m climb, 0.6 m sideways
    v = view_of(p, "z-up")
    assert v.top == (0, 1) and v.normal == 2 and not v.normal_down
    assert v.labels == ("x [m] (horizontal)", "y [m] (horizontal)", "z [m] (up)")
    assert view_of(p, None).top == (0, 2)  # unknown world: the two axes of largest extent


def test_unknown_world_uses_the_two_axes_of_largest_extent_without_naming_directions():
    p = np.column_stack([np.zeros(5), np.arange(5.0), 0.1 * np.arange(5.0)])
    assert view_of(p, None).top == (1, 2) and view_of(p, None).labels == ("x [m]", "y [m]", "z [m]")
    assert view_of(np.zeros((3, 3)), None).top == (0, 1)  # no extent at all: seen from z


@pytest.mark.parametrize("fmt, world", [("kitti", "camera-level"), ("euroc", "z-up"), ("tum", None)])
def test_world_of_a_file_follows_its_format(tmp_path, fmt, world):
    """KITTI pose files are cam0 of KITTI's level car camera; EuRoC ground truth is a z-up mocap world;
    a TUM file says nothing about its world."""
    traj = Trajectory(np.arange(3, dtype=np.int64) * 100_000_000, _car_in_kitti_camera_frame(3),
                      np.tile([1.0, 0, 0, 0], (3, 1)), frame="body")
    assert world_of(read_trajectory(write_trajectory(traj, tmp_path / f"t.{fmt}", fmt))) == world


def test_run_world_follows_the_method_and_the_dataset():
    assert run_world(RunStatus(method="gevi", imu={"initialised": True}), "euroc") == "z-up"
    assert run_world(RunStatus(method="gevi", imu={"initialised": False}), "euroc") == "camera"  # first cam0
    assert run_world(RunStatus(method="cfo"), "kitti") == "camera-level"  # KITTI: body = cam0
    assert run_world(RunStatus(method="cfo"), "euroc") is None  # the first IMU frame, attitude unknown


def _png_size(path) -> tuple:
    import cv2

    img = cv2.imread(str(path))
    assert img is not None, path
    assert img.std() > 10  # not blank
    return img.shape[1], img.shape[0]


def test_every_run_folder_has_a_small_trajectory_png(pool_render, tmp_path, capsys):
    """Without --plots too (--max-frames keeps it short); and from the trajectory alone without a ground truth."""
    out = tmp_path / "run"
    code, stdout, _ = run_cli(["run", pool_render, "--method", "cfo", "-o", out, "-q", "--max-frames", "10"], capsys)
    assert code == 0, stdout
    assert _png_size(out / "trajectory.png") == (320, 320)
    assert not (out / "eval" / "plots").exists()
    (out / "trajectory.png").unlink()
    assert write_trajectory_png(out, RunStatus(method="cfo", sequence="pool-easy"), "euroc") == out / "trajectory.png"
    assert _png_size(out / "trajectory.png") == (320, 320)
    assert write_trajectory_png(tmp_path, RunStatus(method="cfo"), "euroc") is None  # no poses: no picture


def test_kitti06_head_run_folder_png(tmp_path, capsys):
    seq = shared_path("kitti06_head", "dataset", "sequences", "06")
    out = tmp_path / "run"
    code, stdout, _ = run_cli(["run", seq, "-o", out, "-q", "--max-frames", "10"], capsys)
    assert code == 0, stdout
    assert json.loads((out / "status.json").read_text())["evaluation"]["ate_m"] < 0.05  # evaluated: drawn over GT
    assert _png_size(out / "trajectory.png") == (320, 320)
