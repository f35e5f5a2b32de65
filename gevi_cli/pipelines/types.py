"""Values the odometry objects return to the run driver."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from gevi_cli.geometry import invert_pose
from gevi_cli.pipelines.disparity_offset import DisparityOffset

OK, BRIDGED, LOST = "ok", "bridged", "lost"
#: GeVI: the frame could not be tracked visually, its pose comes from the IMU alone (preintegration
#: from the last pose and velocity, or "at rest" during a standstill the IMU shows)
INERTIAL = "inertial"


#: PoseEvent kinds: a pose as known when tracked; a pose that will not change any more (after the local
#: BA of its window, or at once without BA).  Over a run every frame is released FINAL exactly once, in
#: frame order (the last ones by ``Odometry.close``): tests/pipelines/test_pose_events.py checks it.
ONLINE, FINAL = "online", "final"

#: PoseEvent worlds.  WORLD_FIRST_CAM0: the first keyframe's rectified cam0 (a stereo odometry; its
#: body trajectory is written relative to the first body pose, T_B0_B = T_BC T_C0_C T_CB).
#: WORLD_GRAVITY: GeVI's gravity-aligned W (z up; body poses T_W_B = T_W_C T_CB).
#: WORLD_PROVISIONAL: GeVI's world before its initialisation answered (the first keyframe's rectified
#: cam0, poses held to be re-expressed in W); only a run that ends before the initialisation releases poses in it, written as T_V_B = T_V_C T_CB.
WORLD_FIRST_CAM0, WORLD_GRAVITY, WORLD_PROVISIONAL = "first-cam0", "gravity", "provisional"


@dataclass(frozen=True)
class PoseEvent:
    """One pose leaving the odometry: frame ``index``'s ``sensor`` (rectified "cam0") pose ``T`` (4x4,
    metres) in ``world``; ``kind`` ONLINE or FINAL (see above)."""

    kind: str
    index: int
    T: np.ndarray
    world: str
    sensor: str = "cam0"

    def body(self, T_B_C0: np.ndarray) -> np.ndarray:
        """The body pose of this event, given cam0 -> body ``T_B_C0``: in the first body frame for the
        WORLD_FIRST_CAM0 world, else in the event's world (see the worlds above)."""
        T_B_C = T_B_C0 if self.world == WORLD_FIRST_CAM0 else np.eye(4)
        return T_B_C @ self.T @ invert_pose(T_B_C0)


def pose_events(kind: str, items, world: str) -> list[PoseEvent]:
    """``(index, T)`` pairs as PoseEvents of ``kind`` in ``world``."""
    return [PoseEvent(kind, int(i), T, world) for i, T in items]


@dataclass
class FrameResult:
    """Outcome of ``Odometry.track`` for one frame.

    ``T_w_c`` (4x4) is the odometry's working pose of rectified cam0 in its world, as known when the
    frame was tracked; what leaves the odometry is ``poses``: the :class:`PoseEvent` s this frame
    released (its online pose, or the held ones, then the poses made final), in that order.  ``status``
    is ``ok``, or ``bridged`` when the pose could not be estimated and was extrapolated at constant
    velocity, or ``inertial`` when it could not be tracked visually and the IMU carried it (GeVI).
    ``kf_trigger`` says why the keyframe rule asked for a keyframe here ("" : it did not; ``keyframe``
    says whether one was made): "first", "untracked", "inliers", "displacement", "frames", or "source"
    (a track export's own keyframes).
    """

    index: int
    t_ns: int
    T_w_c: np.ndarray
    status: str = OK
    keyframe: bool = False
    kf_trigger: str = ""
    n_matches: int = 0
    n_inliers: int = 0
    sigma_px: float = float("nan")
    message: str = ""
    poses: list[PoseEvent] = field(default_factory=list)
    timings: dict = field(default_factory=dict)  # stage -> seconds
    extra: dict = field(default_factory=dict)  # pipeline-specific per-frame state (GeVI: imu_states.csv row)


class Odometry(Protocol):
    """What the run driver (:mod:`gevi_cli.run.driver`) needs of an odometry object.

    Poses leave through one channel: the :class:`PoseEvent` s of each ``track`` result
    (``FrameResult.poses``), then those of ``close`` once at the end (what the odometry still holds,
    made final; ``closing_ba``: the sequence ended normally, so the last window may get its BA; after an
    interrupt or a crash ``False``).  ``state_columns`` / ``state_file``: the per-frame state each
    ``FrameResult.extra`` holds and the run-folder file it goes to (no columns: none); ``fallbacks``:
    frames whose pose step started from SQPnP; ``disparity_offset``: the stereo self-calibration (None:
    off); ``summary`` is what ``status.json`` records of the odometry's own state (``imu``)."""

    state_columns: tuple
    state_file: str
    fallbacks: int
    disparity_offset: DisparityOffset | None

    def track(self, frame) -> FrameResult: ...

    def close(self, closing_ba: bool = False) -> list[PoseEvent]: ...

    def summary(self) -> dict: ...
