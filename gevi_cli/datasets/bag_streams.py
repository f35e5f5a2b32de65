"""Which bag topics are the IMU and the ground truth, and how their messages become timed samples.

Shared by the stereo bag reader (:mod:`.rosbag`) and the IMU-only one (:mod:`.bag_imu`).

* **Stamps.**  Header stamps are the sensor's clock and are used; the bag's receive time only
  replaces them for a topic whose header stamps are *all* zero (a driver that never fills them), with a
  warning.  Messages of a topic with some zero stamps are dropped, counted in a warning.  A topic whose
  header stamps sit far (> 1 s) from its receive times is kept on its header clock and reported with
  the offset (simulation time, an unsynchronised sensor clock); topics whose offsets disagree by more
  than 0.5 s are on different clocks, and that is reported with both numbers instead of silently
  mixing them.
* **Split IMU.**  RealSense drivers publish accelerometer and gyroscope as two ``sensor_msgs/Imu``
  topics, each filling one vector (the other all zero).  They are merged as the driver's own
  ``linear_interpolation`` mode does: accelerometer samples interpolated linearly to the gyro stamps
  inside the accelerometer's span.  Chosen by ``--topics gyro=...,accel=...``, or automatically when
  a bag has exactly one IMU topic named for each.  An IMU stream whose gyro or accelerometer is all
  zeros is refused.
* **Ground truth.**  A pose topic is taken as ground truth only when its name says so (ground truth,
  mocap, vicon, optitrack, leica, gt) or it is a ``geometry_msgs/TransformStamped`` topic (what
  motion-capture bridges publish); a device's own odometry (RealSense ``/camera/odom/sample``) is not.
  Otherwise the candidates are listed and ``--topics gt=TOPIC`` asked for.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from gevi_cli.datasets.bagfile import stamp_ns
from gevi_cli.errors import DataError

IMU_TYPE = "sensor_msgs/msg/Imu"
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
              "geometry_msgs/msg/TransformStamped", "nav_msgs/msg/Odometry")
MOCAP_TYPES = ("geometry_msgs/msg/TransformStamped",)
_GT_WORDS = ("groundtruth", "ground_truth", "ground-truth", "mocap", "vicon", "optitrack", "leica", "qualisys")
FAR_FROM_RECEIVE_NS = 1_000_000_000
CLOCK_MISMATCH_NS = 500_000_000


def names_ground_truth(topic: str) -> bool:
    """True when the topic's name says ground truth (``gt`` only as a whole word: not ``/gtk``)."""
    low = topic.lower()
    if any(w in low for w in _GT_WORDS):
        return True
    return "gt" in re.split(r"[^a-z0-9]+", low)


def ground_truth_topic(poses: dict[str, str]) -> tuple[str | None, str | None]:
    """(topic, warning) among the pose topics ``{name: msgtype}`` by the rule in the module docstring."""
    if not poses:
        return None, None
    names = sorted(poses)
    chosen = [t for t in names if names_ground_truth(t)] or [t for t in names if poses[t] in MOCAP_TYPES]
    listing = ", ".join(f"{t} ({poses[t].split('/')[-1]})" for t in names)
    if not chosen:
        return None, (f"no ground truth: none of the pose topics ({listing}) is named as ground truth "
                      "(groundtruth, mocap, vicon, optitrack, leica, gt) or is a motion-capture transform; a "
                      "device's own odometry is not ground truth; pass --topics gt=TOPIC to use one")
    if len(chosen) > 1:
        return chosen[0], (f"took {chosen[0]} as ground truth of {len(chosen)} candidates ({', '.join(chosen)}); "
                           "override with --topics gt=TOPIC")
    return chosen[0], None


@dataclass(frozen=True)
class ImuTopics:
    """The IMU topic(s): ``single`` for one ``Imu`` topic, or ``gyro`` + ``accel`` for a split pair."""

    single: str | None = None
    gyro: str | None = None
    accel: str | None = None

    @property
    def split(self) -> bool:
        return self.single is None

    @property
    def names(self) -> tuple[str, ...]:
        return (self.single,) if self.single else (self.gyro, self.accel)

    def describe(self) -> str:
        return self.single if self.single else f"{self.gyro} (gyro) + {self.accel} (accel, interpolated)"


def split_imu_pair(imu_topics: list[str]) -> tuple[str, str] | None:
    """(gyro, accel) when the bag's IMU topics are exactly one named gyro* and one named accel*."""
    gyros = [t for t in imu_topics if "gyro" in t.lower()]
    accels = [t for t in imu_topics if "accel" in t.lower()]
    if len(imu_topics) == 2 and len(gyros) == 1 and len(accels) == 1 and gyros[0] != accels[0]:
        return gyros[0], accels[0]
    return None


