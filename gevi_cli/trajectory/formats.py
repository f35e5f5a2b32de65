"""Read and write trajectory files; detect their format from the content.

Formats (``fmt`` names):

* ``tum``: ``t tx ty tz qx qy qz qw``, whitespace separated, stamps in seconds.  Also read: ORB-SLAM3
  files that put nanosecond stamps in the TUM columns, Basalt/rpg files with ``#`` headers.
* ``euroc``: ``t_ns,px,py,pz,qw,qx,qy,qz[,...]`` comma separated, w-first quaternions.  Also read:
  VINS-Fusion ``vio.csv`` (velocities after the pose, trailing comma) and ASL ground truth (17 cols).
* ``kitti``: 12 numbers per row, the 3x4 ``[R|t]`` row-major; no stamps (row i is frame i).
* ``kitti-idx``: the same with a leading frame index (13 columns), as kitti-odom-eval writes.

Readers validate every row (see :mod:`gevi_cli.trajectory.validate`) and raise
:class:`gevi_cli.errors.DataError` naming the file and the line.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from gevi_cli.errors import DataError, GeviError
from gevi_cli.trajectory.stamps import decimal_strings_to_ns, ns_to_seconds_strings
from gevi_cli.trajectory.trajectory import KITTI_NOMINAL_PERIOD_NS, Trajectory
from gevi_cli.trajectory.validate import duplicate_stamp_mask, validate_rows

WRITE_FORMATS = ("tum", "euroc", "kitti", "kitti-idx")

# A stamp written as an integer above this is nanoseconds (1e17 ns = 3.2 years; 1e17 s is absurd).
_NS_THRESHOLD = 1e17


def read_text(path: Path) -> str:
    """The text of ``path`` (UTF-8, a BOM dropped); every failure a :class:`GeviError` naming the file."""
    try:
        return path.read_text(encoding="utf-8-sig", errors="strict")
    except FileNotFoundError:
        raise GeviError(path, "no such file") from None
    except IsADirectoryError:
        raise GeviError(path, "is a folder, expected a text file") from None
    except UnicodeDecodeError:
        raise DataError(path, "is not a text file (binary content, not UTF-8)") from None
    except OSError as err:
        raise GeviError(path, f"cannot be read ({err.strerror or type(err).__name__})") from None


def _load_table(path: Path):
    """Return (header comment lines, data tokens (n, k) as str, file line numbers (n,), delimiter).

    Lines are split at commas when the first data line has one, else at whitespace (spaces, tabs).
    Blank lines and ``#``/``%`` comments are skipped; a line before the first data row none of whose
    tokens is a number (``timestamp,x,y,...``) is a header when it is the first such line.  A UTF-8 BOM and CRLF ends are accepted.
    """
    text = read_text(path)
    if "\x00" in text:
        raise DataError(path, "is not a text trajectory file (holds NUL bytes)")
    headers, rows, lines = [], [], []
    delimiter = None
    first = True
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith(("#", "%")):
            if not rows:
                headers.append(line.lstrip("#% ").strip())
            continue
        maybe_header, first = first, False
        if not rows and delimiter is None:
            delimiter = "," if "," in line else None
        if delimiter is None and ";" in line:
            raise DataError(f"{path}:{lineno}", "is ';'-separated; trajectory files are whitespace (TUM, KITTI) "
                                                "or comma (EuRoC csv) separated")
        parts = line.split(delimiter) if delimiter else line.split()
        parts = [p.strip() for p in parts]
        while parts and parts[-1] == "":  # VINS-Fusion's trailing comma
            parts.pop()
        if maybe_header and _looks_like_header(parts):
            headers.append(line)
            continue
        rows.append(parts)
        lines.append(lineno)
    if not rows:
        raise DataError(path, "contains no pose rows" + (" (only a header)" if headers else " (the file is empty)"))
    width = len(rows[0])
    for parts, lineno in zip(rows, lines):
        if len(parts) != width:
            raise DataError(f"{path}:{lineno}", f"has {len(parts)} columns, expected {width} like the first row")
    return headers, np.array(rows, dtype=str), np.array(lines), delimiter


def _looks_like_header(parts) -> bool:
    """A header names columns: none of its tokens is, or starts like, a number (``1.5;2;3`` is a
    data row with the wrong delimiter, not a header)."""
    return not any(_NUMBER_START.match(part) or _is_number(part) for part in parts)


_NUMBER_START = re.compile(r"^[+-]?\.?\d")


def _is_number(token: str) -> bool:
    try:
        float(token)
        return True
    except ValueError:
        return False


def _to_float(tokens: np.ndarray, path: Path, lines: np.ndarray, columns=None) -> np.ndarray:
    """float64 of a (n, k) token block; ``columns`` (k,) are the 0-based file columns (for messages)."""
    columns = list(range(tokens.shape[1])) if columns is None else list(columns)
    try:
        return tokens.astype(np.float64)
    except ValueError:
        for r in range(tokens.shape[0]):
            for c in range(tokens.shape[1]):
                try:
                    float(tokens[r, c])
                except ValueError:
                    raise DataError(f"{path}:{lines[r]}",
                                    f"column {columns[c] + 1} is not a number: {tokens[r, c][:30]!r}") from None
        raise


def detect_format(path: str | Path) -> str:
    """Name the format of a trajectory file from its content (see module docstring)."""
    return _parse(Path(path))[0]


def _header_names(header: str) -> list[str]:
    """Column names of a header line: lower case, units (``[m]``, ``(s)``) and ``#`` removed."""
    header = re.sub(r"\[[^\]]*\]|\([^)]*\)", " ", header.lower()).replace("#", " ")
    return [t for t in re.split(r"[\s,;]+", header) if t]


