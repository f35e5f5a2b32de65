"""Gravity-prior covariance estimation for the 6-DOF BCD refinement (spec section 8).

Only the closed-form Sigma-step is implemented so far; ``bcd_refine`` (the chi-step over
yaw, translation and the per-sample tilts) is not yet written (see docs/estimators_notes.md).
"""

from __future__ import annotations

import numpy as np

from ._checks import as_points, finite_scalar, need
from .errors import DegenerateInput


def sigma_step(residuals, lo, hi) -> np.ndarray:
    """Closed-form minimiser of tr(Sigma^-1 S) + K log det Sigma s.t. lo <= eig(Sigma) <= hi.

    ``residuals`` (K, 3): gravity-prior residuals a_k - R_tilt_k^T e3 (unit-vector differences,
    dimensionless). With S = sum r r^T = V diag(s) V^T the minimiser is
    V diag(clip(s / K, lo, hi)) V^T (spec 8.3). [PROPOSAL] lo = (sigma_a / g)^2, hi = 0.2^2.
    """
    r = as_points(residuals, 3, "residuals")
    K = len(r)
    need(K, 1, "residual vectors")
    lo = finite_scalar(lo, "lo")
    hi = finite_scalar(hi, "hi")
    if not 0 < lo <= hi:
        raise DegenerateInput("sigma_step needs 0 < lo <= hi")
    s, V = np.linalg.eigh(r.T @ r)
    return (V * np.clip(s / K, lo, hi)) @ V.T


def sigma_objective(Sigma, residuals) -> float:
    """tr(Sigma^-1 S) + K log det Sigma (the Sigma-dependent part of the joint cost)."""
    r = np.asarray(residuals, float)
    S = r.T @ r
    sign, logdet = np.linalg.slogdet(Sigma)
    if sign <= 0:
        raise DegenerateInput("Sigma not positive definite")
    return float(np.trace(np.linalg.solve(Sigma, S)) + len(r) * logdet)
