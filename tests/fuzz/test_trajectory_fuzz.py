"""Fuzzing the trajectory readers and writers (TUM, EuRoC csv, KITTI, KITTI with index).

A random trajectory is written with gevi's writer (what ``gevi convert`` writes), the text is
mutated, and :func:`read_trajectory` must return the written numbers (benign mutations), the
numbers the documented rule says (duplicates dropped, columns named by the header), or refuse with
a :class:`GeviError` at the file and line of the bad row.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from fuzz_support import FUZZ, check_error, count_lines, trajectories
from hypothesis import given, settings
from hypothesis import strategies as st

from gevi_cli.errors import DataError, GeviError
from gevi_cli.trajectory import Trajectory, read_trajectory, write_trajectory
from gevi_cli.trajectory.formats import format_header, format_rows
from gevi_cli.trajectory.validate import MAX_ABS_POSITION_M

FORMATS = ("tum", "euroc", "kitti", "kitti-idx")
BENIGN = ("none", "bom", "crlf", "bom+crlf", "whitespace", "blank-lines")
MUTATIONS = BENIGN + ("truncate", "nonfinite", "text-token", "glitch", "persistent-jump", "most-rows-corrupt",
                      "absurd-rotation", "duplicate", "swap-rows", "swap-columns", "drop-column", "delimiter", "empty",
                      "header-only", "garbage")


def _position_columns(fmt: str) -> list[int]:
    return {"tum": [1, 2, 3], "euroc": [1, 2, 3], "kitti": [3, 7, 11], "kitti-idx": [4, 8, 12]}[fmt]


def _n_columns(fmt: str) -> int:
    return {"tum": 8, "euroc": 8, "kitti": 12, "kitti-idx": 13}[fmt]


def _assert_same(back: Trajectory, traj: Trajectory, fmt: str) -> None:
    """The parsed trajectory is the written one: stamps and positions exactly (the writers print
    repr-level digits, a UTM or ECEF offset included), rotations to float precision."""
    assert len(back) == len(traj)
    np.testing.assert_array_equal(back.positions, traj.positions)
    if fmt in ("tum", "euroc"):
        np.testing.assert_array_equal(back.t_ns, traj.t_ns)
        np.testing.assert_array_equal(back.quat_wxyz, traj.quat_wxyz)
    else:
        assert back.indexed
        np.testing.assert_array_equal(back.t_ns, np.arange(len(traj)) * 100_000_000)
        np.testing.assert_allclose(back.rotations, traj.rotations, atol=1e-12)


class Case:
    """A file's lines split into header and data rows (tokens), mutated in place."""

    def __init__(self, traj: Trajectory, fmt: str):
        self.fmt = fmt
        self.sep = "," if fmt == "euroc" else " "
        header = format_header(fmt)
        self.header = [header] if header else []
        self.rows = [r.split(self.sep) for r in format_rows(traj, fmt)]

    def line_of(self, row: int) -> int:
        return len(self.header) + row + 1

    def text(self, sep: str | None = None, newline: str = "\n") -> str:
        sep = sep or self.sep
        return newline.join(self.header + [sep.join(r) for r in self.rows]) + newline


def rng_unit(seed: int) -> np.ndarray:
    """A random unit vector (3,)."""
    v = np.random.default_rng(seed).normal(size=3)
    return v / np.linalg.norm(v)


def _set_positions(case: Case, positions: np.ndarray, rows) -> None:
    """Write ``positions`` (m) of ``rows`` into the case's position columns (exact repr text)."""
    cols = _position_columns(case.fmt)
    for r in rows:
        for axis in range(3):
            case.rows[r][cols[axis]] = repr(float(positions[r, axis]))


