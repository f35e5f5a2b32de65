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

from gevi_cli.geometry import homogeneous, rot_z, skew

from ._checks import as_matrix, as_points, finite_scalar, need, same_length
from .errors import DegenerateInput, ShapeError

_ANG5 = 2.0 * np.pi * np.arange(5) / 5.0
_RZ5 = rot_z(_ANG5)  # (5, 3, 3)
_COS = np.cos(np.outer([1, 2], _ANG5))
_SIN = np.sin(np.outer([1, 2], _ANG5))
_CS_T = np.ascontiguousarray(np.concatenate([_COS, _SIN]).T)  # (5, 4): f @ _CS_T = [a1, a2, b1, b2] * 5/2


_RZ5T = np.ascontiguousarray(np.swapaxes(_RZ5, 1, 2))

# The fast paths below evaluate every quantity with the very floating-point operations of the plain
# formulas (each entry of a matrix product is the same 3-term dot product, cross products
# a x b = a[P1] b[P2] - a[P2] b[P1] componentwise as in np.cross, sums over 3 terms left to right
# as numpy reduces them), only laid out for fewer and larger numpy calls.
_P1 = np.array([1, 2, 0])
_P2 = np.array([2, 0, 1])
_P12 = np.concatenate([_P1, _P2])
_P21 = np.concatenate([_P2, _P1])
# u @ _RZ5T_P12 = Rz(psi_k) u permuted by P1 and by P2 for the 5 sample angles: [l, (r, k, c)]
_RZ5T_P12 = np.ascontiguousarray(_RZ5T[:, :, np.stack([_P1, _P2])].transpose(1, 2, 0, 3).reshape(3, 30))
# Rz (3, 3) flattened -> Rz^T with its columns permuted by P1 and by P2, (3, 6): entry [l, (r, c)]
_RZT_P12 = (3 * _P12[None, :] + np.arange(3)[:, None]).ravel()
# the three pairwise cross products (rows 0x1, 0x2, 1x2) of a flattened (3, 3) matrix: the left and
# right factors of the products a[P1] b[P2] and a[P2] b[P1]
_I, _J, _C = np.repeat([0, 0, 1], 3), np.repeat([1, 2, 2], 3), np.tile(np.arange(3), 3)
_PAIRS = np.concatenate([3 * _I + _P1[_C], 3 * _I + _P2[_C], 3 * _J + _P2[_C], 3 * _J + _P1[_C]])
# skew(t)^T = skew(-t) flattened, from [t, -t, 0]
_SKEW_T = np.array([6, 2, 4, 5, 6, 0, 1, 3, 6])
_CMP = {}  # batch size -> companion-matrix template (ones on the subdiagonal)


def _companion(B):
    C = _CMP.get(B)
    if C is None:
        C = _CMP[B] = np.zeros((B, 4, 4), dtype=complex)
        C[:, 1, 0] = C[:, 2, 1] = C[:, 3, 2] = 1.0
    return C.copy()


def _level_points(uwT):
    """Per-point data of levelled bearings u, w given transposed and stacked, uwT (6, n) = [u^T; w^T],
    for :func:`_solve_core`: (n, 11) array [u, w permuted by P2 then by P1, |u|, |w|]."""
    P = np.empty((uwT.shape[1], 11))
    P[:, :3] = uwT[:3].T
    P[:, 3:9] = uwT[3 + _P21].T
    x = (uwT * uwT).reshape(2, 3, -1)
    x[:, 0] += x[:, 1]
    x[:, 0] += x[:, 2]  # = np.add.reduce over the components (left to right)
    P[:, 9:] = np.sqrt(x[:, 0]).T
    return P


def _solve_batch(u, w, unit_tol=1e-3):
    """Batched solver. u, w: levelled bearings (B, 3, 3) [sample, point, xyz].

    Returns (sample_index (H,), psi (H,), tau (H, 3) unit, in the level frame).
    """
    u, w = np.asarray(u, dtype=float), np.asarray(w, dtype=float)
    P = _level_points(np.concatenate([u.reshape(-1, 3).T, w.reshape(-1, 3).T])).reshape(u.shape[0], 3, 11)
    sidx, psi, tau, _ = _solve_core(P, unit_tol)
    return sidx, psi, tau


