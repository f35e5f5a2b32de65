"""The topic rules shared by the bag readers: which pose topic is ground truth, which IMU topics pair."""
from __future__ import annotations

from gevi_cli.datasets.bag_streams import ground_truth_topic, names_ground_truth, split_imu_pair

PS, ODOM, TF = "geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry", "geometry_msgs/msg/TransformStamped"


def test_ground_truth_only_when_named_or_motion_capture():
    assert ground_truth_topic({"/camera/odom/sample": ODOM})[0] is None  # a device's own VIO
    topic, warning = ground_truth_topic({"/odom": ODOM, "/amcl_pose": PS})
    assert topic is None and "--topics gt=TOPIC" in warning and "/odom" in warning and "/amcl_pose" in warning
    assert ground_truth_topic({"ORB-SLAM": PS, "groundtruth": PS}) == ("groundtruth", None)
    assert ground_truth_topic({"/vicon/firefly_sbx/firefly_sbx": TF, "/odom": ODOM})[0] == "/vicon/firefly_sbx/firefly_sbx"
    assert ground_truth_topic({"/robot/pose": PS, "/mocap_node/body": TF})[0] == "/mocap_node/body"
    assert ground_truth_topic({"/ext/pose": TF})[0] == "/ext/pose"  # what motion-capture bridges publish
    topic, warning = ground_truth_topic({"/leica/position": PS, "/optitrack/rig": PS})
    assert topic == "/leica/position" and "2 candidates" in warning
    assert ground_truth_topic({}) == (None, None)


def test_gt_as_a_word_only():
    assert names_ground_truth("/gt/pose") and names_ground_truth("/body_gt") and names_ground_truth("/Ground_Truth")
    assert not names_ground_truth("/gtk_state") and not names_ground_truth("/light/pose")


def test_split_imu_pair_needs_exactly_one_of_each():
    assert split_imu_pair(["/camera/accel/sample", "/camera/gyro/sample"]) == ("/camera/gyro/sample",
                                                                               "/camera/accel/sample")
    assert split_imu_pair(["/imu0", "/imu1"]) is None
    assert split_imu_pair(["/camera/accel/sample", "/camera/gyro/sample", "/imu"]) is None