def _mutate(data, case: Case, traj: Trajectory, kind: str):
    """Return (file bytes, expectation) where expectation is a dict the checker understands."""
    n = len(case.rows)
    k = _n_columns(case.fmt)
    if kind in BENIGN:
        text = case.text()
        if kind == "whitespace":
            text = case.text(sep=", " if case.fmt == "euroc" else data.draw(st.sampled_from(["\t", "  ", " \t "])))
            text = "\n".join("  " + line + " \t" for line in text.splitlines()) + "\n"
        if kind == "blank-lines":
            lines = text.splitlines()
            at = data.draw(st.integers(0, len(lines)))
            text = "\n".join(lines[:at] + ["", "   "] + lines[at:]) + "\n\n"
        if "crlf" in kind:
            text = text.replace("\n", "\r\n")
        raw = text.encode()
        if "bom" in kind:
            raw = b"\xef\xbb\xbf" + raw
        return raw, {"same": True}
    if kind == "truncate":
        raw = case.text().encode()
        cut = data.draw(st.integers(0, len(raw) - 1))
        complete = raw[:cut].count(b"\n") - len(case.header)
        return raw[:cut], {"prefix": max(complete, 0)}
    if kind in ("nonfinite", "text-token"):
        r, c = data.draw(st.integers(0, n - 1)), data.draw(st.integers(0, k - 1))
        if kind == "nonfinite":
            token = data.draw(st.sampled_from(["nan", "NaN", "inf", "-inf", "+Infinity", "1e999", "-1e400"]))
        else:
            token = data.draw(st.text(alphabet="abcdefghijklmnopqrstuvwxyzXYZ_-+.:/", min_size=1, max_size=8))
            try:
                float(token)
                token = "x" + token  # a letters-only token float() takes is nan/inf: keep it a non-number
            except ValueError:
                pass
        case.rows[r][c] = token
        return case.text().encode(), {"error_line": case.line_of(r)}
    if kind == "glitch":
        r, axis = data.draw(st.integers(0, n - 1)), data.draw(st.integers(0, 2))
        extent = float(np.ptp(traj.positions, axis=0).max())
        jump = 10.0 ** data.draw(st.integers(6, 12)) * (1.0 + extent) * data.draw(st.sampled_from([1, -1]))
        value = traj.positions[r, axis] + jump
        case.rows[r][_position_columns(case.fmt)[axis]] = repr(float(value))
        if n < 3 and abs(value) <= MAX_ABS_POSITION_M:
            # two poses: no rest of the trajectory to compare with; the file's numbers are read
            expected = traj.positions.copy()
            expected[r, axis] = value
            return case.text().encode(), {"positions": expected}
        return case.text().encode(), {"error_line": case.line_of(r), "message": "not plausible"}
    if kind == "persistent-jump":
        # from row r on, every row is moved by one big offset: the jump persists (a frame offset added
        # to the rest of the file), however many rows follow; refused at r, the first moved row
        if n < 3:
            return case.text().encode(), {"same": True}
        r = data.draw(st.integers(2, n - 1))
        before = np.linalg.norm(np.diff(traj.positions[:r], axis=0), axis=1).max()
        direction = rng_unit(data.draw(st.integers(0, 2**32 - 1)))
        jump = direction * (1e5 * (before + 1e-3) + 1e3)  # far beyond the steps before it, |p| < 1e8 m
        moved = traj.positions.copy()
        moved[r:] += jump
        _set_positions(case, moved, range(r, n))
        return case.text().encode(), {"error_line": case.line_of(r), "message": "not plausible"}
    if kind == "most-rows-corrupt":
        # issue 35's file: one coordinate multiplied by 1e9..1e12 from row r to the end (at least half
        # the rows); the rule relative to the whole file cannot see it, the absolute bound does
        r, axis = data.draw(st.integers(0, n // 2)), data.draw(st.integers(0, 2))
        factor = 10.0 ** data.draw(st.integers(9, 12))
        factor = max(factor, 2 * MAX_ABS_POSITION_M / abs(traj.positions[r, axis]))  # row r itself is beyond 1e8 m
        moved = traj.positions.copy()
        moved[r:, axis] *= factor
        _set_positions(case, moved, range(r, n))
        return case.text().encode(), {"error_line": case.line_of(r), "message": "not plausible"}
    if kind == "absurd-rotation":
        # a quaternion component (or rotation entry) 20..1e6 off: a corrupt row, not a rounding error
        r = data.draw(st.integers(0, n - 1))
        c = data.draw(st.sampled_from({"tum": [4, 5, 6, 7], "euroc": [4, 5, 6, 7], "kitti": [0, 1, 2, 4, 5, 6, 8, 9, 10],
                                       "kitti-idx": [1, 2, 3, 5, 6, 7, 9, 10, 11]}[case.fmt]))
        off = data.draw(st.sampled_from([20.0, 1e3, 1e6])) * data.draw(st.sampled_from([1, -1]))
        case.rows[r][c] = repr(float(case.rows[r][c]) + off)
        return case.text().encode(), {"error_line": case.line_of(r),
                                      "message": "quaternion" if case.fmt in ("tum", "euroc") else "rotation block"}
    if kind == "duplicate":
        r = data.draw(st.integers(0, n - 1))
        case.rows.insert(r + 1, list(case.rows[r]))
        if case.fmt in ("tum", "euroc"):  # documented: the first pose of each stamp is kept, with a warning
            return case.text().encode(), {"same": True, "warning": f":{case.line_of(r + 1)}:"}
        if case.fmt == "kitti-idx":
            return case.text().encode(), {"error_line": case.line_of(r + 1)}
        return case.text().encode(), {"positions": np.insert(traj.positions, r + 1, traj.positions[r], axis=0)}
    if kind == "swap-rows":
        if n < 2:
            return case.text().encode(), {"same": True}
        r1 = data.draw(st.integers(0, n - 2))
        r2 = data.draw(st.integers(r1 + 1, n - 1))
        case.rows[r1], case.rows[r2] = case.rows[r2], case.rows[r1]
        if case.fmt == "kitti":  # no stamps: the order cannot be checked; the rows read are the file's
            perm = np.arange(n)
            perm[[r1, r2]] = [r2, r1]
            return case.text().encode(), {"positions_or_error": traj.positions[perm]}
        return case.text().encode(), {"error_line": case.line_of(r1 + 1)}
    if kind == "swap-columns":
        if case.fmt in ("kitti", "kitti-idx"):  # no header names the columns: a swap is undetectable
            return case.text().encode(), {"any": True}
        a, b = data.draw(st.lists(st.integers(0, 7), min_size=2, max_size=2, unique=True))
        for row in case.rows:
            row[a], row[b] = row[b], row[a]
        names = case.header[0].lstrip("#").split("," if case.fmt == "euroc" else None)
        names[a], names[b] = names[b], names[a]
        case.header = ["#" + case.sep.join(names)]
        return case.text().encode(), {"same": True}
    if kind == "drop-column":
        c = data.draw(st.integers(0, k - 1))
        for row in case.rows:
            del row[c]
        return case.text().encode(), {"any": True}
    if kind == "delimiter":
        sep = data.draw(st.sampled_from([",", "\t", " ", ";"]))
        if case.fmt != "euroc" and case.header:
            case.header = ["# " + sep.join(case.header[0].lstrip("# ").split())]
        elif case.fmt == "euroc":
            case.header = ["#" + sep.join(h.replace(" ", "") for h in case.header[0].lstrip("#").split(","))]
        if sep == ";":
            return case.text(sep=sep).encode(), {"error_line": case.line_of(0), "message": "';'"}
        return case.text(sep=sep).encode(), {"same": True}
    if kind == "empty":
        return b"", {"error_line": None, "file_error": True}
    if kind == "header-only":
        return ("\n".join(case.header or ["# frame poses"]) + "\n").encode(), {"file_error": True}
    if kind == "garbage":
        return data.draw(st.binary(min_size=1, max_size=300)), {"any": True}
    raise AssertionError(kind)


def _check(path: Path, raw: bytes, traj: Trajectory, fmt: str, expect: dict) -> None:
    try:
        back = read_trajectory(path)
    except GeviError as err:
        if expect.get("same") or "positions" in expect:
            raise AssertionError(f"a valid file was refused: {err.one_line()}") from err
        check_error(err, path, expect.get("error_line"), count_lines(raw))
        if expect.get("file_error"):
            assert err.where == str(path)
        if "message" in expect:
            assert expect["message"] in err.message, err.one_line()
        return
    # a valid read
    assert "error_line" not in expect and not expect.get("file_error"), f"accepted a file that must be refused ({expect})"
    assert np.all(np.diff(back.t_ns) > 0)
    assert np.isfinite(back.positions).all() and np.isfinite(back.quat_wxyz).all()
    # validate_rows keeps rows within 1e-5 of unit norm as written (a truncated last digit can leave one
    # there) and renormalizes the others
    np.testing.assert_allclose(np.linalg.norm(back.quat_wxyz, axis=1), 1.0, atol=1e-5)
    if expect.get("same"):
        _assert_same(back, traj, fmt)
        if "warning" in expect:
            assert any(expect["warning"] in w and "repeat the previous timestamp" in w for w in back.meta["warnings"])
        else:
            assert back.meta["warnings"] == []
    for key in ("positions", "positions_or_error"):
        if key in expect:
            np.testing.assert_array_equal(back.positions, expect[key])
    if "prefix" in expect:
        m = expect["prefix"]
        assert m <= len(back) <= m + 1
        np.testing.assert_array_equal(back.positions[:m], traj.positions[:m])
        if fmt in ("tum", "euroc"):
            np.testing.assert_array_equal(back.t_ns[:m], traj.t_ns[:m])
            np.testing.assert_array_equal(back.quat_wxyz[:m], traj.quat_wxyz[:m])


@pytest.mark.parametrize("fmt", FORMATS)
@settings(FUZZ, max_examples=150)
@given(traj=trajectories(), kind=st.sampled_from(MUTATIONS), data=st.data())
def test_mutated_trajectory_files(fmt, traj, kind, data):
    case = Case(traj, fmt)
    raw, expect = _mutate(data, case, traj, kind)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"traj.{'csv' if fmt == 'euroc' else 'txt'}"
        path.write_bytes(raw)
        _check(path, raw, traj, fmt, expect)


@pytest.mark.parametrize("kind", ["persistent-jump", "most-rows-corrupt"])
@pytest.mark.parametrize("fmt", FORMATS)
@FUZZ
@given(traj=trajectories(min_len=3), data=st.data())
def test_corrupt_tails_are_refused_at_their_first_row(fmt, kind, traj, data):
    """Issue 35: a jump that persists to the end, and a tail of most rows scaled by 1e9..1e12, are
    refused at the first corrupt row (the sampled mutations above draw them too, among the others)."""
    case = Case(traj, fmt)
    raw, expect = _mutate(data, case, traj, kind)
    assert "error_line" in expect
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "traj.txt"
        path.write_bytes(raw)
        _check(path, raw, traj, fmt, expect)


@pytest.mark.parametrize("fmt", FORMATS)
@FUZZ
@given(traj=trajectories())
def test_writer_round_trip_is_exact(fmt, traj):
    """What ``gevi convert`` writes reads back as the same numbers, at UTM and ECEF offsets too."""
    with tempfile.TemporaryDirectory() as tmp:
        back = read_trajectory(write_trajectory(traj, Path(tmp) / "t.txt", fmt))
    assert back.meta["format"] == fmt
    _assert_same(back, traj, fmt)


# ------------------------------------------------------------------ the relative absurdity rule, both sides
def _line_trajectory(offset, n=100, step=0.5):
    t = 1_403_715_273_000_000_000 + np.arange(n) * 50_000_000
    p = np.asarray(offset, dtype=float) + np.column_stack([np.arange(n) * step, np.sin(np.arange(n) * 0.1), np.zeros(n)])
    q = np.tile([1.0, 0, 0, 0], (n, 1))
    return Trajectory(t, p, q)


@pytest.mark.parametrize("offset", [(512_345.678901, 4_512_345.678901, 250.0), (4_205_000.0, 168_000.0, 4_778_000.0),
                                    (0.0, 0.0, 6_400_000.0)])
@pytest.mark.parametrize("fmt", FORMATS)
def test_utm_and_ecef_offset_trajectories_round_trip(tmp_path, offset, fmt):
    traj = _line_trajectory(offset)
    back = read_trajectory(write_trajectory(traj, tmp_path / "gt.txt", fmt))
    np.testing.assert_array_equal(back.positions, traj.positions)  # not a micrometre lost at 6.4e6 m
    assert back.meta["warnings"] == []


@pytest.mark.parametrize("row", [0, 37, 99])
@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (512_345.678, 4_512_345.678, 250.0)])
def test_single_glitch_row_is_refused_with_its_line(tmp_path, row, offset):
    traj = _line_trajectory(offset)
    rows = format_rows(traj, "tum")
    tokens = rows[row].split()
    tokens[2] = repr(float(tokens[2]) + 1e9)  # a glitch 1e9 m away
    rows[row] = " ".join(tokens)
    path = tmp_path / "gt.txt"
    path.write_text(format_header("tum") + "\n" + "\n".join(rows) + "\n")
    with pytest.raises(DataError) as err:
        read_trajectory(path)
    assert err.value.where == f"{path}:{row + 2}"
    assert "not plausible" in err.value.message


