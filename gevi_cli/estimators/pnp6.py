"""6-DOF PnP: CPnP-style linear model, Bias-Eli(-W) estimator, pose recovery, weighted one-step
refinement and the l1 pre-filter (spec section 5).

Frames/units: ``p`` (n, 3) are points in keyframe-left coordinates (m), ``cov`` (n, 3, 3) their
covariances (m^2), ``q`` (n, 2) normalized current-left coordinates (treated as exact). The
returned pose ``(R, t)`` maps keyframe-left into current-left: ``X_C = R p + t`` (t in m).
"""

from __future__ import annotations

import math

import numpy as np

from ._checks import as_covs, as_matrix, as_points, need, same_length, solve_checked
from .errors import DegenerateInput, ShapeError
from .lie import exp_so3, project, project_jacobian, project_to_so3

MIN_POINTS = 6  # 11 unknowns, two rows per point


def _inputs(p, q, weights):
    p = as_points(p, 3, "p")
    q = as_points(q, 2, "q")
    n = same_length(p, q)
    need(n, MIN_POINTS)
    if weights is None:
        w = np.ones(n)
    else:
        w = np.asarray(weights, dtype=float)
        if w.shape != (n,):
            raise ShapeError(f"weights must have shape ({n},)")
        if not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise DegenerateInput("weights must be finite and > 0")
    return p, q, w, n


def build_H(p, q, weights=None):
    """Stack the CPnP linear rows. Returns ``H`` (2n, 11), ``d`` (2n,), centroid ``pbar`` (3,).

    theta = [r3/k, r1/k, t1/k, r2/k, t2/k] (0-based slices 0:3, 3:6, 6, 7:10, 10), kappa = depth
    of the centroid in the current frame. Rows of point i are 2i (x) and 2i+1 (y).
    """
    p, q, w, n = _inputs(p, q, weights)
    pbar = p.mean(axis=0)
    pc = p - pbar
    H = np.zeros((n, 2, 11))
    H[:, 0, 0:3] = -q[:, 0:1] * pc
    H[:, 0, 3:6] = p
    H[:, 0, 6] = 1.0
    H[:, 1, 0:3] = -q[:, 1:2] * pc
    H[:, 1, 7:10] = p
    H[:, 1, 10] = 1.0
    H *= w[:, None, None]
    d = q * w[:, None]
    return H.reshape(2 * n, 11), d.reshape(2 * n), pbar


def bias_matrix_G(cov, q, weights=None) -> np.ndarray:
    """G = (1/n) sum_i w_i^2 G_i (11 x 11), the expected noise part of H^T H / n (spec 5.2)."""
    q = np.asarray(q, dtype=float)
    n = len(q)
    w2 = np.ones(n) if weights is None else np.asarray(weights, dtype=float) ** 2
    S0 = np.einsum("n,nij->ij", w2, cov) / n
    Sqq = np.einsum("n,nij->ij", w2 * np.sum(q * q, axis=1), cov) / n
    S1 = np.einsum("n,nij->ij", w2 * q[:, 0], cov) / n
    S2 = np.einsum("n,nij->ij", w2 * q[:, 1], cov) / n
    G = np.zeros((11, 11))
    G[0:3, 0:3] = Sqq
    G[0:3, 3:6] = -S1
    G[3:6, 0:3] = -S1
    G[0:3, 7:10] = -S2
    G[7:10, 0:3] = -S2
    G[3:6, 3:6] = S0
    G[7:10, 7:10] = S0
    return G


def recover_pose(theta, pbar):
    """CPnP recovery (spec 5.3): theta (11,) -> (R, t). Raises DegenerateInput if kappa <= 0."""
    theta = np.asarray(theta, dtype=float)
    Rt = np.stack([theta[3:6], theta[7:10], theta[0:3]])
    tt = np.array([theta[6], theta[10], 1.0 - theta[0:3] @ pbar])
    det = np.linalg.det(Rt)
    if not np.isfinite(det) or abs(det) < 1e-300:
        raise DegenerateInput("recover_pose: singular rotation block")
    s = math.copysign(1.0, det)
    # After the sign flip the centroid depth of the recovered pose is s / k: s < 0 means the
    # linear solution puts the points behind the camera (kappa <= 0).
    if s < 0:
        raise DegenerateInput("recover_pose: kappa <= 0 (centroid behind the current camera)")
    k = det ** (1.0 / 3.0)
    R = project_to_so3(Rt / k)
    t = tt / k
    return R, t


def _solve_theta(p, q, w, cov=None):
    H, d, pbar = build_H(p, q, w)
    n = len(p)
    M = H.T @ H / n
    if cov is not None:
        M = M - bias_matrix_G(cov, q, w)
    theta = solve_checked(M, H.T @ d / n, "pnp6")
    return theta, pbar


def pnp6_ls(p, q, weights=None):
    """Plain (biased) linear least-squares PnP (spec 5.1) -> (R, t)."""
    p, q, w, _ = _inputs(p, q, weights)
    theta, pbar = _solve_theta(p, q, w)
    return recover_pose(theta, pbar)


def pnp6_be(p, cov, q, weights=None):
    """Bias-Eli(-W) PnP (spec 5.2-5.3) -> (R, t).

    ``weights`` are the row weights w_i (default 1, [PROPOSAL]); the authors' code uses
    w_i = Z_i^(-3/2) with Z_i the triangulated depth (see :func:`depth_weights`).
    """
    p, q, w, n = _inputs(p, q, weights)
    cov = as_covs(cov, n, 3, "cov")
    theta, pbar = _solve_theta(p, q, w, cov)
    return recover_pose(theta, pbar)


