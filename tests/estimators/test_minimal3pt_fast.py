"""The vectorized 3-point RANSAC (minimal3pt._solve_core, _abs_sampson_t, ransac_3pt_upright) against
the plain formulation it replaced (kept here as the reference).

The fast path performs the same floating-point operations as the reference (every entry of a
matrix product is the same 3-term dot product, cross products and 3-term sums in the same order),
only in other array layouts, so on one machine the results are bit-identical. The tolerances below
only allow for a BLAS that rounds the same dot product differently in differently shaped products:
one ulp in the model entries moves psi and t_dir by ~1e-16 times the (small) condition number of
these problems, hence 1e-12; a point changes side of the threshold only if its distance is within
an ulp of it, which does not happen on these draws, hence equal masks and iteration counts.
"""

import math

import numpy as np
import pytest

from gevi_cli.estimators import (
    DegenerateInput,
    essential_upright,
    ransac_3pt_upright,
    ransac_iterations,
    sampson_distances,
)
from gevi_cli.estimators import minimal3pt as m3
from gevi_cli.geometry import homogeneous, rot_z, skew
from gevi_cli.studies import simulation as sim

# ----------------------------------------------------------------------------------- reference
_ANG5 = 2.0 * np.pi * np.arange(5) / 5.0
_RZ5T = np.ascontiguousarray(np.swapaxes(rot_z(_ANG5), 1, 2))
_COS = np.cos(np.outer([1, 2], _ANG5))
_SIN = np.sin(np.outer([1, 2], _ANG5))


def _ref_solve_batch(u, w, unit_tol=1e-3):
    Ru = np.matmul(u[:, None], _RZ5T[None])
    f = np.linalg.det(np.cross(Ru, w[:, None, :, :]))
    a0 = f.mean(axis=1)
    a = 2.0 / 5.0 * f @ _COS.T
    b = 2.0 / 5.0 * f @ _SIN.T
    c4 = (a[:, 1] - 1j * b[:, 1]) / 2.0
    c3 = (a[:, 0] - 1j * b[:, 0]) / 2.0
    coeffs = np.stack([c4, c3, a0 + 0j, np.conj(c3), np.conj(c4)], axis=1)
    scale = np.max(np.abs(coeffs), axis=1)
    ref = np.prod(np.linalg.norm(u, axis=2), axis=1) * np.prod(np.linalg.norm(w, axis=2), axis=1)
    valid = scale > 1e-12 * ref
    roots = np.full((u.shape[0], 4), np.nan + 0j)
    good = valid & (np.abs(c4) > 1e-10 * scale)
    if np.any(good):
        cm = coeffs[good] / c4[good][:, None]
        Cmp = np.zeros((cm.shape[0], 4, 4), dtype=complex)
        Cmp[:, 0, :] = -cm[:, 1:]
        Cmp[:, 1, 0] = Cmp[:, 2, 1] = Cmp[:, 3, 2] = 1.0
        roots[good] = np.linalg.eigvals(Cmp)
    for s in np.flatnonzero(valid & ~good):
        r = np.roots(np.trim_zeros(coeffs[s] / scale[s], "f"))
        roots[s, : len(r)] = r
    on = np.isfinite(roots) & (np.abs(np.abs(roots) - 1.0) < unit_tol)
    sidx, ridx = np.nonzero(on)
    psi = np.angle(roots[sidx, ridx])
    mm = np.cross(np.matmul(u[sidx], np.swapaxes(rot_z(psi), 1, 2)), w[sidx])
    cands = np.stack([np.cross(mm[:, 0], mm[:, 1]), np.cross(mm[:, 0], mm[:, 2]), np.cross(mm[:, 1], mm[:, 2])], 1)
    nr = np.linalg.norm(cands, axis=2)
    best = np.argmax(nr, axis=1)
    tau = cands[np.arange(len(best)), best]
    nb = nr[np.arange(len(best)), best]
    ok = nb > 0
    return sidx[ok], psi[ok], tau[ok] / nb[ok, None]