def test_a_genuine_big_step_in_a_long_trajectory_is_kept(tmp_path):
    """A 500 m re-fix in a 10 km drive is 1e5 typical steps but not 100x the rest: read, not refused."""
    traj = _line_trajectory((0.0, 0.0, 0.0), n=2000, step=5.0)
    p = traj.positions.copy()
    p[1000:, 0] += 500.0
    traj = Trajectory(traj.t_ns, p, traj.quat_wxyz)
    back = read_trajectory(write_trajectory(traj, tmp_path / "t.txt", "tum"))
    np.testing.assert_array_equal(back.positions, p)


def test_small_integer_ns_stamps_in_euroc_csv_are_ns(tmp_path):
    """KITTI converted to EuRoC has stamps 0, 1e8, 2e8 ns: read as ns, not as seconds."""
    path = tmp_path / "k.csv"
    path.write_text("0,0,0,0,1,0,0,0\n100000000,0.1,0,0,1,0,0,0\n200000000,0.2,0,0,1,0,0,0\n")
    assert read_trajectory(path).t_ns.tolist() == [0, 100_000_000, 200_000_000]


def test_stamps_beyond_int64_are_refused_with_line(tmp_path):
    path = tmp_path / "t.txt"
    path.write_text("1.0 0 0 0 0 0 0 1\n99999999999.5 0 0 0 0 0 0 1\n")
    with pytest.raises(DataError) as err:
        read_trajectory(path)
    assert err.value.where == f"{path}:2" and "out of range" in err.value.message
