"""The fuzz properties on real files: published trajectories, EuRoC-micro csv files, KITTI 06 head.

* BOM + CRLF copies of every real file read to exactly the same numbers;
* every real trajectory moved to UTM and ECEF offsets is accepted and round-trips exactly through
  its own format's writer (the relative absurdity rule does not fire on real motion);
* one glitch row (1e9 m off) in such a trajectory is refused at its line.
"""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli.datasets.euroc import read_image_list, read_imu
from gevi_cli.datasets.kitti import read_calib, read_times
from gevi_cli.errors import DataError
from gevi_cli.trajectory import Trajectory, read_trajectory, write_trajectory
from gevi_cli.trajectory.formats import format_header, format_rows
from support import shared_path


def _real_trajectory_files():
    root = shared_path("trajectories")
    files = sorted(p for p in root.rglob("*") if p.suffix in (".txt", ".csv") and p.name != "SOURCE.md"
                   and p.name != "KITTI_00_gt_times.txt")
    files += sorted(shared_path("euroc_micro", "groundtruth").glob("*.*"))
    return files


def _bom_crlf(src, dst):
    dst.write_bytes(b"\xef\xbb\xbf" + src.read_bytes().replace(b"\r\n", b"\n").replace(b"\n", b"\r\n"))
    return dst


def _equal(a: Trajectory, b: Trajectory):
    np.testing.assert_array_equal(a.t_ns, b.t_ns)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.quat_wxyz, b.quat_wxyz)


def test_real_trajectories_with_bom_and_crlf_read_the_same(tmp_path):
    files = _real_trajectory_files()
    assert len(files) >= 60
    for i, path in enumerate(files):
        copy = _bom_crlf(path, tmp_path / f"{i}{path.suffix}")
        _equal(read_trajectory(copy), read_trajectory(path))


@pytest.mark.slow
def test_real_trajectories_at_utm_and_ecef_offsets(tmp_path):
    rng = np.random.default_rng(0)
    offsets = [(512_345.678, 4_512_345.678, 250.0), (4_205_000.0, 168_000.0, 4_778_000.0)]  # UTM, ECEF in turn
    for i, path in enumerate(_real_trajectory_files()):
        offset = offsets[i % 2]
        real = read_trajectory(path)
        fmt = real.meta["format"]
        moved = Trajectory(real.t_ns, real.positions + offset, real.quat_wxyz, indexed=real.indexed)
        out = write_trajectory(moved, tmp_path / f"{i}.txt", fmt)
        back = read_trajectory(out)
        assert back.meta["warnings"] == [], (path, back.meta["warnings"])
        np.testing.assert_array_equal(back.positions, moved.positions, err_msg=str(path))
        # one glitch row, 1e9 m away, is refused at its line
        rows = format_rows(moved, fmt)
        r = int(rng.integers(0, len(rows)))
        sep = "," if fmt == "euroc" else " "
        tokens = rows[r].split(sep)
        col = {"tum": 1, "euroc": 1, "kitti": 3, "kitti-idx": 4}[fmt]
        tokens[col] = repr(float(tokens[col]) + 1e9)
        rows[r] = sep.join(tokens)
        header = format_header(fmt)
        bad = tmp_path / f"{i}_bad.txt"
        bad.write_text("\n".join(([header] if header else []) + rows) + "\n")
        with pytest.raises(DataError) as err:
            read_trajectory(bad)
        assert err.value.where == f"{bad}:{r + 1 + (1 if header else 0)}", (path, err.value.one_line())
        assert "not plausible" in err.value.message


def test_real_euroc_csvs_with_bom_and_crlf(tmp_path):
    mav0 = shared_path("euroc_micro", "mav0")
    for cam in ("cam0", "cam1"):
        folder = tmp_path / cam
        folder.mkdir()
        (folder / "data").symlink_to(mav0 / cam / "data")
        _bom_crlf(mav0 / cam / "data.csv", folder / "data.csv")
        want, got = read_image_list(mav0 / cam), read_image_list(folder)
        np.testing.assert_array_equal(got[0], want[0])
        assert got[2] == want[2]
    imu = tmp_path / "imu0"
    imu.mkdir()
    _bom_crlf(mav0 / "imu0" / "data.csv", imu / "data.csv")
    want, got = read_imu(mav0 / "imu0"), read_imu(imu)
    np.testing.assert_array_equal(got.t_ns, want.t_ns)
    np.testing.assert_array_equal(got.gyro, want.gyro)
    np.testing.assert_array_equal(got.acc, want.acc)


def test_real_kitti_times_and_calib_with_bom_and_crlf(tmp_path):
    seqs = sorted(p.parent for p in shared_path("kitti06_head").rglob("times.txt"))
    assert seqs
    for seq in seqs:
        times = _bom_crlf(seq / "times.txt", tmp_path / "times.txt")
        np.testing.assert_array_equal(read_times(times), read_times(seq / "times.txt"))
        calib = _bom_crlf(seq / "calib.txt", tmp_path / "calib.txt")
        want, got = read_calib(seq / "calib.txt"), read_calib(calib)
        assert set(got) == set(want) and {"P0", "P1"} <= set(got)
        for key, value in want.items():
            np.testing.assert_array_equal(got[key], value)