def _solve_core(P, unit_tol=1e-3):
    """:func:`_solve_batch` on per-point data P (B, 3, 11) of :func:`_level_points`.

    Returns (sample_index (H,), psi (H,), tau (H, 3) unit, Rz(psi) (H, 3, 3)).
    """
    B = P.shape[0]
    u, W = P[:, :, :3], P[:, :, 3:9]
    # m[s, j, k] = Rz(psi_k) u_sj x w_sj, psi_k = 2 pi k / 5; f(psi_k) = det_j,c m[s, j, k, c]
    G = (u.reshape(3 * B, 3) @ _RZ5T_P12).reshape(B, 3, 2, 5, 3)
    G *= W.reshape(B, 3, 2, 1, 3)
    f = np.linalg.det((G[:, :, 0] - G[:, :, 1]).transpose(0, 2, 1, 3))  # (B, 5): f(psi_k)
    a0 = np.add.reduce(f, axis=1) / 5  # = f.mean(axis=1)
    ab = 2.0 / 5.0 * f @ _CS_T  # (B, 4): a1, a2, b1, b2
    c34 = (ab[:, :2] - 1j * ab[:, 2:]) / 2.0  # (B, 2): c3, c4
    coeffs = np.empty((B, 5), dtype=complex)
    coeffs[:, 0] = c34[:, 1]
    coeffs[:, 1] = c34[:, 0]
    coeffs[:, 2] = a0 + 0j
    np.conjugate(c34, out=coeffs[:, 3:])
    acoef = np.abs(coeffs)
    scale = np.maximum.reduce(acoef, axis=1)
    ref = np.multiply.reduce(P[:, :, 9:], axis=1)  # (B, 2): prod |u_j|, prod |w_j|
    valid = scale > 1e-12 * (ref[:, 0] * ref[:, 1])  # f identically zero -> degenerate sample
    good = valid & (acoef[:, 0] > 1e-10 * scale)
    if good.all():
        Cmp = _companion(B)
        np.negative(coeffs[:, 1:] / coeffs[:, :1], out=Cmp[:, 0, :])
        roots = np.linalg.eigvals(Cmp)
    else:
        roots = np.full((B, 4), np.nan + 0j)
        if good.any():
            cm = coeffs[good] / coeffs[good, :1]
            Cmp = _companion(cm.shape[0])
            Cmp[:, 0, :] = -cm[:, 1:]
            roots[good] = np.linalg.eigvals(Cmp)
        for s in np.flatnonzero(valid & ~good):  # rare: vanishing leading coefficient
            r = np.roots(np.trim_zeros(coeffs[s] / scale[s], "f"))
            roots[s, : len(r)] = r
    on = np.abs(np.abs(roots) - 1.0) < unit_tol  # (false for the nan of missing roots)
    sidx = on.nonzero()[0]
    r = roots[on]
    psi = np.arctan2(r.imag, r.real)  # = np.angle
    H = len(psi)
    # translation direction from the two columns with the largest cross product
    Rp = rot_z(psi)
    G = np.matmul(u[sidx], Rp.reshape(H, 9)[:, _RZT_P12].reshape(H, 3, 6))  # Rz(psi) u_j permuted
    G *= W[sidx]
    mm = (G[:, :, :3] - G[:, :, 3:]).reshape(H, 9)  # rows Rz u_j x w_j
    g = mm[:, _PAIRS]
    g = g[:, :18] * g[:, 18:]
    cands = (g[:, :9] - g[:, 9:]).reshape(H, 3, 3)
    nr = np.sqrt(np.add.reduce(cands * cands, axis=2))  # = np.linalg.norm(cands, axis=2)
    best = nr.argmax(axis=1)
    ar = np.arange(H)
    tau = cands[ar, best]
    nb = nr[ar, best]
    ok = nb > 0
    if not ok.all():
        sidx, psi, tau, nb, Rp = sidx[ok], psi[ok], tau[ok], nb[ok], Rp[ok]
    tau /= nb[:, None]
    return sidx, psi, tau, Rp


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
    """|Sampson distances| (H, n) of E given row-major as (3, H, 3) [row i, hypothesis, column], points
    given transposed: zhT, qhT (3, n) contiguous.

    The same operations as :func:`_sampson_h` (each entry of E z^h, E^T q^h is the same 3-term dot
    product, num = (q0 (Ez)0 + q1 (Ez)1) + (Ez)2), laid out with the points along contiguous rows.
    """
    H = E.shape[1]
    Ez = (E.reshape(3 * H, 3) @ zhT).reshape(3, H, -1)  # [i, h] = (E_h z^h)_i
    Et = (E.transpose(2, 1, 0)[:2].reshape(2 * H, 3) @ qhT).reshape(2, H, -1)  # [k, h] = (E_h^T q^h)_k
    num = Ez[0] * qhT[0]
    num += Ez[1] * qhT[1]
    num += Ez[2]
    E01 = Ez[:2]
    np.square(E01, out=E01)
    np.square(Et, out=Et)
    den = E01[0] + E01[1]
    den += Et[0]
    den += Et[1]
    np.sqrt(den, out=den)
    if den.min() < 1e-300:  # (a cheap test: np.maximum is the identity otherwise)
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


