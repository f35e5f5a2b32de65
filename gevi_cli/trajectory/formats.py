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


def _load_table(path: Path):
    """Return (header comment lines, data tokens (n, k) as str, file line numbers (n,), delimiter)."""
    try:
        text = path.read_text(encoding="utf-8", errors="strict")
    except FileNotFoundError:
        raise GeviError(path, "no such file") from None
    except IsADirectoryError:
        raise GeviError(path, "is a folder, expected a trajectory file") from None
    except UnicodeDecodeError:
        raise DataError(path, "is not a text trajectory file (binary content)") from None
    headers, rows, lines = [], [], []
    delimiter = None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#") or line.startswith("%"):
            if not rows:
                headers.append(line.lstrip("#% ").strip())
            continue
        if delimiter is None:
            delimiter = "," if "," in line else None
        parts = line.split(delimiter) if delimiter else line.split()
        parts = [p.strip() for p in parts]
        while parts and parts[-1] == "":  # VINS-Fusion's trailing comma
            parts.pop()
        if not rows and _looks_like_header(parts):
            headers.append(line)
            continue
        rows.append(parts)
        lines.append(lineno)
    if not rows:
        raise DataError(path, "contains no pose rows")
    width = len(rows[0])
    for parts, lineno in zip(rows, lines):
        if len(parts) != width:
            raise DataError(f"{path}:{lineno}", f"has {len(parts)} columns, expected {width} like the first row")
    return headers, np.array(rows, dtype=str), np.array(lines), delimiter


def _looks_like_header(parts) -> bool:
    try:
        float(parts[0])
        return False
    except ValueError:
        return True


def _to_float(tokens: np.ndarray, path: Path, lines: np.ndarray) -> np.ndarray:
    try:
        return tokens.astype(np.float64)
    except ValueError:
        for r in range(tokens.shape[0]):
            for c in range(tokens.shape[1]):
                try:
                    float(tokens[r, c])
                except ValueError:
                    raise DataError(f"{path}:{lines[r]}", f"column {c + 1} is not a number: {tokens[r, c]!r}") from None
        raise


def detect_format(path: str | Path) -> str:
    """Name the format of a trajectory file from its content (see module docstring)."""
    return _parse(Path(path))[0]


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


def _parse(path: Path):
    headers, tok, lines, delimiter = _load_table(path)
    k = tok.shape[1]
    if k == 12:
        return "kitti", headers, tok, lines, delimiter
    if k == 13 and delimiter is None:
        first = tok[:, 0]
        if np.all(np.char.isdigit(first)):
            return "kitti-idx", headers, tok, lines, delimiter
    if k >= 8:
        if delimiter == ",":
            return "euroc", headers, tok, lines, delimiter
        return "tum", headers, tok, lines, delimiter
    raise DataError(path, f"has {k} columns per row; expected TUM (8), EuRoC csv (>= 8, comma), KITTI (12) or KITTI with index (13)")


def read_trajectory(path: str | Path, name: str | None = None, frame: str = "unknown") -> Trajectory:
    """Read any supported trajectory file, detecting the format from its content.

    KITTI files carry no stamps: ``t_ns`` is then the frame index times 0.1 s and ``indexed`` is set.
    """
    path = Path(path)
    fmt, headers, tok, lines, _ = _parse(path)
    name = name if name is not None else path.stem
    warnings: list[str] = []
    if fmt in ("kitti", "kitti-idx"):
        if fmt == "kitti-idx":
            index = tok[:, 0].astype(np.int64)
            values = _to_float(tok[:, 1:], path, lines)
        else:
            index = np.arange(len(tok), dtype=np.int64)
            values = _to_float(tok, path, lines)
        M = values.reshape(-1, 3, 4)
        R, t = M[:, :, :3], M[:, :, 3]
        t_ns = index * KITTI_NOMINAL_PERIOD_NS
        validate_rows(path, lines, t_ns, t, rotations=R, warnings=warnings)
        traj = Trajectory.from_rotations(t_ns, _nearest_rotations(R), t, frame=frame, indexed=True, name=name)
    else:
        t_ns = _stamps_to_ns(tok[:, 0], path, lines)
        keep = duplicate_stamp_mask(path, lines, t_ns, warnings)
        tok, lines, t_ns = tok[keep], lines[keep], t_ns[keep]
        values = _to_float(tok[:, 1:8], path, lines)
        if fmt == "euroc":
            order = _quat_order(headers, "wxyz")
        else:
            order = _quat_order(headers, "xyzw")
        q = values[:, 3:7]
        q_wxyz = q if order == "wxyz" else np.roll(q, 1, axis=1)
        pos = values[:, 0:3]
        q_wxyz = validate_rows(path, lines, t_ns, pos, quat_wxyz=q_wxyz, warnings=warnings)
        traj = Trajectory(t_ns, pos, q_wxyz, frame=frame, name=name)
    traj.meta.update({"path": str(path), "format": fmt, "warnings": warnings})
    return traj


def _stamps_to_ns(tokens: np.ndarray, path: Path, lines: np.ndarray) -> np.ndarray:
    try:
        as_float = tokens.astype(np.float64)
    except ValueError:
        _to_float(tokens[:, None], path, lines)
        raise
    bad = ~np.isfinite(as_float)
    if bad.any():
        r = int(np.argmax(bad))
        raise DataError(f"{path}:{lines[r]}", f"timestamp is not finite: {tokens[r]!r}")
    is_ns = np.nanmedian(np.abs(as_float)) > _NS_THRESHOLD
    return decimal_strings_to_ns(tokens, 1 if is_ns else 1_000_000_000)


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
        return [s + " " + " ".join(f"{v:.9f}" for v in row) for s, row in zip(stamps, body.tolist())]
    if fmt == "euroc":
        body = np.column_stack([p, q])
        return [f"{t}," + ",".join(f"{v:.9f}" for v in row) for t, row in zip(traj.t_ns.tolist(), body.tolist())]
    M = traj.matrices[:, :3, :].reshape(-1, 12)
    if fmt == "kitti":
        return [" ".join(f"{v:.9e}" for v in row) for row in M.tolist()]
    index = _frame_indices(traj)
    return [f"{i} " + " ".join(f"{v:.9e}" for v in row) for i, row in zip(index.tolist(), M.tolist())]


def _frame_indices(traj: Trajectory) -> np.ndarray:
    if traj.indexed:
        return traj.t_ns // KITTI_NOMINAL_PERIOD_NS
    return np.arange(len(traj))
