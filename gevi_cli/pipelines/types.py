"""Values the odometry objects return to the run driver."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from gevi_cli.pipelines.disparity_offset import DisparityOffset

OK, BRIDGED, LOST = "ok", "bridged", "lost"
#: GeVI: the frame could not be tracked visually, its pose comes from the IMU alone (preintegration
#: from the last pose and velocity, or "at rest" during a standstill the IMU shows)
INERTIAL = "inertial"


@dataclass
class FrameResult:
    """Outcome of ``Odometry.track`` for one frame.

    ``T_w_c`` (4x4) is the *online* pose of rectified cam0 in the world frame (= the first
    keyframe's rectified cam0), as known when the frame was tracked.  ``status`` is ``ok``, or
    ``bridged`` when the pose could not be estimated and was extrapolated at constant velocity, or
    ``inertial`` when it could not be tracked visually and the IMU carried it (GeVI).
    ``final`` lists ``(index, T_w_c)`` poses that will not change any more (after the local BA of the
    window they belong to, or immediately without BA); every frame appears there exactly once over a
    run (the last ones on ``Odometry.finish()``).  ``kf_trigger`` says why the keyframe rule asked for a
    keyframe here ("" : it did not; ``keyframe`` says whether one was made): "first", "untracked",
    "inliers", "displacement", "frames", or "source" (a track export's own keyframes).
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
    final: list = field(default_factory=list)
    # online poses to write now, (index, T_w_c), instead of this frame's T_w_c; None: this frame's.  GeVI
    # holds the initialisation window's until the gravity-aligned world exists, so the file is one piece
    online: list | None = None
    timings: dict = field(default_factory=dict)  # stage -> seconds
    extra: dict = field(default_factory=dict)  # pipeline-specific per-frame state (GeVI: imu_states.csv row)


class Odometry(Protocol):
    """What the run driver (:mod:`gevi_cli.run.driver`) needs of an odometry object.

    ``world_is_cam0``: the world is the first rectified cam0 (a stereo odometry) rather than a frame of
    the odometry's own (GeVI: gravity-aligned); ``state_columns`` / ``state_file``: the per-frame state
    each ``FrameResult.extra`` holds and the run-folder file it goes to (no columns: none);
    ``fallbacks``: frames whose pose step started from SQPnP; ``disparity_offset``: the stereo self-calibration
(None: off).  ``finish`` makes the held poses final
    (``closing_ba``: the sequence ended normally), ``release_online`` hands over held online poses,
    ``summary`` is what ``status.json`` records of the odometry's own state (``imu``)."""

    world_is_cam0: bool
    state_columns: tuple
    state_file: str
    fallbacks: int
    disparity_offset: DisparityOffset | None

    def track(self, frame) -> FrameResult: ...

    def finish(self, closing_ba: bool = False) -> list: ...

    def release_online(self) -> list: ...

    def summary(self) -> dict: ...