def ransac_3pt_upright(z, q, L_k, L_c, threshold, seed=0, confidence=0.99, max_iter=1000, batch=8, first_batch=2):
    """RANSAC over the 3-point known-vertical solver, scored by Sampson distance.

    ``threshold`` in normalized units ([PROPOSAL] 3 sigma_hat). ``seed``: an int, or a
    ``numpy.random.Generator`` to draw from (a run passes one generator re-positioned per frame: creating
    a generator per call cost more than the whole 3-point solve of a clean frame). Samples are drawn in
    batches and evaluated vectorized; the adaptive stop N(3) is re-evaluated after each batch, so
    ``iterations`` (the number of minimal samples drawn) can exceed N(3) by < ``batch``.  Batches
    grow from ``first_batch`` by doubling up to ``batch``: with few outliers N(3) is 1-2 and the
    first small batch ends the search (a batch of 8 cost 0.46 ms per frame against 0.32 ms on
    pool-easy_s1, where OpenCV's 5-point takes 0.34; study in docs/method.md section 7), while many
    outliers still get large vectorized batches.
    Returns (psi, t_dir, inlier mask, iterations); t_dir is unit, sign fixed by cheirality; the mask
    is the one the winning hypothesis was counted with.
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
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    zqT = np.empty((6, n))  # homogeneous points, transposed: [z^h; q^h]
    zqT[:2], zqT[3:5] = z.T, q.T
    zqT[2] = zqT[5] = 1.0
    zhT, qhT = zqT[:3], zqT[3:]
    LL = np.zeros((6, 6))  # levelled bearings [u; w] = diag(L_k, L_c) [z^h; q^h], for the drawn points only
    LL[:3, :3], LL[3:, 3:] = L_k, L_c
    best = (-1, np.inf, None, None, None, None)  # count, truncated cost, psi, tau, inlier mask, Rz(psi)
    it = 0
    n_req = max_iter
    B_next = max(1, min(first_batch, batch))
    while it < min(n_req, max_iter):
        B = min(B_next, max_iter - it)
        B_next = min(2 * B_next, batch)
        idx = _draw3(rng, n, B)
        _, psi, tau, Rz = _solve_core(_level_points(LL @ zqT[:, idx.ravel()]).reshape(B, 3, 11))
        it += B
        H = len(psi)
        if H == 0:
            continue
        # E = L_c^T [tau]x Rz(psi) L_k (q^T E z = w^T [tau]x Rz u), with L_c^T [tau]x = ([tau]x^T L_c)^T
        T = np.empty((H, 7))
        T[:, :3] = tau
        np.negative(tau, out=T[:, 3:6])
        T[:, 6] = 0.0
        A = (T[:, _SKEW_T].reshape(3 * H, 3) @ L_c).reshape(H, 3, 3)
        E = np.matmul(np.swapaxes(A, 1, 2), Rz).transpose(1, 0, 2) @ L_k  # (3, H, 3) [row, h, column]
        d = _abs_sampson_t(E, zhT, qhT)  # (H, n)
        inl = d < threshold
        cnt = np.add.reduce(inl, axis=1, dtype=np.intp)  # = np.count_nonzero(., axis=1)
        np.minimum(d, threshold, out=d)
        cost = np.add.reduce(np.square(d, out=d), axis=1)
        h = np.lexsort((cost, -cnt))[0]
        if cnt[h] > best[0] or (cnt[h] == best[0] and cost[h] < best[1]):
            best = (int(cnt[h]), float(cost[h]), float(psi[h]), tau[h], inl[h], Rz[h])
            n_req = ransac_iterations(best[0] / n, 3, confidence)
    if best[2] is None:
        raise DegenerateInput("ransac_3pt_upright: no valid hypothesis")
    psi, tau, inliers = best[2], best[3], best[4]
    L_cT = L_c.T
    t_dir = L_cT @ tau
    R = L_cT @ best[5] @ L_k
    # cheirality: keyframe depth lambda_k = -(q x t).(q x Rz)/|q x Rz|^2 > 0 for most inliers
    Q = qhT[_P12]  # q permuted by P1 and by P2
    qR = Q * (R[_P21] @ zhT)  # with R z^h permuted by P2 and by P1
    qR = qR[:3] - qR[3:]  # q x Rz
    qt = Q * t_dir[_P21, None]
    qt = qt[:3] - qt[3:]  # q x t
    qR *= qt
    s = qR[0] + qR[1]
    s += qR[2]  # = -lambda_k |q x Rz|^2
    s = s[inliers]
    if np.add.reduce(np.sign(s)) > 0:  # more negative depths than positive ones
        t_dir = -t_dir
    return psi, t_dir, inliers, it


_DUP_A, _DUP_B = np.array([0, 0, 1]), np.array([1, 2, 2])


def _draw3(rng, n, B):
    """B minimal samples of 3 distinct indices in [0, n), uniform: floor(n U) (U < 1, so < n), with the
    samples holding a repeated index drawn again."""
    idx = (rng.random((B, 3)) * n).astype(np.intp)
    for _ in range(1000):
        dup = (idx[:, _DUP_A] == idx[:, _DUP_B]).any(axis=1)
        if not dup.any():
            return idx
        idx[dup] = (rng.random((int(dup.sum()), 3)) * n).astype(np.intp)
    raise DegenerateInput(f"could not draw 3 distinct indices out of {n}")
