"""Small input validators shared by the estimator modules (private)."""

from __future__ import annotations

import numpy as np

from .errors import DegenerateInput, NonFiniteInput, ShapeError, TooFewPoints


def as_points(x, dim: int, name: str) -> np.ndarray:
    """Return ``x`` as a float (n, dim) array; raise on wrong shape or non-finite values."""
    a = np.asarray(x, dtype=float)
    if a.ndim != 2 or a.shape[1] != dim:
        raise ShapeError(f"{name} must have shape (n, {dim}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise NonFiniteInput(f"{name} contains non-finite values")
    return a


def as_matrix(x, shape: tuple, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != shape:
        raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise NonFiniteInput(f"{name} contains non-finite values")
    return a


def as_covs(x, n: int, dim: int, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != (n, dim, dim):
        raise ShapeError(f"{name} must have shape ({n}, {dim}, {dim}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise NonFiniteInput(f"{name} contains non-finite values")
    return a


def finite_scalar(x, name: str) -> float:
    v = float(x)
    if not np.isfinite(v):
        raise NonFiniteInput(f"{name} is not finite")
    return v


def same_length(*arrays) -> int:
    n = arrays[0].shape[0]
    for a in arrays[1:]:
        if a.shape[0] != n:
            raise ShapeError(f"inconsistent numbers of points: {[b.shape[0] for b in arrays]}")
    return n


def need(n: int, minimum: int, what: str = "points") -> None:
    if n < minimum:
        raise TooFewPoints(n, minimum, what)


def solve_checked(M: np.ndarray, rhs: np.ndarray, what: str, rcond: float = 1e-12) -> np.ndarray:
    """Solve the square system ``M x = rhs``; raise DegenerateInput if M is (near) singular.

    The test is on the 2-norm condition number after symmetric diagonal scaling (so that
    unknowns of different units do not trigger false alarms).
    """
    d = np.sqrt(np.abs(np.diag(M)))
    if np.any(d == 0) or not np.all(np.isfinite(M)):
        raise DegenerateInput(f"{what}: singular system (zero diagonal)")
    Ms = M / d[:, None] / d[None, :]
    s = np.linalg.svd(Ms, compute_uv=False)
    if s[-1] <= rcond * s[0]:
        raise DegenerateInput(f"{what}: ill-conditioned system (cond {s[0] / max(s[-1], 1e-300):.3g})")
    x = np.linalg.solve(Ms, (rhs.T / d).T if rhs.ndim > 1 else rhs / d)
    x = (x.T / d).T if x.ndim > 1 else x / d
    if not np.all(np.isfinite(x)):
        raise DegenerateInput(f"{what}: non-finite solution")
    return x


def stereo_inputs(z, y, R_rl, t_rl):
    """Validated keyframe stereo observations: ``(z, y, R_rl, t_rl)`` with z, y (n, 2), n >= 1."""
    z = as_points(z, 2, "z")
    y = as_points(y, 2, "y")
    need(same_length(z, y), 1)
    return z, y, as_matrix(R_rl, (3, 3), "R_rl"), as_matrix(t_rl, (3,), "t_rl")
