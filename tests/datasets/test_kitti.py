"""KITTI odometry reader: a sequence folder around the real KITTI 04 ground truth and calibration."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from gevi_cli.datasets import open_sequence
from gevi_cli.trajectory import read_trajectory
from support import run_cli, shared_path

# KITTI 04-10 rectified calibration as the CurrentFeature authors' runner uses it (cfo_kitti04/SOURCE.md)
F, CX, CY, B_GRAY = 707.0912, 601.8873, 183.1104, 0.537150653267924


def _kitti_tree(tmp_path, n=271, with_gt=True):
    seq = tmp_path / "dataset" / "sequences" / "04"
    gt_src = shared_path("cfo_kitti04", "data", "gt_poses", "kitti_gt_pose", "04.txt")
    for cam in ("image_0", "image_1"):
        (seq / cam).mkdir(parents=True)
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, size=(370, 1226), dtype=np.uint8)
    cv2.imwrite(str(seq / "image_0" / "000000.png"), img)
    cv2.imwrite(str(seq / "image_1" / "000000.png"), img[:, ::-1])
    for cam in ("image_0", "image_1"):
        for i in range(1, n):
            (seq / cam / f"{i:06d}.png").symlink_to(seq / cam / "000000.png")
    P0 = [F, 0, CX, 0, 0, F, CY, 0, 0, 0, 1, 0]
    P1 = [F, 0, CX, -F * B_GRAY, 0, F, CY, 0, 0, 0, 1, 0]
    P2 = [F, 0, CX, F * 0.0663, 0, F, CY, 0, 0, 0, 1, 0]
    P3 = [F, 0, CX, F * (0.0663 - 0.5433), 0, F, CY, 0, 0, 0, 1, 0]
    (seq / "calib.txt").write_text("".join(f"P{i}: " + " ".join(f"{v:.12e}" for v in P) + "\n" for i, P in enumerate((P0, P1, P2, P3))))
    (seq / "times.txt").write_text("".join(f"{0.1036 * i:.6e}\n" for i in range(n)))
    if with_gt:
        (tmp_path / "dataset" / "poses").mkdir()
        (tmp_path / "dataset" / "poses" / "04.txt").symlink_to(gt_src)
    return seq, gt_src


def test_kitti_sequence_with_real_groundtruth(tmp_path):
    seq_dir, gt_src = _kitti_tree(tmp_path)
    seq = open_sequence(seq_dir)
    assert seq.kind == "kitti" and seq.name == "04" and len(seq) == 271
    assert seq.imu is None
    rig = seq.calibration
    assert rig.baseline == pytest.approx(B_GRAY, rel=1e-9)
    np.testing.assert_allclose(rig.t_rl, [-B_GRAY, 0, 0], atol=1e-9)
    np.testing.assert_allclose(rig.T_B_C0, np.eye(4), atol=1e-12)  # KITTI: body = cam0
    assert seq.frame_rate_hz == pytest.approx(1 / 0.1036, rel=1e-6)
    gt = seq.groundtruth
    assert gt.frame == "cam0" and not gt.indexed and len(gt) == 271
    np.testing.assert_array_equal(gt.t_ns, seq.stamps_ns)
    np.testing.assert_allclose(gt.positions, read_trajectory(gt_src).positions)
    assert gt.path_length_m == pytest.approx(394, abs=5)  # SOURCE.md: about 394 m
    frame = next(seq.frames(start=5))
    assert frame.left.shape == (370, 1226) and frame.t_ns == seq.stamps_ns[5]


def test_kitti_colour_pair_offsets(tmp_path):
    seq_dir, _ = _kitti_tree(tmp_path, n=3, with_gt=False)
    for cam in ("image_2", "image_3"):
        (seq_dir / cam).symlink_to(seq_dir / "image_0")
    seq = open_sequence(seq_dir, cameras="color")
    rig = seq.calibration
    assert rig.baseline == pytest.approx(0.5433, rel=1e-9)
    # T_20 = [I | (0.0663, 0, 0)]: the colour left camera sits 6.63 cm left of cam0 (x = -0.0663)
    np.testing.assert_allclose(rig.T_B_C0[:3, 3], [-0.0663, 0, 0], atol=1e-12)


def test_kitti_errors(tmp_path, capsys):
    seq_dir, _ = _kitti_tree(tmp_path, n=3, with_gt=False)
    (seq_dir / "calib.txt").write_text("P0: 1 2 3\n")
    code, _, err = run_cli(["info", seq_dir], capsys)
    assert code == 2 and "calib.txt:1" in err and "12" in err
    (seq_dir / "calib.txt").unlink()
    code, _, err = run_cli(["info", seq_dir], capsys)
    assert code == 2 and "not a recognised dataset" in err


def test_kitti_root_with_one_sequence(tmp_path):
    _kitti_tree(tmp_path, n=3, with_gt=False)
    seq = open_sequence(tmp_path / "dataset")
    assert seq.kind == "kitti" and seq.name == "04" and len(seq) == 3
