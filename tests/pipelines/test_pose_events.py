"""The odometry's one pose channel (``FrameResult.poses`` and ``Odometry.close``, PoseEvents): over a run
every frame is released FINAL exactly once and in frame order, and ONLINE exactly once, for CFO and
GeVI, whether the run ends at the sequence's end, mid-window, before GeVI's initialisation or on an
interrupt; each event names its world."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli.pipelines.types import FINAL, ONLINE, WORLD_FIRST_CAM0, WORLD_GRAVITY, WORLD_PROVISIONAL, PoseEvent


def _track(sequence, method: str, n: int, closing_ba: bool):
    """(events of every track(), events of close(), keyframe indices, the odometry) over the first ``n``
    frames.  The render moves fast at 10 Hz (every frame would be a keyframe by image displacement): a
    looser keyframe rule gives the keyframe windows of several frames the tests are about."""
    from gevi_cli.run.assemble import make_pipeline
    from gevi_cli.run.session import RunRequest, resolve

    r = resolve(RunRequest(sequence=str(sequence), method=method, max_frames=n, quiet=True,
                           sets=("keyframe.max_mean_disp_px=30", "keyframe.min_tracked_ratio=0.5", "keyframe.min_tracked=10")))
    _, odometry = make_pipeline(r, warn=lambda msg: None)
    tracked, keyframes = [], []
    for i in range(r.start, r.stop):
        res = odometry.track(r.source.read_pair(i))
        tracked += res.poses
        keyframes += [res.index] if res.keyframe else []
    closed = odometry.close(closing_ba=closing_ba)
    return tracked, closed, keyframes, odometry


def _check_once(events: list[PoseEvent], n: int) -> None:
    finals = [e.index for e in events if e.kind == FINAL]
    assert finals == list(range(n)), "every frame final exactly once, in frame order"
    assert sorted(e.index for e in events if e.kind == ONLINE) == list(range(n)), "every frame online exactly once"
    for e in events:
        assert e.sensor == "cam0" and e.T.shape == (4, 4) and np.all(np.isfinite(e.T))


# (method, frames, closing_ba): the whole render ended normally; mid-window; an interrupt (no closing BA)
# (keyframes with these settings: 0, 25, 29, 36/37, 51/54)
CASES = [("cfo", None, True), ("cfo", 23, True), ("cfo", 33, True), ("cfo", 45, False),
         ("gevi", None, True), ("gevi", 33, True), ("gevi", 45, False)]


@pytest.mark.parametrize("method, n, closing_ba", CASES)
def test_every_frame_final_exactly_once_in_order(pool_render, method, n, closing_ba):
    tracked, closed, keyframes, odometry = _track(pool_render, method, n or 10_000, closing_ba)
    total = odometry.index + 1
    _check_once(tracked + closed, total)
    if n is not None:  # the run ended inside a keyframe window: close() released the poses still pending
        assert keyframes[-1] < total - 1 and any(e.kind == FINAL for e in closed)
    world = WORLD_FIRST_CAM0 if method == "cfo" else WORLD_GRAVITY
    assert {e.world for e in tracked + closed} == {world}


def test_gevi_ending_before_its_initialisation_releases_every_pose_provisionally(pool_render):
    """The render starts with 1.5 s at rest: after 5 frames GeVI has no gravity-aligned world yet, holds
    every pose, and close() releases them all in its provisional world (the first cam0)."""
    tracked, closed, _, odometry = _track(pool_render, "gevi", 5, True)
    assert not odometry.start.done and tracked == []
    _check_once(closed, 5)
    assert {e.world for e in closed} == {WORLD_PROVISIONAL}


def test_body_pose_of_an_event_follows_its_world():
    """A stereo odometry's body trajectory starts at the identity (T_B0_B); GeVI's is T_W_C T_CB."""
    T_B_C0 = np.eye(4)
    T_B_C0[:3, 3] = [0.1, -0.2, 0.3]
    first = PoseEvent(FINAL, 0, np.eye(4), WORLD_FIRST_CAM0)
    np.testing.assert_array_equal(first.body(T_B_C0), np.eye(4))
    gravity = PoseEvent(FINAL, 0, np.eye(4), WORLD_GRAVITY)
    np.testing.assert_allclose(gravity.body(T_B_C0)[:3, 3], [-0.1, 0.2, -0.3])
