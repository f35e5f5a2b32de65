"""Row-level validation of trajectories read from files.

Everything here raises :class:`gevi_cli.errors.DataError` with ``file:line`` so a user can open the
file at the bad row.  Quaternions a little off unit norm (files written with 4-6 decimals) are
renormalized with a warning; stamps must strictly increase; positions must be finite and plausible.
"""
from __future__ import annotations

import numpy as np

from gevi_cli.errors import DataError

#: A coordinate beyond this (metres) is not a position on Earth's surface scale: a corrupt value.
MAX_ABS_COORDINATE_M = 1.0e6
#: A single step this many times the typical (median) step, and over 100 m, is a corrupt jump.
MAX_STEP_RATIO = 1.0e4
QUAT_NORM_TOLERANCE = 1e-3


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

    big = np.abs(positions) > MAX_ABS_COORDINATE_M
    if big.any():
        r = int(np.argmax(big.any(axis=1)))
        fail(r, f"coordinate {positions[r][big[r]][0]:.6g} m is not plausible (|x| > {MAX_ABS_COORDINATE_M:g} m): corrupt row?")
    if len(positions) > 2:
        steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
        typical = np.median(steps)
        jump = (steps > 100.0) & (steps > MAX_STEP_RATIO * max(typical, 1e-3))
        if jump.any():
            r = int(np.argmax(jump)) + 1
            fail(r, f"position jumps {steps[r - 1]:.6g} m from the previous row (typical step {typical:.3g} m): corrupt row?")

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
