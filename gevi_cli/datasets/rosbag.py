"""ROS bags as stereo(-inertial) sequences: ROS1 ``.bag``, ROS2 folders, lone ``.mcap``/``.db3`` (:mod:`.bagfile`).

Read with :class:`rosbags.highlevel.AnyReader` (pure Python, no ROS install); message types come
from the definitions stored in the bag, or the ROS2 Humble typestore for ROS2 bags without them.

Topics are found by message type:

* images: ``sensor_msgs/Image`` (mono8, mono16, bgr8, rgb8, bgra8, rgba8, bgr16, rgb16) and
  ``sensor_msgs/CompressedImage`` (png, jpeg: anything OpenCV decodes); converted to 8-bit grayscale
  (colour: OpenCV's luma weights; 16 bit: the high byte).
* IMU: ``sensor_msgs/Imu`` (angular velocity rad/s, linear acceleration m/s^2, taken as the body frame).
* ground truth: ``geometry_msgs/PoseStamped``, ``PoseWithCovarianceStamped``, ``TransformStamped``,
  ``nav_msgs/Odometry``; read as body poses ``T_W_B``.

Which image topic is left/right, in order of precedence:

1. the ``topics`` option (``left=/cam0/image_raw,right=/cam1/image_raw,imu=/imu0,gt=/gt``; a role
   set to ``none`` is not read);
2. the ``rostopic`` of ``cam0``/``cam1`` in the Kalibr camchain, when the bag has that topic;
3. by name: image topics in sorted order; left = the first whose name contains ``cam0`` or ``left``,
   right = the first other one containing ``cam1`` or ``right`` (case-insensitive).  With exactly two
   image topics a side no name identifies gets the remaining topic (neither named: the one sorting
   first is left, with a warning).  With more than two and a side unidentified: an error asking for
   ``--topics``.

IMU and ground truth: chosen by the rules of :mod:`.bag_streams` (one IMU topic, the imu.yaml
``rostopic``, or a split gyro/accel pair merged; ground truth only from a topic named as such or a
motion-capture transform).  Stamps are the message header stamps (never silently the bag receive time:
see :mod:`.bag_streams`); left and right are paired by stamp within ``pair_tolerance_ns``
(:func:`~gevi_cli.datasets.sequence.pair_stereo`).

Images are not held in memory: opening reads the bag once, keeping for every image message only
its header stamp and bag time (parsed from the first bytes of the serialized message), plus all
IMU and ground-truth messages.  :meth:`RosbagSequence.read_pair` fetches one pair by bag time;
:meth:`RosbagSequence.frames` streams the requested pairs in one pass.

Calibration (the bag holds none): the ``calib`` option, a Kalibr camchain YAML or an EuRoC
``mav0`` folder (a folder with ``cam0/sensor.yaml`` and ``cam1/sensor.yaml``); without it, the first
of ``<stem>_camchain.yaml``, ``camchain-imucam-<stem>.yaml``, ``camchain-<stem>.yaml``,
``camchain.yaml`` next to the bag (for a ROS2 folder: inside it, then next to it).  IMU noise: the
``imu_calib`` option, else ``imu0/sensor.yaml`` of an EuRoC calib folder, else ``<stem>_imu.yaml``,
``imu-<stem>.yaml``, ``imu.yaml`` next to the bag or the camchain (Kalibr imu.yaml keys).
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from gevi_cli.datasets import bag_streams as streams
from gevi_cli.datasets.bagfile import bag_root, describe_error, header_stamp, is_bag, open_reader
from gevi_cli.datasets.euroc import DEFAULT_PAIR_TOLERANCE_NS, rig_from_sensor_yamls
from gevi_cli.datasets.kalibr import read_camchain, read_imu_noise
from gevi_cli.datasets.registry import register
from gevi_cli.datasets.sequence import ImuData, Sequence, StereoFrame, pair_stereo
from gevi_cli.datasets.yamlio import load_yaml
from gevi_cli.errors import DataError, GeviError, LayoutError
from gevi_cli.trajectory import Trajectory, read_trajectory

IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
IMAGE_TYPES = (IMAGE, COMPRESSED)
IMU_TYPES = (streams.IMU_TYPE,)
GT_TYPES = streams.POSE_TYPES
ROLES = {"left": IMAGE_TYPES, "right": IMAGE_TYPES, "imu": IMU_TYPES, "gyro": IMU_TYPES, "accel": IMU_TYPES,
         "gt": GT_TYPES}
_ROLE_ALIASES = {"cam0": "left", "cam1": "right", "groundtruth": "gt", "imu0": "imu", "acc": "accel"}
_LEFT_WORDS, _RIGHT_WORDS = ("cam0", "left"), ("cam1", "right")

# encoding -> (channels, bytes per channel, cv2 conversion to gray or None)
_ENCODINGS = {
    "mono8": (1, 1, None), "8uc1": (1, 1, None),
    "mono16": (1, 2, None), "16uc1": (1, 2, None),
    "bgr8": (3, 1, cv2.COLOR_BGR2GRAY), "8uc3": (3, 1, cv2.COLOR_BGR2GRAY), "rgb8": (3, 1, cv2.COLOR_RGB2GRAY),
    "bgra8": (4, 1, cv2.COLOR_BGRA2GRAY), "8uc4": (4, 1, cv2.COLOR_BGRA2GRAY), "rgba8": (4, 1, cv2.COLOR_RGBA2GRAY),
    "bgr16": (3, 2, cv2.COLOR_BGR2GRAY), "rgb16": (3, 2, cv2.COLOR_RGB2GRAY),
}


def parse_topics(value) -> dict[str, str | None]:
    """``"left=/a,right=/b,imu=/c,gt=/d"`` (or a dict) -> ``{"left": "/a", ...}``; ``none`` -> None."""
    if value is None or value == "":
        return {}
    if isinstance(value, dict):
        items = list(value.items())
    else:
        items = []
        for part in str(value).split(","):
            part = part.strip()
            if not part:
                continue
            if "=" not in part:
                raise GeviError("--topics", f"'{part}' is not ROLE=TOPIC; expected e.g. "
                                            "left=/cam0/image_raw,right=/cam1/image_raw,imu=/imu0,gt=/groundtruth/pose")
            role, topic = part.split("=", 1)
            items.append((role, topic))
    out: dict[str, str | None] = {}
    for role, topic in items:
        role = _ROLE_ALIASES.get(str(role).strip().lower(), str(role).strip().lower())
        if role not in ROLES:
            raise GeviError("--topics", f"unknown role '{role}'; use left=, right=, imu= (or gyro= and accel=), gt= "
                                        "(none to skip imu/gt)")
        if role in out:
            raise GeviError("--topics", f"'{role}=' given twice")
        topic = None if topic is None else str(topic).strip()
        if topic is None or topic.lower() in ("", "none"):
            if role in ("left", "right", "gyro", "accel"):
                raise GeviError("--topics", f"{role}= needs a topic")
            topic = None
        out[role] = topic
    if ("gyro" in out) != ("accel" in out):
        raise GeviError("--topics", "gyro= and accel= go together (a split IMU: one topic each)")
    if "imu" in out and "gyro" in out:
        raise GeviError("--topics", "give either imu= or gyro= and accel=, not both")
    return out


# -------------------------------------------------------------------------------- raw decoding
def image_to_gray(msg, msgtype: str, where: str) -> np.ndarray:
    """An ``Image``/``CompressedImage`` message as a (height, width) uint8 array."""
    if msgtype == COMPRESSED:
        image = cv2.imdecode(np.frombuffer(np.asarray(msg.data, dtype=np.uint8), dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise DataError(where, f"CompressedImage (format '{msg.format}') cannot be decoded by OpenCV")
        return image
    encoding = str(msg.encoding).lower()
    if encoding not in _ENCODINGS:
        raise DataError(where, f"image encoding '{msg.encoding}' is not supported "
                               f"({', '.join(k for k in _ENCODINGS if not k[0].isdigit())})")
    channels, depth, conversion = _ENCODINGS[encoding]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.asarray(msg.data, dtype=np.uint8)
    row = w * channels * depth
    if h == 0 or w == 0 or step < row or len(data) < h * step:
        raise DataError(where, f"image data ({len(data)} bytes, step {step}) does not fit {w}x{h} {msg.encoding}")
    pixels = np.ascontiguousarray(data[: h * step].reshape(h, step)[:, :row])
    if depth == 2:
        pixels = (pixels.view(">u2" if msg.is_bigendian else "<u2") >> 8).astype(np.uint8)
    pixels = pixels.reshape(h, w, channels) if channels > 1 else pixels.reshape(h, w)
    if conversion is not None:
        pixels = cv2.cvtColor(pixels, conversion)
    return pixels


# ------------------------------------------------------------------------------------- reader
@register("rosbag")
class RosbagSequence(Sequence):
    """A ROS1 ``.bag`` file or a ROS2 bag folder (see the module docstring for topics and calibration).

    Options: ``topics`` ("left=...,right=...,imu=...,gt=..." or a dict), ``calib`` (Kalibr camchain
    YAML or EuRoC mav0 folder), ``imu_calib`` (Kalibr imu.yaml), ``groundtruth`` (trajectory file
    overriding the bag's ground-truth topic), ``pair_tolerance_ns``.
    """

    detect = staticmethod(is_bag)

    def __init__(self, path: Path, topics=None, calib: str | Path | None = None,
                 imu_calib: str | Path | None = None, groundtruth: str | Path | None = None,
                 pair_tolerance_ns: int = DEFAULT_PAIR_TOLERANCE_NS):
        super().__init__()
        self.path = bag_root(Path(path))
        if not self.path.exists():
            raise GeviError(self.path, "no such file or folder")
        self._name = self.path.stem if self.path.is_file() else self.path.resolve().name
        requested = parse_topics(topics)
        for option, value in (("--calib", calib), ("--imu-calib", imu_calib), ("--groundtruth", groundtruth)):
            if value is not None and not Path(value).exists():
                raise GeviError(option, f"{value}: no such file or folder")
        self._reader = None
        reader = self._open_reader()
        try:
            self.is_ros2 = reader.is2
            available = {name: info.msgtype for name, info in reader.topics.items()}
            self._check_stereo_topics(available)  # before the calibration: no images is the first thing to say
            self._rig, calib_topics, noise, imu_topic_hint = self._load_calibration(calib, imu_calib)
            self.topics = self._select_topics(available, requested, calib_topics, imu_topic_hint,
                                              skip_gt=groundtruth is not None)
            scan = self._scan(reader)
        finally:
            reader.close()
        self._build_pairs(scan["left"], scan["right"], pair_tolerance_ns)
        self._check_image_sizes(scan["sizes"])
        self._imu = self._make_imu(scan["samples"], noise)
        if groundtruth is not None:
            gt = read_trajectory(groundtruth, name="groundtruth", frame="body")
            self.warnings.extend(gt.meta["warnings"])
            self._gt = gt
        else:
            gt_topic = self.topics["gt"]
            self._gt = (None if gt_topic is None else
                        streams.build_groundtruth(str(self.path), gt_topic, scan["samples"][gt_topic], self.warnings))

    # ----------------------------------------------------------------------------- opening
    def _open_reader(self):
        return open_reader(self.path)

    def _bag_error(self, what: str) -> LayoutError:
        return LayoutError(self.path, what)

    def _search_dirs(self) -> list[tuple[Path, str]]:
        return search_dirs(self.path)

    def _load_calibration(self, calib, imu_calib):
        """(rig, camchain topics, IMU noise dict, IMU topic named by imu.yaml or None)."""
        noise_files: list[Path] = []
        calib_topics: dict[str, str] = {}
        if calib is not None:
            calib = Path(calib)
            if calib.is_dir():
                folder = next((c for c in (calib / "mav0", calib)
                               if (c / "cam0" / "sensor.yaml").is_file() and (c / "cam1" / "sensor.yaml").is_file()), None)
                if folder is None:
                    raise GeviError("--calib", f"{calib}: folder has no cam0/sensor.yaml and cam1/sensor.yaml; pass an "
                                               "EuRoC mav0 folder or a Kalibr camchain YAML")
                rig = rig_from_sensor_yamls(folder)
                noise_files.append(folder / "imu0" / "sensor.yaml")
                camchain_file = None
            else:
                camchain_file = calib
        else:
            camchain_file = find_camchain(self.path)
            if camchain_file is None:
                stem = self._search_dirs()[0][1]
                raise GeviError(self.path, f"no camera calibration (a ROS bag carries none): pass --calib with a Kalibr "
                                           f"camchain YAML or an EuRoC mav0 folder, or put {stem}_camchain.yaml next to the bag")
        if camchain_file is not None:
            chain = read_camchain(camchain_file)
            rig, calib_topics = chain.rig, chain.topics
            self.warnings.extend(chain.warnings)
            self.imu_time_offset_s = chain.time_shift_s
            self.calibration_file = camchain_file
        else:
            self.calibration_file = Path(calib)

        noise, topic_hint, self.imu_calibration_file = find_imu_noise(self.path, imu_calib, camchain_file, noise_files)
        return rig, calib_topics, noise, topic_hint

    def _check_stereo_topics(self, available: dict[str, str]) -> None:
        images = sorted(t for t, ty in available.items() if ty in IMAGE_TYPES)
        if not images:
            everything = ", ".join(f"{t} ({ty})" for t, ty in sorted(available.items())) or "none"
            raise self._bag_error(f"no image topics (sensor_msgs/Image or sensor_msgs/CompressedImage); a stereo "
                                  f"sequence needs two; topics: {everything}")
        if len(images) == 1:
            raise self._bag_error(f"only one image topic ({images[0]}); a stereo sequence needs two, left and right")

    def _select_topics(self, available: dict[str, str], requested: dict, calib_topics: dict, imu_hint, skip_gt: bool):
        by_type = {role: sorted(t for t, ty in available.items() if ty in types) for role, types in ROLES.items()}
        images = by_type["left"]

        def listing(names):
            return ", ".join(names) if names else "none"

        check_requested_topics(self.path, available, requested)

        chosen: dict[str, str | None] = {}
        for side in ("left", "right"):
            if side in requested:
                chosen[side] = requested[side]
            elif side in calib_topics:
                if calib_topics[side] in images:
                    chosen[side] = calib_topics[side]
                else:
                    self.warnings.append(f"{self.calibration_file}: rostopic {calib_topics[side]} of "
                                         f"{'cam0' if side == 'left' else 'cam1'} is not an image topic of the bag; "
                                         "choosing by name")
        if "left" not in chosen:
            chosen["left"] = next((t for t in images if t != chosen.get("right") and _names(t, _LEFT_WORDS)), None)
        if "right" not in chosen:
            chosen["right"] = next((t for t in images if t != chosen["left"] and _names(t, _RIGHT_WORDS)), None)
        missing = [side for side in ("left", "right") if chosen[side] is None]
        if missing:
            if len(images) != 2:
                raise self._bag_error(f"{len(images)} image topics ({listing(images)}) and no name says which is "
                                      f"{' and '.join(missing)}; pass --topics left=TOPIC,right=TOPIC")
            for side in missing:
                rest = [t for t in images if t not in chosen.values()]
                chosen[side] = rest[0]
            if len(missing) == 2:
                self.warnings.append(f"{self.path}: image topic names do not say left/right (cam0/cam1); took "
                                     f"{chosen['left']} as left, {chosen['right']} as right (override with --topics)")
        if chosen["left"] == chosen["right"]:
            raise self._bag_error(f"left and right are the same topic {chosen['left']}; pass two image topics")
        unused = [t for t in images if t not in (chosen["left"], chosen["right"])]
        if unused:
            self.warnings.append(f"{self.path}: image topic(s) {listing(unused)} not used "
                                 f"(left {chosen['left']}, right {chosen['right']})")

        self.imu_topics = choose_imu_topics(self.path, available, requested, imu_hint, self.warnings)
        chosen["imu"] = self.imu_topics.describe() if self.imu_topics else None
        chosen["gt"] = None if skip_gt else choose_gt_topic(self.path, available, requested, self.warnings)
        return chosen

    def _scan(self, reader) -> dict:
        """One pass over the selected topics: image index entries, IMU and ground-truth messages."""
        topic_role = {topic: role for role, topic in self.topics.items() if topic is not None and role != "imu"}
        for topic in (self.imu_topics.names if self.imu_topics else ()):
            topic_role[topic] = "imu"
        images = {"left": ([], []), "right": ([], [])}  # (header stamps, bag times)
        sizes: dict[str, tuple[int, int]] = {}
        samples = {topic: streams.TopicSamples.empty() for topic, role in topic_role.items() if role in ("imu", "gt")}
        everything = [c for c in reader.connections if c.topic in topic_role]
        is2 = reader.is2
        count = 0
        try:
            for conn, bag_ns, raw in reader.messages(connections=everything):
                role = topic_role[conn.topic]
                count += 1
                if role in ("left", "right"):
                    images[role][0].append(header_stamp(raw, is2))
                    images[role][1].append(bag_ns)
                    if role not in sizes:
                        msg = reader.deserialize(raw, conn.msgtype)
                        sizes[role] = image_to_gray(msg, conn.msgtype, f"{self.path}:{conn.topic}").shape[::-1]
                elif role == "imu":
                    samples[conn.topic].add_imu(reader.deserialize(raw, conn.msgtype), bag_ns)
                else:
                    samples[conn.topic].add_pose(reader.deserialize(raw, conn.msgtype), conn.msgtype, bag_ns)
        except GeviError:
            raise
        except Exception as err:
            raise DataError(self.path, f"cannot read message {count + 1} of the selected topics "
                                       f"({describe_error(err)}); the bag may be truncated or corrupt") from err
        out = {"sizes": sizes, "samples": samples}
        for side in ("left", "right"):
            out[side] = (np.array(images[side][0], dtype=np.int64), np.array(images[side][1], dtype=np.int64))
        return out

    def _build_pairs(self, left, right, tolerance_ns: int) -> None:
        """Pair left/right by stamp; keeps per side (stamp used, bag time, raw header stamp) to find them again."""
        sides = {}
        offsets = {}
        for side, (header, bag_ns) in (("left", left), ("right", right)):
            topic = self.topics[side]
            if len(header) == 0:
                raise self._bag_error(f"{side} image topic {topic} has no messages")
            offsets[topic] = streams.clock_offset_ns(header, bag_ns)
            stamps, kept = streams.timed(f"{self.path}:{topic}", header, bag_ns, self.warnings)
            header, bag_ns = header[kept], bag_ns[kept]
            order = np.argsort(stamps, kind="stable")
            stamps, bag_ns, header = stamps[order], bag_ns[order], header[order]
            keep = np.ones(len(stamps), dtype=bool)
            keep[1:] = np.diff(stamps) != 0
            if keep.sum() < 0.5 * len(stamps):
                raise DataError(self.path, f"{topic}: {int((~keep).sum())} of {len(stamps)} images repeat a header stamp "
                                           f"(first: {stamps[int(np.argmin(keep))]} ns); the driver does not fill "
                                           "header.stamp, so the images cannot be timed")
            if not keep.all():
                self.warnings.append(f"{self.path}: {topic}: {int((~keep).sum())} image(s) repeat a header stamp; "
                                     "kept the first of each")
            sides[side] = (stamps[keep], bag_ns[keep], header[keep])
        self._image_clock = offsets
        (t0, b0, h0), (t1, b1, h1) = sides["left"], sides["right"]
        names = (f"{self.path}: {self.topics['left']}", f"{self.path}: {self.topics['right']}")
        i0, i1 = pair_stereo(t0, t1, tolerance_ns, names, self.path, self.warnings)
        self._stamps = t0[i0]
        self._left = (h0[i0], b0[i0])
        self._right = (h1[i1], b1[i1])

    def _check_image_sizes(self, sizes) -> None:
        for side, cam in (("left", self._rig.cam0), ("right", self._rig.cam1)):
            if side in sizes and tuple(sizes[side]) != cam.resolution:
                self.warnings.append(f"{self.path}: {self.topics[side]} images are {sizes[side][0]}x{sizes[side][1]} "
                                     f"but the calibration ({self.calibration_file}) says {cam.width}x{cam.height}")

    def _make_imu(self, samples, noise) -> ImuData | None:
        if self.imu_topics is None:
            return None
        imu = streams.build_imu(str(self.path), self.imu_topics, samples, noise, self.warnings)
        if imu is not None and not noise:
            self.warnings.append(f"{self.path}: no IMU noise model found (pass --imu-calib with a Kalibr imu.yaml, or put "
                                 f"{self._search_dirs()[0][1]}_imu.yaml next to the bag)")
        if imu is not None:
            clocks = dict(self._image_clock)
            for topic in self.imu_topics.names:
                s = samples[topic]
                clocks[topic] = streams.clock_offset_ns(np.array(s.header_ns), np.array(s.bag_ns))
            streams.check_same_clock(str(self.path), clocks, self.warnings)
        return imu

    # --------------------------------------------------------------------------------- metadata
    @property
    def imu(self) -> ImuData | None:
        return self._imu

    @property
    def groundtruth(self) -> Trajectory | None:
        return self._gt

    # ----------------------------------------------------------------------------------- images
    def _connections(self, reader, side: str) -> list:
        return [c for c in reader.connections if c.topic == self.topics[side]]

    def _fetch(self, reader, side: str, index: int) -> np.ndarray:
        stamps, bag_ns = self._left if side == "left" else self._right
        stamp, at = int(stamps[index]), int(bag_ns[index])
        topic = self.topics[side]
        try:
            for conn, _, raw in reader.messages(connections=self._connections(reader, side), start=at, stop=at + 1):
                if header_stamp(raw, reader.is2) == stamp:
                    return image_to_gray(reader.deserialize(raw, conn.msgtype), conn.msgtype, f"{self.path}:{topic}")
        except GeviError:
            raise
        except Exception as err:
            raise DataError(self.path, f"cannot read the {topic} image stamped {stamp} ns ({describe_error(err)})") from err
        raise DataError(self.path, f"the {topic} image stamped {stamp} ns has disappeared from the bag (was it modified?)")

    def read_pair(self, index: int) -> StereoFrame:
        if self._reader is None:
            self._reader = self._open_reader()
        return StereoFrame(int(self._stamps[index]), self._fetch(self._reader, "left", index),
                           self._fetch(self._reader, "right", index))

    def frames(self, start: int | None = None, stop: int | None = None, step: int = 1) -> Iterator[StereoFrame]:
        """Stream pairs ``start:stop:step`` in one pass over the bag (own reader; memory: a few images).

        Images arrive in bag-time order; a pair is yielded once both its images were read, in index order.
        """
        selected = range(*slice(start, stop, step).indices(len(self)))
        if len(selected) == 0:
            return
        wanted: dict[tuple[str, int, int], int] = {}
        for pos, index in enumerate(selected):
            for side, (stamps, bag_ns) in (("left", self._left), ("right", self._right)):
                wanted[(side, int(bag_ns[index]), int(stamps[index]))] = pos
        times = np.concatenate([self._left[1][list(selected)], self._right[1][list(selected)]])
        side_of = {self.topics["left"]: "left", self.topics["right"]: "right"}
        reader = self._open_reader()
        pending: dict[int, dict[str, tuple]] = {}
        next_pos = 0
        try:
            conns = self._connections(reader, "left") + self._connections(reader, "right")
            try:
                for conn, bag_ns, raw in reader.messages(connections=conns, start=int(times.min()), stop=int(times.max()) + 1):
                    side = side_of[conn.topic]
                    pos = wanted.pop((side, bag_ns, header_stamp(raw, reader.is2)), None)
                    if pos is None:
                        continue
                    pending.setdefault(pos, {})[side] = (conn.msgtype, raw)
                    while len(pending.get(next_pos, ())) == 2:
                        entry = pending.pop(next_pos)
                        index = selected[next_pos]
                        images = [image_to_gray(reader.deserialize(entry[s][1], entry[s][0]), entry[s][0],
                                                f"{self.path}:{self.topics[s]}") for s in ("left", "right")]
                        next_pos += 1
                        yield StereoFrame(int(self._stamps[index]), *images)
            except GeviError:
                raise
            except Exception as err:
                raise DataError(self.path, f"cannot read images ({describe_error(err)}); the bag may be truncated or "
                                           "corrupt") from err
            if next_pos < len(selected):
                raise DataError(self.path, f"{len(selected) - next_pos} image pair(s) indexed on open were not found "
                                           "again (was the bag modified?)")
        finally:
            reader.close()

    # ------------------------------------------------------------------------------- lifetime
    def close(self) -> None:
        """Close the reader kept open for random access (:meth:`read_pair`); reopened on demand."""
        if self._reader is not None:
            reader, self._reader = self._reader, None
            try:
                reader.close()
            except Exception:
                pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def check_requested_topics(where, available: dict[str, str], requested: dict) -> None:
    """Every ``--topics`` role names a topic of the bag with a type of that role, or a one-line error."""
    for role, topic in requested.items():
        if topic is None:
            continue
        if topic not in available:
            wanted = ", ".join(sorted(t for t, ty in available.items() if ty in ROLES[role])) or "none"
            raise LayoutError(where, f"--topics {role}={topic}: no such topic in the bag "
                                     f"({'image' if role in ('left', 'right') else role} topics: {wanted})")
        if available[topic] not in ROLES[role]:
            raise LayoutError(where, f"--topics {role}={topic}: the topic has type {available[topic]}, expected "
                                     f"{' or '.join(ROLES[role])}")


def search_dirs(path: Path) -> list[tuple[Path, str]]:
    """(folder, stem) pairs where calibration files of the bag at ``path`` are looked for."""
    stem = path.stem if path.is_file() else path.name
    if path.is_dir():
        return [(path, stem), (path.parent, stem)]
    return [(path.parent, stem)]


def find_camchain(path: Path) -> Path | None:
    """The first Kalibr camchain next to (or, for a ROS2 folder, inside) the bag, by the documented names."""
    for folder, stem in search_dirs(path):
        for name in (f"{stem}_camchain.yaml", f"camchain-imucam-{stem}.yaml", f"camchain-{stem}.yaml", "camchain.yaml"):
            if (folder / name).is_file():
                return folder / name
    return None


def find_imu_noise(path: Path, imu_calib, camchain_file: Path | None = None, first: list[Path] | None = None):
    """(noise dict, IMU topic the imu.yaml names or None, file or None): ``imu_calib``, then ``first``
    (an EuRoC calib folder's imu0/sensor.yaml), then ``<stem>_imu.yaml``, ``imu-<stem>.yaml``,
    ``imu.yaml`` next to the bag and next to the camchain."""
    files = ([Path(imu_calib)] if imu_calib is not None else []) + list(first or [])
    dirs = search_dirs(path)
    if camchain_file is not None:
        chain_stem = camchain_file.stem
        for suffix in ("_camchain", "-camchain"):
            chain_stem = chain_stem.removesuffix(suffix)
        dirs.append((camchain_file.parent, chain_stem))
    for folder, stem in dirs:
        files += [folder / f"{stem}_imu.yaml", folder / f"imu-{stem}.yaml", folder / "imu.yaml"]
    for file in files:
        if file.is_file():
            data = load_yaml(file) if file.name != "sensor.yaml" else {}
            topic = data.get("rostopic") or (data.get("imu0") or {}).get("rostopic")
            return read_imu_noise(file), (str(topic) if topic else None), file
    return {}, None, None


def choose_imu_topics(where, available: dict[str, str], requested: dict, hint: str | None, warnings: list[str]):
    """The IMU topic(s) (:class:`~.bag_streams.ImuTopics`) or None, by ``--topics``, then the bag's shape."""
    imu = sorted(t for t, ty in available.items() if ty in IMU_TYPES)
    if "imu" in requested:
        return None if requested["imu"] is None else streams.ImuTopics(single=requested["imu"])
    if "gyro" in requested:
        return streams.ImuTopics(gyro=requested["gyro"], accel=requested["accel"])
    if not imu:
        return None
    if len(imu) == 1:
        return streams.ImuTopics(single=imu[0])
    if hint in imu:
        return streams.ImuTopics(single=hint)
    pair = streams.split_imu_pair(imu)
    if pair is not None:
        warnings.append(f"{where}: gyroscope and accelerometer on two topics ({pair[0]}, {pair[1]}); merged them, "
                        "accelerometer interpolated to the gyro stamps (choose with --topics gyro=...,accel=...)")
        return streams.ImuTopics(gyro=pair[0], accel=pair[1])
    warnings.append(f"{where}: {len(imu)} IMU topics ({', '.join(imu)}); using {imu[0]} (override with --topics "
                    "imu=TOPIC, or gyro=TOPIC,accel=TOPIC for a split IMU)")
    return streams.ImuTopics(single=imu[0])


def choose_gt_topic(where, available: dict[str, str], requested: dict, warnings: list[str]) -> str | None:
    if "gt" in requested:
        return requested["gt"]
    topic, warning = streams.ground_truth_topic({t: ty for t, ty in available.items() if ty in GT_TYPES})
    if warning:
        warnings.append(f"{where}: {warning}")
    return topic


def _names(topic: str, words) -> bool:
    low = topic.lower()
    return any(w in low for w in words)
