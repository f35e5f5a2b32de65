"""Trajectory formats: reading every real file by auto-detection, exact round trips, validation."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli.errors import DataError
from gevi_cli.trajectory import Trajectory, detect_format, read_trajectory, write_trajectory
from gevi_cli.trajectory.stamps import decimal_strings_to_ns
from support import run_cli, shared_path


def _real_trajectory_files():
    root = shared_path("trajectories")
    return sorted(p for p in root.rglob("*") if p.suffix in (".txt", ".csv") and p.name != "SOURCE.md"
                  and p.name != "KITTI_00_gt_times.txt")


def test_every_shared_trajectory_loads_by_detection():
    files = _real_trajectory_files()
    assert len(files) >= 60
    for path in files:
        traj = read_trajectory(path)
        assert len(traj) > 10, path
        assert np.all(np.diff(traj.t_ns) > 0), path
        np.testing.assert_allclose(np.linalg.norm(traj.quat_wxyz, axis=1), 1.0, atol=1e-5, err_msg=str(path))


def test_formats_of_known_files():
    root = shared_path("trajectories")
    assert detect_format(root / "evo_test_data/KITTI_00_gt.txt") == "kitti"
    assert detect_format(root / "kitti_odom_eval/result/example_0/09.txt") == "kitti-idx"
    assert detect_format(root / "evo_test_data/V102_groundtruth.csv") == "euroc"
    assert detect_format(root / "evo_test_data/V102.txt") == "tum"
    idx = read_trajectory(root / "kitti_odom_eval/result/example_0/09.txt")
    assert idx.indexed and idx.t_ns[0] == 2 * 100_000_000  # starts at frame 2


def test_euroc_and_tum_copies_of_one_groundtruth_agree():
    root = shared_path("euroc_micro", "groundtruth")
    csv = read_trajectory(root / "V1_01_easy.csv")
    tum = read_trajectory(root / "V1_01_easy.txt")
    # the TUM copy is rounded to 10 us; poses are equal to the file precision (1e-6)
    assert len(csv) == len(tum)
    assert np.abs(csv.t_ns - tum.t_ns).max() < 10_000
    np.testing.assert_allclose(csv.positions, tum.positions, atol=1e-6)
    np.testing.assert_allclose(csv.quat_wxyz, tum.quat_wxyz, atol=1e-5)


def test_rpg_stamped_groundtruth_equals_asl_csv():
    root = shared_path("trajectories")
    asl = read_trajectory(root / "evo_test_data/V102_groundtruth.csv")
    rpg = read_trajectory(root / "rpg_trajectory_evaluation/results/euroc_vislam_mono/laptop/vislam_rp/"
                          "laptop_vislam_rp_V1_02/stamped_groundtruth.txt")
    assert len(asl) == len(rpg)
    assert np.abs(asl.t_ns - rpg.t_ns).max() <= 1000
    np.testing.assert_allclose(asl.positions, rpg.positions, atol=1e-9)


def test_duplicate_stamps_in_real_file_keep_first_with_warning():
    traj = read_trajectory(shared_path("trajectories", "evo_test_data", "V102.txt"))
    assert len(traj) == 803  # 807 rows, 4 repeat their predecessor's stamp
    assert any("repeat the previous timestamp" in w and "V102.txt:433" in w for w in traj.meta["warnings"])


def _random_trajectory(n=50, seed=0, t0=1403715273262142976):
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    t_ns = t0 + np.cumsum(rng.integers(40_000_000, 60_000_000, size=n))
    return Trajectory(t_ns, rng.normal(size=(n, 3)) * 10, q, frame="body")


@pytest.mark.parametrize("fmt", ["tum", "euroc"])
def test_stamped_round_trip_is_exact(tmp_path, fmt):
    traj = _random_trajectory()
    back = read_trajectory(write_trajectory(traj, tmp_path / f"t.{fmt}", fmt))
    assert back.meta["format"] == fmt
    np.testing.assert_array_equal(back.t_ns, traj.t_ns)  # nanoseconds survive: no 4-decimal seconds
    np.testing.assert_allclose(back.positions, traj.positions, atol=1e-9)
    # q and -q are one rotation
    dots = np.abs(np.sum(back.quat_wxyz * traj.quat_wxyz, axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-10)


@pytest.mark.parametrize("fmt", ["kitti", "kitti-idx"])
def test_kitti_round_trip(tmp_path, fmt):
    traj = _random_trajectory()
    back = read_trajectory(write_trajectory(traj, tmp_path / "t.txt", fmt))
    assert back.meta["format"] == fmt and back.indexed
    np.testing.assert_allclose(back.matrices, traj.matrices, atol=1e-8)


def test_orbslam3_ns_stamps_in_tum_columns(tmp_path):
    path = tmp_path / "f_dataset-MH01_stereo.txt"
    path.write_text("1403636580838555648 0.1 0.2 0.3 0 0 0 1\n1403636580888555520 0.1 0.2 0.4 0 0 0 1\n")
    traj = read_trajectory(path)
    assert traj.meta["format"] == "tum"
    assert traj.t_ns.tolist() == [1403636580838555648, 1403636580888555520]


def test_vins_fusion_vio_csv(tmp_path):
    # ns, comma, w-first quaternion, velocities, trailing comma (VINS-Fusion's vio.csv)
    path = tmp_path / "vio.csv"
    path.write_text("1403636580838555648,0.1,0.2,0.3,0.7071068,0,0,0.7071068,0.5,0,0,\n"
                    "1403636580888555520,0.1,0.2,0.4,1,0,0,0,0.5,0,0,\n")
    traj = read_trajectory(path)
    assert traj.meta["format"] == "euroc"
    np.testing.assert_allclose(traj.quat_wxyz[0], [0.7071068, 0, 0, 0.7071068])
    assert traj.t_ns[0] == 1403636580838555648


def test_stamp_parsing_is_exact():
    ns = decimal_strings_to_ns(["1403715273.262142976", "1403715273.26214", "12", "0.0000000015"], 10**9)
    assert ns.tolist() == [1403715273262142976, 1403715273262140000, 12_000_000_000, 2]


def _write(tmp_path, rows):
    path = tmp_path / "bad.txt"
    path.write_text("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(rows) + "\n")
    return path


GOOD = ["1.0 0 0 0 0 0 0 1", "1.1 0.1 0 0 0 0 0 1", "1.2 0.2 0 0 0 0 0 1", "1.3 0.3 0 0 0 0 0 1"]


@pytest.mark.parametrize("row, line, text", [
    (2, 4, "non-finite"),
    (3, 5, "goes back in time"),
    (1, 3, "not plausible"),
])
def test_validation_errors_name_the_row(tmp_path, row, line, text):
    rows = list(GOOD)
    if text == "non-finite":
        rows[row] = "1.2 nan 0 0 0 0 0 1"
    elif text == "goes back in time":
        rows[row] = "1.05 0.3 0 0 0 0 0 1"
    else:
        rows[row] = "1.1 100000000 0 0 0 0 0 1"  # one coordinate 1e9 times larger
    path = _write(tmp_path, rows)
    with pytest.raises(DataError) as err:
        read_trajectory(path)
    assert err.value.where == f"{path}:{line}"
    assert text in err.value.message


def test_corrupt_tail_is_rejected_with_row(tmp_path):
    rows = [f"{1 + 0.1 * i:.1f} {0.1 * i} 0 0 0 0 0 1" for i in range(20)]
    rows[12:] = [f"{1 + 0.1 * i:.1f} {0.1 * i * 1e9} 0 0 0 0 0 1" for i in range(12, 20)]
    path = _write(tmp_path, rows)
    with pytest.raises(DataError) as err:
        read_trajectory(path)
    assert err.value.where == f"{path}:14"


def test_jump_without_huge_coordinates_is_rejected(tmp_path):
    rows = [f"{1 + 0.1 * i:.1f} {0.01 * i} 0 0 0 0 0 1" for i in range(20)]
    rows[10] = "2.0 5000 0 0 0 0 0 1"
    with pytest.raises(DataError, match="position jumps"):
        read_trajectory(_write(tmp_path, rows))


def test_non_unit_quaternion_renormalized_with_warning(tmp_path):
    rows = list(GOOD)
    rows[1] = "1.1 0.1 0 0 0 0 0 2"
    traj = read_trajectory(_write(tmp_path, rows))
    np.testing.assert_allclose(traj.quat_wxyz[1], [1, 0, 0, 0])
    assert any(":3:" in w and "renormalized" in w for w in traj.meta["warnings"])


def test_ragged_rows_and_text(tmp_path):
    path = _write(tmp_path, GOOD + ["1.4 0 0 0 0 0 1"])
    with pytest.raises(DataError, match="has 7 columns"):
        read_trajectory(path)
    path = _write(tmp_path, GOOD[:2] + ["1.4 zero 0 0 0 0 0 1"])
    with pytest.raises(DataError, match="not a number"):
        read_trajectory(path)


def test_convert_cli_and_errors(tmp_path, capsys):
    src = shared_path("trajectories", "evo_test_data", "KITTI_00_ORB.txt")
    code, out, _ = run_cli(["convert", src, tmp_path / "o.csv", "--to", "euroc"], capsys)
    assert code == 0 and "4541 poses" in out
    back = read_trajectory(tmp_path / "o.csv")
    np.testing.assert_allclose(back.positions, read_trajectory(src).positions, atol=1e-8)
    code, _, err = run_cli(["convert", tmp_path / "missing.txt", tmp_path / "x.txt", "--to", "tum"], capsys)
    assert code == 2 and err.strip().count("\n") == 0 and "missing.txt: no such file" in err
    bad = _write(tmp_path, ["1.0 0 0 0 0 0 0 1", "0.5 0 0 0 0 0 0 1"])
    code, _, err = run_cli(["convert", bad, tmp_path / "x.txt", "--to", "tum"], capsys)
    assert code == 2 and f"{bad}:3" in err and "Traceback" not in err
