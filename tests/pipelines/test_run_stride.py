"""`gevi run --stride K`: every K-th frame with its own stamp, the IMU and the ground truth whole."""
from __future__ import annotations

import json

import numpy as np
import pytest

from support import run_cli, shared_path


def _stamps_s(run_dir):
    return np.loadtxt(run_dir / "traj_body.tum", comments="#", ndmin=2)[:, 0]


def _strided_kitti_copy(seq, dst, k):
    """A KITTI sequence holding every k-th frame of ``seq`` (images linked, times.txt and poses rows kept)."""
    out = dst / "sequences" / seq.name
    for cam in ("image_0", "image_1"):
        (out / cam).mkdir(parents=True)
        for j, src in enumerate(sorted((seq / cam).glob("*.png"))[::k]):
            (out / cam / f"{j:06d}.png").symlink_to(src)
    (out / "calib.txt").write_text((seq / "calib.txt").read_text())
    (out / "times.txt").write_text("".join((seq / "times.txt").read_text().splitlines(keepends=True)[::k]))
    poses = seq.parent.parent / "poses" / f"{seq.name}.txt"
    (dst / "poses").mkdir()
    (dst / "poses" / poses.name).write_text("".join(poses.read_text().splitlines(keepends=True)[::k]))
    return out


def test_kitti06_stride3_is_the_strided_copy(tmp_path, capsys):
    """17 frames stamped 0, 0.3, ..., 4.8 s, all tracked, evaluated against exactly the 17 strided
    ground-truth poses, and the same poses and metrics as a run on a copy holding only every 3rd frame
    (its accuracy is the regression gate's row kitti06_head_stride3)."""
    seq = shared_path("kitti06_head", "dataset", "sequences", "06")
    code, out, err = run_cli(["run", seq, "--method", "cfo", "--stride", "3", "-q", "--results-root",
                              tmp_path / "results"], capsys)
    assert code == 0, err  # 3.6 m per frame: every frame tracked (motion-predicted, scale-aware LK)
    run = (tmp_path / "results" / "cfo" / "06_stride3" / "latest").resolve()  # the stride names the folder
    assert np.allclose(_stamps_s(run), np.arange(17) * 0.3)
    status = json.loads((run / "status.json").read_text())
    assert status["stride"] == 3 and status["frames_done"] == 17 and status["evaluation"]["matched"] == 17
    assert status["frames_tracked"] == 17
    assert "stride: 3" in (run / "config.yaml").read_text()

    copy = _strided_kitti_copy(seq, tmp_path / "copy", 3)
    code_copy, _, err = run_cli(["run", copy, "--method", "cfo", "-q", "-o", tmp_path / "copy_run"], capsys)
    assert code_copy == code, err
    ref = json.loads((tmp_path / "copy_run" / "status.json").read_text())
    assert ref["evaluation"]["matched"] == 17
    assert ref["evaluation"]["ate_m"] == status["evaluation"]["ate_m"]
    assert ref["evaluation"]["rpe_m"] == status["evaluation"]["rpe_m"]
    ours = np.loadtxt(run / "traj_body.tum", comments="#")
    theirs = np.loadtxt(tmp_path / "copy_run" / "traj_body.tum", comments="#")
    assert np.array_equal(ours, theirs)


def test_stride_keeps_the_whole_imu(pool_render, tmp_path, capsys):
    """GeVI at stride 2 on a render: half the frames, every IMU sample, the run evaluated at the strided stamps."""
    from gevi_cli.datasets import open_sequence
    from gevi_cli.run.session import RunRequest, open_input

    whole = open_sequence(pool_render)
    strided, kind = open_input(RunRequest(sequence=str(pool_render), stride=2))
    assert kind == whole.kind and strided.name == whole.name + "_stride2"
    assert np.array_equal(strided.stamps_ns, whole.stamps_ns[::2])
    assert len(strided.imu) == len(whole.imu) and np.array_equal(strided.imu.t_ns, whole.imu.t_ns)
    assert np.array_equal(strided.read_pair(3).left, whole.read_pair(6).left)
    assert [f.t_ns for f in strided.frames(1, 7, 2)] == list(whole.stamps_ns[2:14:4])

    code, _, err = run_cli(["run", pool_render, "--stride", "2", "-q", "-o", tmp_path / "run"], capsys)
    assert code == 0, err
    status = json.loads((tmp_path / "run" / "status.json").read_text())
    assert status["method"] == "gevi" and status["stride"] == 2
    assert status["frames_done"] == (len(whole) + 1) // 2 == status["evaluation"]["matched"]
    assert np.allclose(_stamps_s(tmp_path / "run") * 1e9, whole.stamps_ns[::2], atol=1e3)


@pytest.mark.parametrize("stride", ["0", "-2", "x"])
def test_bad_stride_is_one_line(pool_render, stride, capsys):
    code, _, err = run_cli(["run", pool_render, "--stride", stride], capsys)
    assert code == 2
    assert err.count("\n") == 1 and "--stride" in err


def test_track_export_refuses_a_stride(capsys):
    root = shared_path("cfo_kitti04")
    export = root / "data" / "ov2slam_data" / "ov2slam_data_kitti_04_gray"
    code, _, err = run_cli(["run", export, "--calib", root / "calib" / "gray_calib.txt", "--stride", "2"], capsys)
    assert code == 2
    assert err.count("\n") == 1 and "--stride" in err and "track export" in err
