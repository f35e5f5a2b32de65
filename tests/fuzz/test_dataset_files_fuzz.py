"""Fuzzing the EuRoC csv readers (cam ``data.csv``, ``imu0/data.csv``), KITTI ``times.txt`` and
``calib.txt``, and the OV2SLAM track export reader.

Each file is written valid, then mutated; the reader returns the written numbers (benign
mutations: BOM, CRLF, blank lines, spacing) or refuses with a GeviError at the file and the line of
the mutation, never another exception.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
from fuzz_support import FUZZ, check_error, count_lines
from hypothesis import given
from hypothesis import strategies as st

from gevi_cli.datasets.euroc import read_image_list, read_imu
from gevi_cli.datasets.kitti import read_calib, read_times
from gevi_cli.datasets.track_export import TrackExport
from gevi_cli.errors import GeviError
from gevi_cli.trajectory.stamps import ns_to_seconds_strings

BENIGN = ("none", "bom", "crlf", "blank-lines", "spacing")
LINE_MUTATIONS = BENIGN + ("truncate", "nonfinite", "text-token", "duplicate", "swap", "drop-token", "extra-token",
                           "delimiter", "empty", "garbage")
NONFINITE = ("nan", "NaN", "inf", "-inf", "Infinity", "1e999")


@st.composite
def stamps_ns(draw, min_len=1, max_len=120):
    n = draw(st.integers(min_len, max_len))
    t0 = draw(st.sampled_from([0, 1_403_715_273_262_142_976, 1_000]))
    step = draw(st.sampled_from([1, 1_000, 5_000_000, 50_000_000, 1_000_000_000]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    return t0 + np.cumsum(rng.integers(step, 2 * step + 1, size=n))


def _mutate_lines(data, header: list[str], rows: list[list[str]], sep: str, kind: str, numeric_cols):
    """Mutate a line-oriented file; return (bytes, expectation).  ``numeric_cols``: the columns whose
    tokens the reader checks as numbers (a non-number there must be refused at its line)."""
    n, h = len(rows), len(header)

    def text(lines_sep=sep, newline="\n"):
        return newline.join(header + [lines_sep.join(r) for r in rows]) + newline

    if kind in BENIGN:
        out = text()
        if kind == "blank-lines":
            lines = out.splitlines()
            at = data.draw(st.integers(0, len(lines)))
            out = "\n".join(lines[:at] + ["", "  "] + lines[at:]) + "\n\n"
        if kind == "spacing":
            out = text(lines_sep=sep + " " if sep == "," else "\t")
        if kind == "crlf":
            out = out.replace("\n", "\r\n")
        raw = out.encode()
        return (b"\xef\xbb\xbf" + raw if kind == "bom" else raw), {"same": True}
    if kind == "truncate":
        raw = text().encode()
        cut = data.draw(st.integers(0, len(raw) - 1))
        return raw[:cut], {"prefix": max(raw[:cut].count(b"\n") - h, 0)}
    if kind in ("nonfinite", "text-token"):
        r, c = data.draw(st.integers(0, n - 1)), data.draw(st.sampled_from(numeric_cols))
        if kind == "nonfinite":
            rows[r][c] = data.draw(st.sampled_from(NONFINITE))
        else:
            rows[r][c] = "x" + data.draw(st.text(alphabet="abcdefxyz_-+.:", max_size=6))
        return text().encode(), {"error_line": h + r + 1, "row": r}
    if kind == "duplicate":
        r = data.draw(st.integers(0, n - 1))
        rows.insert(r + 1, list(rows[r]))
        return text().encode(), {"error_line": h + r + 2, "duplicate": r}
    if kind == "swap":
        if n < 2:
            return text().encode(), {"same": True}
        r1 = data.draw(st.integers(0, n - 2))
        r2 = data.draw(st.integers(r1 + 1, n - 1))
        rows[r1], rows[r2] = rows[r2], rows[r1]
        return text().encode(), {"error_line": h + r1 + 2, "swap": (r1, r2)}
    if kind in ("drop-token", "extra-token"):
        r = data.draw(st.integers(0, n - 1))
        if kind == "drop-token":
            del rows[r][data.draw(st.integers(0, len(rows[r]) - 1))]
        else:
            rows[r].insert(data.draw(st.integers(0, len(rows[r]))), "0.5")
        return text().encode(), {"error_line": h + r + 1, "row": r, "ragged": True}
    if kind == "delimiter":
        other = data.draw(st.sampled_from([";", "|"] + ([" "] if sep == "," else [","])))
        return text(lines_sep=other).encode(), {"error_line": h + 1, "row": 0, "ragged": True}
    if kind == "empty":
        return b"", {"file_error": True}
    if kind == "garbage":
        return data.draw(st.binary(min_size=1, max_size=200)), {"any": True}
    raise AssertionError(kind)


def _run(read, path: Path, raw: bytes, expect: dict, check_same, check_prefix, lenient=()):
    """Call ``read()``; check the outcome against ``expect``.  ``lenient``: expectation keys for which
    this reader may also accept the file (documented reader rules), checked by ``check_same``."""
    try:
        result = read()
    except GeviError as err:
        assert not expect.get("same"), f"a valid file was refused: {err.one_line()}"
        check_error(err, path, expect.get("error_line"), count_lines(raw))
        if "error_line_in" in expect:
            assert err.where in [f"{path}:{line}" for line in expect["error_line_in"]], err.one_line()
        if expect.get("file_error"):
            assert err.where == str(path)
        return None
    assert not expect.get("file_error"), "an empty file was accepted"
    refused = "error_line" in expect or "refused" in expect
    if refused and not any(k in expect for k in lenient):
        raise AssertionError(f"accepted a file that must be refused at line {expect['error_line']}: {expect}")
    if expect.get("same"):
        check_same(result)
    if "prefix" in expect:
        check_prefix(result, expect["prefix"])
    return result


# ------------------------------------------------------------------------------- EuRoC cam data.csv
@FUZZ
@given(t=stamps_ns(), kind=st.sampled_from(LINE_MUTATIONS), data=st.data())
def test_euroc_image_list(t, kind, data):
    names = [f"{s}.png" for s in t.tolist()]
    present = data.draw(st.lists(st.booleans(), min_size=len(t), max_size=len(t)))
    rows = [[str(s), name] for s, name in zip(t.tolist(), names)]
    raw, expect = _mutate_lines(data, ["#timestamp [ns],filename"], rows, ",", kind, [0])
    with tempfile.TemporaryDirectory() as tmp:
        cam = Path(tmp) / "cam0"
        (cam / "data").mkdir(parents=True)
        for name, keep in zip(names, present):
            if keep:
                (cam / "data" / name).write_bytes(b"")
        (cam / "data.csv").write_bytes(raw)
        want = t[np.array(present, dtype=bool)]

        def same(result):
            stamps, paths, missing = result
            np.testing.assert_array_equal(stamps, want)
            assert [Path(p).name for p in paths] == [f"{s}.png" for s in want.tolist()]
            assert missing == len(t) - len(want)

        def prefix(result, m):
            stamps, _, _ = result
            full = t[:m][np.array(present[:m], dtype=bool)]
            np.testing.assert_array_equal(stamps[:len(full)], full)

        _run(lambda: read_image_list(cam), cam / "data.csv", raw, expect, same, prefix)


# ------------------------------------------------------------------------------- EuRoC imu0/data.csv
@FUZZ
@given(t=stamps_ns(min_len=1, max_len=150), seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(LINE_MUTATIONS),
       data=st.data())
def test_euroc_imu_csv(t, seed, kind, data):
    rng = np.random.default_rng(seed)
    values = rng.normal(size=(len(t), 6)) * np.array([0.3, 0.3, 0.3, 3, 3, 3]) + np.array([0, 0, 0, 0, 0, 9.81])
    rows = [[str(s)] + [repr(float(v)) for v in row] for s, row in zip(t.tolist(), values)]
    header = [("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
               "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")]
    raw, expect = _mutate_lines(data, header, rows, ",", kind, list(range(7)))
    lenient = ()
    if kind == "extra-token" and expect["row"] == 0 and len(t) == 1:
        lenient = ("ragged",)  # a one-row file with 8 columns: later columns are documented as ignored
    with tempfile.TemporaryDirectory() as tmp:
        imu = Path(tmp) / "imu0"
        imu.mkdir()
        (imu / "data.csv").write_bytes(raw)

        def same(result):
            np.testing.assert_array_equal(result.t_ns, t)
            np.testing.assert_array_equal(np.column_stack([result.gyro, result.acc]), values)

        def prefix(result, m):
            np.testing.assert_array_equal(result.t_ns[:m], t[:m])
            np.testing.assert_array_equal(result.gyro[:m], values[:m, :3])

        if kind == "extra-token" and expect["row"] == 0:
            # the first row sets the width: the second row is then the odd one (or the first row's
            # stamp, when the extra value went before it); a one-row file with 8 columns is valid
            del expect["error_line"]
            expect["refused"] = True
            lenient = ("refused",) if len(t) == 1 else ()
            if len(t) > 1:
                expect["error_line_in"] = (2, 3)
        _run(lambda: read_imu(imu), imu / "data.csv", raw, expect, same, prefix, lenient)


# ------------------------------------------------------------------------------- KITTI times.txt
@FUZZ
@given(t=stamps_ns(), sci=st.booleans(), kind=st.sampled_from(LINE_MUTATIONS), data=st.data())
def test_kitti_times(t, sci, kind, data):
    if sci:  # KITTI writes "1.036000e-01": exact only to the printed digits; compare with what is printed
        tokens = [f"{s * 1e-9:.6e}" for s in t.tolist()]
        want = np.rint(np.array([float(x) for x in tokens]) * 1e9).astype(np.int64)
        if (np.diff(want) <= 0).any():
            tokens, want = ns_to_seconds_strings(t), t
    else:
        tokens, want = ns_to_seconds_strings(t), t
    if kind in ("drop-token", "delimiter"):
        kind = "extra-token"  # one value per line: dropping it leaves a blank line (skipped by design)
    raw, expect = _mutate_lines(data, [], [[x] for x in tokens], " ", kind, [0])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "times.txt"
        path.write_bytes(raw)

        def same(result):
            np.testing.assert_array_equal(result, want)

        def prefix(result, m):
            np.testing.assert_array_equal(result[:m], want[:m])

        _run(lambda: read_times(path), path, raw, expect, same, prefix)


# ------------------------------------------------------------------------------- KITTI calib.txt
@FUZZ
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(LINE_MUTATIONS), data=st.data())
def test_kitti_calib(seed, kind, data):
    rng = np.random.default_rng(seed)
    f, cx, cy = rng.uniform(300, 1500), rng.uniform(300, 700), rng.uniform(100, 400)
    P = {}
    for i, tx in enumerate((0.0, -f * rng.uniform(0.05, 0.6), f * 0.06, -f * 0.48)):
        P[f"P{i}"] = np.array([[f, 0, cx, tx], [0, f, cy, 0], [0, 0, 1, 0]])
    rows = [[f"P{i}:"] + [repr(float(v)) for v in P[f"P{i}"].ravel()] for i in range(4)]
    if kind in ("duplicate", "swap", "delimiter"):
        # a duplicated P row is refused; swapped rows are the same rows (keys, not order); a ';' file has no P rows
        kind = {"duplicate": "duplicate", "swap": "none", "delimiter": "extra-token"}[kind]
    raw, expect = _mutate_lines(data, [], rows, " ", kind, list(range(1, 13)))
    if kind == "empty":
        expect = {"empty_calib": True}
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "calib.txt"
        path.write_bytes(raw)

        def same(result):
            assert set(result) == set(P)
            for key, want in P.items():
                np.testing.assert_array_equal(result[key], want)

        def prefix(result, m):
            for i in range(m):
                np.testing.assert_array_equal(result[f"P{i}"], P[f"P{i}"])

        result = _run(lambda: read_calib(path), path, raw, expect, same, prefix)
        if kind == "empty":
            assert result == {}  # no P rows: the sequence reader then says which it needs


# ------------------------------------------------------------------------------- OV2SLAM track export
def _export_files(rng, n_frames: int):
    tracks, stereo = [], []
    kf = sorted({0} | set(rng.choice(np.arange(n_frames), size=min(3, n_frames), replace=False).tolist()))
    for k in kf:
        m = int(rng.integers(1, 6))
        ids = rng.choice(1000, size=m, replace=False)
        uv = rng.uniform([0, 0], [1226, 370], size=(m, 2))
        stereo += [[str(k)], [repr(float(v)) for v in uv[:, 0]], [repr(float(v)) for v in uv[:, 1]],
                   [repr(float(v)) for v in uv[:, 0] - 10], [repr(float(v)) for v in uv[:, 1]], [str(i) for i in ids]]
    for _ in range(1, n_frames):
        m = int(rng.integers(1, 6))
        ids = rng.choice(1000, size=m, replace=False)
        block = [rng.uniform(0, 1226, m), rng.uniform(0, 370, m), rng.normal(size=m), rng.normal(size=m),
                 rng.normal(size=m), rng.integers(0, 4, m).astype(float)]
        tracks += [[repr(float(v)) for v in line] for line in block]
        tracks += [[str(i) for i in ids], [str(int(v)) for v in rng.integers(0, 2, m)]]
    return tracks, stereo


CALIB = "".join(f"P{i}: " + " ".join(repr(v) for v in (707.0912, 0.0, 601.8873, tx, 0.0, 707.0912, 183.1104, 0.0,
                                                      0.0, 0.0, 1.0, 0.0)) + "\n"
                for i, tx in enumerate((0.0, -379.8145, 46.88015, -337.2825)))


@FUZZ
@given(seed=st.integers(0, 2**32 - 1), n_frames=st.integers(2, 6), target=st.sampled_from(["tracks", "stereo"]),
       kind=st.sampled_from(("none", "bom", "crlf", "truncate", "nonfinite", "text-token", "duplicate", "drop-token",
                             "extra-token", "empty", "garbage")),
       data=st.data())
def test_track_export(seed, n_frames, target, kind, data):
    rng = np.random.default_rng(seed)
    tracks, stereo = _export_files(rng, n_frames)
    rows = tracks if target == "tracks" else stereo
    # numbers the reader checks on every line: tracks x, y and outlier flag lines and the id line; stereo all
    checked = (0, 1, 6, 7) if target == "tracks" else (0, 1, 2, 3, 4, 5)
    per_block = 8 if target == "tracks" else 6
    line_kind = kind
    if kind in ("nonfinite", "text-token"):
        line_kind = "none"
    raw, expect = _mutate_lines(data, [], rows, " ", line_kind, [0])
    if kind in ("nonfinite", "text-token"):
        candidates = [i for i in range(len(rows)) if i % per_block in checked and rows[i]]
        r = data.draw(st.sampled_from(candidates))
        c = data.draw(st.integers(0, len(rows[r]) - 1))
        rows[r][c] = data.draw(st.sampled_from(NONFINITE)) if kind == "nonfinite" else "x1"
        raw = ("\n".join(" ".join(x) for x in rows) + "\n").encode()
        expect = {"error_line": r + 1}
    if kind in ("duplicate", "drop-token", "extra-token"):
        expect.pop("error_line")  # the line at fault may be another of its block (or the line count): any line
        expect["refused"] = True
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "ov2slam_data_kitti_04_gray"
        folder.mkdir()
        calib = Path(tmp) / "calib.txt"
        calib.write_text(CALIB)
        files = {"tracks": ("\n".join(" ".join(x) for x in tracks) + "\n").encode(),
                 "stereo": ("\n".join(" ".join(x) for x in stereo) + "\n").encode()}
        files[target] = raw
        (folder / "ov2slam_pnp_data_seq04.txt").write_bytes(files["tracks"])
        (folder / "ov2slam_stereo_matches.txt").write_bytes(files["stereo"])
        path = folder / ("ov2slam_pnp_data_seq04.txt" if target == "tracks" else "ov2slam_stereo_matches.txt")

        def same(export):
            assert len(export) == n_frames
            frame = export.frame(n_frames - 1)
            block = tracks[8 * (n_frames - 2):8 * (n_frames - 1)]
            np.testing.assert_array_equal(frame.obs.uv[:, 0], [float(v) for v in block[0]])
            np.testing.assert_array_equal(frame.obs.ids, [int(v) for v in block[6]])

        _run(lambda: TrackExport(folder, calib), path, raw, expect, same, lambda r, m: None)
