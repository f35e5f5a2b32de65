"""Bags written by real ROS tools (``../shared/data/real_bags``): read right, or refused in one line.

The expected topics, types, counts, image sizes and encodings are parsed from each folder's
SOURCE.md (its rosbags inspection block), not typed in here, so the test checks `gevi info` against
what an independent pass over the bag found.
"""
from __future__ import annotations

import re
import shutil

import numpy as np
import pytest

from gevi_cli.datasets import open_sequence
from gevi_cli.datasets.bag_imu import BagImu
from gevi_cli.errors import GeviError
from support import SHARED_DATA, run_cli, shared_path

BAGS = {
    "kapture_t265_stereo_imu": "trimmed_locoffice.bag",
    "fiducials_aruco_images": "aruco_images.bag",
    "imu_tools_phidgets": "phidgets_imu_upside_down.bag",
    "plotjuggler_tilt_laser": "tilt_laser.bag",
    "evo_ros_example_poses": "ROS_example.bag",
    "evo_tf_example_lz4": "tf_example.bag",
    "rerun_rosbag2_humble_mcap": "rosbag2_2025_09_10-13_03_56_0.mcap",
    "plotjuggler_rosbag2_dashing_db3": "rosbag2_test",
    "evo_nav2_turtlebot_mcap": "nav2_turtlebot.mcap",
}
_TOPIC = re.compile(r"^  (\S+)\s+(\S+/msg/\S+)\s+count=(\d+)")
_IMAGE = re.compile(r"\[decode\] (\S+): Image (\d+x\d+) encoding=(\S+)")
_COMPRESSED = re.compile(r"\[decode\] (\S+): CompressedImage format='([^']*)'.*decoded_header=\S+ (\d+x\d+)")


def _expected(folder: str) -> dict:
    text = (SHARED_DATA / "real_bags" / folder / "SOURCE.md").read_text()
    topics = {m.group(1): (m.group(2), int(m.group(3))) for m in map(_TOPIC.match, text.splitlines()) if m}
    images = {m.group(1): f"{m.group(2)} {m.group(3)}" for m in _IMAGE.finditer(text)}
    images.update({m.group(1): f"{m.group(3)} compressed '{m.group(2)}'" for m in _COMPRESSED.finditer(text)})
    return {"topics": topics, "images": images}


@pytest.mark.parametrize("folder", sorted(BAGS))
def test_gevi_info_describes_every_real_bag(folder, capsys):
    bag = shared_path("real_bags", folder, BAGS[folder])
    expected = _expected(folder)
    assert expected["topics"], f"no inspection block parsed from {folder}/SOURCE.md"
    code, out, err = run_cli(["info", bag], capsys)
    assert code == 0, err
    assert "Traceback" not in out + err
    lines = out.splitlines()
    for topic, (msgtype, count) in expected["topics"].items():
        short = msgtype.replace("/msg/", "/")
        row = [ln for ln in lines if ln.startswith(f"  {topic} ")]
        assert len(row) == 1, f"{topic} missing from gevi info"
        fields = row[0].split()
        assert fields[1] == short and int(fields[2]) == count, row[0]
    for topic, detail in expected["images"].items():
        row = next(ln for ln in lines if ln.startswith(f"  {topic} "))
        assert detail in row, (detail, row)
    # what gevi run and gevi imu can do with it: a verdict each, one line
    run_line = next(ln for ln in lines if ln.startswith("gevi run "))
    imu_line = next(ln for ln in lines if ln.startswith("gevi imu "))
    n_images = sum(1 for t, (ty, _) in expected["topics"].items() if ty.endswith(("/Image", "/CompressedImage")))
    has_imu = any(ty == "sensor_msgs/msg/Imu" for ty, _ in expected["topics"].values())
    assert ("yes" in run_line) == (folder == "kapture_t265_stereo_imu")
    if n_images == 0:
        assert "no image topics" in run_line  # not "no camera calibration": that is not what is missing
    elif n_images == 1:
        assert "only one image topic" in run_line
    assert imu_line.startswith("gevi imu      yes") == has_imu


