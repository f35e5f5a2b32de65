"""`gevi run` from images: real EuRoC and KITTI frames, a short render end to end, bad input, determinism."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from support import run_cli, shared_path


def _status(d):
    return json.loads((d / "status.json").read_text())


# ------------------------------------------------------------------------------------ real data
def test_euroc_micro_real_images(tmp_path, capsys):
    """95 real frames, vehicle at rest (GT moves 2.2 mm): ORB-SLAM3 stereo's figures measured here
    on the same frames are ATE 0.73 mm, RPE 0.56 mm (issue 8)."""
    root = shared_path("euroc_micro")
    code, out, err = run_cli(["run", root, "--gt", root / "groundtruth/V1_01_easy.csv", "-o", tmp_path, "-q"], capsys)
    assert code == 0, err
    st = _status(tmp_path)
    assert st["frames_tracked"] == st["frames_done"] == 95 and st["state"] == "ok"
    ev = st["evaluation"]
    assert ev["ate_m"] <= 0.73e-3 and ev["rpe_m"] <= 0.56e-3, ev
    assert ev["ate_m"] > 1e-5  # a real estimate (the GT itself moves 2.2 mm)


@pytest.fixture(scope="module")
def kitti06(tmp_path_factory):
    d = tmp_path_factory.mktemp("k06")
    from gevi_cli.cli import main

    try:
        main(["run", str(shared_path("kitti06_head", "dataset/sequences/06")), "-o", str(d), "-q"])
        code = 0
    except SystemExit as e:
        code = e.code
    return code, d


def test_kitti06_head_real_moving_images(kitti06):
    """51 real frames at 43 km/h: every frame tracked; ATE no worse than ORB-SLAM3 stereo's median
    over 3 runs on the same frames (0.041 m; measured here 0.024 m, 0.036 m before the row
    refinement of the stereo matches); RPE guarded at the old level (0.016 m; the ORB-SLAM3 RPE
    target is the next test)."""
    code, d = kitti06
    st = _status(d)
    assert code == 0 and st["frames_tracked"] == 51
    ev = st["evaluation"]
    assert ev["ate_m"] <= 0.041 and ev["rpe_m"] <= 0.016, ev
    # the 59.9 m of travel are recovered to within 1 %
    from gevi_cli.trajectory import read_trajectory

    est = read_trajectory(d / "traj_body.tum")
    assert est.path_length_m == pytest.approx(59.86, rel=0.01)


def test_kitti06_head_rpe_reaches_orbslam3(kitti06):
    """Issue 8: ORB-SLAM3 stereo's median RPE on these frames is 0.0121 m; measured 0.0112 m (0.0147 m
    before the stereo matches were refined on the rectified row, docs/method.md "Real images")."""
    assert _status(kitti06[1])["evaluation"]["rpe_m"] <= 0.0121


# ----------------------------------------------------------------------------- simulated run
@pytest.fixture(scope="module")
def render(tmp_path_factory):
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    root = tmp_path_factory.mktemp("render")
    cfg = SimulationConfig("pool-easy", seed=3, duration_s=4.0, rate_hz=10.0, resolution=(376, 240))
    return simulate(cfg, root / "pool-easy", "euroc", progress=False, workers=1)


def test_simulated_run_end_to_end_and_deterministic(render, tmp_path, capsys):
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        code, stdout, err = run_cli(["run", render, "-o", out, "-q"], capsys)
        assert code == 0, err
    st = _status(a)
    assert st["frames_tracked"] == st["frames_done"] == 40 and st["keyframes"] >= 1
    # pool-easy at 376x240: the floor is ~2 m away, 0.07 m baseline at half resolution; the render is
    # exact, so millimetres are expected and anything above 2 cm would be a broken pipeline
    assert st["evaluation"]["ate_m"] < 0.02
    for name in ("traj_body.tum", "traj_cam0.tum", "traj_online_body.tum", "frames.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert "wrote" in stdout and "ATE" in stdout


def _copy(render, tmp_path):
    d = tmp_path / "seq"
    shutil.copytree(render, d)
    return d


def test_unreadable_image_in_the_middle_is_skipped(render, tmp_path, capsys):
    d = _copy(render, tmp_path)
    img = sorted((d / "mav0/cam0/data").glob("*.png"))[20]
    img.write_bytes(b"not a png")
    code, out, err = run_cli(["run", d, "-o", tmp_path / "out", "-q"], capsys)
    assert code == 0
    assert "frame 20 skipped" in err and img.name in err
    st = _status(tmp_path / "out")
    assert [s["index"] for s in st["skipped_frames"]] == [20] and st["frames_tracked"] == 39


def _blacken(d, i0, i1):
    """Frames i0..i1-1 of both cameras all black: nothing to track."""
    import cv2

    for cam in ("cam0", "cam1"):
        for img in sorted((d / f"mav0/{cam}/data").glob("*.png"))[i0:i1]:
            shape = cv2.imread(str(img), cv2.IMREAD_GRAYSCALE).shape
            cv2.imwrite(str(img), np.zeros(shape, np.uint8))
    return d


def test_black_frames_are_a_reported_loss(render, tmp_path, capsys):
    d = _blacken(_copy(render, tmp_path), 15, 20)
    out = tmp_path / "out"
    code, stdout, err = run_cli(["run", d, "--method", "cfo", "-o", out, "-q"], capsys)
    assert code == 3 and "tracking lost" in stdout and "lost-tracking" in err
    st = _status(out)
    assert st["state"] == "lost-tracking" and st["lost_intervals"]
    assert set(range(15, 20)) <= set(st["bridged_frames"])
    assert st["lost_intervals"][0]["start_s"] > 0
    # the trajectory stays one piece: every frame has a pose, and tracking came back afterwards
    rows = [r for r in (out / "traj_body.tum").read_text().splitlines() if not r.startswith("#")]
    assert len(rows) == 40 and st["frames_tracked"] >= 30


@pytest.mark.parametrize("damage, expect", [
    ("no_calib", "sensor.yaml"),
    ("bad_calib", "sensor.yaml"),
    ("one_frame", "at least two"),
])
def test_bad_sequences_are_one_line(render, tmp_path, capsys, damage, expect):
    d = _copy(render, tmp_path)
    args = ["run", d, "-o", tmp_path / "out", "-q"]
    if damage == "no_calib":
        (d / "mav0/cam0/sensor.yaml").unlink()
    elif damage == "bad_calib":
        (d / "mav0/cam0/sensor.yaml").write_text("intrinsics: [1, 2]\nresolution: nope\n")
    else:
        args += ["--max-frames", "1"]
    code, _, err = run_cli(args, capsys)
    assert code == 2 and err.count("\n") == 1 and err.startswith("gevi: error: "), err
    assert expect in err


def test_black_frames_are_carried_by_the_imu_in_gevi(render, tmp_path, capsys):
    """GeVI keeps a pose for frames vision cannot track (IMU preintegration), says so, and tracks on."""
    d = _blacken(_copy(render, tmp_path), 15, 20)
    out = tmp_path / "out"
    code, stdout, err = run_cli(["run", d, "--method", "gevi", "-o", out, "-q"], capsys)
    assert code == 0, err
    st = _status(out)
    assert set(range(15, 20)) <= set(st["inertial_frames"]) and st["frames_tracked"] == 40
    assert "carried by the IMU alone" in stdout
    assert st["evaluation"]["ate_m"] < 0.05


def test_frames_after_the_last_keyframe_get_the_closing_ba(render, tmp_path, capsys):
    """A run that ends between keyframes closes that window with the BA (finish(closing_ba=True)):
    the tail's written poses are the BA's, not the tracked ones; the frames before are untouched."""
    import pandas as pd

    from gevi_cli.trajectory import read_trajectory

    full = tmp_path / "full"
    assert run_cli(["run", render, "--method", "cfo", "-o", full, "-q"], capsys)[0] == 0
    kf = pd.read_csv(full / "frames.csv").query("keyframe == 1")["index"].to_numpy()
    gaps = [(a, b) for a, b in zip(kf[:-1], kf[1:]) if b - a >= 3]
    assert gaps, "the render has no window of 3+ frames"
    k0, k1 = gaps[0]
    stop = k0 + 2  # ends two frames after keyframe k0, before k1
    cut = tmp_path / "cut"
    assert run_cli(["run", render, "--method", "cfo", "--max-frames", str(stop + 1), "-o", cut, "-q"], capsys)[0] == 0

    def poses(d, name):
        tr = read_trajectory(d / name, frame="body")
        return np.column_stack([tr.positions, tr.quat_wxyz])

    after, online = poses(cut, "traj_body.tum"), poses(cut, "traj_online_body.tum")
    assert len(after) == stop + 1
    np.testing.assert_array_equal(after[: k0 + 1], poses(full, "traj_body.tum")[: k0 + 1])
    assert np.abs(after[k0 + 1:] - online[k0 + 1:]).max() > 0  # the BA moved the tail
    # its result is the BA of a full-length window: within a few mm of the tracked poses on this render
    assert np.abs(after[k0 + 1:, :3] - online[k0 + 1:, :3]).max() < 5e-3


def test_frames_csv_says_why_each_keyframe_was_made(render, tmp_path, capsys):
    """frames.csv's kf_trigger: "first" on frame 0, a reason of the rule on every other keyframe, none
    on the frames the rule kept in a keyframe's window."""
    import pandas as pd

    out = tmp_path / "run"
    assert run_cli(["run", render, "--method", "cfo", "-o", out, "-q"], capsys)[0] == 0
    frames = pd.read_csv(out / "frames.csv", keep_default_na=False)
    assert frames.kf_trigger.iloc[0] == "first"
    kf = frames[frames.keyframe == 1]
    assert set(kf.kf_trigger.iloc[1:]) <= {"inliers", "displacement", "frames", "untracked"}
    assert (frames[frames.keyframe == 0].kf_trigger == "").all()
    assert len(kf) < len(frames)
