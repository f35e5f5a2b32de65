"""EuRoC ASL and pool-style readers, and `gevi info`, on the real EuRoC-micro data."""
from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest

from gevi_cli.datasets import open_sequence
from gevi_cli.errors import DataError, GeviError
from gevi_cli.trajectory import Trajectory, write_trajectory
from support import run_cli


def test_euroc_micro_contents(euroc_micro):
    seq = open_sequence(euroc_micro)
    assert seq.kind == "euroc"
    assert len(seq) == 95
    assert seq.frame_rate_hz == pytest.approx(20.0, rel=1e-6)
    # cam1/data.csv lists 99 rows, 95 files exist: the 4 extra rows are counted and reported
    assert any("4 row(s) have no image file" in w for w in seq.warnings)
    rig = seq.calibration
    assert rig.cam0.distortion_model == "radtan"
    assert rig.cam0.fx == pytest.approx(458.654)
    np.testing.assert_allclose(rig.t_rl, -np.array([0.110074, -0.000157, 0.000889]) @ np.eye(3), atol=3e-3)
    assert rig.baseline == pytest.approx(0.1101, abs=1e-4)
    assert rig.rectification.baseline == pytest.approx(rig.baseline, rel=1e-9)
    imu = seq.imu
    assert len(imu) == 29120 and imu.rate_hz == pytest.approx(200.0, rel=1e-3)
    assert imu.duration_s == pytest.approx(145.6, abs=0.01)
    assert imu.gyro_noise_density == pytest.approx(1.6968e-4)
    assert np.linalg.norm(imu.acc, axis=1).mean() == pytest.approx(9.797, abs=0.01)
    assert seq.groundtruth is None  # data.csv is absent in this copy
    assert any("no ground truth" in w for w in seq.warnings)


def test_frames_are_lazy_paired_gray(euroc_micro):
    seq = open_sequence(euroc_micro)
    frames = list(seq.frames(start=10, stop=20, step=3))
    assert [f.t_ns for f in frames] == seq.stamps_ns[10:20:3].tolist()
    f = frames[0]
    assert f.left.dtype == np.uint8 and f.left.shape == (480, 752) and f.right.shape == (480, 752)
    name = f"{f.t_ns}.png"
    np.testing.assert_array_equal(f.left, cv2.imread(str(euroc_micro / "mav0/cam0/data" / name), cv2.IMREAD_GRAYSCALE))


def test_rectification_aligns_rows(euroc_micro):
    """A point seen by both raw cameras lands on the same rectified row."""
    rig = open_sequence(euroc_micro).calibration
    rect = rig.rectification
    rng = np.random.default_rng(1)
    X0 = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-0.6, 0.6, 50), rng.uniform(2, 6, 50)])
    X1 = X0 @ rig.R_rl.T + rig.t_rl
    uv0 = cv2.projectPoints(X0, np.zeros(3), np.zeros(3), rig.cam0.K, rig.cam0.dist_coeffs)[0].reshape(-1, 2)
    uv1 = cv2.projectPoints(X1, np.zeros(3), np.zeros(3), rig.cam1.K, rig.cam1.dist_coeffs)[0].reshape(-1, 2)
    r0 = cv2.undistortPoints(uv0.reshape(-1, 1, 2), rig.cam0.K, rig.cam0.dist_coeffs, R=rect.R0, P=rect.P0).reshape(-1, 2)
    r1 = cv2.undistortPoints(uv1.reshape(-1, 1, 2), rig.cam1.K, rig.cam1.dist_coeffs, R=rect.R1, P=rect.P1).reshape(-1, 2)
    np.testing.assert_allclose(r0[:, 1], r1[:, 1], atol=1e-3)
    depth = rect.K[0, 0] * rect.baseline / (r0[:, 0] - r1[:, 0])
    np.testing.assert_allclose(depth, (X0 @ rect.R0.T)[:, 2], rtol=1e-5)
    # undistort_points inverts the distortion model
    np.testing.assert_allclose(rig.cam0.undistort_points(uv0), X0[:, :2] / X0[:, 2:], atol=1e-6)