def timed(where: str, header_ns: np.ndarray, bag_ns: np.ndarray, warnings: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(stamps, kept) for one topic's messages by the stamp rule of the module docstring."""
    header_ns = np.asarray(header_ns, dtype=np.int64)
    bag_ns = np.asarray(bag_ns, dtype=np.int64)
    zero = header_ns == 0
    if len(header_ns) and zero.all():
        warnings.append(f"{where}: every header stamp is zero (the driver does not fill header.stamp); using the bag's "
                        "receive times instead, which include transport delay")
        return bag_ns.copy(), np.ones(len(bag_ns), dtype=bool)
    if zero.any():
        warnings.append(f"{where}: {int(zero.sum())} of {len(zero)} message(s) have a zero header stamp; dropped them "
                        "(their receive time is another clock)")
    kept = ~zero
    offset = float(np.median(header_ns[kept] - bag_ns[kept])) if kept.any() else 0.0
    if abs(offset) > FAR_FROM_RECEIVE_NS:
        warnings.append(f"{where}: header stamps are {offset * 1e-9:+.3f} s from the bag's receive times (simulation "
                        "time or an unsynchronised sensor clock); kept the header stamps")
    return header_ns[kept], kept


def clock_offset_ns(header_ns: np.ndarray, bag_ns: np.ndarray) -> float | None:
    """Median header - receive time (ns) of a topic, None when it has no messages."""
    if len(header_ns) == 0:
        return None
    return float(np.median(np.asarray(header_ns, dtype=np.int64) - np.asarray(bag_ns, dtype=np.int64)))


def check_same_clock(where: str, offsets: dict[str, float | None], warnings: list[str]) -> None:
    """Warn when the topics' header clocks disagree by more than :data:`CLOCK_MISMATCH_NS`."""
    known = {t: o for t, o in offsets.items() if o is not None}
    if len(known) < 2:
        return
    lo, hi = min(known, key=known.get), max(known, key=known.get)
    if known[hi] - known[lo] > CLOCK_MISMATCH_NS:
        warnings.append(f"{where}: topics stamp on different clocks: header - receive time is {known[lo] * 1e-9:+.3f} s "
                        f"on {lo} but {known[hi] * 1e-9:+.3f} s on {hi}; their samples will not line up")


def merge_split_imu(t_gyro: np.ndarray, gyro: np.ndarray, t_acc: np.ndarray, acc: np.ndarray, where: str,
                    warnings: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gyro samples with the accelerometer linearly interpolated to their stamps (ns; inside its span)."""
    if len(t_acc) < 2 or len(t_gyro) < 1:
        raise DataError(where, f"split IMU needs at least 2 accelerometer and 1 gyro sample, got {len(t_acc)} and "
                               f"{len(t_gyro)}")
    inside = (t_gyro >= t_acc[0]) & (t_gyro <= t_acc[-1])
    if not inside.any():
        raise DataError(where, "gyro and accelerometer stamps do not overlap")
    if not inside.all():
        warnings.append(f"{where}: {int((~inside).sum())} gyro sample(s) outside the accelerometer's span dropped "
                        "(accelerometer interpolated to the gyro stamps)")
    t = t_gyro[inside]
    x = (t - t_acc[0]).astype(np.float64)
    xa = (t_acc - t_acc[0]).astype(np.float64)
    a = np.column_stack([np.interp(x, xa, acc[:, k]) for k in range(3)])
    return t, gyro[inside], a


def check_imu_axes(where: str, gyro: np.ndarray, acc: np.ndarray, hint: str = "") -> None:
    """Refuse an IMU stream whose gyro or accelerometer is all zeros (half of a split IMU)."""
    for name, field, values in (("gyroscope", "angular_velocity", gyro), ("accelerometer", "linear_acceleration", acc)):
        if len(values) and not np.any(values):
            raise DataError(where, f"the {name} is all zeros ({field} never set): this topic holds only half an "
                                   f"IMU{hint}")


def sorted_unique(where: str, t: np.ndarray, arrays: list[np.ndarray], warnings: list[str], what: str = "message"):
    """Sort by stamp and keep the first of equal stamps (warned); returns (t, arrays)."""
    order = np.argsort(t, kind="stable")
    t = t[order]
    arrays = [a[order] for a in arrays]
    keep = np.ones(len(t), dtype=bool)
    keep[1:] = np.diff(t) != 0
    if not keep.all():
        warnings.append(f"{where}: {int((~keep).sum())} {what}(s) repeat a header stamp; kept the first of each")
    return t[keep], [a[keep] for a in arrays]


# ------------------------------------------------------------------------------- decoding & building
@dataclass
class TopicSamples:
    """Raw per-message values of one topic, in bag order: header and receive stamps (ns) and vectors."""

    header_ns: list
    bag_ns: list
    a: list  # IMU: angular velocity; poses: position
    b: list  # IMU: linear acceleration; poses: quaternion (w, x, y, z)

    @classmethod
    def empty(cls) -> "TopicSamples":
        return cls([], [], [], [])

    def add_imu(self, msg, bag_ns: int) -> None:
        w, acc = msg.angular_velocity, msg.linear_acceleration
        self.header_ns.append(stamp_ns(msg.header.stamp))
        self.bag_ns.append(bag_ns)
        self.a.append((w.x, w.y, w.z))
        self.b.append((acc.x, acc.y, acc.z))

    def add_pose(self, msg, msgtype: str, bag_ns: int) -> None:
        if msgtype == "geometry_msgs/msg/TransformStamped":
            p, q = msg.transform.translation, msg.transform.rotation
        elif msgtype == "geometry_msgs/msg/PoseStamped":
            p, q = msg.pose.position, msg.pose.orientation
        else:  # Odometry, PoseWithCovarianceStamped
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
        self.header_ns.append(stamp_ns(msg.header.stamp))
        self.bag_ns.append(bag_ns)
        self.a.append((p.x, p.y, p.z))
        self.b.append((q.w, q.x, q.y, q.z))

    def arrays(self):
        """(header_ns, bag_ns, a (n, 3), b (n, 3 or 4)) as arrays."""
        b = np.array(self.b, dtype=np.float64)
        return (np.array(self.header_ns, dtype=np.int64), np.array(self.bag_ns, dtype=np.int64),
                np.array(self.a, dtype=np.float64).reshape(-1, 3), b.reshape(len(self.b), -1) if len(self.b) else b)


def _imu_arrays(where: str, s: TopicSamples, warnings: list[str]):
    header, bag, w, a = s.arrays()
    bad = ~(np.isfinite(w).all(axis=1) & np.isfinite(a).all(axis=1))
    if bad.any():
        raise DataError(where, f"IMU message {int(np.argmax(bad)) + 1} contains a non-finite value")
    t, kept = timed(where, header, bag, warnings)
    t, (w, a) = sorted_unique(where, t, [w[kept], a[kept]], warnings, "IMU message")
    return t, w, a


def build_imu(bag: str, topics: ImuTopics, samples: dict[str, TopicSamples], noise: dict, warnings: list[str]):
    """:class:`ImuData` from the collected IMU message(s), by the rules of the module docstring (None: no samples)."""
    from gevi_cli.datasets.sequence import ImuData

    if not topics.split:
        where = f"{bag}:{topics.single}"
        if not samples[topics.single].header_ns:
            warnings.append(f"{where}: IMU topic has no messages")
            return None
        t, w, a = _imu_arrays(where, samples[topics.single], warnings)
        check_imu_axes(where, w, a, "; if the driver splits gyro and accel, pass --topics gyro=TOPIC,accel=TOPIC")
    else:
        parts = {}
        for role, topic in (("gyro", topics.gyro), ("accel", topics.accel)):
            where = f"{bag}:{topic}"
            if not samples[topic].header_ns:
                raise DataError(where, f"the {role} topic has no messages")
            parts[role] = _imu_arrays(where, samples[topic], warnings)
        tg, wg, ag = parts["gyro"]
        ta, wa, aa = parts["accel"]
        # each half must carry its own vector; a "gyro" topic with zero rates is a wrong choice of topics
        check_imu_axes(f"{bag}:{topics.gyro}", wg, np.ones((1, 3)), " (is it the accelerometer topic?)")
        check_imu_axes(f"{bag}:{topics.accel}", np.ones((1, 3)), aa, " (is it the gyroscope topic?)")
        t, w, a = merge_split_imu(tg, wg, ta, aa, f"{bag}:{topics.gyro}+{topics.accel}", warnings)
    return ImuData(t, w, a, **noise)


def build_groundtruth(bag: str, topic: str, s: TopicSamples, warnings: list[str]):
    """Body poses ``T_W_B`` from a pose topic (None without messages), checked like a trajectory file."""
    from gevi_cli.trajectory import Trajectory
    from gevi_cli.trajectory.validate import duplicate_stamp_mask, validate_rows

    where = f"{bag}:{topic}"
    if not s.header_ns:
        warnings.append(f"{where}: ground-truth topic has no messages")
        return None
    header, bag_ns, pos, q = s.arrays()
    t, kept = timed(where, header, bag_ns, warnings)
    lines = np.flatnonzero(kept) + 1  # message numbers in bag order, for messages
    pos, q = pos[kept], q[kept]
    order = np.argsort(t, kind="stable")
    t, pos, q, lines = t[order], pos[order], q[order], lines[order]
    own: list[str] = []
    keep = duplicate_stamp_mask(where, lines, t, own)
    t, pos, q, lines = t[keep], pos[keep], q[keep], lines[keep]
    q = validate_rows(where, lines, t, pos, quat_wxyz=q, warnings=own)
    warnings.extend(own)
    traj = Trajectory(t, pos, q, frame="body", name="groundtruth")
    traj.meta.update({"path": where, "format": "rosbag", "warnings": own})
    return traj
