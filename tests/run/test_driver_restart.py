"""The run driver restarts a run once, from its first frame, when the stereo self-calibration finds the
pair's disparity offset within its first keyframes (gevi_cli.run.driver): what the first pass handed on is
superseded, every frame reaches the sinks (folder and memory) exactly once, the restarted odometry carries
the one fixed value, and status.json says what ran (the offset, the first pass, the online trajectory's
causality).  Found later, the offset applies from the next keyframe on, without a restart."""
import json

import numpy as np

from gevi_cli.pipelines import disparity_offset as mod
from gevi_cli.pipelines.disparity_offset import DisparityOffset, Step
from gevi_cli.pipelines.types import FINAL, ONLINE, FrameResult, pose_events
from gevi_cli.run.driver import run_odometry
from gevi_cli.run.folder import RunStatus
from gevi_cli.run.sinks import FolderSink, MemorySink


class _Frames:
    """A source of ``n`` frames stamped 0.1 s apart (only their stamps matter here)."""

    def __init__(self, n):
        self.n = n

    def frames(self, start, stop):
        for i in range(start, stop):
            yield type("F", (), {"index": i, "t_ns": i * 100_000_000})()


class _StubOdometry:
    """Moves 1 m per frame along x and makes a keyframe at every frame; its self-calibration reads 0.8 px on
    every keyframe from frame ``found_from`` on (found MIN_KEYFRAMES keyframes later)."""

    state_columns, state_file, fallbacks = (), "states.csv", 0

    def __init__(self, found_from):
        self.found_from, self.index = found_from, -1
        self.disparity_offset = DisparityOffset()
        self.carried_value = None  # the offset the odometry had when it tracked its first frame

    def track(self, frame):
        self.index += 1
        if self.index == 0:
            self.carried_value = self.disparity_offset.value
        self.disparity_offset.keyframe_made(self.index, self.disparity_offset.value)
        if self.index >= self.found_from:
            self.disparity_offset.add(Step(self.index, self.index, 0.8, 0.05))
        T = np.eye(4)
        T[0, 3] = float(self.index)
        res = FrameResult(self.index, int(frame.t_ns), T)
        res.poses = pose_events(ONLINE, [(self.index, T)], "w") + pose_events(FINAL, [(self.index, T)], "w")
        return res

    def close(self, closing_ba=False):
        return []

    def summary(self):
        return {}


def test_the_run_restarts_once_with_the_offset_and_every_frame_is_handed_on_once(tmp_path):
    built = []

    def rebuild():
        built.append(_StubOdometry(found_from=0))  # would find it again: the carried value must win
        return built[-1]

    memory, folder, status = MemorySink(), FolderSink(tmp_path, kitti_rows=False), RunStatus()
    out = run_odometry(_Frames(10), _StubOdometry(found_from=0), status, [memory, folder], T_B_C0=np.eye(4),
                       start=0, stop=10, progress=False, warn=lambda msg: None, rebuild=rebuild)
    assert out.exit_code == 0 and len(built) == 1
    restarted = built[0]
    found_at = mod.MIN_KEYFRAMES - 1  # the frame whose step made the evidence
    assert restarted.carried_value == 0.8 and restarted.disparity_offset.restarted
    assert status.first_pass["frames"] == found_at + 1 and status.first_pass["elapsed_s"] >= 0
    assert not status.online_causal and status.frames_done == 10 == status.frames_tracked
    rec = status.disparity_offset
    assert rec["applied_px"] == rec["estimate_px"] == 0.8 and rec["restarted"] and rec["found_at_frame"] == found_at
    assert rec["applied_from_frame"] == 0 and rec["diagnostic_steps"] == 10 and rec["steps"] == mod.MIN_KEYFRAMES
    assert [r[0] for r in memory.frame_rows] == list(range(10))
    assert [r[0] for r in memory.final_rows] == [i * 100_000_000 for i in range(10)]
    rows = (tmp_path / "traj_body.tum").read_text().splitlines()
    assert len([r for r in rows if not r.startswith("#")]) == 10
    assert len((tmp_path / "frames.csv").read_text().splitlines()) == 11  # header + 10 frames
    saved = json.loads((tmp_path / "status.json").read_text())
    assert saved["disparity_offset"] == rec and saved["first_pass"] == status.first_pass
    assert saved["online_causal"] is False


def test_an_offset_found_after_the_first_keyframes_applies_without_a_restart():
    built = []
    late = mod.RESTART_MAX_KEYFRAMES + 2
    memory, status = MemorySink(), RunStatus()
    run_odometry(_Frames(late + 10), _StubOdometry(found_from=late), status, [memory], T_B_C0=np.eye(4), start=0,
                 stop=late + 10, progress=False, warn=lambda msg: None, rebuild=lambda: built.append(1))
    rec = status.disparity_offset
    assert not built and status.first_pass == {} and status.online_causal
    assert rec["applied_px"] == 0.8 and not rec["restarted"] and rec["found_at_frame"] == late + mod.MIN_KEYFRAMES - 1
    assert rec["applied_from_frame"] == late + mod.MIN_KEYFRAMES  # the next keyframe
    assert [r[0] for r in memory.frame_rows] == list(range(late + 10))