def test_groundtruth_override_and_coverage(euroc_micro):
    from gevi_cli.datasets.coverage import frame_coverage

    seq = open_sequence(euroc_micro, groundtruth=euroc_micro / "groundtruth/V1_01_easy.csv")
    assert seq.groundtruth.frame == "body"
    assert frame_coverage(seq.stamps_ns, seq.groundtruth).covered == 95
    orig = open_sequence(euroc_micro, groundtruth=euroc_micro / "groundtruth/V1_01_easy_original.txt")
    cov = frame_coverage(orig.stamps_ns, orig.groundtruth)
    assert cov.covered == 74 and cov.start_gap_s == pytest.approx(1.04, abs=0.005)


def test_info_reports_euroc_micro_figures(euroc_micro, capsys):
    code, out, err = run_cli(["info", euroc_micro, "--groundtruth", euroc_micro / "groundtruth/V1_01_easy.csv"], capsys)
    assert code == 0, err
    assert "95 stereo pairs at 20.0 Hz" in out
    assert "IMU 200 Hz over 145.6 s" in out
    assert "baseline      0.110 m" in out
    assert "GT coverage   95 of 95 frames" in out
    assert "4 row(s) have no image file" in err
    code, out, _ = run_cli(["info", euroc_micro, "--groundtruth", euroc_micro / "groundtruth/V1_01_easy_original.txt"], capsys)
    assert code == 0 and "74 of 95 frames, GT starts 1.04 s after the first frame" in out


def _copy_small(euroc_micro, dst, n=6):
    """A small EuRoC folder with the first n pairs of euroc_micro (symlinked images)."""
    src = euroc_micro / "mav0"
    mav0 = dst / "mav0"
    for cam in ("cam0", "cam1"):
        (mav0 / cam / "data").mkdir(parents=True)
        shutil.copy(src / cam / "sensor.yaml", mav0 / cam / "sensor.yaml")
        lines = (src / cam / "data.csv").read_text().splitlines()
        (mav0 / cam / "data.csv").write_text("\n".join(lines[: n + 1]) + "\n")
        for line in lines[1: n + 1]:
            name = line.split(",")[1]
            (mav0 / cam / "data" / name).symlink_to(src / cam / "data" / name)
    (mav0 / "imu0").mkdir()
    shutil.copy(src / "imu0" / "sensor.yaml", mav0 / "imu0" / "sensor.yaml")
    lines = (src / "imu0" / "data.csv").read_text().splitlines()
    (mav0 / "imu0" / "data.csv").write_text("\n".join(lines[:100]) + "\n")
    return mav0


def test_pairing_by_stamp_not_row(euroc_micro, tmp_path):
    mav0 = _copy_small(euroc_micro, tmp_path)
    lines = (mav0 / "cam1" / "data.csv").read_text().splitlines()
    del lines[3]  # drop a right image row: rows no longer line up
    (mav0 / "cam1" / "data.csv").write_text("\n".join(lines) + "\n")
    seq = open_sequence(tmp_path)
    assert len(seq) == 5
    for frame in seq.frames():
        assert frame.t_ns in seq.stamps_ns
    assert any("1 image(s) without a partner" in w for w in seq.warnings)


def test_pool_layout_groundtruth_from_mocap(euroc_micro, tmp_path):
    mav0 = _copy_small(euroc_micro, tmp_path)
    gt = Trajectory.from_matrices(np.arange(10) * 50_000_000 + 1403715273262142976,
                                  np.tile(np.eye(4), (10, 1, 1)) @ _pose(0.3, [1, 2, 0.5]), frame="body")
    T_B_M = _pose(0.7, [0.05, -0.02, 0.1])
    marker = gt.with_sensor_frame(T_B_M, frame="unknown")
    (mav0 / "mocap0").mkdir()
    write_trajectory(marker, mav0 / "mocap0" / "data.csv", "euroc")
    (mav0 / "mocap0" / "sensor.yaml").write_text(
        "%YAML:1.0\nsensor_type: mocap\nT_BS:\n  cols: 4\n  rows: 4\n  data: " + str(T_B_M.ravel().tolist()) + "\n")
    seq = open_sequence(tmp_path)
    assert seq.kind == "pool"
    np.testing.assert_allclose(seq.groundtruth.matrices, gt.matrices, atol=1e-8)


def _pose(angle, t):
    T = np.eye(4)
    c, s = np.cos(angle), np.sin(angle)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    T[:3, 3] = t
    return T


