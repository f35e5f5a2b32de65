"""4-DOF gravity-aided PnP: linear LS / bias-eliminated estimators and the one-step Gauss-Newton on
the point-to-epipolar-line ML cost (spec section 6).

Model: ``R_CK(psi) = L_C^T Rz(psi) L_K`` with levelling rotations L_K, L_C (camera -> level frame,
see :func:`levelling`), ``t_CK`` in metres in current-left coordinates. ``p`` (n, 3) keyframe-left
points (m) with covariances ``cov`` (n, 3, 3); ``q`` (n, 2) normalized current-left coordinates
(treated as exact); ``z``/``y`` normalized keyframe-left/right coordinates.
"""

from __future__ import annotations

import numpy as np

from gevi_cli.geometry import drot_z, homogeneous, rot_z, skew, wrap_angle

from ._checks import (
    as_covs,
    as_matrix,
    as_points,
    finite_scalar,
    need,
    same_length,
    solve_checked,
)
from .errors import DegenerateInput

MIN_POINTS = 3
_M1 = np.diag([1.0, 1.0, 0.0])
_M2 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
_M3 = -np.diag([0.0, 0.0, 1.0])
_MS = (_M1, _M2, _M3)


def _cross(a, b):
    """Row-wise cross product of (n, 3) arrays (same products/order as np.cross, less overhead)."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    out = np.empty(a.shape)
    out[:, 0] = a1 * b2 - a2 * b1
    out[:, 1] = a2 * b0 - a0 * b2
    out[:, 2] = a0 * b1 - a1 * b0
    return out


def row_vectors(q, L_c, rows="orth") -> np.ndarray:
    """The two constraint directions v_i1, v_i2 (orthogonal to u_i = L_C q_i^h), shape (n, 3, 2).

    ``rows="orth"`` [PROPOSAL, recommended]: an orthonormal basis of u_i^perp (the estimator only
    depends on the projector sum_k v v^T, so the particular basis is irrelevant).
    ``rows="paper"``: (u3, 0, -u1) and (0, u3, -u2); for L_C = I (u3 = 1) these are exactly S1's rows
    (1, 0, -q1), (0, 1, -q2). [Choice] For L_C != I we scale by u3 instead of dividing, which is
    the same constraint; it degenerates for horizontal levelled bearings (raises).
    """
    u = homogeneous(q) @ np.asarray(L_c).T
    n = len(u)
    V = np.empty((n, 3, 2))
    if rows == "orth":
        un = u / np.sqrt(np.einsum("ij,ij->i", u, u))[:, None]
        # helper axis: the coordinate axis least aligned with u
        idx = np.argmin(np.abs(un), axis=1)
        a = np.zeros_like(un)
        a[np.arange(n), idx] = 1.0
        v1 = _cross(un, a)
        v1 /= np.sqrt(np.einsum("ij,ij->i", v1, v1))[:, None]
        v2 = _cross(un, v1)
        V[:, :, 0] = v1
        V[:, :, 1] = v2
    elif rows == "paper":
        if np.any(np.abs(u[:, 2]) < 1e-6 * np.linalg.norm(u, axis=1)):
            raise DegenerateInput("paper rows: levelled bearing orthogonal to the yaw axis; use rows='orth'")
        V[:, :, 0] = np.stack([u[:, 2], np.zeros(n), -u[:, 0]], axis=1)
        V[:, :, 1] = np.stack([np.zeros(n), u[:, 2], -u[:, 1]], axis=1)
    else:
        raise ValueError(f"rows must be 'orth' or 'paper', got {rows!r}")
    return V


def _A_from(rho, V):
    """A (n, 2, 5) and b (n, 2) of spec 6.1 from level-frame points rho and rows V (n, 3, 2):
    a_k = [v_k . M1 rho, v_k . M2 rho, v_k], beta_k = v_k . M3 rho (written out elementwise)."""
    n = len(rho)
    r0, r1, r2 = rho[:, 0:1], rho[:, 1:2], rho[:, 2:3]
    v0, v1, v2 = V[:, 0, :], V[:, 1, :], V[:, 2, :]  # (n, 2) each
    A = np.empty((n, 2, 5))
    A[:, :, 0] = v0 * r0 + v1 * r1
    A[:, :, 1] = v1 * r0 - v0 * r1
    A[:, :, 2] = v0
    A[:, :, 3] = v1
    A[:, :, 4] = v2
    return A, -v2 * r2


def build_A(p, q, L_k, L_c, rows="orth"):
    """Linear system A x = b of spec 6.1, x = [cos psi, sin psi, tau], tau = L_C t_CK.

    Returns A (2n, 5), b (2n,), V (n, 3, 2), rho = L_K p (n, 3).
    """
    rho = p @ np.asarray(L_k).T
    V = row_vectors(q, L_c, rows)
    n = len(p)
    A, b = _A_from(rho, V)
    return A.reshape(2 * n, 5), b.reshape(2 * n), V, rho


def _bias_terms_frame(cov, V, L=None):
    """G1, g2 of spec 6.2 with the level-frame covariances L cov L^T (L = None: cov already in
    the level frame). Uses (G1)_ac = 1/n sum_ik (M_a^T v_ik)^T S_i (M_c^T v_ik)."""
    n = len(V)
    Ut = np.zeros((n, 3, 2, 3))  # (point, c, k, coord): (M_c^T v_ik)^T
    Vt = np.swapaxes(V, 1, 2)  # (n, 2, 3)
    Ut[:, 0, :, :2] = Vt[:, :, :2]
    Ut[:, 1, :, 0] = Vt[:, :, 1]
    Ut[:, 1, :, 1] = -Vt[:, :, 0]
    Ut[:, 2, :, 2] = -Vt[:, :, 2]
    if L is not None:
        # (L^T U)^T = U^T L, so that U^T (L cov L^T) U = (L^T U)^T cov (L^T U); one plain GEMM
        Ut = (Ut.reshape(6 * n, 3) @ np.asarray(L)).reshape(n, 3, 2, 3)
    SUt = Ut.reshape(n, 6, 3) @ cov  # rows (S U)^T since cov is symmetric
    G = np.tensordot(Ut, SUt.reshape(n, 3, 2, 3), axes=([0, 2, 3], [0, 2, 3])) / n
    G1 = np.zeros((5, 5))
    g2 = np.zeros(5)
    G1[:2, :2] = G[:2, :2]
    g2[:2] = G[:2, 2]
    return G1, g2


def bias_terms(cov_rho, V):
    """G1 (5x5) and g2 (5,) of spec 6.2 for level-frame covariances cov_rho (n, 3, 3).

    (G1)_ac = 1/n sum_i tr(P_i M_a S_i M_c^T), (g2)_a = 1/n sum_i tr(P_i M_a S_i M_3^T), with
    P_i = sum_k v_ik v_ik^T; only the leading 2x2 block / first two entries are non-zero.
    """
    return _bias_terms_frame(np.asarray(cov_rho, float), V)


def _inputs4(p, q, L_k, L_c):
    p = as_points(p, 3, "p")
    q = as_points(q, 2, "q")
    n = same_length(p, q)
    need(n, MIN_POINTS)
    L_k = as_matrix(L_k, (3, 3), "L_k")
    L_c = as_matrix(L_c, (3, 3), "L_c")
    return p, q, L_k, L_c, n


def _recover(x, L_c):
    if np.hypot(x[0], x[1]) <= 1e-12:
        raise DegenerateInput("pnp4: cos/sin part vanished")
    return float(np.arctan2(x[1], x[0])), L_c.T @ x[2:]


def pnp4_ls(p, q, L_k, L_c, rows="orth"):
    """Plain LS 4-DOF estimator (biased; spec 6.2) -> (psi [rad], t_CK [m])."""
    p, q, L_k, L_c, n = _inputs4(p, q, L_k, L_c)
    A, b, _, _ = build_A(p, q, L_k, L_c, rows)
    x = solve_checked(A.T @ A / n, A.T @ b / n, "pnp4_ls")
    return _recover(x, L_c)


def pnp4_be(p, cov, q, L_k, L_c, rows="orth"):
    """Bias-eliminated 4-DOF estimator (S1 eq. 7, general rows) -> (psi [rad], t_CK [m]).

    x = (A^T A/n - G1)^-1 (A^T b/n - g2); t_CK = L_C^T x[2:], no rescaling by |(cos, sin)|.
    """
    p, q, L_k, L_c, n = _inputs4(p, q, L_k, L_c)
    cov = as_covs(cov, n, 3, "cov")
    A, b, V, _ = build_A(p, q, L_k, L_c, rows)
    G1, g2 = _bias_terms_frame(cov, V, L_k)
    x = solve_checked(A.T @ A / n - G1, A.T @ b / n - g2, "pnp4_be")
    return _recover(x, L_c)


def pnp4_be_cov(p, cov, q, L_k, L_c, rows="orth"):
    """BE estimate with its first-order (sandwich) covariance -> (psi, t_CK, C (4, 4)).

    Row residuals e_ik = a_ik^T x - beta_ik = v_ik^T (Rz(psi) rho_i + tau) carry the noise
    v_ik^T Rz(psi) d(rho_i), so Var(e_i) = V_i^T Rz S_rho_i Rz^T V_i and
    Cov(x) ~ (A^T A)^-1 [sum_i A_i^T Var(e_i) A_i] (A^T A)^-1; C is mapped to chi = (psi, t_CK)
    (order psi, t1, t2, t3). Used by :func:`pnp4_gn` (``be_cov``) to keep the BE value along
    directions where cost (1) carries less information than the BE estimate.
    """
    p, q, L_k, L_c, n = _inputs4(p, q, L_k, L_c)
    cov = as_covs(cov, n, 3, "cov")
    A, b, V, _ = build_A(p, q, L_k, L_c, rows)
    G1, g2 = _bias_terms_frame(cov, V, L_k)
    x = solve_checked(A.T @ A / n - G1, A.T @ b / n - g2, "pnp4_be")
    psi, t = _recover(x, L_c)
    # (Rz L_k)^T V_i -> rows in the keyframe frame; Var(e_i) = W_i^T cov_i W_i
    Wt = np.swapaxes(V, 1, 2) @ (rot_z(psi) @ L_k)  # (n, 2, 3)
    Ve = Wt @ cov @ np.swapaxes(Wt, 1, 2)  # (n, 2, 2)
    A3 = A.reshape(n, 2, 5)
    meat = A.T @ (Ve @ A3).reshape(2 * n, 5)  # sum_i A_i^T Var(e_i) A_i
    Ninv = np.linalg.inv(A.T @ A)
    Cx = Ninv @ meat @ Ninv
    D = np.zeros((4, 5))
    h = x[0] ** 2 + x[1] ** 2
    D[0, 0], D[0, 1] = -x[1] / h, x[0] / h
    D[1:, 2:] = L_c.T
    return psi, t, D @ Cx @ D.T


# ---------------------------------------------------------------------------------------------
# Epipolar ML cost (1) and its Jacobian


def _epipolar_mats(psi, t, L_k, L_c, R_rl, t_rl, jac=True):
    """Per keyframe image s in (L, R) the matrices whose product with q^h gives the epipolar line
    l = ([t_Cs]x R_Cs)^T q^h and (``jac``) its derivatives w.r.t. psi and t_k:
    returns (3, m) with the columns of [E_L, (dE_L/dpsi, [e_k]x R_L), E_R, (...)] side by side."""
    R = L_c.T @ rot_z(psi) @ L_k
    Rs_ = (R, R @ R_rl.T)
    ts_ = (t, t - Rs_[1] @ t_rl)
    blocks = []
    if jac:
        dR = L_c.T @ drot_z(psi) @ L_k
        dRs_ = (dR, dR @ R_rl.T)
        dts_ = (None, -dRs_[1] @ t_rl)
    for s_ in range(2):  # two keyframe images (3x3 matrices only; the point work is batched)
        Rs, ts = Rs_[s_], ts_[s_]
        blocks.append(skew(ts) @ Rs)
        if jac:
            dE = skew(ts) @ dRs_[s_]
            if dts_[s_] is not None:
                dE = dE + skew(dts_[s_]) @ Rs
            blocks.append(dE)
            blocks.append(_EK @ Rs)  # (3, 3, 3): [e_k]x R_s
    return blocks


_EK = skew(np.eye(3))  # [e_k]x, k = 0..2


def _epipolar(psi, t, z, y, q, L_k, L_c, R_rl, t_rl, jac=True):
    """Batched over points and both keyframe images; r (n, 2) and J (n, 2, 4) (or None)."""
    qh = homogeneous(q)
    n = len(qh)
    blocks = _epipolar_mats(psi, t, L_k, L_c, R_rl, t_rl, jac)
    if jac:
        # M (3, 2*5*3): per image [E, dE/dpsi, [e1]x R, [e2]x R, [e3]x R]; row vector l = q^h M
        M = np.concatenate([blocks[0][None], blocks[1][None], blocks[2],
                            blocks[3][None], blocks[4][None], blocks[5]])  # (10, 3, 3)
        D = (qh @ M.transpose(1, 0, 2).reshape(3, 30)).reshape(n, 2, 5, 3)
        lines = D[:, :, 0, :]
    else:
        M = np.concatenate([blocks[0][None], blocks[1][None]])  # (2, 3, 3)
        lines = (qh @ M.transpose(1, 0, 2).reshape(3, 6)).reshape(n, 2, 3)
    xh = np.empty((n, 2, 3))
    xh[:, 0, :2] = z
    xh[:, 1, :2] = y
    xh[:, :, 2] = 1.0
    l0, l1 = lines[:, :, 0], lines[:, :, 1]
    nrm = np.sqrt(l0 * l0 + l1 * l1)
    if np.any(nrm <= 1e-300):
        raise DegenerateInput("epipolar: degenerate epipolar line (zero translation?)")
    num = l0 * xh[:, :, 0] + l1 * xh[:, :, 1] + lines[:, :, 2]
    d = num / nrm
    if not jac:
        return d, None
    inv = 1.0 / nrm
    c = num * inv * inv * inv
    g0 = xh[:, :, 0] * inv - c * l0  # dd/dl (n, 2, 3)
    g1 = xh[:, :, 1] * inv - c * l1
    dl = D[:, :, 1:, :]  # (n, 2, 4, 3)
    J = g0[:, :, None] * dl[..., 0] + g1[:, :, None] * dl[..., 1] + inv[:, :, None] * dl[..., 2]
    return d, J


def epipolar_residuals_jac(psi, t, z, y, q, L_k, L_c, R_rl, t_rl):
    """Signed point-to-epipolar-line distances and their gradient w.r.t. chi = (psi, t_CK).

    Returns r (2n,) ordered [d_1L, d_1R, d_2L, ...] (normalized units) and J (2n, 4).
    """
    L_k = np.asarray(L_k, float)
    L_c = np.asarray(L_c, float)
    R_rl = np.asarray(R_rl, float)
    t_rl = np.asarray(t_rl, float)
    t = np.asarray(t, float)
    d, J = _epipolar(psi, t, z, y, q, L_k, L_c, R_rl, t_rl)
    n = len(d)
    return d.reshape(2 * n), J.reshape(2 * n, 4)


def pnp4_gn(psi, t, z, y, q, L_k, L_c, R_rl, t_rl, cond_min=1e-5, on_degenerate="truncate", backtrack=True,
            be_cov=None, sigma2=None):
    """One Gauss-Newton step on sum_i d_iL^2 + d_iR^2 (spec 6.3) -> (psi+, t+).

    ``r``/``J`` are the distances and their gradients; chi+ = chi - (J^T J)^-1 J^T r.

    ``be_cov`` (4, 4) with ``sigma2`` (normalized image variance): covariance of the input (BE)
    estimate, e.g. from :func:`pnp4_be_cov`. Then the step is taken only along the generalized
    eigen-directions of (J^T J / sigma2, be_cov^-1) whose epipolar information exceeds the BE
    information (mu >= 1); along the others (the weakly observable baseline direction near the
    collinear-centre degeneracy, spec 6.3) the BE value is kept. This replaces the
    ``cond_min`` cut; backtracking is applied as below.

    Safeguards (spec 6.3 [PROPOSAL], our parameter choices, see docs/estimators_notes.md):

    * Conditioning: eigen-directions of J^T J with eigenvalue < ``cond_min`` * lambda_max are
      not moved (truncated GN step), i.e. the BE value is kept along them
      (``on_degenerate="truncate"``); ``"raise"`` raises DegenerateInput instead. The spec's
      1e-8 only catches the exact collinear-centre configuration; in the 11.3 simulations runs
      with ratio < 1e-5 (about 0.15 %) had one-step/ML translation errors of up to 7x their own
      CRLB4 (nonlinear regime along the weak baseline direction) while BE was fine there.
      ``cond_min`` compares rad^2 with m^2 entries (chi = (psi [rad], t [m])).
    * ``backtrack=True``: accept the step only if it lowers cost (1), halving it up to 4 times,
      else keep the input. Asymptotically the full step always descends, so S1's
      o_p(n^-1/2) argument is unaffected. ``backtrack=False`` is the plain step.
    """
    psi = finite_scalar(psi, "psi")
    t = as_matrix(t, (3,), "t")
    z = as_points(z, 2, "z")
    y = as_points(y, 2, "y")
    q = as_points(q, 2, "q")
    n = same_length(z, y, q)
    need(n, 2)
    if on_degenerate not in ("truncate", "raise"):
        raise ValueError("on_degenerate must be 'truncate' or 'raise'")
    L_k = np.asarray(L_k, float)
    L_c = np.asarray(L_c, float)
    R_rl = np.asarray(R_rl, float)
    t_rl = np.asarray(t_rl, float)
    r, J = _epipolar(psi, t, z, y, q, L_k, L_c, R_rl, t_rl)
    r = r.reshape(2 * n)
    J = J.reshape(2 * n, 4)
    N = J.T @ J
    ev, V = np.linalg.eigh(N)
    if not ev[-1] > 0:
        raise DegenerateInput("pnp4_gn: zero Jacobian")
    ok = ev >= cond_min * ev[-1]
    if not ok.all() and on_degenerate == "raise":
        raise DegenerateInput(f"pnp4_gn: ill-conditioned J^T J (ratio {ev[0] / ev[-1]:.3g})")
    if be_cov is None:
        Vk = V[:, ok]
        delta = Vk @ ((Vk.T @ (J.T @ r)) / ev[ok])
    else:
        if sigma2 is None or not sigma2 > 0:
            raise ValueError("be_cov needs sigma2 > 0")
        Lb = np.linalg.cholesky(as_matrix(be_cov, (4, 4), "be_cov"))  # be_cov = Lb Lb^T
        Fw = Lb.T @ N @ Lb / sigma2  # epipolar information in BE-whitened coordinates
        mu, Wv = np.linalg.eigh(Fw)
        keep = mu >= 1.0
        Wk = Wv[:, keep]
        delta = Lb @ (Wk @ ((Wk.T @ (Lb.T @ (J.T @ r) / sigma2)) / mu[keep]))
    if not backtrack:
        return float(wrap_angle(psi - delta[0])), t - delta[1:]
    cost0 = r @ r
    for k in range(5):
        a = 0.5**k
        cand = (float(wrap_angle(psi - a * delta[0])), t - a * delta[1:])
        rc, _ = _epipolar(cand[0], cand[1], z, y, q, L_k, L_c, R_rl, t_rl, jac=False)
        rc = rc.reshape(2 * n)
        if rc @ rc <= cost0:
            return cand
    return psi, t.copy()