def _ref_draw3(rng, n, B):
    idx = np.floor(rng.random((B, 3)) * n).astype(int)
    while True:
        dup = (idx[:, 0] == idx[:, 1]) | (idx[:, 0] == idx[:, 2]) | (idx[:, 1] == idx[:, 2])
        if not dup.any():
            return idx
        idx[dup] = np.floor(rng.random((int(dup.sum()), 3)) * n).astype(int)


def _ref_ransac(z, q, L_k, L_c, threshold, seed=0, confidence=0.99, max_iter=1000, batch=8, first_batch=2):
    rng = np.random.default_rng(seed)
    n = len(z)
    zh, qh = homogeneous(z), homogeneous(q)
    u_all, w_all = zh @ L_k.T, qh @ L_c.T
    best = (-1, np.inf, None, None)
    it, n_req, k = 0, max_iter, 0
    while it < min(n_req, max_iter):
        B = min(min(first_batch * 2 ** k, batch), max_iter - it)  # batches of 2, 4, 8, 8, ...
        k += 1
        idx = _ref_draw3(rng, n, B)
        _, psi, tau = _ref_solve_batch(u_all[idx], w_all[idx])
        it += B
        if len(psi) == 0:
            continue
        E = L_c.T @ skew(tau) @ rot_z(psi) @ L_k
        d = np.abs(sampson_distances(E, z, q))
        cnt = (d < threshold).sum(axis=1)
        cost = np.sum(np.minimum(d, threshold) ** 2, axis=1)
        h = np.lexsort((cost, -cnt))[0]
        if cnt[h] > best[0] or (cnt[h] == best[0] and cost[h] < best[1]):
            best = (int(cnt[h]), float(cost[h]), float(psi[h]), tau[h])
            n_req = ransac_iterations(best[0] / n, 3, confidence)
    if best[2] is None:
        raise DegenerateInput("no valid hypothesis")
    psi, t_dir = best[2], L_c.T @ best[3]
    inl = np.abs(sampson_distances(essential_upright(psi, t_dir, L_k, L_c), z, q)) < threshold
    R = L_c.T @ rot_z(psi) @ L_k
    qhi = homogeneous(q[inl])
    lam = -np.sum(np.cross(qhi, t_dir) * np.cross(qhi, homogeneous(z[inl]) @ R.T), axis=1)
    return psi, t_dir * (1.0 if np.sum(lam > 0) >= np.sum(lam < 0) else -1.0), inl, it


# ----------------------------------------------------------------------------------- tests
def _problems():
    rng = np.random.default_rng(2024)
    for k in range(60):
        n = (5, 12, 64, 65, 150, 400)[k % 6]
        ratio = (0.0, 0.3, 0.6)[k % 3]
        s = sim.scene4(rng, n, R_ic=sim.R_IC_FORWARD if k % 2 else None, noise_q=bool(k % 4))
        q = sim.add_outliers(rng, s.q, ratio)[0] if ratio else s.q
        yield s.z, q, s.L_k, s.L_c, 3.0 * s.sigma, int(rng.integers(1 << 31))


@pytest.mark.parametrize("prob", list(_problems()), ids=lambda p: f"n{len(p[0])}")
def test_ransac_matches_reference(prob):
    z, q, L_k, L_c, thr, seed = prob
    psi0, t0, inl0, it0 = _ref_ransac(z, q, L_k, L_c, thr, seed=seed)
    psi1, t1, inl1, it1 = ransac_3pt_upright(z, q, L_k, L_c, thr, seed=seed)
    assert it1 == it0
    assert np.array_equal(inl1, inl0)
    assert abs(psi1 - psi0) <= 1e-12
    assert np.max(np.abs(t1 - t0)) <= 1e-12


