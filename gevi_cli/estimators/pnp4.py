"""4-DOF gravity-aided PnP: linear LS / bias-eliminated estimators and the one-step Gauss-Newton on
the point-to-epipolar-line ML cost (spec section 6).

Model: ``R_CK(psi) = L_C^T Rz(psi) L_K`` with levelling rotations L_K, L_C (camera -> level frame,
see :func:`levelling`), ``t_CK`` in metres in current-left coordinates. ``p`` (n, 3) keyframe-left
points (m) with covariances ``cov`` (n, 3, 3); ``q`` (n, 2) normalized current-left coordinates
(treated as exact); ``z``/``y`` normalized keyframe-left/right coordinates.
"""

from __future__ import annotations

import numpy as np

from ._checks import as_covs, as_matrix, as_points, finite_scalar, need, same_length, solve_checked
from .errors import DegenerateInput, ShapeError
from .lie import drot_z, homogeneous, rot_z, wrap_angle

MIN_POINTS = 3
_M1 = np.diag([1.0, 1.0, 0.0])
_M2 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
_M3 = -np.diag([0.0, 0.0, 1.0])
_MS = (_M1, _M2, _M3)


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
        un = u / np.linalg.norm(u, axis=1, keepdims=True)
        # helper axis: the coordinate axis least aligned with u
        idx = np.argmin(np.abs(un), axis=1)
        a = np.zeros_like(un)
        a[np.arange(n), idx] = 1.0
        v1 = np.cross(un, a)
        v1 /= np.linalg.norm(v1, axis=1, keepdims=True)
        v2 = np.cross(un, v1)
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


def build_A(p, q, L_k, L_c, rows="orth"):
    """Linear system A x = b of spec 6.1, x = [cos psi, sin psi, tau], tau = L_C t_CK.

    Returns A (2n, 5), b (2n,), V (n, 3, 2), rho = L_K p (n, 3).
    """
    rho = p @ np.asarray(L_k).T
    V = row_vectors(q, L_c, rows)
    n = len(p)
    C = np.empty((n, 3, 5))
    C[:, :, 0] = rho @ _M1.T
    C[:, :, 1] = rho @ _M2.T
    C[:, :, 2:] = np.eye(3)
    Vt = np.swapaxes(V, 1, 2)
    A = Vt @ C  # (n, 2, 5)
    b = np.einsum("nki,ni->nk", Vt, rho @ _M3.T)
    return A.reshape(2 * n, 5), b.reshape(2 * n), V, rho


def bias_terms(cov_rho, V):
    """G1 (5x5) and g2 (5,) of spec 6.2 for level-frame covariances cov_rho (n, 3, 3).

    (G1)_ac = 1/n sum_i tr(P_i M_a S_i M_c^T), (g2)_a = 1/n sum_i tr(P_i M_a S_i M_3^T), with
    P_i = sum_k v_ik v_ik^T; only the leading 2x2 block / first two entries are non-zero.
    """
    n = len(V)
    P = V @ np.swapaxes(V, 1, 2)
    PM = [P @ M for M in _MS[:2]]
    SM = [cov_rho @ M.T for M in _MS]
    G1 = np.zeros((5, 5))
    g2 = np.zeros(5)
    for a in range(2):  # matrix indices, not points
        for c in range(2):
            G1[a, c] = np.einsum("nij,nji->", PM[a], SM[c]) / n
        g2[a] = np.einsum("nij,nji->", PM[a], SM[2]) / n
    return G1, g2


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
    cov_rho = L_k @ cov @ L_k.T
    G1, g2 = bias_terms(cov_rho, V)
    x = solve_checked(A.T @ A / n - G1, A.T @ b / n - g2, "pnp4_be")
    return _recover(x, L_c)


# ---------------------------------------------------------------------------------------------
# Epipolar ML cost (1) and its Jacobian


def epipolar_residuals_jac(psi, t, z, y, q, L_k, L_c, R_rl, t_rl):
    """Signed point-to-epipolar-line distances and their gradient w.r.t. chi = (psi, t_CK).

    Returns r (2n,) ordered [d_1L, d_1R, d_2L, ...] (normalized units) and J (2n, 4).
    """
    L_k = np.asarray(L_k, float)
    L_c = np.asarray(L_c, float)
    R_rl = np.asarray(R_rl, float)
    t_rl = np.asarray(t_rl, float)
    t = np.asarray(t, float)
    R = L_c.T @ rot_z(psi) @ L_k
    dR = L_c.T @ drot_z(psi) @ L_k
    qh = homogeneous(q)
    n = len(qh)
    out_r = np.empty((n, 2))
    out_J = np.empty((n, 2, 4))
    cams = (
        (R, t, dR, np.zeros(3), homogeneous(z)),
        (R @ R_rl.T, t - R @ R_rl.T @ t_rl, dR @ R_rl.T, -dR @ R_rl.T @ t_rl, homogeneous(y)),
    )
    for s, (Rs, ts, dRs, dts, xh) in enumerate(cams):  # two keyframe images
        qxt = np.cross(qh, ts)  # q x t
        l = qxt @ Rs  # l = R^T (q x t) = ([t]x R)^T q
        dl_psi = qxt @ dRs + np.cross(qh, dts) @ Rs
        dl_t = np.stack([np.cross(qh, e) @ Rs for e in np.eye(3)], axis=2)  # (n, 3, 3): d l / d t_k
        nrm = np.hypot(l[:, 0], l[:, 1])
        if np.any(nrm <= 1e-300):
            raise DegenerateInput("epipolar: degenerate epipolar line (zero translation?)")
        num = np.sum(l * xh, axis=1)
        d = num / nrm
        dd_dl = xh / nrm[:, None]
        dd_dl[:, :2] -= (num / nrm**3)[:, None] * l[:, :2]
        out_r[:, s] = d
        out_J[:, s, 0] = np.sum(dd_dl * dl_psi, axis=1)
        out_J[:, s, 1:] = np.einsum("ni,nik->nk", dd_dl, dl_t)
    return out_r.reshape(2 * n), out_J.reshape(2 * n, 4)


def pnp4_gn(psi, t, z, y, q, L_k, L_c, R_rl, t_rl, cond_min=1e-5, on_degenerate="truncate", backtrack=True):
    """One Gauss-Newton step on sum_i d_iL^2 + d_iR^2 (spec 6.3) -> (psi+, t+).

    ``r``/``J`` are the distances and their gradients; chi+ = chi - (J^T J)^-1 J^T r.

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
    r, J = epipolar_residuals_jac(psi, t, z, y, q, L_k, L_c, R_rl, t_rl)
    N = J.T @ J
    ev, V = np.linalg.eigh(N)
    if not ev[-1] > 0:
        raise DegenerateInput("pnp4_gn: zero Jacobian")
    ok = ev >= cond_min * ev[-1]
    if not ok.all() and on_degenerate == "raise":
        raise DegenerateInput(f"pnp4_gn: ill-conditioned J^T J (ratio {ev[0] / ev[-1]:.3g})")
    Vk = V[:, ok]
    delta = Vk @ ((Vk.T @ (J.T @ r)) / ev[ok])
    if not backtrack:
        return float(wrap_angle(psi - delta[0])), t - delta[1:]
    cost0 = r @ r
    for k in range(5):
        a = 0.5**k
        cand = (float(wrap_angle(psi - a * delta[0])), t - a * delta[1:])
        rc, _ = epipolar_residuals_jac(cand[0], cand[1], z, y, q, L_k, L_c, R_rl, t_rl)
        if rc @ rc <= cost0:
            return cand
    return psi, t.copy()