def depth_weights(p) -> np.ndarray:
    """Row weights Z^(-3/2) of the authors' implementation (option of spec 5.2)."""
    Z = np.asarray(p, dtype=float)[:, 2]
    if np.any(Z <= 0):
        raise DegenerateInput("depth_weights: non-positive depth")
    return Z ** -1.5


def reprojection_residuals(R, t, p, q):
    """r_i = q_i - pi(R p_i + t), (n, 2); raises DegenerateInput if a point is behind the camera."""
    X = p @ np.asarray(R).T + t
    if np.any(X[:, 2] <= 0):
        raise DegenerateInput("point behind the current camera")
    return q - project(X), X


def pnp6_refine(R, t, p, cov, q, sigma2_q=0.0, mu_rel=1e-6):
    """One weighted LM step on the reprojection error (spec 5.4) -> (R+, t+).

    Weights are Sigma_bar_i^-1 with Sigma_bar_i = J_h Sigma_i J_h^T (+ sigma2_q I, [PROPOSAL] for
    a noisy current frame), computed once at the input pose. Right perturbation:
    R+ = R Exp(delta[:3]), t+ = t + delta[3:]. Damping mu = mu_rel * max diag ([PROPOSAL] 1e-6).
    """
    R = as_matrix(R, (3, 3), "R")
    t = as_matrix(t, (3,), "t")
    p = as_points(p, 3, "p")
    q = as_points(q, 2, "q")
    n = same_length(p, q)
    need(n, 3)
    cov = as_covs(cov, n, 3, "cov")
    r, X = reprojection_residuals(R, t, p, q)
    # Explicit 2x2 / 2x3 algebra instead of stacked matmuls: this runs once per frame in the
    # pipelines, and numpy's batched matmul of tiny matrices costs more than the arithmetic.
    dpi = project_jacobian(X)  # (n, 2, 3)
    Jh = dpi @ R  # (n, 2, 3): d pi / d p
    cov9 = cov.reshape(n, 9)
    a, b = Jh[:, 0], Jh[:, 1]
    S00 = ((a[:, :, None] * a[:, None, :]).reshape(n, 9) * cov9).sum(1) + sigma2_q
    S01 = ((a[:, :, None] * b[:, None, :]).reshape(n, 9) * cov9).sum(1)
    S11 = ((b[:, :, None] * b[:, None, :]).reshape(n, 9) * cov9).sum(1) + sigma2_q
    det = S00 * S11 - S01 * S01
    if np.any(det <= 0):
        raise DegenerateInput("pnp6_refine: singular projected covariance (zero point covariance?)")
    W00, W01, W11 = S11 / det, -S01 / det, S00 / det
    # d pi / d delta for R+ = R Exp(dphi), t+ = t + dt: [-Jh [p]_x | dpi]; a^T [p]_x = (a x p)^T.
    J = np.empty((n, 2, 6))
    px, py, pz = p[:, None, 0], p[:, None, 1], p[:, None, 2]
    ax, ay, az = Jh[:, :, 0], Jh[:, :, 1], Jh[:, :, 2]
    J[:, :, 0] = py * az - pz * ay  # -(Jh x p)
    J[:, :, 1] = pz * ax - px * az
    J[:, :, 2] = px * ay - py * ax
    J[:, :, 3:] = dpi
    WJ = np.empty_like(J)
    WJ[:, 0] = W00[:, None] * J[:, 0] + W01[:, None] * J[:, 1]
    WJ[:, 1] = W01[:, None] * J[:, 0] + W11[:, None] * J[:, 1]
    J2, WJ2 = J.reshape(2 * n, 6), WJ.reshape(2 * n, 6)
    Hm = WJ2.T @ J2
    g = WJ2.T @ r.reshape(2 * n)
    Hm = Hm + mu_rel * np.max(np.diag(Hm)) * np.eye(6)
    delta = solve_checked(Hm, g, "pnp6_refine")
    return R @ exp_so3(delta[:3]), t + delta[3:]


def pnp6_l1(p, q):
    """l1-norm linear PnP (spec 5.5): min ||H theta - d||_1 via HiGHS LP -> (R, t)."""
    from scipy.optimize import linprog
    from scipy.sparse import bmat, csr_matrix, identity

    H, d, pbar = build_H(p, q)
    m = H.shape[0]
    Hs = csr_matrix(H)
    I = identity(m, format="csr")
    A_ub = bmat([[Hs, -I], [-Hs, -I]], format="csr")
    b_ub = np.concatenate([d, -d])
    c = np.concatenate([np.zeros(11), np.ones(m)])
    bounds = [(None, None)] * 11 + [(0, None)] * m
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
    if res.status != 0:
        raise DegenerateInput(f"pnp6_l1: LP failed ({res.message})")
    return recover_pose(res.x[:11], pbar)


def pnp_l1_filter(p, q, drop=0.10):
    """l1-PnP pre-filter (spec 5.5): boolean keep-mask dropping the ceil(drop*n) largest
    reprojection errors of the l1 pose (points behind the camera count as infinite error)."""
    p = as_points(p, 3, "p")
    q = as_points(q, 2, "q")
    n = same_length(p, q)
    R, t = pnp6_l1(p, q)
    X = p @ R.T + t
    err = np.full(n, np.inf)
    front = X[:, 2] > 0
    err[front] = np.linalg.norm(q[front] - project(X[front]), axis=1)
    k = int(math.ceil(drop * n - 1e-12))
    keep = np.ones(n, dtype=bool)
    if k > 0:
        keep[np.argsort(err, kind="stable")[n - k:]] = False
    return keep