def test_solver_and_sampson_match_reference():
    rng = np.random.default_rng(7)
    hyps = 0
    for k in range(400):
        u = rng.standard_normal((8, 3, 3))
        w = rng.standard_normal((8, 3, 3))
        if k % 4 == 1:
            w[:, 2] = w[:, 1]  # repeated bearing in every sample
        if k % 4 == 2:
            u[:3] = 0.0  # degenerate samples (f identically zero) next to regular ones
        if k % 4 == 3:
            w = u @ rot_z(np.pi - 1e-7 * k).T  # pure rotation near psi = pi
        if k % 5 == 4:
            u[4:, :2, :2] = 0.0  # two vertical bearings: f(psi) of degree 1 (the np.roots branch)
        s0, p0, t0 = _ref_solve_batch(u, w)
        s1, p1, t1 = m3._solve_batch(u, w)
        assert np.array_equal(s1, s0)
        assert np.allclose(p1, p0, rtol=0.0, atol=1e-12) and np.allclose(t1, t0, rtol=0.0, atol=1e-12)
        hyps += len(p0)
        if len(p0):
            E = skew(t0) @ rot_z(p0)
            z, q = rng.uniform(-0.4, 0.4, (50, 2)), rng.uniform(-0.4, 0.4, (50, 2))
            d0 = np.abs(sampson_distances(E, z, q))
            zhT, qhT = np.ascontiguousarray(homogeneous(z).T), np.ascontiguousarray(homogeneous(q).T)
            d1 = m3._abs_sampson_t(np.ascontiguousarray(np.swapaxes(E, 0, 1)), zhT, qhT)
            assert np.allclose(d1, d0, rtol=4 * np.finfo(float).eps, atol=0.0)
    assert hyps > 1000


def test_single_sample_solver_unchanged():
    # solve_3pt_upright goes through the same batched core
    rng = np.random.default_rng(3)
    s = sim.scene4(rng, 3)
    sols = m3.solve_3pt_upright(s.z_o, s.q_o, s.L_k, s.L_c)
    u = homogeneous(s.z_o) @ s.L_k.T
    w = homogeneous(s.q_o) @ s.L_c.T
    _, psi, tau = _ref_solve_batch(u[None], w[None])
    assert len(sols) == len(psi)
    for (ps, td), p0, t0 in zip(sols, psi, tau):
        assert math.isclose(ps, p0, abs_tol=1e-12)
        assert np.allclose(td, s.L_c.T @ t0, rtol=0.0, atol=1e-12)


def test_sampson_at_the_epipole():
    # a point at the epipole of both views has E z^h = E^T q^h = 0: den = 0 -> the 1e-300 floor
    t = np.array([0.5, -0.25, 1.0])  # (exact products: E z^h is exactly 0 there)
    E = np.stack([skew(t), skew(t) @ rot_z(0.1)])
    z = np.array([[0.5, -0.25], [0.1, 0.05], [-0.2, 0.3]])
    q = np.array([[0.5, -0.25], [0.12, 0.04], [-0.25, 0.3]])
    d0 = np.abs(sampson_distances(E, z, q))
    assert d0[0, 0] == 0.0
    zhT, qhT = np.ascontiguousarray(homogeneous(z).T), np.ascontiguousarray(homogeneous(q).T)
    d1 = m3._abs_sampson_t(np.ascontiguousarray(np.swapaxes(E, 0, 1)), zhT, qhT)
    assert np.array_equal(d1, d0)


def test_generator_or_seed_and_distinct_draws():
    # an int seed and a generator made from it draw the same samples (a run passes its per-frame generator)
    z, q, L_k, L_c, thr, seed = next(_problems())
    a = ransac_3pt_upright(z, q, L_k, L_c, thr, seed=seed)
    b = ransac_3pt_upright(z, q, L_k, L_c, thr, seed=np.random.default_rng(seed))
    assert a[3] == b[3] and np.array_equal(a[2], b[2]) and a[0] == b[0]
    # with n = 3 every sample is the three points: distinct indices, each of the 6 orders about equally often
    idx = m3._draw3(np.random.default_rng(0), 3, 6000)
    assert np.array_equal(np.sort(idx, axis=1), np.tile([0, 1, 2], (6000, 1)))
    counts = np.unique(idx[:, 0] * 9 + idx[:, 1] * 3 + idx[:, 2], return_counts=True)[1]
    assert len(counts) == 6 and np.all(np.abs(counts - 1000) < 5 * np.sqrt(1000 * 5 / 6))  # 5 sigma, binomial
