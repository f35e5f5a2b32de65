"""Cramer-Rao lower bounds (spec section 11.1-11.2).

All bounds are evaluated at the *true* pose with noise-free image coordinates. Units: rad for
angles, metres for translations; ``sigma2`` is the per-coordinate variance in normalized units.
"""

from __future__ import annotations

import numpy as np

from gevi_cli.geometry import project_jacobian, skew

from ._checks import as_covs, as_matrix, as_points, need, same_length
from .errors import DegenerateInput
from .pnp4 import epipolar_residuals_jac


def _inv_checked(F, what):
    ev = np.linalg.eigvalsh(F)
    if not ev[-1] > 0 or ev[0] <= 1e-14 * ev[-1]:
        raise DegenerateInput(f"{what}: singular Fisher information")
    return np.linalg.inv(F)


def crlb4(psi, t, z, y, q, L_k, L_c, R_rl, t_rl, sigma2):
    """CRLB of chi = (psi, t_CK) under the epipolar model (1): F4 = sum grad d grad d^T / sigma2.

    Pass noise-free z, y, q. Returns the 4x4 covariance bound (order psi, t1, t2, t3); report
    sqrt(C[0, 0]) and sqrt(trace C[1:, 1:]). When averaging over Monte Carlo runs with different
    poses, average the variances, then take the root (spec 11.1).
    """
    z = as_points(z, 2, "z")
    need(same_length(z, as_points(y, 2, "y"), as_points(q, 2, "q")), 2)
    _, J = epipolar_residuals_jac(psi, t, z, y, q, L_k, L_c, R_rl, t_rl)
    return _inv_checked(J.T @ J / sigma2, "crlb4")


def fisher6(R, t, p, cov):
    """F6 = sum J_i^T Sigma_bar_i^-1 J_i (right perturbation [dphi, dt]) at the true pose."""
    R = as_matrix(R, (3, 3), "R")
    t = as_matrix(t, (3,), "t")
    p = as_points(p, 3, "p")
    n = len(p)
    cov = as_covs(cov, n, 3, "cov")
    X = p @ R.T + t
    if np.any(X[:, 2] <= 0):
        raise DegenerateInput("crlb6: point behind the current camera")
    dpi = project_jacobian(X)
    Jh = dpi @ R
    Sb = Jh @ cov @ np.swapaxes(Jh, 1, 2)
    W = np.linalg.inv(Sb)
    Jp = np.empty((n, 3, 6))
    Jp[:, :, :3] = -R @ skew(p)
    Jp[:, :, 3:] = np.eye(3)
    J = dpi @ Jp
    return np.einsum("nji,njk,nkl->il", J, W, J)


def crlb6(R, t, p, cov):
    """6-DOF bound (spec 11.2): inverse of :func:`fisher6`, order (rotation, translation).

    ``p``/``cov`` must be the points and covariances triangulated from *noise-free* stereo
    coordinates. Report sqrt(trace C[:3, :3]) (rad) and sqrt(trace C[3:, 3:]) (m).
    """
    need(len(np.asarray(p)), 3)
    return _inv_checked(fisher6(R, t, p, cov), "crlb6")
