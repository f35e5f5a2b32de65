"""ROS1 bag (rosbags) plus Kalibr-style calibration files.

::

    OUT/simulation.yaml
    OUT/<name>.bag             /cam0/image_raw, /cam1/image_raw (sensor_msgs/Image mono8),
                               /imu0 (sensor_msgs/Imu), /groundtruth/pose (geometry_msgs/PoseStamped,
                               body = IMU poses in the world frame, 200 Hz), and for the pool presets
                               /mocap0/pose (marker body poses, 100 Hz)
    OUT/<name>_camchain.yaml   Kalibr camchain: T_cam_imu (IMU -> camera), intrinsics, radtan, T_cn_cnm1
    OUT/<name>_imu.yaml        Kalibr imu.yaml: noise densities and random walks, update_rate, rostopic

Header stamps and bag record times are the nanosecond stamps of the EuRoC layout; messages are
written in time order.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gevi_cli.datasets.kalibr import write_camchain, write_imu_yaml
from gevi_cli.geometry import matrix_to_quat_wxyz
from gevi_cli.simulate.camera import as_read
from gevi_cli.simulate.writers import write_simulation_yaml

TOPIC_CAM = ("/cam0/image_raw", "/cam1/image_raw")
TOPIC_IMU = "/imu0"
TOPIC_GT = "/groundtruth/pose"
TOPIC_MOCAP = "/mocap0/pose"


def write_bag(seq, out: Path, progress: bool = True, workers: int | None = None, name: str | None = None) -> Path:
    """Write ``seq`` as ``out/<name>.bag`` plus Kalibr yaml files; returns the bag path."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    name = name or seq.config.preset
    write_simulation_yaml(out / "simulation.yaml", seq.description("bag"))
    write_camchain(out / f"{name}_camchain.yaml", as_read(seq.rig), {"left": TOPIC_CAM[0], "right": TOPIC_CAM[1]})
    imu = seq.config.imu
    write_imu_yaml(out / f"{name}_imu.yaml", gyro_noise_density=imu.gyro_noise_density,
                   gyro_random_walk=imu.gyro_random_walk, acc_noise_density=imu.acc_noise_density,
                   acc_random_walk=imu.acc_random_walk, rostopic=TOPIC_IMU, update_rate=imu.rate_hz)

    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    Time = T["builtin_interfaces/msg/Time"]
    Header = T["std_msgs/msg/Header"]
    Image = T["sensor_msgs/msg/Image"]
    Imu = T["sensor_msgs/msg/Imu"]
    PoseStamped = T["geometry_msgs/msg/PoseStamped"]
    Pose = T["geometry_msgs/msg/Pose"]
    Point = T["geometry_msgs/msg/Point"]
    Quaternion = T["geometry_msgs/msg/Quaternion"]
    Vector3 = T["geometry_msgs/msg/Vector3"]

    def header(seq_no: int, t_ns: int, frame: str):
        return Header(seq=seq_no, stamp=Time(sec=t_ns // 1_000_000_000, nanosec=t_ns % 1_000_000_000), frame_id=frame)

    imu = seq.imu
    gt = seq.groundtruth
    q_gt = matrix_to_quat_wxyz(gt.R_WB)
    p = seq.config.imu
    dt = 1.0 / p.rate_hz
    cov_g = np.diag([p.gyro_noise_density ** 2 / dt] * 3).ravel()
    cov_a = np.diag([p.acc_noise_density ** 2 / dt] * 3).ravel()
    no_orientation = np.zeros(9)
    no_orientation[0] = -1.0  # ROS: orientation not provided

    def pose_msg(i, t_ns, pos, q, frame):
        return PoseStamped(header=header(i, t_ns, frame), pose=Pose(
            position=Point(x=float(pos[0]), y=float(pos[1]), z=float(pos[2])),
            orientation=Quaternion(x=float(q[1]), y=float(q[2]), z=float(q[3]), w=float(q[0]))))

    # time-ordered queue of the high-rate streams: (t_ns, order, kind, index)
    events = [(int(t), 0, "imu", i) for i, t in enumerate(imu.t_ns.tolist())]
    events += [(int(t), 1, "gt", i) for i, t in enumerate(imu.t_ns.tolist())]
    mocap = None
    if seq.spec.mocap:
        t_m, T_m = seq.mocap
        mocap = (t_m, T_m[:, :3, 3], matrix_to_quat_wxyz(T_m[:, :3, :3]))
        events += [(int(t), 2, "mocap", i) for i, t in enumerate(t_m.tolist())]
    events.sort()

    bag_path = out / f"{name}.bag"
    with Writer(bag_path) as writer:
        c_cam = [writer.add_connection(tp, "sensor_msgs/msg/Image", typestore=ts) for tp in TOPIC_CAM]
        c_imu = writer.add_connection(TOPIC_IMU, "sensor_msgs/msg/Imu", typestore=ts)
        c_gt = writer.add_connection(TOPIC_GT, "geometry_msgs/msg/PoseStamped", typestore=ts)
        c_mocap = writer.add_connection(TOPIC_MOCAP, "geometry_msgs/msg/PoseStamped", typestore=ts) if mocap else None
        pos = 0

        def flush(until_ns: int):
            nonlocal pos
            while pos < len(events) and events[pos][0] <= until_ns:
                t, _, kind, i = events[pos]
                if kind == "imu":
                    g, a = imu.gyro[i], imu.acc[i]
                    msg = Imu(header=header(i, t, "imu0"), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
                              orientation_covariance=no_orientation,
                              angular_velocity=Vector3(x=float(g[0]), y=float(g[1]), z=float(g[2])),
                              angular_velocity_covariance=cov_g,
                              linear_acceleration=Vector3(x=float(a[0]), y=float(a[1]), z=float(a[2])),
                              linear_acceleration_covariance=cov_a)
                    writer.write(c_imu, t, ts.serialize_ros1(msg, Imu.__msgtype__))
                elif kind == "gt":
                    msg = pose_msg(i, t, gt.p_W[i], q_gt[i], "world")
                    writer.write(c_gt, t, ts.serialize_ros1(msg, PoseStamped.__msgtype__))
                else:
                    msg = pose_msg(i, t, mocap[1][i], mocap[2][i], "world")
                    writer.write(c_mocap, t, ts.serialize_ros1(msg, PoseStamped.__msgtype__))
                pos += 1

        for k, t, left, right in seq.frames(progress=progress, workers=workers):
            flush(t)
            for cam, img in enumerate((left, right)):
                h, w = img.shape
                msg = Image(header=header(k, t, f"cam{cam}"), height=h, width=w, encoding="mono8", is_bigendian=0,
                            step=w, data=np.ascontiguousarray(img).reshape(-1))
                writer.write(c_cam[cam], t, ts.serialize_ros1(msg, Image.__msgtype__))
        flush(np.iinfo(np.int64).max)
    return bag_path