def test_bad_inputs_one_line(euroc_micro, tmp_path, capsys):
    mav0 = _copy_small(euroc_micro, tmp_path)
    (mav0 / "cam0" / "sensor.yaml").write_text("%YAML:1.0\nintrinsics: [1, 2]\nresolution: [752, 480]\nT_BS: [1]\n")
    code, _, err = run_cli(["info", tmp_path], capsys)
    assert code == 2 and "cam0/sensor.yaml" in err and "intrinsics" in err and "Traceback" not in err
    assert err.strip().count("\n") == 0
    code, _, err = run_cli(["info", tmp_path / "nope"], capsys)
    assert code == 2 and "nope: no such file or folder" in err
    code, _, err = run_cli(["info", euroc_micro, "--groundtruth", tmp_path / "gt.csv"], capsys)
    assert code == 2 and "--gt" in err
    with pytest.raises(GeviError):
        open_sequence(euroc_micro, kind="nonsense")


def test_unreadable_image_names_the_file(euroc_micro, tmp_path):
    mav0 = _copy_small(euroc_micro, tmp_path)
    victim = sorted((mav0 / "cam0" / "data").iterdir())[2]
    victim.unlink()
    victim.write_bytes(b"not a png")
    seq = open_sequence(tmp_path)
    with pytest.raises(DataError) as err:
        list(seq.frames())
    assert str(victim) in err.value.where


def test_option_of_another_kind_is_a_one_line_error(euroc_micro, capsys):
    code, _, err = run_cli(["info", euroc_micro, "--calib", euroc_micro / "mav0"], capsys)
    assert code == 2 and "--calib: does not apply to euroc sequences" in err


def test_gt_is_the_option_name_everywhere(euroc_micro, capsys):
    """`--gt` (issue 12: one name for one thing; `--groundtruth` stays as an alias)."""
    gt = euroc_micro / "groundtruth/V1_01_easy.csv"
    for opt in ("--gt", "--groundtruth"):
        code, out, _ = run_cli(["info", euroc_micro, opt, gt], capsys)
        assert code == 0 and "GT coverage   95 of 95 frames" in out


def _linked_copy(euroc_micro, tmp_path, gt_files):
    """euroc_micro's mav0 (linked, without a state_groundtruth_estimate0 data.csv) with ``gt_files`` from its
    groundtruth/ folder linked into a groundtruth/ folder beside it."""
    root = tmp_path / "seq"
    (root / "mav0").mkdir(parents=True)
    for part in ("cam0", "cam1", "imu0", "body.yaml"):
        (root / "mav0" / part).symlink_to(euroc_micro / "mav0" / part)
    (root / "groundtruth").mkdir()
    for name in gt_files:
        (root / "groundtruth" / name).symlink_to(euroc_micro / "groundtruth" / name)
    return root


def test_a_single_groundtruth_file_beside_mav0_is_the_ground_truth(euroc_micro, tmp_path, capsys):
    """Copies of EuRoC sequences often carry the ground truth as groundtruth/<name>.txt instead of
    mav0/state_groundtruth_estimate0/: one such file is taken, and gevi info says which."""
    root = _linked_copy(euroc_micro, tmp_path, ["V1_01_easy.txt"])
    seq = open_sequence(root)
    assert seq.groundtruth is not None and len(seq.groundtruth) > 1000
    assert seq.groundtruth_source == root / "groundtruth" / "V1_01_easy.txt"
    code, out, _ = run_cli(["info", root], capsys)
    assert code == 0 and f"from {root / 'groundtruth' / 'V1_01_easy.txt'}" in out


def test_several_groundtruth_files_beside_mav0_are_not_guessed(euroc_micro, tmp_path):
    root = _linked_copy(euroc_micro, tmp_path, ["V1_01_easy.txt", "V1_01_easy_original.txt"])
    seq = open_sequence(root)
    assert seq.groundtruth is None and seq.groundtruth_source is None
    assert any("2 trajectory files" in w and "V1_01_easy_original.txt" in w for w in seq.warnings)
    given = open_sequence(root, groundtruth=root / "groundtruth" / "V1_01_easy_original.txt")
    assert given.groundtruth is not None and given.groundtruth_source.name == "V1_01_easy_original.txt"
