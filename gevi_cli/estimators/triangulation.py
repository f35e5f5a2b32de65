"""Stereo linear triangulation with first-order covariance, spec section 4.

Inputs are keyframe-left ``z`` and keyframe-right ``y`` normalized coordinates (n, 2) and the
stereo extrinsic ``X_R = R_rl X_L + t_rl`` (metres). Points are returned in keyframe-left
coordinates (metres); covariances in m^2.
"""

from __future__ import annotations

import numpy as np

from gevi_cli.geometry import homogeneous, skew

from ._checks import (
    finite_scalar,
    stereo_inputs,
)
from .errors import DegenerateInput

_EYE_SKEW = skew(np.eye(3))  # [e_j]_x for j = 0..2, shape (3, 3, 3)


def _system(z, y, R_rl, t_rl):
    zh, yh = homogeneous(z), homogeneous(y)
    n = len(z)
    A = np.empty((n, 6, 3))
    A[:, :3, :] = skew(zh)
    Sy = skew(yh)
    A[:, 3:, :] = Sy @ R_rl
    b = np.zeros((n, 6))
    b[:, 3:] = -(Sy @ t_rl)
    return A, b


def triangulate_jacobian(z, y, R_rl, t_rl):
    """Linear LS triangulation and its exact Jacobian.

    Returns ``p`` (n, 3) and ``J_p`` (n, 3, 4) = d p / d (z1, z2, y1, y2).
    Raises DegenerateInput for (near-)zero-parallax points (the normal matrix is singular);
    gate by disparity before calling.
    """
    z, y, R_rl, t_rl = stereo_inputs(z, y, R_rl, t_rl)
    n = len(z)
    A, b = _system(z, y, R_rl, t_rl)
    At = np.swapaxes(A, 1, 2)
    N = At @ A  # (n, 3, 3)
    ev = np.linalg.eigvalsh(N)
    bad = ev[:, 0] <= 1e-12 * ev[:, 2]
    if np.any(bad):
        err = DegenerateInput(f"triangulate: {int(bad.sum())} point(s) with (near) zero parallax")
        err.mask = bad
        raise err
    Ninv = np.linalg.inv(N)
    p = np.einsum("nij,nj->ni", Ninv, np.einsum("nji,nj->ni", A, b))
    res = b - np.einsum("nij,nj->ni", A, p)  # (n, 6)

    # derivatives of A and b w.r.t. (z1, z2, y1, y2)
    J = np.empty((n, 3, 4))
    for k in range(4):  # 4 fixed coordinates, not a loop over points
        dA = np.zeros((6, 3))
        db = np.zeros(6)
        if k < 2:
            dA[:3] = _EYE_SKEW[k]
        else:
            dA[3:] = _EYE_SKEW[k - 2] @ R_rl
            db[3:] = -_EYE_SKEW[k - 2] @ t_rl
        rhs = res @ dA + np.einsum("nji,nj->ni", A, db[None, :] - p @ dA.T)
        J[:, :, k] = np.einsum("nij,nj->ni", Ninv, rhs)
    return p, J


def triangulate(z, y, R_rl, t_rl, sigma2, tied_rows=None):
    """Triangulate stereo matches and propagate isotropic image noise.

    ``sigma2``: variance of each normalized coordinate of z and y (e.g. from
    :func:`sigma2_stereo`). Returns ``p`` (n, 3) in keyframe-left coordinates and
    ``cov`` (n, 3, 3) = sigma2 * J_p J_p^T, evaluated at the measured coordinates.

    ``tied_rows`` (n,) bool, optional: matches whose right row is the left row by construction (a
    rectified pair matched along the row, ``y2 = z2``).  Their ``y2`` is no second measurement, so
    ``d p / d z2`` becomes the total derivative ``J[:, :, 1] + J[:, :, 3]`` and ``y2`` contributes no
    variance of its own [PROPOSAL; spec 4 assumes four independent coordinates].  Counting it as
    independent adds variance the data do not have (docs/method.md 5.4).
    """
    sigma2 = finite_scalar(sigma2, "sigma2")
    if sigma2 < 0:
        raise DegenerateInput("triangulate: negative sigma2")
    p, J = triangulate_jacobian(z, y, R_rl, t_rl)
    if tied_rows is not None:
        tied = np.asarray(tied_rows, dtype=bool)
        J[tied, :, 1] += J[tied, :, 3]
        J[tied, :, 3] = 0.0
    cov = sigma2 * J @ np.swapaxes(J, 1, 2)
    return p, cov