def test_t265_split_imu_is_merged_by_interpolating_the_accelerometer():
    from rosbags.highlevel import AnyReader

    bag = shared_path("real_bags", "kapture_t265_stereo_imu", "trimmed_locoffice.bag")
    seq = open_sequence(bag)
    assert seq.imu_topics.gyro == "/camera/gyro/sample" and seq.imu_topics.accel == "/camera/accel/sample"
    raw = {"/camera/gyro/sample": [], "/camera/accel/sample": []}
    with AnyReader([bag]) as reader:
        for conn, _, data in reader.messages(connections=[c for c in reader.connections if c.topic in raw]):
            msg = reader.deserialize(data, conn.msgtype)
            t = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            w, a = msg.angular_velocity, msg.linear_acceleration
            raw[conn.topic].append((t, w.x, w.y, w.z, a.x, a.y, a.z))
    g = sorted(raw["/camera/gyro/sample"])
    a = sorted(raw["/camera/accel/sample"])
    tg = np.array([r[0] for r in g], dtype=np.int64)  # int64: float64 cannot hold 1.55e18 ns exactly
    ta = np.array([r[0] for r in a], dtype=np.int64)
    g, a = np.array([r[1:] for r in g]), np.array([r[1:] for r in a])
    inside = (tg >= ta[0]) & (tg <= ta[-1])
    imu = seq.imu
    assert len(imu) == inside.sum() == 15  # 19 gyro samples, 4 outside the 6 accelerometer samples' span
    np.testing.assert_array_equal(imu.t_ns, tg[inside])
    np.testing.assert_allclose(imu.gyro, g[inside, 0:3], rtol=0, atol=1e-12)
    for k in range(3):
        expected = np.interp((tg[inside] - ta[0]).astype(float), (ta - ta[0]).astype(float), a[:, 3 + k])
        np.testing.assert_allclose(imu.acc[:, k], expected, rtol=1e-12)
    assert np.all(np.linalg.norm(imu.acc, axis=1) > 9.0) and np.all(np.any(imu.gyro != 0, axis=1))


def test_t265_half_imu_refused_and_device_odometry_not_ground_truth():
    bag = shared_path("real_bags", "kapture_t265_stereo_imu", "trimmed_locoffice.bag")
    with pytest.raises(GeviError) as info:
        open_sequence(bag, topics="imu=/camera/accel/sample")
    line = info.value.one_line()
    assert "\n" not in line and "/camera/accel/sample" in line and "gyroscope is all zeros" in line
    assert "gyro=TOPIC,accel=TOPIC" in line
    seq = open_sequence(bag)
    assert seq.groundtruth is None
    assert any("/camera/odom/sample" in w and "--topics gt=TOPIC" in w for w in seq.warnings)
    # asked for explicitly, the odometry is read (19 poses)
    assert len(open_sequence(bag, topics="gt=/camera/odom/sample").groundtruth) == 19


def test_lone_db3_and_mcap_open(tmp_path):
    src = shared_path("real_bags", "plotjuggler_rosbag2_dashing_db3", "rosbag2_test", "rosbag2_test_0.db3")
    lone = tmp_path / "alone" / "rosbag2_test_0.db3"
    lone.parent.mkdir()
    shutil.copy(src, lone)  # a copy in the test's tmp folder only, without its metadata.yaml
    for path in (lone, lone.parent):
        imu = BagImu(path)
        assert len(imu.imu) == 1565 and imu.groundtruth is None  # /pose is not named as ground truth
    # its /pose holds placeholder values (SOURCE.md: not physical): quaternions of norm 13 are refused
    with pytest.raises(GeviError) as info:
        BagImu(lone, topics="gt=/pose")
    assert "/pose:1: quaternion norm 13.19" in info.value.one_line()
    mcap = shared_path("real_bags", "evo_nav2_turtlebot_mcap", "nav2_turtlebot.mcap")
    with pytest.raises(GeviError) as info:
        BagImu(mcap)
    assert info.value.one_line().startswith(f"{mcap}: no IMU topic (sensor_msgs/Imu); topics: /amcl_pose")


def test_gevi_imu_on_imu_only_bags(tmp_path, capsys):
    bag = shared_path("real_bags", "imu_tools_phidgets", "phidgets_imu_upside_down.bag")
    code, out, err = run_cli(["imu", bag, "-o", tmp_path / "phidgets", "--no-plots"], capsys)
    assert code == 0, err
    assert "IMU: 13964 samples, 56.2 s at 250.0 Hz" in out
    # mounted upside down: the starting roll is 180 deg away from level
    roll = float(re.search(r"roll ([+-]\d+\.\d+) deg", out).group(1))
    assert abs(abs(roll) - 180.0) < 3.0
    assert (tmp_path / "phidgets" / "imu_states.csv").is_file()
    # poses only: one line naming what is missing
    poses = shared_path("real_bags", "evo_ros_example_poses", "ROS_example.bag")
    code, out, err = run_cli(["imu", poses, "-o", tmp_path / "poses"], capsys)
    assert code == 2 and err.count("\n") == 1 and "no IMU topic" in err


def test_gevi_run_on_a_bag_without_images_says_so(tmp_path, capsys):
    bag = shared_path("real_bags", "imu_tools_phidgets", "phidgets_imu_upside_down.bag")
    code, _, err = run_cli(["run", bag, "-o", tmp_path / "r"], capsys)
    assert code == 2 and err.count("\n") == 1
    assert "no image topics" in err and "stereo" in err


def test_simulation_clock_is_kept_and_reported():
    from gevi_cli.datasets.bag_inventory import inventory

    bag = shared_path("real_bags", "evo_nav2_turtlebot_mcap", "nav2_turtlebot.mcap")

    inv = inventory(bag)
    odom = next(t for t in inv.topics if t.name == "/odom")
    # header stamps on the simulation clock (~928 s), the bag's receive times on the wall clock
    assert 900e9 < odom.stamps_ns[0] < 1000e9 and inv.start_ns > 1.7e18
    assert "odometry (an estimate, not ground truth)" in odom.detail
