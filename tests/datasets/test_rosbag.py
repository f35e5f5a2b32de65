"""ROS bag reader: ROS1 and ROS2 bags built from EuRoC-micro must read back exactly as the EuRoC folder.

The bags are written here with the rosbags writers: 20 stereo pairs (ROS1: raw mono8 ``Image``; ROS2
mcap: ``CompressedImage`` holding the original PNG bytes), the IMU samples of that span and the
OpenVINS ground truth poses of that span.  Bag (receive) times are deliberately later than the header
stamps and jittered, so a reader using bag time instead of header stamps fails.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from gevi_cli.datasets import open_sequence
from gevi_cli.datasets.kalibr import read_camchain, write_camchain
from gevi_cli.errors import GeviError
from gevi_cli.geometry import invert_pose
from gevi_cli.trajectory import read_trajectory
from support import run_cli, shared_path

N_PAIRS = 20
FIRST = 30  # first of the EuRoC-micro pairs put in the bags


# ------------------------------------------------------------------------------------ bag writing
def _typestore(ros2: bool):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)


class BagBuilder:
    """Collects (topic, msgtype, bag_ns, message) and writes a ROS1 .bag or a ROS2 folder."""

    def __init__(self, ros2: bool):
        self.ros2 = ros2
        self.ts = _typestore(ros2)
        self.T = self.ts.types
        self.items: list[tuple[str, str, int, object]] = []

    def header(self, t_ns: int, frame_id: str = ""):
        stamp = self.T["builtin_interfaces/msg/Time"](sec=int(t_ns) // 10**9, nanosec=int(t_ns) % 10**9)
        kw = {} if self.ros2 else {"seq": 0}
        return self.T["std_msgs/msg/Header"](**kw, stamp=stamp, frame_id=frame_id)

    def vec(self, x, y, z):
        return self.T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    def image(self, topic, t_ns, pixels: np.ndarray, encoding="mono8", bag_ns=None):
        h, w = pixels.shape[:2]
        data = np.ascontiguousarray(pixels).view(np.uint8).reshape(-1)
        msg = self.T["sensor_msgs/msg/Image"](header=self.header(t_ns, topic), height=h, width=w, encoding=encoding,
                                              is_bigendian=0, step=len(data) // h, data=data)
        self.items.append((topic, "sensor_msgs/msg/Image", bag_ns or t_ns, msg))

    def compressed(self, topic, t_ns, payload: bytes, fmt="mono8; png compressed ", bag_ns=None):
        msg = self.T["sensor_msgs/msg/CompressedImage"](header=self.header(t_ns, topic), format=fmt,
                                                        data=np.frombuffer(payload, dtype=np.uint8))
        self.items.append((topic, "sensor_msgs/msg/CompressedImage", bag_ns or t_ns, msg))

    def imu(self, topic, t_ns, gyro, acc, bag_ns=None):
        q = self.T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        msg = self.T["sensor_msgs/msg/Imu"](
            header=self.header(t_ns, "imu4"), orientation=q, orientation_covariance=np.full(9, -1.0),
            angular_velocity=self.vec(*gyro), angular_velocity_covariance=np.zeros(9),
            linear_acceleration=self.vec(*acc), linear_acceleration_covariance=np.zeros(9))
        self.items.append((topic, "sensor_msgs/msg/Imu", bag_ns or t_ns, msg))

    def pose(self, topic, msgtype, t_ns, p, q_wxyz, bag_ns=None):
        T = self.T
        point = T["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=float(p[2]))
        quat = T["geometry_msgs/msg/Quaternion"](w=float(q_wxyz[0]), x=float(q_wxyz[1]), y=float(q_wxyz[2]),
                                                 z=float(q_wxyz[3]))
        hdr = self.header(t_ns, "world")
        if msgtype == "geometry_msgs/msg/PoseStamped":
            msg = T[msgtype](header=hdr, pose=T["geometry_msgs/msg/Pose"](position=point, orientation=quat))
        elif msgtype == "geometry_msgs/msg/TransformStamped":
            msg = T[msgtype](header=hdr, child_frame_id="body",
                             transform=T["geometry_msgs/msg/Transform"](translation=self.vec(*p), rotation=quat))
        else:  # nav_msgs/msg/Odometry
            pose = T["geometry_msgs/msg/PoseWithCovariance"](
                pose=T["geometry_msgs/msg/Pose"](position=point, orientation=quat), covariance=np.zeros(36))
            twist = T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=self.vec(0, 0, 0), angular=self.vec(0, 0, 0)),
                covariance=np.zeros(36))
            msg = T[msgtype](header=hdr, child_frame_id="body", pose=pose, twist=twist)
        self.items.append((topic, msgtype, bag_ns or t_ns, msg))

    def write(self, path: Path, storage: str = "sqlite3") -> Path:
        if self.ros2:
            from rosbags.rosbag2 import StoragePlugin, Writer

            plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
            writer = Writer(path, version=9, storage_plugin=plugin)
            serialize = self.ts.serialize_cdr
        else:
            from rosbags.rosbag1 import Writer

            writer = Writer(path)
            serialize = self.ts.serialize_ros1
        with writer:
            conns = {}
            for topic, msgtype, bag_ns, msg in sorted(self.items, key=lambda item: item[2]):
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, msgtype, typestore=self.ts)
                writer.write(conns[topic], int(bag_ns), serialize(msg, msgtype))
        return path


def _camchain_from_euroc(mav0: Path, topics: dict | None = None) -> dict:
    """A Kalibr camchain written by hand from the EuRoC sensor.yaml files (T_cam_imu = inv(T_BS))."""
    out = {}
    for cam in ("cam0", "cam1"):
        text = (mav0 / cam / "sensor.yaml").read_text().split("\n", 1)[1]  # drop %YAML:1.0
        data = yaml.safe_load(text)
        T_BS = np.array(data["T_BS"]["data"], dtype=np.float64).reshape(4, 4)
        block = {
            "T_cam_imu": invert_pose(T_BS).tolist(),
            "camera_model": "pinhole",
            "distortion_coeffs": [float(v) for v in data["distortion_coefficients"]],
            "distortion_model": "radtan",
            "intrinsics": [float(v) for v in data["intrinsics"]],
            "resolution": [int(v) for v in data["resolution"]],
            "timeshift_cam_imu": 0.0,
        }
        if topics:
            block["rostopic"] = topics[cam]
        out[cam] = block
    return out


@pytest.fixture(scope="module")
def euroc():
    root = shared_path("euroc_micro")
    seq = open_sequence(root)
    gt = read_trajectory(root / "groundtruth" / "V1_01_easy.csv", name="groundtruth", frame="body")
    stamps = seq.stamps_ns[FIRST:FIRST + N_PAIRS]
    return {"root": root, "seq": seq, "stamps": stamps, "imu": seq.imu.between(int(stamps[0]), int(stamps[-1])),
            "gt": gt, "gt_sel": (gt.t_ns >= stamps[0]) & (gt.t_ns <= stamps[-1])}


def _fill(builder: BagBuilder, euroc, compressed: bool, gt_type: str):
    root, stamps = euroc["root"], euroc["stamps"]
    rng = np.random.default_rng(7)
    for k, t in enumerate(stamps):
        t = int(t)
        for cam, topic in (("cam0", "/cam0/image_raw"), ("cam1", "/cam1/image_raw")):
            file = root / "mav0" / cam / "data" / f"{t}.png"
            # receive time 2-12 ms after the stamp, right often before left
            bag_ns = t + int(rng.integers(2_000_000, 12_000_000))
            if compressed:
                builder.compressed(topic + "/compressed", t, file.read_bytes(), bag_ns=bag_ns)
            else:
                builder.image(topic, t, cv2.imread(str(file), cv2.IMREAD_GRAYSCALE), bag_ns=bag_ns)
    imu = euroc["imu"]
    for t, g, a in zip(imu.t_ns, imu.gyro, imu.acc):
        builder.imu("/imu0", int(t), g, a, bag_ns=int(t) + int(rng.integers(0, 30_000_000)))
    gt, sel = euroc["gt"], euroc["gt_sel"]
    for t, p, q in zip(gt.t_ns[sel], gt.positions[sel], gt.quat_wxyz[sel]):
        builder.pose("/groundtruth/pose", gt_type, int(t), p, q, bag_ns=int(t) + 1_000_000)


@pytest.fixture(scope="module")
def ros1_bag(euroc, tmp_path_factory):
    """ROS1 bag with raw mono8 images, PoseStamped GT, and Kalibr side files found by name."""
    folder = tmp_path_factory.mktemp("ros1")
    builder = BagBuilder(ros2=False)
    _fill(builder, euroc, compressed=False, gt_type="geometry_msgs/msg/PoseStamped")
    bag = builder.write(folder / "micro.bag")
    (folder / "micro_camchain.yaml").write_text(yaml.safe_dump(_camchain_from_euroc(euroc["root"] / "mav0")))
    imu_yaml = {"accelerometer_noise_density": 2.0e-3, "accelerometer_random_walk": 3.0e-3,
                "gyroscope_noise_density": 1.6968e-4, "gyroscope_random_walk": 1.9393e-5, "rostopic": "/imu0",
                "update_rate": 200.0}
    (folder / "micro_imu.yaml").write_text(yaml.safe_dump(imu_yaml))
    return bag


@pytest.fixture(scope="module")
def ros2_bag(euroc, tmp_path_factory):
    """ROS2 mcap bag with CompressedImage (the original PNG bytes) and Odometry GT; no side files."""
    folder = tmp_path_factory.mktemp("ros2")
    builder = BagBuilder(ros2=True)
    _fill(builder, euroc, compressed=True, gt_type="nav_msgs/msg/Odometry")
    return builder.write(folder / "micro_ros2", storage="mcap")


def _assert_same_as_euroc(seq, euroc):
    ref = euroc["seq"]
    stamps = euroc["stamps"]
    assert seq.kind == "rosbag"
    assert len(seq) == N_PAIRS
    np.testing.assert_array_equal(seq.stamps_ns, stamps)
    assert seq.stamps_ns.dtype == np.int64
    # calibration: intrinsics/distortion equal, extrinsics equal to round-off of inv(inv(T_BS))
    mine, theirs = seq.calibration, ref.calibration
    assert (mine.cam0, mine.cam1) == (theirs.cam0, theirs.cam1)
    for T_mine, T_theirs in ((mine.T_B_C0, theirs.T_B_C0), (mine.T_B_C1, theirs.T_B_C1)):
        np.testing.assert_allclose(T_mine, T_theirs, rtol=0, atol=1e-12)
    # IMU: identical samples, bitwise
    imu, ref_imu = seq.imu, euroc["imu"]
    np.testing.assert_array_equal(imu.t_ns, ref_imu.t_ns)
    assert imu.gyro.dtype == np.float64 and imu.gyro.tobytes() == ref_imu.gyro.tobytes()
    assert imu.acc.tobytes() == ref_imu.acc.tobytes()
    assert len(imu) > 150
    assert (imu.gyro_noise_density, imu.gyro_random_walk, imu.acc_noise_density, imu.acc_random_walk) == \
        (1.6968e-4, 1.9393e-5, 2.0e-3, 3.0e-3)
    # ground truth: the CSV poses of the span
    gt, sel = euroc["gt"], euroc["gt_sel"]
    assert seq.groundtruth is not None and seq.groundtruth.frame == "body"
    np.testing.assert_array_equal(seq.groundtruth.t_ns, gt.t_ns[sel])
    assert seq.groundtruth.positions.tobytes() == gt.positions[sel].tobytes()
    assert seq.groundtruth.quat_wxyz.tobytes() == gt.quat_wxyz[sel].tobytes()
    # pixels: streaming and random access both equal to the EuRoC PNGs
    streamed = list(seq.frames())
    assert [f.t_ns for f in streamed] == stamps.tolist()
    for k in (0, 7, N_PAIRS - 1):
        expected = ref.read_pair(FIRST + k)
        for frame in (streamed[k], seq.read_pair(k)):
            assert frame.t_ns == expected.t_ns
            assert frame.left.dtype == np.uint8 and frame.left.shape == (480, 752)
            np.testing.assert_array_equal(frame.left, expected.left)
            np.testing.assert_array_equal(frame.right, expected.right)
    for a, b in zip(streamed, ref.frames(FIRST, FIRST + N_PAIRS)):
        assert a.left.tobytes() == b.left.tobytes() and a.right.tobytes() == b.right.tobytes()
    sub = list(seq.frames(start=3, stop=15, step=4))
    assert [f.t_ns for f in sub] == stamps[3:15:4].tolist()
    np.testing.assert_array_equal(sub[1].right, streamed[7].right)


def test_ros1_bag_reads_like_euroc(ros1_bag, euroc):
    seq = open_sequence(ros1_bag)  # kind detected; camchain and imu.yaml found next to the bag
    assert seq.name == "micro"
    assert seq.topics == {"left": "/cam0/image_raw", "right": "/cam1/image_raw", "imu": "/imu0",
                          "gt": "/groundtruth/pose"}
    _assert_same_as_euroc(seq, euroc)
    assert seq.warnings == []
    seq.close()


def test_ros2_mcap_bag_reads_like_euroc(ros2_bag, euroc):
    seq = open_sequence(ros2_bag, calib=euroc["root"] / "mav0")  # EuRoC folder as calibration
    assert seq.name == "micro_ros2"
    assert seq.topics["left"] == "/cam0/image_raw/compressed"
    _assert_same_as_euroc(seq, euroc)
    seq.close()
    # the .mcap file inside the folder opens the same bag
    mcap = next(ros2_bag.glob("*.mcap"))
    assert len(open_sequence(mcap, calib=euroc["root"] / "mav0")) == N_PAIRS


def test_topics_option_and_kalibr_writer(ros1_bag, euroc, tmp_path):
    # --topics swaps left and right: the stamps stay, the pixels swap
    seq = open_sequence(ros1_bag, topics="left=/cam1/image_raw,right=/cam0/image_raw,gt=none")
    frame = seq.read_pair(2)
    expected = euroc["seq"].read_pair(FIRST + 2)
    np.testing.assert_array_equal(frame.left, expected.right)
    assert seq.groundtruth is None and seq.imu is not None
    # a camchain written by gevi's writer reads back to the same rig, and its rostopic chooses the sides
    calib = tmp_path / "rig.yaml"
    write_camchain(calib, euroc["seq"].calibration, {"left": "/cam1/image_raw", "right": "/cam0/image_raw"})
    chain = read_camchain(calib)
    assert chain.rig.cam0 == euroc["seq"].calibration.cam0
    np.testing.assert_allclose(chain.rig.T_B_C1, euroc["seq"].calibration.T_B_C1, atol=1e-12)
    # an explicit imu_calib (Kalibr imu.yaml, keys under imu0) wins over micro_imu.yaml next to the bag
    imu_yaml = tmp_path / "imu.yaml"
    imu_yaml.write_text(yaml.safe_dump({"imu0": {"accelerometer_noise_density": 0.1, "accelerometer_random_walk": 0.2,
                                                 "gyroscope_noise_density": 0.3, "gyroscope_random_walk": 0.4}}))
    seq = open_sequence(ros1_bag, calib=calib, imu_calib=imu_yaml)
    assert seq.topics["left"] == "/cam1/image_raw"
    assert (seq.imu.acc_noise_density, seq.imu.acc_random_walk, seq.imu.gyro_noise_density,
            seq.imu.gyro_random_walk) == (0.1, 0.2, 0.3, 0.4)


def test_image_decoding_and_name_rule(tmp_path):
    """Colour/16-bit encodings become gray; left = the topic naming left, even when it sorts second."""
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    mono16 = rng.integers(0, 65536, (6, 8), dtype=np.uint16)
    b = BagBuilder(ros2=True)
    for k in range(3):
        t = 1_000_000_000 + k * 50_000_000
        b.image("/a_right/image", t, mono16, encoding="mono16")
        b.image("/b_left/image", t, rgb, encoding="rgb8")
        b.pose("/vicon/body", "geometry_msgs/msg/TransformStamped", t + 7, (k, 2.0, 3.0), (0.0, 1.0, 0.0, 0.0))
    bag = b.write(tmp_path / "colour")
    _tiny_camchain(tmp_path / "colour" / "camchain.yaml")  # inside the ROS2 bag folder
    seq = open_sequence(bag)
    assert seq.topics["left"] == "/b_left/image" and seq.topics["right"] == "/a_right/image"
    assert seq.imu is None
    gt = seq.groundtruth  # TransformStamped, stamps from the headers
    np.testing.assert_array_equal(gt.t_ns, 1_000_000_007 + np.arange(3) * 50_000_000)
    np.testing.assert_array_equal(gt.positions[:, 0], [0.0, 1.0, 2.0])
    np.testing.assert_array_equal(gt.quat_wxyz, np.tile([0.0, 1.0, 0.0, 0.0], (3, 1)))
    frame = seq.read_pair(1)
    np.testing.assert_array_equal(frame.left, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
    np.testing.assert_array_equal(frame.right, (mono16 >> 8).astype(np.uint8))


# ------------------------------------------------------------------------------------- bad input
def _tiny_camchain(path: Path) -> Path:
    block = {"camera_model": "pinhole", "intrinsics": [10.0, 10.0, 4.0, 3.0], "distortion_model": "none",
             "distortion_coeffs": [], "resolution": [8, 6], "T_cam_imu": np.eye(4).tolist()}
    T = np.eye(4)
    T[0, 3] = -0.1
    path.write_text(yaml.safe_dump({"cam0": block, "cam1": {**block, "T_cam_imu": T.tolist()}}))
    return path


def _tiny_bag(path: Path, image_topics=("/cam0/image_raw", "/cam1/image_raw"), ros2=False, imu=True, camchain=True):
    path.parent.mkdir(parents=True, exist_ok=True)
    b = BagBuilder(ros2=ros2)
    img = np.zeros((6, 8), dtype=np.uint8)
    for k in range(3):
        t = 2_000_000_000 + k * 50_000_000
        for topic in image_topics:
            b.image(topic, t, img)
        if imu:
            b.imu("/imu0", t, (1e-3, -2e-3, 5e-4), (0, 0, 9.81))  # a real gyro is never exactly zero
    b.write(path)
    if camchain:
        _tiny_camchain(path.parent / "camchain.yaml")
    return path


def _error(path, **options) -> str:
    with pytest.raises(GeviError) as info:
        open_sequence(path, **options)
    line = info.value.one_line()
    assert "\n" not in line
    return line


def test_corrupt_bags(tmp_path):
    garbage = tmp_path / "garbage.bag"
    garbage.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 4)
    line = _error(garbage)
    assert line.startswith(f"{garbage}: cannot read the ROS1 bag")
    # a truncated real bag (recording interrupted): its index is gone
    good = _tiny_bag(tmp_path / "good" / "x.bag")
    cut = tmp_path / "cut.bag"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    assert _error(cut).startswith(f"{cut}: cannot read the ROS1 bag")
    # a ROS2 folder whose database is not sqlite
    folder = _tiny_bag(tmp_path / "r2", ros2=True)
    next(folder.glob("*.db3")).write_bytes(b"not a database" * 100)
    assert _error(folder).startswith(f"{folder}: cannot read the ROS2 bag")


def test_no_or_one_image_topic(tmp_path):
    none = _tiny_bag(tmp_path / "a" / "none.bag", image_topics=())
    line = _error(none)
    assert line.startswith(f"{none}: no image topics") and "/imu0 (sensor_msgs/msg/Imu)" in line
    one = _tiny_bag(tmp_path / "b" / "one", image_topics=("/cam0/image_raw",), ros2=True)
    assert _error(one) == (f"{one}: only one image topic (/cam0/image_raw); a stereo sequence needs two, "
                           "left and right")


def test_bad_topics_option(tmp_path):
    bag = _tiny_bag(tmp_path / "t.bag")
    line = _error(bag, topics="left=/nope,right=/cam1/image_raw")
    assert line == (f"{bag}: --topics left=/nope: no such topic in the bag "
                    "(image topics: /cam0/image_raw, /cam1/image_raw)")
    assert _error(bag, topics="imu=/cam0/image_raw").startswith(
        f"{bag}: --topics imu=/cam0/image_raw: the topic has type sensor_msgs/msg/Image")
    assert _error(bag, topics="centre=/cam0/image_raw").startswith("--topics: unknown role 'centre'")
    assert _error(bag, topics="/cam0/image_raw").startswith("--topics: '/cam0/image_raw' is not ROLE=TOPIC")
    # three image topics and no name says which is right
    three = _tiny_bag(tmp_path / "3" / "three.bag", image_topics=("/cam0/image", "/x/image", "/y/image"))
    assert "pass --topics left=TOPIC,right=TOPIC" in _error(three)
    assert len(open_sequence(three, topics="right=/y/image")) == 3


def test_missing_calibration(tmp_path):
    bag = _tiny_bag(tmp_path / "nocal.bag", camchain=False)
    line = _error(bag)
    assert line.startswith(f"{bag}: no camera calibration") and "--calib" in line and "nocal_camchain.yaml" in line
    assert _error(bag, calib=tmp_path / "absent.yaml").startswith("--calib: ")
    (tmp_path / "cam0").mkdir()
    assert "cam0/sensor.yaml" in _error(bag, calib=tmp_path)


def test_cli_info_reports_bag_errors(tmp_path, capsys):
    bag = _tiny_bag(tmp_path / "c.bag")
    code, out, err = run_cli(["info", bag, "--topics", "left=/nope,right=/cam1/image_raw"], capsys)
    assert code == 2
    assert err.strip() == (f"gevi: error: {bag}: --topics left=/nope: no such topic in the bag "
                           "(image topics: /cam0/image_raw, /cam1/image_raw)")
    garbage = tmp_path / "g.bag"
    garbage.write_bytes(b"junk")
    code, _, err = run_cli(["info", garbage], capsys)
    assert code == 2 and err.startswith(f"gevi: error: {garbage}: cannot read the ROS1 bag") and err.count("\n") == 1


# ------------------------------------------------------------------------------------ time stamps
def _stamp_bag(path: Path, imu_header, image_header=lambda t: t, split=False):
    """Images and IMU with bag (receive) times ``t + 3 ms``; header stamps from the given functions."""
    path.parent.mkdir(parents=True, exist_ok=True)
    b = BagBuilder(ros2=False)
    img = np.zeros((6, 8), dtype=np.uint8)
    for k in range(5):
        t = 2_000_000_000 + k * 50_000_000
        for topic in ("/cam0/image_raw", "/cam1/image_raw"):
            b.image(topic, image_header(t), img, bag_ns=t + 3_000_000)
    for k in range(50):
        t = 2_000_000_000 + k * 5_000_000
        if split:
            b.imu("/camera/gyro/sample", imu_header(t, k), (0.1, 0.2, 0.3), (0, 0, 0), bag_ns=t + 3_000_000)
            if k % 2 == 0:
                b.imu("/camera/accel/sample", imu_header(t, k), (0, 0, 0), (0.0, 0.1 * k, 9.81), bag_ns=t + 3_000_000)
        else:
            b.imu("/imu0", imu_header(t, k), (1e-3, -2e-3, 5e-4), (0, 0, 9.81), bag_ns=t + 3_000_000)
    b.write(path)
    _tiny_camchain(path.parent / "camchain.yaml")
    return path


def test_zero_header_stamps_fall_back_to_receive_time_with_a_warning(tmp_path):
    seq = open_sequence(_stamp_bag(tmp_path / "a" / "z.bag", imu_header=lambda t, k: 0))
    np.testing.assert_array_equal(seq.imu.t_ns, 2_003_000_000 + np.arange(50) * 5_000_000)
    assert any("/imu0: every header stamp is zero" in w and "receive times" in w for w in seq.warnings)
    np.testing.assert_array_equal(seq.stamps_ns, 2_000_000_000 + np.arange(5) * 50_000_000)  # images: headers
    # images without header stamps are paired on their receive times
    seq = open_sequence(_stamp_bag(tmp_path / "b" / "zi.bag", imu_header=lambda t, k: t, image_header=lambda t: 0))
    np.testing.assert_array_equal(seq.stamps_ns, 2_003_000_000 + np.arange(5) * 50_000_000)


def test_some_zero_stamps_are_dropped_and_counted(tmp_path):
    seq = open_sequence(_stamp_bag(tmp_path / "p.bag", imu_header=lambda t, k: 0 if k in (3, 17) else t))
    assert len(seq.imu) == 48 and 0 not in seq.imu.t_ns
    assert any("/imu0: 2 of 50 message(s) have a zero header stamp; dropped" in w for w in seq.warnings)


def test_clocks_that_disagree_are_reported_with_the_numbers(tmp_path):
    seq = open_sequence(_stamp_bag(tmp_path / "c.bag", imu_header=lambda t, k: t + 7_000_000_000))
    offsets = [w for w in seq.warnings if "different clocks" in w]
    assert len(offsets) == 1 and "+6.997 s" in offsets[0] and "-0.003 s" in offsets[0]
    assert any("/imu0: header stamps are +6.997 s from the bag's receive times" in w for w in seq.warnings)


def test_split_imu_topics_merge_by_name_or_by_option(tmp_path):
    bag = _stamp_bag(tmp_path / "s.bag", imu_header=lambda t, k: t, split=True)
    seq = open_sequence(bag)
    assert seq.imu_topics.split and any("merged them" in w for w in seq.warnings)
    # gyro samples inside the accelerometer's span (0..48 of 50), accel interpolated: a_y = 0.1 k
    np.testing.assert_array_equal(seq.imu.t_ns, 2_000_000_000 + np.arange(49) * 5_000_000)
    np.testing.assert_allclose(seq.imu.acc[:, 1], 0.1 * np.arange(49), atol=1e-12)
    np.testing.assert_allclose(seq.imu.gyro, np.tile([0.1, 0.2, 0.3], (49, 1)))
    same = open_sequence(bag, topics="gyro=/camera/gyro/sample,accel=/camera/accel/sample")
    np.testing.assert_array_equal(same.imu.acc, seq.imu.acc)
    # swapped: the "gyro" topic has zero rates, named in one line
    assert "/camera/accel/sample: the gyroscope is all zeros" in _error(
        bag, topics="gyro=/camera/accel/sample,accel=/camera/gyro/sample")
    assert _error(bag, topics="gyro=/camera/gyro/sample").startswith("--topics: gyro= and accel= go together")
