"""The IMU of any ROS bag, with its ground truth when it has one: what ``gevi imu`` reads from a bag.

Unlike :class:`~gevi_cli.datasets.rosbag.RosbagSequence` it needs no images and no camera
calibration, so IMU-only bags (a Phidgets or Xsens recording) are reports too.  Topic choice, split
accel/gyro merging, stamps and the ground-truth rule are those of :mod:`.bag_streams`.
"""
from __future__ import annotations

from pathlib import Path

from gevi_cli.datasets import bag_streams as streams
from gevi_cli.datasets.bagfile import bag_root, describe_error, open_reader
from gevi_cli.datasets.rosbag import (
    check_requested_topics,
    choose_gt_topic,
    choose_imu_topics,
    find_imu_noise,
    parse_topics,
)
from gevi_cli.errors import DataError, GeviError, LayoutError
from gevi_cli.trajectory import read_trajectory


class BagImu:
    """``imu`` (:class:`~gevi_cli.datasets.sequence.ImuData`, body frame) and ``groundtruth`` (body poses or
    None) of the bag at ``path``; ``topics`` as for ``--topics`` (imu=, gyro= + accel=, gt=)."""

    kind = "rosbag"
    imu_time_offset_s = 0.0  # no camera clock here: the IMU's own stamps

    def __init__(self, path: Path, topics=None, imu_calib=None, groundtruth=None):
        self.path = bag_root(Path(path))
        self.name = self.path.stem if self.path.is_file() else self.path.resolve().name
        self.warnings: list[str] = []
        requested = parse_topics(topics)
        for role in ("left", "right"):
            requested.pop(role, None)
        reader = open_reader(self.path)
        try:
            available = {name: info.msgtype for name, info in reader.topics.items()}
            check_requested_topics(self.path, available, requested)
            noise, hint, self.imu_calibration_file = find_imu_noise(self.path, imu_calib)
            self.imu_topics = choose_imu_topics(self.path, available, requested, hint, self.warnings)
            if self.imu_topics is None:
                listing = ", ".join(f"{t} ({ty})" for t, ty in sorted(available.items())) or "none"
                raise LayoutError(self.path, f"no IMU topic (sensor_msgs/Imu); topics: {listing}")
            self.gt_topic = None if groundtruth is not None else choose_gt_topic(self.path, available, requested,
                                                                                 self.warnings)
            wanted = set(self.imu_topics.names) | ({self.gt_topic} if self.gt_topic else set())
            samples = {t: streams.TopicSamples.empty() for t in wanted}
            count = 0
            try:
                for conn, bag_ns, raw in reader.messages(connections=[c for c in reader.connections if c.topic in wanted]):
                    count += 1
                    msg = reader.deserialize(raw, conn.msgtype)
                    if conn.topic == self.gt_topic:
                        samples[conn.topic].add_pose(msg, conn.msgtype, bag_ns)
                    else:
                        samples[conn.topic].add_imu(msg, bag_ns)
            except GeviError:
                raise
            except Exception as err:
                raise DataError(self.path, f"cannot read message {count + 1} of the IMU/pose topics "
                                           f"({describe_error(err)}); the bag may be truncated or corrupt") from err
        finally:
            reader.close()
        self.imu = streams.build_imu(str(self.path), self.imu_topics, samples, noise, self.warnings)
        if groundtruth is not None:
            self.groundtruth = read_trajectory(groundtruth, name="groundtruth", frame="body")
            self.warnings.extend(self.groundtruth.meta["warnings"])
        elif self.gt_topic is not None:
            self.groundtruth = streams.build_groundtruth(str(self.path), self.gt_topic, samples[self.gt_topic],
                                                         self.warnings)
        else:
            self.groundtruth = None
