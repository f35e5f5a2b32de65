"""Row-level validation of trajectories read from files.

Everything here raises :class:`gevi_cli.errors.DataError` with ``file:line`` so a user can open the
file at the bad row.  Quaternions a little off unit norm (files written with 4-6 decimals) are
renormalized with a warning; stamps must strictly increase; positions must be finite and plausible
(:func:`position_problem`: within :data:`MAX_ABS_POSITION_M` of the origin, and without a jump that
:func:`persistent_jump_row` or :func:`absurd_row` finds relative to the trajectory's own steps).
Row numbers in messages are the file's line numbers, 1-based, as an editor shows them.
"""
from __future__ import annotations

import numpy as np

from gevi_cli.errors import DataError

#: A step this many times the typical (median) step ...
MAX_STEP_RATIO = 1.0e4
#: ... and this many times the length of all the other (ordinary) steps together is a corrupt jump.
MAX_EXTENT_RATIO = 100.0
#: Steps under this are never corrupt jumps (a few metres is always a possible move).
MIN_JUMP_M = 100.0
#: No Earth-fixed frame puts a pose farther from its origin (ECEF |p| ~6.4e6 m, UTM northings < 1e7 m,
#: even a geostationary orbit is at 4.2e7 m): a coordinate beyond this is corrupt in every format.
MAX_ABS_POSITION_M = 1.0e8
#: A step this many times the median of the steps just before it (and over MIN_JUMP_M) is a jump ...
PERSISTENT_STEP_RATIO = 1.0e4
#: ... where "just before" is at most this many steps.
PERSISTENT_WINDOW = 100
QUAT_NORM_TOLERANCE = 1e-3
#: A quaternion whose norm is off by more than this factor is not a rounding problem: a corrupt row.
QUAT_NORM_REFUSE_FACTOR = 10.0


def absurd_row(positions: np.ndarray) -> tuple[int, float, float] | None:
    """The first corrupt row of a trajectory as ``(row, jump m, typical step m)``, or None.

    "Absurd" is relative to the trajectory's own steps and extent, never an absolute coordinate
    bound: real ground truth in UTM (northing ~4.5e6 m) or ECEF (~6.4e6 m) is far from the origin
    but moves in ordinary steps, while a glitch row (a value 1e9 m off, a digit lost in a column)
    is reached by a step that dwarfs everything else the trajectory does.

    Rule: a step is a *jump* when it is longer than all of

    * :data:`MIN_JUMP_M` (100 m),
    * :data:`MAX_STEP_RATIO` (1e4) times the typical step, the lower quartile of the steps (floored at
      1 mm; rates and speeds vary, four orders of magnitude do not happen between consecutive poses;
      a quartile, not the median, because one glitch row makes *two* steps huge, which in a file of
      four rows is two of its three steps; the pool also holds the two-row skips ``|p[i+1] - p[i-1]|``,
      which step over a glitch row: in a file of three rows with the middle one corrupt, both steps
      are huge and only the skip shows the ordinary motion), and
    * :data:`MAX_EXTENT_RATIO` (100) times (1 m + the summed length of all non-jump steps): that sum
      bounds the extent of the rest of the trajectory, so a long drive with a genuine big step
      (a VO reset, a GPS re-fix) is not refused, only a step 100x larger than anything else it covers.

    A jump has two ends; the corrupt one is the row farther from the trajectory's coordinate-wise
    median (the median is not moved by a minority of corrupt rows), so a glitch in the first row
    is reported at the first row, a corrupt tail at its first row.  Trajectories of two poses have
    no "rest" to compare with and are never refused.
    """
    if len(positions) < 3:
        return None
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    skips = np.linalg.norm(positions[2:] - positions[:-2], axis=1)
    typical = float(np.quantile(np.concatenate([steps, skips]), 0.25, method="lower"))
    candidate = (steps > MIN_JUMP_M) & (steps > MAX_STEP_RATIO * max(typical, 1e-3))
    if not candidate.any():
        return None
    rest = float(steps[~candidate].sum())
    jump = candidate & (steps > MAX_EXTENT_RATIO * (1.0 + rest))
    if not jump.any():
        return None
    s = int(np.argmax(jump))  # step s goes from row s to row s + 1
    centre = np.median(positions, axis=0)
    far = np.linalg.norm(positions[[s, s + 1]] - centre, axis=1)
    row = s if far[0] > far[1] else s + 1
    return row, float(steps[s]), typical


