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
_CS_T = np.ascontiguousarray(np.concatenate([_COS, _SIN]).T)  # (5, 4): f @ _CS_T = [a1, a2, b1, b2] * 5/2


def _cross(a, b):
    """np.cross for (..., 3) arrays without its axis-juggling overhead."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


_RZ5T = np.ascontiguousarray(np.swapaxes(_RZ5, 1, 2))

# Cross products a x b are evaluated as a[P1] * b[P2] - a[P2] * b[P1] (component c of the result is
# a[c+1] b[c+2] - a[c+2] b[c+1]: the very products and differences of _cross / np.cross).
_P1 = np.array([1, 2, 0])
_P2 = np.array([2, 0, 1])
_P12 = np.concatenate([_P1, _P2])
# u @ _RZ5T_P12 gives, for each of the 5 sample angles, Rz(psi_k) u with its components permuted by
# P1 and by P2 in one matrix product: [l, (r, k, c)] = Rz(psi_k)^T[l, P_r[c]], shape (3, 2 * 5 * 3).
_RZ5T_P12 = np.ascontiguousarray(_RZ5T[:, :, np.stack([_P1, _P2])].transpose(1, 2, 0, 3).reshape(3, 30))
# the three pairwise cross products of the rows of a (3, 3) matrix (rows 0x1, 0x2, 1x2), flat indices
_I, _J = np.repeat([0, 0, 1], 3), np.repeat([1, 2, 2], 3)
_C = np.tile(np.arange(3), 3)
_PAIRS = np.concatenate([3 * _I + _P1[_C], 3 * _J + _P2[_C], 3 * _I + _P2[_C], 3 * _J + _P1[_C]])


def _level_points(u, w):
    """Per-point data of levelled bearings u, w (..., 3) for :func:`_solve_core`.

    Returns (u, w with its components permuted by P1 and by P2 (..., 6), |u| (...), |w| (...)).
    """
    nu = np.sqrt(np.sum(u * u, axis=-1))
    nw = np.sqrt(np.sum(w * w, axis=-1))
    return u, w[..., _P12], nu, nw


def _solve_batch(u, w, unit_tol=1e-3):
    """Batched solver. u, w: levelled bearings (B, 3, 3) [sample, point, xyz].

    Returns (sample_index (H,), psi (H,), tau (H, 3) unit, in the level frame).
    """
    u = np.ascontiguousarray(u, dtype=float)
    w = np.ascontiguousarray(w, dtype=float)
    sidx, psi, tau, _ = _solve_core(*_level_points(u, w), unit_tol)
    return sidx, psi, tau


def _solve_core(u, w12, nu, nw, unit_tol=1e-3):
    """:func:`_solve_batch` on the output of :func:`_level_points` (u contiguous (B, 3, 3)).

    Returns (sample_index (H,), psi (H,), tau (H, 3) unit, Rz(psi) (H, 3, 3)).
    """
    B = u.shape[0]
    # m[s, j, k] = Rz(psi_k) u_sj x w_sj, psi_k = 2 pi k / 5; f(psi_k) = det_j,c m[s, j, k, c]
    G = (u.reshape(3 * B, 3) @ _RZ5T_P12).reshape(B, 3, 2, 5, 3)
    m = G[:, :, 0] * w12[:, :, None, 3:] - G[:, :, 1] * w12[:, :, None, :3]  # (B, 3, 5, 3)
    f = np.linalg.det(m.transpose(0, 2, 1, 3))  # (B, 5): f(psi_k)
    a0 = f.mean(axis=1)
    ab = 2.0 / 5.0 * f @ _CS_T  # (B, 4): a1, a2, b1, b2
    c34 = (ab[:, :2] - 1j * ab[:, 2:]) / 2.0  # (B, 2): c3, c4
    coeffs = np.empty((B, 5), dtype=complex)
    coeffs[:, 0] = c34[:, 1]
    coeffs[:, 1] = c34[:, 0]
    coeffs[:, 2] = a0 + 0j
    coeffs[:, 3:] = np.conj(c34)
    acoef = np.abs(coeffs)
    scale = np.max(acoef, axis=1)
    nup, nwp = nu[:, 0] * nu[:, 1] * nu[:, 2], nw[:, 0] * nw[:, 1] * nw[:, 2]
    valid = scale > 1e-12 * (nup * nwp)  # f identically zero -> degenerate sample
    good = valid & (acoef[:, 0] > 1e-10 * scale)
    if good.all():
        Cmp = np.zeros((B, 4, 4), dtype=complex)
        Cmp[:, 0, :] = -(coeffs[:, 1:] / coeffs[:, :1])
        Cmp[:, 1, 0] = Cmp[:, 2, 1] = Cmp[:, 3, 2] = 1.0
        roots = np.linalg.eigvals(Cmp)
    else:
        roots = np.full((B, 4), np.nan + 0j)
        if np.any(good):
            cm = coeffs[good] / coeffs[good, :1]
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
    H = len(psi)
    # translation direction from the two columns with the largest cross product
    Rp = rot_z(psi)
    G = np.matmul(u[sidx], np.swapaxes(Rp, 1, 2)[:, :, _P12])  # (H, 3, 6): Rz(psi) u_j permuted
    w12 = w12[sidx]
    mm = (G[:, :, :3] * w12[:, :, 3:] - G[:, :, 3:] * w12[:, :, :3]).reshape(H, 9)  # rows Rz u_j x w_j
    g = mm[:, _PAIRS]
    cands = (g[:, :9] * g[:, 9:18] - g[:, 18:27] * g[:, 27:]).reshape(H, 3, 3)
    sq = cands * cands
    nr = np.sqrt(sq[:, :, 0] + sq[:, :, 1] + sq[:, :, 2])
    best = np.argmax(nr, axis=1)
    ar = np.arange(H)
    tau = cands[ar, best]
    nb = nr[ar, best]
    ok = nb > 0
    if not ok.all():
        sidx, psi, tau, nb, Rp = sidx[ok], psi[ok], tau[ok], nb[ok], Rp[ok]
    return sidx, psi, tau / nb[:, None], Rp


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


def _abs_sampson_t(E, zhT, qhT):
    """|Sampson distances| (H, n) of E (H, 3, 3), points given transposed: zhT, qhT (3, n) contiguous.

    The same operations as :func:`_sampson_h` (each entry of E z^h, E^T q^h is the same 3-term dot
    product, num = (q0 (Ez)0 + q1 (Ez)1) + (Ez)2), laid out with the points along contiguous rows.
    """
    H, n = E.shape[0], zhT.shape[1]
    Ez = (E.reshape(3 * H, 3) @ zhT).reshape(H, 3, n)
    Et = (np.swapaxes(E, 1, 2)[:, :2].reshape(2 * H, 3) @ qhT).reshape(H, 2, n)
    num = Ez[:, 0] * qhT[0]
    num += Ez[:, 1] * qhT[1]
    num += Ez[:, 2]
    np.square(Ez[:, :2], out=Ez[:, :2])
    np.square(Et, out=Et)
    den = Ez[:, 0] + Ez[:, 1]
    den += Et[:, 0]
    den += Et[:, 1]
    np.sqrt(den, out=den)
    np.maximum(den, 1e-300, out=den)
    np.divide(num, den, out=num)
    return np.abs(num, out=num)


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


def _cheirality_sign_t(R, t_dir, zhT, qhT):
    """:func:`_cheirality_sign` with R = R_CK given and the (inlier) points transposed (3, k)."""
    Rz_ = R @ zhT  # (3, k)
    q0, q1 = qhT[0], qhT[1]
    # q x Rz and q x t with q = (q0, q1, 1); the sign of lambda_k is the sign of -(q x t).(q x Rz)
    s = (q1 * t_dir[2] - t_dir[1]) * (q1 * Rz_[2] - Rz_[1])
    s += (t_dir[0] - q0 * t_dir[2]) * (Rz_[0] - q0 * Rz_[2])
    s += (q0 * t_dir[1] - q1 * t_dir[0]) * (q0 * Rz_[1] - q1 * Rz_[0])
    return 1.0 if np.count_nonzero(s < 0) >= np.count_nonzero(s > 0) else -1.0


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
    zhT, qhT = np.ascontiguousarray(zh.T), np.ascontiguousarray(qh.T)
    u_all, w12_all, nu_all, nw_all = _level_points(zh @ L_k.T, qh @ L_c.T)
    L_cT = L_c.T
    best = (-1, np.inf, None, None)  # count, truncated cost, psi, tau
    it = 0
    n_req = max_iter
    while it < min(n_req, max_iter):
        B = min(batch, max_iter - it)
        idx = np.argsort(rng.random((B, n)), axis=1)[:, :3] if n <= 64 else _draw3(rng, n, B)
        sidx, psi, tau, Rz = _solve_core(u_all[idx], w12_all[idx], nu_all[idx], nw_all[idx])
        it += B
        H = len(psi)
        if H == 0:
            continue
        E = (L_cT @ skew(tau)) @ Rz @ L_k  # q^T E z = w^T [tau]x Rz u
        d = _abs_sampson_t(E, zhT, qhT)  # (H, n)
        cnt = np.count_nonzero(d < threshold, axis=1)
        np.minimum(d, threshold, out=d)
        cost = np.sum(np.square(d, out=d), axis=1)
        h = np.lexsort((cost, -cnt))[0]
        if cnt[h] > best[0] or (cnt[h] == best[0] and cost[h] < best[1]):
            best = (int(cnt[h]), float(cost[h]), float(psi[h]), tau[h])
            n_req = ransac_iterations(best[0] / n, 3, confidence)
    if best[2] is None:
        raise DegenerateInput("ransac_3pt_upright: no valid hypothesis")
    psi, tau = best[2], best[3]
    t_dir = L_cT @ tau
    R = L_cT @ rot_z(psi) @ L_k
    E = skew(t_dir) @ R  # = essential_upright(psi, t_dir, L_k, L_c)
    inliers = _abs_sampson_t(E[None], zhT, qhT)[0] < threshold
    t_dir = t_dir * _cheirality_sign_t(R, t_dir, zhT[:, inliers], qhT[:, inliers])
    return psi, t_dir, inliers, it


def _draw3(rng, n, B):
    idx = rng.integers(0, n, size=(B, 3))
    for _ in range(100):
        dup = (idx[:, 0] == idx[:, 1]) | (idx[:, 0] == idx[:, 2]) | (idx[:, 1] == idx[:, 2])
        if not dup.any():
            break
        idx[dup] = rng.integers(0, n, size=(int(dup.sum()), 3))
    return idx