def test_no_rebuild_means_no_restart():
    memory, status = MemorySink(), RunStatus()
    run_odometry(_Frames(8), _StubOdometry(found_from=0), status, [memory], T_B_C0=np.eye(4), start=0, stop=8,
                 progress=False, warn=lambda msg: None)
    assert status.first_pass == {} and [r[0] for r in memory.frame_rows] == list(range(8))
    assert status.disparity_offset["applied_from_frame"] == mod.MIN_KEYFRAMES


def test_a_gevi_run_restarts_with_its_imu_and_writes_each_frame_once(pool_render, tmp_path, monkeypatch, capsys):
    """GeVI rebuilt for the restart reads its IMU again from the start: an offset made to appear at frame 20
    (the pool render's points are near, so its own estimate never counts a step) restarts the run, and the run
    folder holds one row per frame in every file, the IMU states included, all tracked."""
    import pandas as pd

    from gevi_cli.pipelines import disparity_offset as mod
    from support import run_cli

    real = mod.DisparityOffset.observe

    def observe(self, index, *args):
        real(self, index, *args)
        if index == 20 and not self.restarted:
            for k in range(mod.MIN_KEYFRAMES):
                self.add(Step(index, 1000 + k, 0.3, 0.05))

    monkeypatch.setattr(mod.DisparityOffset, "observe", observe)
    out = tmp_path / "run"
    code, _, err = run_cli(["run", pool_render, "--method", "gevi", "-o", out], capsys)
    assert code == 0, err
    assert "restarting from the first frame" in err
    status = json.loads((out / "status.json").read_text())
    n = status["frames_total"]
    assert status["first_pass"]["frames"] == 21 and status["disparity_offset"]["applied_px"] == 0.3
    assert status["state"] == "ok" and status["frames_done"] == status["frames_tracked"] == n
    frames = pd.read_csv(out / "frames.csv")
    assert list(frames["index"]) == list(range(n))
    assert len(pd.read_csv(out / "imu_states.csv")) == n
    for name in ("traj_body.tum", "traj_online_body.tum"):
        rows = [r for r in (out / name).read_text().splitlines() if r and not r.startswith("#")]
        assert len(rows) == n


def test_the_run_path_checks_sinks_and_keeps_warnings_and_a_given_pair_is_never_swapped(pool_render):
    """api-level contract (issue 50): a sink without restart() is refused before the first frame; an
    odometry given as one pair is not replaced at a restart (an offset found applies from the next
    keyframe); a factory is called again for the restart; every warning is in RunResult.warnings."""
    import pytest

    from gevi_cli.errors import GeviError
    from gevi_cli.run.assemble import make_pipeline
    from gevi_cli.run.pipeline import run_and_evaluate
    from gevi_cli.run.session import RunRequest, resolve

    class NoRestart:
        """A sink written before restarts existed."""

        def final(self, *a): ...
        def online(self, *a): ...
        def frame(self, *a): ...
        def status(self, *a): ...
        def close(self, *a): ...

    resolved = resolve(RunRequest(sequence=str(pool_render), method="cfo", quiet=True, max_frames=8))
    with pytest.raises(GeviError, match="NoRestart lacks restart"):
        run_and_evaluate(resolved, RunStatus(), [NoRestart()])

    def forced(odometry):
        """The odometry's self-calibration finds 0.3 px at its 3rd frame (the render's own never counts)."""
        real = odometry.track

        def track(frame):
            res = real(frame)
            if res.index == 2 and odometry.disparity_offset.found is None and not odometry.disparity_offset.restarted:
                for k in range(mod.MIN_KEYFRAMES):
                    odometry.disparity_offset.add(Step(2, 100 + k, 0.3, 0.05))
            return res
        odometry.track = track
        return odometry

    frontend, odometry = make_pipeline(resolved)
    pair = (frontend, forced(odometry))
    result = run_and_evaluate(resolved, RunStatus(), pipeline=pair)
    rec = result.status.disparity_offset
    assert not rec["restarted"] and rec["applied_px"] == 0.3 and result.status.first_pass == {}
    assert any("applied from the next keyframe on, without a restart" in w for w in result.warnings)
    assert result.status.primary == "traj_body.tum"

    calls = []

    def factory():
        calls.append(1)
        fe, od = make_pipeline(resolved)
        return fe, (forced(od) if len(calls) == 1 else od)

    result = run_and_evaluate(resolved, RunStatus(), pipeline=factory)
    assert len(calls) == 2 and result.status.disparity_offset["restarted"]
    assert any("restarting from the first frame" in w for w in result.warnings)
