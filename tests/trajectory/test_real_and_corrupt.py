"""Issue 35: every real trajectory loads, at UTM and ECEF offsets too; a corrupt tail is refused.

The corrupt file is built at test time from KITTI 00's ORB-SLAM estimate (shared data, never copied
into the repo): written as TUM with nanosecond stamps, its y multiplied by a factor from **file line
499** (1-based, the line number an editor shows; the file has no header, so it is the 499th pose,
index 498) to the end: 4043 of 4541 rows (89 %) corrupt.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from gevi_cli.errors import DataError
from gevi_cli.trajectory import Trajectory, read_trajectory, write_trajectory
from gevi_cli.trajectory.validate import position_problem
from support import shared_path

#: ORB-SLAM3-style epoch stamps in ns (> 1e17, so a TUM reader takes them as ns)
EPOCH_NS = 1_317_000_000_000_000_000
FIRST_CORRUPT_LINE = 499


def real_trajectory_files() -> list[Path]:
    """Every trajectory file of the shared ``trajectories/`` folder (not times, configs, zips, images)."""
    root = shared_path("trajectories")
    return sorted(p for p in root.rglob("*") if p.is_file() and p.suffix in (".txt", ".csv")
                  and not p.name.endswith("_times.txt"))


def kitti00_stamped(name: str) -> Trajectory:
    """KITTI 00's ``name`` (evo's test data) stamped with the sequence's times (row i = frame i), in ns."""
    folder = shared_path("trajectories", "evo_test_data")
    times_s = np.loadtxt(folder / "KITTI_00_gt_times.txt")
    t_ns = EPOCH_NS + np.round(times_s * 1e9).astype(np.int64)
    kitti = read_trajectory(folder / name)
    return Trajectory(t_ns, kitti.positions, kitti.quat_wxyz)