def far_row(positions: np.ndarray) -> int | None:
    """The first row farther than :data:`MAX_ABS_POSITION_M` (m) from the origin, or None."""
    far = np.linalg.norm(positions, axis=1) > MAX_ABS_POSITION_M
    return int(np.argmax(far)) if far.any() else None


def persistent_jump_row(positions: np.ndarray) -> tuple[int, float, float] | None:
    """The first row reached by a jump as ``(row, jump m, typical step m)``, or None.

    A step is a jump when it is longer than :data:`MIN_JUMP_M` (100 m) and :data:`PERSISTENT_STEP_RATIO`
    (1e4) times the median of the (up to :data:`PERSISTENT_WINDOW`) steps before it (floored at 1 mm).
    Only the part *before* the step sets its scale, so the rule holds when the rows after it are
    corrupt too, however many (a tail multiplied by 1e9, a frame offset added from some row on):
    :func:`absurd_row`'s comparison with the whole file is blind there.  The reported row is the one
    the jump reaches, the first that differs.  Speeds change smoothly: a car's 10 Hz steps (~1 m)
    would need a 10 km step, a 200 Hz ground truth (~5 mm steps) a 100 m one.
    """
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    candidates = np.flatnonzero(steps > MIN_JUMP_M)
    candidates = candidates[candidates >= 1]  # the first step has nothing before it
    if len(candidates) == 0:
        return None
    before = np.concatenate([np.full(PERSISTENT_WINDOW, np.nan), steps])
    windows = np.lib.stride_tricks.sliding_window_view(before, PERSISTENT_WINDOW)
    for chunk in np.array_split(candidates, -(-len(candidates) // 4096)):  # bounded memory, stop early
        typical = np.maximum(np.nanmedian(windows[chunk], axis=1), 1e-3)
        jump = steps[chunk] > PERSISTENT_STEP_RATIO * typical
        if jump.any():
            k = int(np.argmax(jump))
            return int(chunk[k]) + 1, float(steps[chunk[k]]), float(typical[k])
    return None


def position_problem(positions: np.ndarray) -> tuple[int, str, bool] | None:
    """The first implausible row as ``(row, what is wrong, is a jump)``, or None (positions in m).

    Checked in order: a position beyond :data:`MAX_ABS_POSITION_M` (never allowed), a jump of
    :func:`persistent_jump_row`, a glitch of :func:`absurd_row` on the rows before that jump (a
    glitch row or a bad first row is found there).  ``is a jump``: what ``--allow-jumps`` lets through.
    """
    far = far_row(positions)
    if far is not None:
        dist = float(np.linalg.norm(positions[far]))
        return far, (f"position {_fmt_xyz(positions[far])} m is not plausible: it is {dist:.3g} m from the origin, "
                     "farther than any Earth-fixed frame reaches (UTM, ECEF: < 1e7 m; limit "
                     f"{MAX_ABS_POSITION_M:.3g} m); corrupt row?"), False
    persistent = persistent_jump_row(positions)
    end = persistent[0] if persistent is not None else len(positions)
    glitch = absurd_row(positions[:end])
    if glitch is not None:
        r, jump, typical = glitch
        return r, (f"position {_fmt_xyz(positions[r])} m is not plausible: it is {jump:.6g} m from its neighbour "
                   f"while the typical step is {typical:.3g} m (position jumps; corrupt row?)"), True
    if persistent is not None:
        r, jump, typical = persistent
        return r, (f"position {_fmt_xyz(positions[r])} m is not plausible: it is {jump:.6g} m from the previous row "
                   f"while the steps before it are typically {typical:.3g} m (position jumps: a corrupt row, or "
                   "corrupt rows from here on?)"), True
    return None


def duplicate_stamp_mask(path, lines, t_ns, warnings) -> np.ndarray:
    """Rows to keep: the first of each run of equal stamps.

    Real files have them (evo's V102.txt, TUM fr2/desk ground truth): two poses written for one
    stamp.  Keeping the first and warning is what a user of those files needs; an error would make
    published data unreadable.  Stamps going *back* in time stay an error (see validate_rows).
    """
    keep = np.ones(len(t_ns), dtype=bool)
    keep[1:] = np.diff(t_ns) != 0
    if not keep.all():
        r = int(np.argmin(keep))
        warnings.append(
            f"{path}:{lines[r]}: {int((~keep).sum())} row(s) repeat the previous timestamp "
            f"(first: {t_ns[r]} ns); kept the first pose of each stamp"
        )
    return keep


def validate_rows(path, lines, t_ns, positions, quat_wxyz=None, rotations=None, warnings=None,
                  allow_jumps=False, allowed=None):
    """Check stamps, positions and orientation rows; return the (renormalized) quaternions.

    Stamps must not decrease (equal stamps are removed beforehand by :func:`duplicate_stamp_mask`).
    Positions: see :func:`position_problem`; with ``allow_jumps`` a jump is not an error but a
    warning, also appended to ``allowed`` (a list) when given.

    Args:
        path: file the rows came from (for messages); lines: (n,) 1-based line numbers.
        t_ns: (n,) int64 stamps; positions: (n, 3) metres.
        quat_wxyz: (n, 4) or None; rotations: (n, 3, 3) or None (KITTI).
        warnings: list that receives human-readable warnings.
    """
    warnings = warnings if warnings is not None else []

    def fail(row: int, what: str):
        raise DataError(f"{path}:{lines[row]}", what)

    finite = np.isfinite(positions).all(axis=1)
    if quat_wxyz is not None:
        finite &= np.isfinite(quat_wxyz).all(axis=1)
    if rotations is not None:
        finite &= np.isfinite(rotations).all(axis=(1, 2))
    if not finite.all():
        fail(int(np.argmin(finite)), "contains a non-finite value (nan or inf)")

    dt = np.diff(t_ns)
    if (dt < 0).any():
        r = int(np.argmax(dt < 0)) + 1
        fail(r, f"timestamp {t_ns[r]} ns goes back in time (previous row has {t_ns[r - 1]} ns); rows must be sorted")

    problem = position_problem(positions)
    if problem is not None:
        r, what, is_jump = problem
        if not (is_jump and allow_jumps):
            fail(r, what + ("" if not is_jump else "; if the file really jumps, gevi convert/eval --allow-jumps "
                                                    "read it as written"))
        note = f"{path}:{lines[r]}: {what}; read as written (--allow-jumps)"
        warnings.append(note)
        if allowed is not None:
            allowed.append(note)

    if rotations is not None:
        err = np.abs(np.einsum("nij,nkj->nik", rotations, rotations) - np.eye(3)).max(axis=(1, 2))
        bad = err > 1e-2
        if bad.any():
            fail(int(np.argmax(bad)), f"the 3x3 rotation block is not orthonormal (max |R R^T - I| = {err[bad][0]:.3g})")
        det = np.linalg.det(rotations)
        if (det < 0).any():
            fail(int(np.argmax(det < 0)), "the 3x3 rotation block is a reflection (det < 0)")
        return None

    norms = np.linalg.norm(quat_wxyz, axis=1)
    if (norms < 1e-6).any():
        fail(int(np.argmax(norms < 1e-6)), "quaternion is zero")
    absurd_norm = (norms > QUAT_NORM_REFUSE_FACTOR) | (norms < 1.0 / QUAT_NORM_REFUSE_FACTOR)
    if absurd_norm.any():
        r = int(np.argmax(absurd_norm))
        fail(r, f"quaternion norm {norms[r]:.6g} is not a rounded unit quaternion (wrong columns or corrupt row?)")
    off = np.abs(norms - 1.0) > QUAT_NORM_TOLERANCE
    if off.any():
        r = int(np.argmax(off))
        warnings.append(
            f"{path}:{lines[r]}: {int(off.sum())} quaternion(s) off unit norm (first: |q| = {norms[r]:.6f}); renormalized"
        )
    # Rows within 1e-5 of unit norm keep their written values, so converting a file does not
    # change its numbers; the rest are renormalized (and warned about above when > 1e-3 off).
    fix = np.abs(norms - 1.0) > 1e-5
    out = quat_wxyz.copy()
    out[fix] /= norms[fix, None]
    return out


def _fmt_xyz(p) -> str:
    return "(" + ", ".join(f"{v:.10g}" for v in p) + ")"