_ROLE_NAMES = {
    "t": ("timestamp", "time", "t", "stamp", "timestamp_ns", "timestamp_s", "time_ns", "time_s", "t_ns", "t_s"),
    "px": ("tx", "px", "p_x", "pos_x", "position_x", "p_rs_r_x", "t_x"),
    "py": ("ty", "py", "p_y", "pos_y", "position_y", "p_rs_r_y", "t_y"),
    "pz": ("tz", "pz", "p_z", "pos_z", "position_z", "p_rs_r_z", "t_z"),
    "qw": ("qw", "q_w", "q_rs_w", "orientation_w", "rw"),
    "qx": ("qx", "q_x", "q_rs_x", "orientation_x", "rx"),
    "qy": ("qy", "q_y", "q_rs_y", "orientation_y", "ry"),
    "qz": ("qz", "q_z", "q_rs_z", "orientation_z", "rz"),
}
_ROLES = ("t", "px", "py", "pz", "qw", "qx", "qy", "qz")


def _header_columns(headers: list[str], k: int) -> dict[str, int] | None:
    """Columns of t, p and q named by the header closest to the data, when it names all eight exactly
    once and has one name per column (``k``); bare ``x y z`` are the position, a second ``x y z`` and
    ``w`` the quaternion.  None when no header does: the format's default column order applies."""
    for header in reversed(headers):
        names = _header_names(header)
        if len(names) != k:
            continue
        found: dict[str, list[int]] = {role: [] for role in _ROLES}
        for i, name in enumerate(names):
            for role, aliases in _ROLE_NAMES.items():
                if name in aliases:
                    found[role].append(i)
        for axis in "xyz":
            bare = [i for i, name in enumerate(names) if name == axis]
            if len(bare) == 2 and not found["p" + axis] and not found["q" + axis]:
                found["p" + axis], found["q" + axis] = [bare[0]], [bare[1]]
            elif len(bare) == 1 and not found["p" + axis]:
                found["p" + axis] = bare
        if not found["qw"]:
            found["qw"] = [i for i, name in enumerate(names) if name == "w"]
        if all(len(v) == 1 for v in found.values()):
            columns = {role: v[0] for role, v in found.items()}
            if len(set(columns.values())) == len(_ROLES):
                return columns
    return None