def write_corrupt_orb(path: Path, factor: float = 1e9) -> Path:
    """KITTI 00 ORB as TUM with ns stamps, y times ``factor`` from file line 499 on (no header)."""
    orb = kitti00_stamped("KITTI_00_ORB.txt")
    p = orb.positions.copy()
    p[FIRST_CORRUPT_LINE - 1:, 1] *= factor
    q = orb.quat_wxyz
    rows = [f"{t} " + " ".join(repr(float(v)) for v in (*pp, q_[1], q_[2], q_[3], q_[0]))
            for t, pp, q_ in zip(orb.t_ns.tolist(), p, q)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_every_real_trajectory_loads_without_a_position_problem():
    files = real_trajectory_files()
    assert len(files) >= 60  # 69 of its 83 files (the rest: result zips, images, yaml configs, SOURCE.md, times)
    for path in files:
        traj = read_trajectory(path)
        assert traj.meta["allowed_jumps"] == [], path
        assert position_problem(traj.positions) is None, path


@pytest.mark.parametrize("offset", [(5.0e5, 4.5e6, 0.0),  # UTM easting, northing
                                    (4_205_000.0, 168_000.0, 4_778_000.0)])  # ECEF, |p| = 6.37e6 m
@pytest.mark.parametrize("fmt", ["tum", "kitti"])
def test_utm_and_ecef_offset_copies_load(tmp_path, offset, fmt):
    gt = kitti00_stamped("KITTI_00_gt.txt")
    moved = Trajectory(gt.t_ns, gt.positions + np.array(offset), gt.quat_wxyz)
    back = read_trajectory(write_trajectory(moved, tmp_path / f"gt.{fmt}", fmt))
    np.testing.assert_array_equal(back.positions, moved.positions)
    assert back.meta["warnings"] == []


def test_corrupt_tail_is_refused_at_line_499_by_the_absolute_bound(tmp_path):
    """y x 1e9: |y| up to 1.3e10 m, beyond any Earth-fixed frame (1e8 m)."""
    path = write_corrupt_orb(tmp_path / "corrupt.txt")
    with pytest.raises(DataError) as err:
        read_trajectory(path)
    assert err.value.where == f"{path}:{FIRST_CORRUPT_LINE}"
    assert "from the origin" in err.value.message
    with pytest.raises(DataError):  # no Earth-fixed frame reaches there: not a jump --allow-jumps lets through
        read_trajectory(path, allow_jumps=True)


def test_corrupt_tail_within_1e8_m_is_refused_at_line_499_as_a_persistent_jump(tmp_path):
    """y x 1e6: |y| up to 1.3e7 m (a UTM/ECEF-sized number), 89 % of the rows: only the rule that
    measures the steps *before* the jump sees it (the whole file's typical step is the corrupt one)."""
    path = write_corrupt_orb(tmp_path / "corrupt.txt", factor=1e6)
    with pytest.raises(DataError) as err:
        read_trajectory(path)
    assert err.value.where == f"{path}:{FIRST_CORRUPT_LINE}"
    assert "from the previous row" in err.value.message and "--allow-jumps" in err.value.message
    traj = read_trajectory(path, allow_jumps=True)  # the opt-in reads it as written and says so
    assert traj.positions[FIRST_CORRUPT_LINE - 1, 1] < -1e6
    assert len(traj.meta["allowed_jumps"]) == 1 and f":{FIRST_CORRUPT_LINE}:" in traj.meta["allowed_jumps"][0]
    assert traj.meta["allowed_jumps"][0] in traj.meta["warnings"]


# ------------------------------------------------------------------------------ through the CLI
def _one_error_line(code: int, err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("gevi: error: "), err
    return lines[0]


@pytest.mark.parametrize("factor", [1e9, 1e6])
def test_convert_and_eval_refuse_the_corrupt_file_at_line_499(tmp_path, capsys, factor):
    from support import run_cli

    bad = write_corrupt_orb(tmp_path / "corrupt.txt", factor)
    gt = write_trajectory(kitti00_stamped("KITTI_00_gt.txt"), tmp_path / "gt00.tum", "tum")
    line = _one_error_line(*run_cli(["convert", bad, tmp_path / "out.txt", "--to", "tum"], capsys)[::2])
    assert line.startswith(f"gevi: error: {bad}:{FIRST_CORRUPT_LINE}: position (") and "not plausible" in line
    assert not (tmp_path / "out.txt").exists()
    line = _one_error_line(*run_cli(["eval", "--gt", gt, "-e", f"corrupt={bad}", "--no-plots",
                                     "-o", tmp_path / "ev"], capsys)[::2])
    assert line.startswith(f"gevi: error: {bad}:{FIRST_CORRUPT_LINE}: ")
    assert not (tmp_path / "ev").exists()


def test_allow_jumps_reads_it_and_the_table_says_so_with_a_failed_cell(tmp_path, capsys):
    """--allow-jumps: the 1e6 file is read, its ATE (4.8e6 m on a 751 m drive) is refused as not
    physical (a failed cell with the reason), the table note names it; ORB-SLAM next to it is 1.303 m."""
    import json

    from support import run_cli

    bad = write_corrupt_orb(tmp_path / "corrupt.txt", factor=1e6)
    good = write_corrupt_orb(tmp_path / "orb.txt", factor=1.0)
    gt = write_trajectory(kitti00_stamped("KITTI_00_gt.txt"), tmp_path / "gt00.tum", "tum")
    code, out, err = run_cli(["eval", "--gt", gt, "-e", f"corrupt={bad}", "-e", f"orb={good}", "--no-plots",
                              "--no-kitti", "--allow-jumps", "-o", tmp_path / "ev"], capsys)
    assert code == 0, err
    assert f"{bad}:{FIRST_CORRUPT_LINE}:" in err and "read as written (--allow-jumps)" in err
    ate_table = out.split("ATE translation RMSE")[1].split("\n\n")[0]
    assert "--allow-jumps: position jumps read as written" in ate_table and "corrupt/gt00" in ate_table
    assert "| gt00     | failed  | **1.303** |" in ate_table
    results = {r["method"]: r for r in json.loads((tmp_path / "ev" / "metrics.json").read_text())["results"]}
    assert results["corrupt"]["status"] == "failed" and "not physical" in results["corrupt"]["reason"]
    assert results["orb"]["status"] == "ok" and results["orb"]["allowed_jumps"] == []
    assert "not physical" in (tmp_path / "ev" / "summary.md").read_text()
