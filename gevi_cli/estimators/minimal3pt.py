"""3-point relative-pose solver with known roll/pitch (yaw + translation direction) and its RANSAC
(spec section 7).

Inputs: keyframe-left ``z`` and current-left ``q`` normalized coordinates (n, 2), levelling
rotations L_K, L_C. Outputs: relative yaw ``psi`` (rad) of ``R_CK = L_C^T Rz(psi) L_K`` and the unit
direction of ``t_CK`` (current-left coordinates). The 2D-2D solver cannot fix the scale; the sign
of the direction is fixed by cheirality in :func:`ransac_3pt_upright` only.
"""

from __future__ import annotations

import math

import numpy as np

from ._checks import as_matrix, as_points, finite_scalar, need, same_length
from .errors import DegenerateInput, ShapeError
from .lie import homogeneous, rot_z, skew

_ANG5 = 2.0 * np.pi * np.arange(5) / 5.0
_RZ5 = rot_z(_ANG5)  # (5, 3, 3)
_COS = np.cos(np.outer([1, 2], _ANG5))
_SIN = np.sin(np.outer([1, 2], _ANG5))


def _cross(a, b):
    """np.cross for (..., 3) arrays without its axis-juggling overhead."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


_RZ5T = np.ascontiguousarray(np.swapaxes(_RZ5, 1, 2))


def _solve_batch(u, w, unit_tol=1e-3):
    """Batched solver. u, w: levelled bearings (B, 3, 3) [sample, point, xyz].

    Returns (sample_index (H,), psi (H,), tau (H, 3) unit, in the level frame).
    """
    B = u.shape[0]
    Ru = np.matmul(u[:, None], _RZ5T[None])  # (B, 5, 3, 3): [s, k, j, :] = Rz(psi_k) u_sj
    m = _cross(Ru, w[:, None, :, :])
    f = np.linalg.det(m)  # (B, 5): f(psi_k)
    a0 = f.mean(axis=1)
    a = 2.0 / 5.0 * f @ _COS.T  # (B, 2): a1, a2
    b = 2.0 / 5.0 * f @ _SIN.T  # (B, 2): b1, b2
    c4 = (a[:, 1] - 1j * b[:, 1]) / 2.0
    c3 = (a[:, 0] - 1j * b[:, 0]) / 2.0
    coeffs = np.stack([c4, c3, a0 + 0j, np.conj(c3), np.conj(c4)], axis=1)  # (B, 5)
    scale = np.max(np.abs(coeffs), axis=1)
    ref = np.prod(np.linalg.norm(u, axis=2), axis=1) * np.prod(np.linalg.norm(w, axis=2), axis=1)
    valid = scale > 1e-12 * ref  # f identically zero -> degenerate sample
    roots = np.full((B, 4), np.nan + 0j)
    good = valid & (np.abs(c4) > 1e-10 * scale)
    if np.any(good):
        cm = coeffs[good] / c4[good][:, None]
        Cmp = np.zeros((cm.shape[0], 4, 4), dtype=complex)
        Cmp[:, 0, :] = -cm[:, 1:]
        Cmp[:, 1, 0] = Cmp[:, 2, 1] = Cmp[:, 3, 2] = 1.0
        roots[good] = np.linalg.eigvals(Cmp)
    for s in np.flatnonzero(valid & ~good):  # rare: vanishing leading coefficient
        r = np.roots(np.trim_zeros(coeffs[s] / scale[s], "f"))
        roots[s, : len(r)] = r
    on = np.isfinite(roots) & (np.abs(np.abs(roots) - 1.0) < unit_tol)
    sidx, ridx = np.nonzero(on)
    psi = np.angle(roots[sidx, ridx])
    # translation direction from the two columns with the largest cross product
    Rp = rot_z(psi)
    mm = _cross(np.matmul(u[sidx], np.swapaxes(Rp, 1, 2)), w[sidx])  # (H, 3, 3)
    cands = np.stack([_cross(mm[:, 0], mm[:, 1]), _cross(mm[:, 0], mm[:, 2]), _cross(mm[:, 1], mm[:, 2])], 1)
    nr = np.linalg.norm(cands, axis=2)
    best = np.argmax(nr, axis=1)
    tau = cands[np.arange(len(best)), best]
    nb = nr[np.arange(len(best)), best]
    ok = nb > 0
    return sidx[ok], psi[ok], tau[ok] / nb[ok, None]


def solve_3pt_upright(z3, q3, L_k, L_c):
    """All solutions (up to 4) of the 3-point known-vertical problem: list of (psi, t_dir).

    ``t_dir`` is a unit vector in current-left coordinates with arbitrary sign.
    """
    z3 = as_points(z3, 2, "z3")
    q3 = as_points(q3, 2, "q3")
    if len(z3) != 3 or len(q3) != 3:
        raise ShapeError("solve_3pt_upright needs exactly 3 correspondences")
    L_k = as_matrix(L_k, (3, 3), "L_k")
    L_c = as_matrix(L_c, (3, 3), "L_c")
    u = homogeneous(z3) @ L_k.T
    w = homogeneous(q3) @ L_c.T
    _, psi, tau = _solve_batch(u[None], w[None])
    if len(psi) == 0:
        raise DegenerateInput("solve_3pt_upright: no real solution / degenerate sample")
    return [(float(ps), L_c.T @ ta) for ps, ta in zip(psi, tau)]


def essential_upright(psi, t_dir, L_k, L_c):
    """E with q^h^T E z^h = 0 for R_CK = L_C^T Rz(psi) L_K and translation t_CK (any scale)."""
    return skew(np.asarray(t_dir)) @ (np.asarray(L_c).T @ rot_z(psi) @ np.asarray(L_k))


def sampson_distances(E, z, q):
    """Sampson distances (normalized units) for one or many essential matrices E (..., 3, 3)."""
    zh, qh = homogeneous(z), homogeneous(q)
    return _sampson_h(np.asarray(E, dtype=float), zh, qh)


def _sampson_h(E, zh, qh):
    Ez = zh @ np.swapaxes(E, -1, -2)  # (..., n, 3)
    Etq = qh @ E
    num = np.sum(qh * Ez, axis=-1)
    den = np.sqrt(Ez[..., 0] ** 2 + Ez[..., 1] ** 2 + Etq[..., 0] ** 2 + Etq[..., 1] ** 2)
    return num / np.maximum(den, 1e-300)


def ransac_iterations(w, s=3, p=0.99) -> int:
    """N(s) = ceil(log(1-p) / log(1-w^s)) for inlier ratio w."""
    if w >= 1.0:
        return 1
    if w <= 0.0:
        return 10**9
    return int(math.ceil(math.log(1.0 - p) / math.log(1.0 - w**s)))


def _cheirality_sign(psi, t_dir, z, q, L_k, L_c):
    R = np.asarray(L_c).T @ rot_z(psi) @ np.asarray(L_k)
    Rz_ = homogeneous(z) @ R.T
    qh = homogeneous(q)
    qxR = np.cross(qh, Rz_)
    # keyframe depth lambda_k = -(q x t).(q x Rz)/|q x Rz|^2 must be > 0
    lam = -np.sum(np.cross(qh, t_dir) * qxR, axis=1)
    return 1.0 if np.sum(lam > 0) >= np.sum(lam < 0) else -1.0


def ransac_3pt_upright(z, q, L_k, L_c, threshold, seed=0, confidence=0.99, max_iter=1000, batch=8):
    """RANSAC over the 3-point known-vertical solver, scored by Sampson distance.

    ``threshold`` in normalized units ([PROPOSAL] 3 sigma_hat). Samples are drawn in batches of
    ``batch`` and evaluated vectorized; the adaptive stop N(3) is re-evaluated after each batch,
    so ``iterations`` (the number of minimal samples drawn) can exceed N(3) by < ``batch``.
    Returns (psi, t_dir, inlier mask, iterations); t_dir is unit, sign fixed by cheirality.
    """
    z = as_points(z, 2, "z")
    q = as_points(q, 2, "q")
    n = same_length(z, q)
    need(n, 3)
    L_k = as_matrix(L_k, (3, 3), "L_k")
    L_c = as_matrix(L_c, (3, 3), "L_c")
    threshold = finite_scalar(threshold, "threshold")
    if threshold <= 0:
        raise DegenerateInput("threshold must be > 0")
    rng = np.random.default_rng(seed)
    zh, qh = homogeneous(z), homogeneous(q)
    u_all = zh @ L_k.T
    w_all = qh @ L_c.T
    best = (-1, np.inf, None, None)  # count, truncated cost, psi, tau
    it = 0
    n_req = max_iter
    while it < min(n_req, max_iter):
        B = min(batch, max_iter - it)
        idx = np.argsort(rng.random((B, n)), axis=1)[:, :3] if n <= 64 else _draw3(rng, n, B)
        sidx, psi, tau = _solve_batch(u_all[idx], w_all[idx])
        it += B
        if len(psi) == 0:
            continue
        E = L_c.T @ skew(tau) @ rot_z(psi) @ L_k  # q^T E z = w^T [tau]x Rz u
        d = np.abs(_sampson_h(E, zh, qh))  # (H, n)
        inl = d < threshold
        cnt = inl.sum(axis=1)
        cost = np.sum(np.minimum(d, threshold) ** 2, axis=1)
        h = np.lexsort((cost, -cnt))[0]
        if cnt[h] > best[0] or (cnt[h] == best[0] and cost[h] < best[1]):
            best = (int(cnt[h]), float(cost[h]), float(psi[h]), tau[h])
            n_req = ransac_iterations(best[0] / n, 3, confidence)
    if best[2] is None:
        raise DegenerateInput("ransac_3pt_upright: no valid hypothesis")
    psi, tau = best[2], best[3]
    t_dir = L_c.T @ tau
    E = essential_upright(psi, t_dir, L_k, L_c)
    inliers = np.abs(sampson_distances(E, z, q)) < threshold
    t_dir = t_dir * _cheirality_sign(psi, t_dir, z[inliers], q[inliers], L_k, L_c)
    return psi, t_dir, inliers, it


def _draw3(rng, n, B):
    idx = rng.integers(0, n, size=(B, 3))
    for _ in range(100):
        dup = (idx[:, 0] == idx[:, 1]) | (idx[:, 0] == idx[:, 2]) | (idx[:, 1] == idx[:, 2])
        if not dup.any():
            break
        idx[dup] = rng.integers(0, n, size=(int(dup.sum()), 3))
    return idx
