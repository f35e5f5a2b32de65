"""Row-level validation of trajectories read from files.

Everything here raises :class:`gevi_cli.errors.DataError` with ``file:line`` so a user can open the
file at the bad row.  Quaternions a little off unit norm (files written with 4-6 decimals) are
renormalized with a warning; stamps must strictly increase; positions must be finite and plausible
(see :func:`absurd_row` for what "plausible" means: relative to the trajectory itself).
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


def validate_rows(path, lines, t_ns, positions, quat_wxyz=None, rotations=None, warnings=None):
    """Check stamps, positions and orientation rows; return the (renormalized) quaternions.

    Stamps must not decrease (equal stamps are removed beforehand by :func:`duplicate_stamp_mask`).

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

    absurd = absurd_row(positions)
    if absurd is not None:
        r, jump, typical = absurd
        fail(r, f"position {_fmt_xyz(positions[r])} m is not plausible: it is {jump:.6g} m from its neighbour "
                f"while the typical step is {typical:.3g} m (position jumps; corrupt row?)")

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