def _quat_order(headers: list[str], default: str) -> str:
    """'wxyz' or 'xyzw' from header column names, else the format's default."""
    names = " ".join(headers).lower()
    names = re.sub(r"[\[\]()]", " ", names)
    tokens = re.split(r"[\s,]+", names)
    qw = [i for i, t in enumerate(tokens) if t in ("qw", "q_w") or t.startswith("q_rs_w") or t == "w"]
    qx = [i for i, t in enumerate(tokens) if t in ("qx", "q_x") or t.startswith("q_rs_x") or t == "x"]
    if qw and qx:
        return "wxyz" if qw[0] < qx[-1] else "xyzw"
    return default


def _default_columns(fmt: str, headers: list[str]) -> dict[str, int]:
    """TUM ``t p qx qy qz qw`` / EuRoC ``t p qw qx qy qz``, or the other quaternion order if the header says so."""
    order = _quat_order(headers, "wxyz" if fmt == "euroc" else "xyzw")
    q = {"qw": 4, "qx": 5, "qy": 6, "qz": 7} if order == "wxyz" else {"qx": 4, "qy": 5, "qz": 6, "qw": 7}
    return {"t": 0, "px": 1, "py": 2, "pz": 3, **q}


def _is_kitti_idx(tok: np.ndarray) -> bool:
    """13 columns, an integer first column and (for a comma file) rotation blocks in the KITTI places."""
    if not np.all(np.char.isdigit(tok[:, 0])):
        return False
    try:
        R = tok[:, 1:].astype(np.float64).reshape(-1, 3, 4)[:, :, :3]
    except ValueError:
        return False
    with np.errstate(all="ignore"):
        err = np.abs(np.einsum("nij,nkj->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    return bool(np.all(err < 1e-2))


def _parse(path: Path):
    headers, tok, lines, delimiter = _load_table(path)
    k = tok.shape[1]
    if k == 12:
        return "kitti", headers, tok, lines, delimiter
    # 13 columns, whitespace: kitti-odom-eval's layout when the first column is mostly frame indices
    # (a bad index or row is then reported as such, at its line); a comma file is KITTI with index
    # only when its numbers are rotation blocks (else a 13-column csv).
    if k == 13 and ((delimiter is None and np.mean(np.char.isdigit(tok[:, 0])) > 0.5)
                    or (delimiter == "," and _is_kitti_idx(tok))):
        return "kitti-idx", headers, tok, lines, delimiter
    if k >= 8:
        if delimiter == ",":
            return "euroc", headers, tok, lines, delimiter
        return "tum", headers, tok, lines, delimiter
    raise DataError(path, f"has {k} columns per row; expected TUM (8), EuRoC csv (>= 8, comma), KITTI (12) or KITTI with index (13)")


def read_trajectory(path: str | Path, name: str | None = None, frame: str = "unknown",
                    allow_jumps: bool = False) -> Trajectory:
    """Read any supported trajectory file, detecting the format from its content.

    ``allow_jumps``: a position jump (see :func:`~gevi_cli.trajectory.validate.position_problem`) is
    read as written, with a warning also kept in ``meta["allowed_jumps"]``, instead of refused.

    KITTI files carry no stamps: ``t_ns`` is then the frame index times 0.1 s and ``indexed`` is set.
    TUM and EuRoC columns are taken from the header when it names every column (``# timestamp tx ty
    tz qx qy qz qw``, ASL's ``p_RS_R_x [m]``, ...), else the format's order.
    """
    path = Path(path)
    fmt, headers, tok, lines, _ = _parse(path)
    name = name if name is not None else path.stem
    warnings: list[str] = []
    allowed: list[str] = []
    checks = {"warnings": warnings, "allow_jumps": allow_jumps, "allowed": allowed}
    if fmt in ("kitti", "kitti-idx"):
        if fmt == "kitti-idx":
            index = _kitti_index(tok[:, 0], path, lines)
            values = _to_float(tok[:, 1:], path, lines, range(1, 13))
        else:
            index = np.arange(len(tok), dtype=np.int64)
            values = _to_float(tok, path, lines)
        M = values.reshape(-1, 3, 4)
        R, t = M[:, :, :3], M[:, :, 3]
        t_ns = index * KITTI_NOMINAL_PERIOD_NS
        validate_rows(path, lines, t_ns, t, rotations=R, **checks)
        traj = Trajectory.from_rotations(t_ns, _nearest_rotations(R), t, frame=frame, indexed=True, name=name)
    else:
        cols = _header_columns(headers, tok.shape[1]) or _default_columns(fmt, headers)
        t_ns = _stamps_to_ns(tok[:, cols["t"]], path, lines, cols["t"], integer_ns=_integer_stamps_are_ns(fmt, headers))
        keep = duplicate_stamp_mask(path, lines, t_ns, warnings)
        tok, lines, t_ns = tok[keep], lines[keep], t_ns[keep]
        order = [cols[r] for r in ("px", "py", "pz", "qw", "qx", "qy", "qz")]
        values = _to_float(tok[:, order], path, lines, order)
        pos, q_wxyz = values[:, 0:3], values[:, 3:7]
        q_wxyz = validate_rows(path, lines, t_ns, pos, quat_wxyz=q_wxyz, **checks)
        traj = Trajectory(t_ns, pos, q_wxyz, frame=frame, name=name)
    traj.meta.update({"path": str(path), "format": fmt, "warnings": warnings, "allowed_jumps": allowed})
    return traj


def _kitti_index(tokens: np.ndarray, path: Path, lines: np.ndarray) -> np.ndarray:
    """The frame indices of a kitti-idx file: whole numbers, strictly increasing."""
    for r, token in enumerate(tokens.tolist()):
        if not token.isdigit() or len(token) > 15:
            raise DataError(f"{path}:{lines[r]}", f"column 1 must be a frame index (a whole number), not {token[:30]!r}")
    index = tokens.astype(np.int64)
    bad = np.diff(index) <= 0
    if bad.any():
        r = int(np.argmax(bad)) + 1
        raise DataError(f"{path}:{lines[r]}", f"frame index {index[r]} does not follow {index[r - 1]} "
                                              "(indices must increase; repeated or unsorted row?)")
    return index


#: |stamp| limit: int64 nanoseconds reach 9.22e18 ns (year 2262).
_MAX_ABS_NS = 9.0e18


def _integer_stamps_are_ns(fmt: str, headers: list[str]) -> bool:
    """EuRoC csv stamps are ns by definition (``#timestamp [ns]``); TUM's are seconds unless the header says ns."""
    text = " ".join(headers).lower()
    return fmt == "euroc" or "[ns]" in text or bool(re.search(r"\b(timestamp|time|t)_ns\b", text))


def _stamps_to_ns(tokens: np.ndarray, path: Path, lines: np.ndarray, column: int = 0,
                  integer_ns: bool = False) -> np.ndarray:
    """Stamps in ns.  The unit: ns when the values are beyond 1e17 (ORB-SLAM3 writes ns in TUM files),
    or when every stamp is a whole number and ``integer_ns`` (EuRoC, a header saying ns); else seconds."""
    as_float = _to_float(tokens[:, None], path, lines, [column])[:, 0]
    bad = ~np.isfinite(as_float)
    if bad.any():
        r = int(np.argmax(bad))
        raise DataError(f"{path}:{lines[r]}", f"timestamp is not finite: {tokens[r][:30]!r}")
    whole = bool(np.all(np.char.isdigit(np.char.lstrip(tokens, "+-"))))
    is_ns = np.median(np.abs(as_float)) > _NS_THRESHOLD or (integer_ns and whole)
    scale = 1 if is_ns else 1_000_000_000
    big = np.abs(as_float) * scale > _MAX_ABS_NS
    if big.any():
        r = int(np.argmax(big))
        raise DataError(f"{path}:{lines[r]}", f"timestamp {tokens[r][:30]} {'ns' if is_ns else 's'} is out of range "
                                              "(nanoseconds must fit in int64, before year 2262)")
    try:
        return decimal_strings_to_ns(tokens, scale)
    except (ValueError, OverflowError):  # a token float() takes but the exact parser does not
        for r, token in enumerate(tokens.tolist()):
            try:
                decimal_strings_to_ns([token], scale)
            except (ValueError, OverflowError):
                raise DataError(f"{path}:{lines[r]}", f"timestamp {token[:30]!r} is not a decimal number") from None
        raise


def _nearest_rotations(R: np.ndarray) -> np.ndarray:
    """Project 3x3 matrices onto SO(3) (KITTI files are written with ~1e-6 precision)."""
    U, _, Vt = np.linalg.svd(R)
    D = np.ones((len(R), 3))
    D[:, 2] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[:, None, :]) @ Vt


def write_trajectory(traj: Trajectory, path: str | Path, fmt: str) -> Path:
    """Write ``traj`` as ``fmt`` (one of :data:`WRITE_FORMATS`); stamps are written exactly."""
    path = Path(path)
    check_write_format(fmt)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = format_header(fmt)
    path.write_text("\n".join(([header] if header else []) + format_rows(traj, fmt)) + "\n")
    return path


def check_write_format(fmt: str) -> None:
    if fmt not in WRITE_FORMATS:
        raise GeviError("--to", f"unknown trajectory format {fmt!r}; choose one of {', '.join(WRITE_FORMATS)}")


def format_header(fmt: str) -> str | None:
    """The comment line a file of ``fmt`` starts with (None for the KITTI formats)."""
    if fmt == "tum":
        return "# timestamp tx ty tz qx qy qz qw"
    if fmt == "euroc":
        return "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []"
    return None


def format_rows(traj: Trajectory, fmt: str) -> list[str]:
    """The text rows of ``traj`` in ``fmt`` (no header): what :func:`write_trajectory` writes, and what
    a run streams to disk pose by pose."""
    p, q = traj.positions, traj.quat_wxyz
    if fmt == "tum":
        stamps = ns_to_seconds_strings(traj.t_ns)
        body = np.column_stack([p, q[:, 1:], q[:, :1]])
        return [s + " " + " ".join(map(_num, row)) for s, row in zip(stamps, body.tolist())]
    if fmt == "euroc":
        body = np.column_stack([p, q])
        return [f"{t}," + ",".join(map(_num, row)) for t, row in zip(traj.t_ns.tolist(), body.tolist())]
    M = traj.matrices[:, :3, :].reshape(-1, 12)
    if fmt == "kitti":
        return [" ".join(map(_num, row)) for row in M.tolist()]
    index = _frame_indices(traj)
    return [f"{i} " + " ".join(map(_num, row)) for i, row in zip(index.tolist(), M.tolist())]


def _num(value: float) -> str:
    """The shortest text that reads back as exactly ``value`` (Python's repr): a UTM or ECEF position
    (4.5e6 m, 6.4e6 m) keeps all its float64 digits, which a fixed ``%.9e`` (1 mm at 6.4e6 m) would not."""
    return repr(float(value)) if value != 0 else "0.0"


def _frame_indices(traj: Trajectory) -> np.ndarray:
    if traj.indexed:
        return traj.t_ns // KITTI_NOMINAL_PERIOD_NS
    return np.arange(len(traj))
