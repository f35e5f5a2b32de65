"""What a ROS bag holds, whatever it is: topics with types and counts, image sizes and encodings, IMU
rate and gaps, pose topics, duration; and which gevi commands can use it.

``gevi info`` prints this for every bag, so a bag without images, or without a calibration, is
described instead of refused with a misleading "no camera calibration".  Only messages of the types
gevi reads are decoded (images: the first of each topic; IMU and poses: all), so bags with custom
message types whose definitions the type store lacks are described too.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gevi_cli.datasets import bag_streams as streams
from gevi_cli.datasets.bagfile import bag_format, bag_root, describe_error, header_stamp, open_reader
from gevi_cli.datasets.sequence import GAP_FACTOR, rate_hz
from gevi_cli.errors import DataError

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")


@dataclass(frozen=True)
class TopicInfo:
    """One topic: ``count`` messages of ``msgtype``; ``detail`` says what gevi read of it."""

    name: str
    msgtype: str
    count: int
    detail: str = ""
    role: str = ""  # "image", "imu", "pose", "tf" or ""
    frame_id: str = ""
    stamps_ns: np.ndarray = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class BagInventory:
    path: Path
    format: str
    start_ns: int
    end_ns: int
    topics: tuple[TopicInfo, ...]

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9

    def of_role(self, role: str) -> list[TopicInfo]:
        return [t for t in self.topics if t.role == role]

    @property
    def message_count(self) -> int:
        return sum(t.count for t in self.topics)


def _image_detail(reader, conn, raw) -> tuple[str, str]:
    from gevi_cli.datasets.rosbag import image_to_gray

    msg = reader.deserialize(raw, conn.msgtype)
    frame = str(msg.header.frame_id)
    if conn.msgtype.endswith("CompressedImage"):
        import cv2

        img = cv2.imdecode(np.frombuffer(np.asarray(msg.data, dtype=np.uint8), dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            return f"format '{msg.format}', not decodable by OpenCV", frame
        channels = 1 if img.ndim == 2 else img.shape[2]
        return f"{img.shape[1]}x{img.shape[0]} compressed '{msg.format}' ({channels} channel{'s' if channels > 1 else ''})", frame
    try:
        image_to_gray(msg, conn.msgtype, conn.topic)
        usable = ""
    except DataError as err:
        usable = f", unusable: {err.message}"
    return f"{msg.width}x{msg.height} {msg.encoding}{usable}", frame


def _imu_detail(s: streams.TopicSamples) -> str:
    t, _, w, a = s.arrays()
    if len(t) == 0:
        return "no messages"
    parts = []
    if len(t) > 1:
        order = np.sort(t)
        dt = np.diff(order)
        med = float(np.median(dt))
        gaps = int((dt > GAP_FACTOR * med).sum()) if med > 0 else 0
        longest = float(dt.max()) * 1e-9
        parts.append(f"{rate_hz(order):.1f} Hz, {gaps} gap{'s' if gaps != 1 else ''}"
                     + (f" (longest {longest:.3f} s)" if gaps else ""))
    if not np.any(w):
        parts.append("gyro all zero")
    if not np.any(a):
        parts.append("accel all zero")
    else:
        parts.append(f"|a| median {float(np.median(np.linalg.norm(a, axis=1))):.2f} m/s^2")
    return ", ".join(parts)


def _pose_detail(s: streams.TopicSamples, name: str, msgtype: str) -> str:
    t, _, p, _ = s.arrays()
    if len(t) == 0:
        return "no messages"
    path = float(np.linalg.norm(np.diff(p[np.argsort(t, kind='stable')], axis=0), axis=1).sum()) if len(p) > 1 else 0.0
    rate = f"{rate_hz(np.sort(t)):.1f} Hz, " if len(t) > 1 else ""
    if streams.names_ground_truth(name):
        kind = "ground-truth candidate (named)"
    elif msgtype in streams.MOCAP_TYPES:
        kind = "ground-truth candidate (motion-capture transform)"
    elif msgtype == "nav_msgs/msg/Odometry":
        kind = "odometry (an estimate, not ground truth)"
    else:
        kind = "poses"
    return f"{rate}path {path:.2f} m; {kind}"


def _tf_detail(reader, topic: str) -> str:
    """The transforms (parent.child, evo's notation) of the first message of a TF topic."""
    conns = [c for c in reader.connections if c.topic == topic]
    try:
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            pairs = sorted({f"{t.header.frame_id.lstrip('/')}.{t.child_frame_id.lstrip('/')}" for t in msg.transforms})
            more = f" and {len(pairs) - 3} more" if len(pairs) > 3 else ""
            return "first message: " + ", ".join(pairs[:3]) + more
    except Exception as err:  # a TF type this type store cannot decode: the count is still worth showing
        return f"not decoded ({describe_error(err)})"
    return ""


def inventory(path: Path) -> BagInventory:
    """Read the bag at ``path`` once and describe every topic (see the module docstring)."""
    root = bag_root(Path(path))
    reader = open_reader(root)
    try:
        topics = sorted(reader.topics.items())
        wanted = {name for name, info in topics
                  if info.msgtype in IMAGE_TYPES + (streams.IMU_TYPE,) + streams.POSE_TYPES}
        tf_first: dict[str, str] = {}
        image_first: dict[str, tuple] = {}
        image_stamps: dict[str, list] = {}
        samples: dict[str, streams.TopicSamples] = {}
        conns = [c for c in reader.connections if c.topic in wanted]
        count = 0
        try:
            # (rosbags reads every topic when given no connections)
            for conn, bag_ns, raw in (reader.messages(connections=conns) if conns else ()):
                count += 1
                if conn.msgtype in IMAGE_TYPES:
                    image_stamps.setdefault(conn.topic, []).append(header_stamp(raw, reader.is2))
                    if conn.topic not in image_first:
                        image_first[conn.topic] = _image_detail(reader, conn, raw)
                elif conn.msgtype == streams.IMU_TYPE:
                    samples.setdefault(conn.topic, streams.TopicSamples.empty()).add_imu(
                        reader.deserialize(raw, conn.msgtype), bag_ns)
                else:
                    samples.setdefault(conn.topic, streams.TopicSamples.empty()).add_pose(
                        reader.deserialize(raw, conn.msgtype), conn.msgtype, bag_ns)
        except Exception as err:
            raise DataError(root, f"cannot read message {count + 1} ({describe_error(err)}); the bag may be truncated "
                                  "or corrupt") from err
        for name, info in topics:
            if info.msgtype in TF_TYPES and info.msgcount:
                tf_first[name] = _tf_detail(reader, name)
        infos = []
        for name, info in topics:
            ty, n = info.msgtype, int(info.msgcount)
            if ty in IMAGE_TYPES:
                detail, frame = image_first.get(name, ("no messages", ""))
                st = np.array(image_stamps.get(name, []), dtype=np.int64)
                if len(st) > 1:
                    detail += f", {rate_hz(np.sort(st)):.1f} Hz"
                infos.append(TopicInfo(name, ty, n, detail, "image", frame, st))
            elif ty == streams.IMU_TYPE:
                s = samples.get(name, streams.TopicSamples.empty())
                infos.append(TopicInfo(name, ty, n, _imu_detail(s), "imu", "", np.array(s.header_ns, dtype=np.int64)))
            elif ty in streams.POSE_TYPES:
                s = samples.get(name, streams.TopicSamples.empty())
                infos.append(TopicInfo(name, ty, n, _pose_detail(s, name, ty), "pose", "",
                                       np.array(s.header_ns, dtype=np.int64)))
            else:
                infos.append(TopicInfo(name, ty, n, tf_first.get(name, ""), "tf" if ty in TF_TYPES else ""))
        return BagInventory(root, bag_format(root), int(reader.start_time), int(reader.end_time), tuple(infos))
    finally:
        reader.close()


def describe(inv: BagInventory) -> list[str]:
    """The inventory as ``gevi info`` lines."""
    lines = [f"bag           {inv.format}, {inv.duration_s:.3f} s, {inv.message_count} messages on "
             f"{len(inv.topics)} topics"]
    width = max((len(t.name) for t in inv.topics), default=10)
    for t in inv.topics:
        short = t.msgtype.replace("/msg/", "/")
        detail = f"  {t.detail}" if t.detail else ""
        lines.append(f"  {t.name:<{width}}  {short:<36s} {t.count:>7d}{detail}")
    return lines


def usable_by(inv: BagInventory, stereo_problem: str | None) -> list[str]:
    """Which gevi commands can use the bag, each with the reason when it cannot."""
    images, imu, poses = inv.of_role("image"), inv.of_role("imu"), inv.of_role("pose")
    out = []
    if stereo_problem is None:
        out.append("gevi run      yes (stereo pair, calibration found)")
    else:
        out.append(f"gevi run      no: {stereo_problem}")
    if imu:
        gt, _ = streams.ground_truth_topic({t.name: t.msgtype for t in poses})
        names = ", ".join(t.name for t in imu)
        out.append(f"gevi imu      yes (IMU: {names}; ground truth: {gt or 'none'})")
    else:
        out.append("gevi imu      no: no sensor_msgs/Imu topic")
    if poses:
        out.append(f"pose topics   {', '.join(t.name for t in poses)}: ground truth for gevi run / gevi imu with "
                   "--topics gt=TOPIC")
    tf = [t for t in inv.of_role("tf") if t.count]
    if tf:
        out.append(f"tf topics     {', '.join(t.name for t in tf)}: gevi reads no trajectory from TF; export one with "
                   f"evo: evo_traj bag {inv.path.name} /tf:PARENT.CHILD --save_as_tum")
    if len(images) == 2 and images[0].frame_id and images[0].frame_id == images[1].frame_id:
        out.append(f"note          both image topics have frame_id '{images[0].frame_id}': probably one camera "
                   "(e.g. raw and compressed), not a stereo pair")
    return out
