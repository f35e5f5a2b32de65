import numpy as np
import pytest

from gevi_cli.estimators import (
    DegenerateInput,
    TooFewPoints,
    bias_terms,
    build_A,
    epipolar_residuals_jac,
    pnp4_be,
    pnp4_gn,
    pnp4_ls,
    triangulate,
)
from gevi_cli.estimators.pnp4 import pnp4_be_cov
from gevi_cli.geometry import wrap_angle
from gevi_cli.studies import montecarlo as mc
from gevi_cli.studies import simulation as sim


def _noise_free(s):
    # G is the *expected* noise part of A^T A / n, so exact recovery needs cov ~ 0 (as the
    # estimated sigma^2 of noise-free data is); use a negligible covariance.
    return triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, 1e-30)


@pytest.mark.parametrize("rows", ["orth", "paper"])
def test_noise_free_recovery(scene4, rows):
    s = scene4
    p, cov = _noise_free(s)
    for psi, t in (pnp4_ls(p, s.q_o, s.L_k, s.L_c, rows), pnp4_be(p, cov, s.q_o, s.L_k, s.L_c, rows)):
        assert abs(psi - s.psi) < 1e-9 and np.max(np.abs(t - s.t)) < 1e-9


def test_noise_free_forward_looking_tilted(scene_fwd):
    s = scene_fwd
    assert not np.allclose(s.L_c, np.eye(3))
    p, cov = _noise_free(s)
    for psi, t in (pnp4_ls(p, s.q_o, s.L_k, s.L_c), pnp4_be(p, cov, s.q_o, s.L_k, s.L_c)):
        assert abs(psi - s.psi) < 1e-9 and np.max(np.abs(t - s.t)) < 1e-9


def test_paper_rows_equal_s1_form(scene4):
    s = scene4  # L_C = I: rows (1, 0, -q1), (0, 1, -q2) and b = rho3 q  (S1)
    p = s.P
    A, b, _, rho = build_A(p, s.q_o, s.L_k, s.L_c, "paper")
    q = s.q_o
    A1 = np.column_stack([rho[:, 0], -rho[:, 1], np.ones(len(p)), np.zeros(len(p)), -q[:, 0]])
    A2 = np.column_stack([rho[:, 1], rho[:, 0], np.zeros(len(p)), np.ones(len(p)), -q[:, 1]])
    assert np.allclose(A[0::2], A1) and np.allclose(A[1::2], A2)
    assert np.allclose(b[0::2], rho[:, 2] * q[:, 0]) and np.allclose(b[1::2], rho[:, 2] * q[:, 1])


@pytest.mark.parametrize("rows", ["orth", "paper"])
def test_bias_terms_match_monte_carlo(rng, rows):
    s = sim.scene4(rng, 20)
    _, cov = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s.sigma**2)
    A0, b0, V, _ = build_A(s.P, s.q_o, s.L_k, s.L_c, rows)
    G1, g2 = bias_terms(s.L_k @ cov @ s.L_k.T, V)
    draws = 20000
    Lc = np.linalg.cholesky(cov)
    eps = np.einsum("nij,dnj->dni", Lc, rng.standard_normal((draws, 20, 3)))
    AA = np.zeros((5, 5))
    Ab = np.zeros(5)
    for d in range(0, draws, 2000):  # chunks of draws (memory), vectorized inside
        P = s.P[None] + eps[d:d + 2000]
        A = np.stack([build_A(Pk, s.q_o, s.L_k, s.L_c, rows)[0] for Pk in P])
        b = np.stack([build_A(Pk, s.q_o, s.L_k, s.L_c, rows)[1] for Pk in P])
        dA, db = A - A0, b - b0
        AA += np.einsum("dri,drj->ij", dA, dA)
        Ab += np.einsum("dri,dr->i", dA, db)
    AA /= draws * 20
    Ab /= draws * 20
    # MC relative SE with 20000 draws of 20 points ~ 1/sqrt(4e5) ~ 0.2 %
    assert np.allclose(AA[:2, :2], G1[:2, :2], rtol=0.02, atol=0.02 * np.abs(G1).max())
    assert np.allclose(AA[2:, :], 0, atol=1e-12)
    assert np.allclose(Ab[:2], g2[:2], rtol=0.05, atol=0.02 * np.abs(g2).max())


@pytest.mark.parametrize("fwd", [False, True])
def test_epipolar_jacobian_central_differences(rng, central_diff, fwd):
    s = sim.scene4(rng, 40, R_ic=sim.R_IC_FORWARD if fwd else None)
    chi = np.r_[s.psi + 0.01, s.t + 0.01]
    args = (s.z, s.y, s.q, s.L_k, s.L_c, s.R_rl, s.t_rl)
    _, J = epipolar_residuals_jac(chi[0], chi[1:], *args)
    Jn = central_diff(lambda c: epipolar_residuals_jac(c[0], c[1:], *args)[0], chi, h=1e-6)
    assert np.max(np.abs(J - Jn)) <= 1e-6 * np.max(np.abs(J))


def test_gn_noise_free_fixed_point_and_convergence(scene4):
    s = scene4
    args = (s.z_o, s.y_o, s.q_o, s.L_k, s.L_c, s.R_rl, s.t_rl)
    r, _ = epipolar_residuals_jac(s.psi, s.t, *args)
    assert np.max(np.abs(r)) < 1e-14
    psi, t = s.psi + 0.003, s.t + np.array([0.004, -0.003, 0.002])
    for _ in range(3):
        psi, t = pnp4_gn(psi, t, *args)
    assert abs(psi - s.psi) < 1e-9 and np.max(np.abs(t - s.t)) < 1e-9


def test_collinear_centre_degeneracy_keeps_be(rng):
    # current camera centre c = -R^T t on the keyframe baseline line (the x axis): J has rank 3
    psi, L_k, L_c, R, _ = sim.pose4_gevi(rng)
    c = np.array([0.37, 0.0, 0.0])
    t = -R @ c
    s = sim.make_scene(rng, R, t, 100, psi=psi, L_k=L_k, L_c=L_c)
    args = (s.z_o, s.y_o, s.q_o, s.L_k, s.L_c, s.R_rl, s.t_rl)
    _, J = epipolar_residuals_jac(psi, t, *args)
    U, sv, Vt = np.linalg.svd(J)
    assert sv[3] < 1e-10 * sv[0]
    null = Vt[3]
    start = np.r_[psi + 0.001, t + 0.001]
    out = pnp4_gn(start[0], start[1:], *args)
    step = np.r_[out[0], out[1]] - start
    # the safeguard keeps the input (BE) value along the weak direction at the start point ...
    _, J0 = epipolar_residuals_jac(start[0], start[1:], *args)
    ev, V = np.linalg.eigh(J0.T @ J0)
    assert ev[0] < 1e-5 * ev[-1]
    assert abs(step @ V[:, 0]) < 1e-12
    # ... (which is close to the exact null direction at the truth) and corrects the others
    assert abs(V[:, 0] @ null) > 0.99
    err_obs = (np.eye(4) - np.outer(null, null)) @ (np.r_[out[0], out[1]] - np.r_[psi, t])
    assert np.linalg.norm(err_obs) < 0.1 * np.linalg.norm(start - np.r_[psi, t])
    with pytest.raises(DegenerateInput):
        pnp4_gn(start[0], start[1:], *args, on_degenerate="raise")


def test_degenerate_inputs(scene4):
    s = scene4
    p, cov = _noise_free(s)
    with pytest.raises(TooFewPoints):
        pnp4_be(p[:2], cov[:2], s.q_o[:2], s.L_k, s.L_c)
    with pytest.raises(DegenerateInput):  # all points identical -> rank deficient
        pnp4_ls(np.repeat(p[:1], 10, 0), np.repeat(s.q_o[:1], 10, 0), s.L_k, s.L_c)
    with pytest.raises(DegenerateInput):  # paper rows with horizontal levelled bearings
        pnp4_ls(p[:3], np.array([[0.0, 0.0], [0.1, 0.0], [0.2, 0.0]]), s.L_k, sim.R_IC_FORWARD, "paper")


# ------------------------------------------------------------------------------------------------
# Statistical acceptance (spec 11.3 protocol, 700 runs per n; fixed seeds)

NS = (50, 100, 300, 1000)
# 700 runs as in the paper; n = 300 gets 2000 runs because the BE bias criterion has little
# margin there: BE keeps an O(sigma^2) t_z floor of ~0.16 cm (LS ~1.6 cm), per-axis SE at 700
# runs ~0.08 cm (at seed 1300 and 700 runs the BE bias read 0.35 cm against a 0.34 cm limit).
RUNS = {50: 700, 100: 700, 300: 2000, 1000: 700}


def _becov_extra(s, p, cov, out):
    psi, t, C = pnp4_be_cov(p, cov, s.q, s.L_k, s.L_c)
    psi, t = pnp4_gn(psi, t, s.z, s.y, s.q, s.L_k, s.L_c, s.R_rl, s.t_rl, be_cov=C, sigma2=s.sigma**2)
    out["gn_becov"] = (float(wrap_angle(psi - s.psi)), t - s.t)


@pytest.fixture(scope="module")
def mc4():
    return {n: mc.run4(n, RUNS[n], seed=1000 + n, extra=_becov_extra) for n in NS}


@pytest.mark.slow
def test_be_removes_ls_translation_bias(mc4):
    # spec 15 rule: |b_BE| < max(0.25 b_LS, 3 SE) with SE = RMSE_BE / sqrt(runs) per axis
    for n in (300, 1000):
        r = mc4[n]
        assert r.bias_t("be") < max(0.25 * r.bias_t("ls"), 3 * r.se_t("be")), n
    # the LS bias does not fall with n (allow 3 combined standard errors)
    b300, b1000 = mc4[300].bias_t("ls"), mc4[1000].bias_t("ls")
    se = np.hypot(mc4[300].se_t("ls"), mc4[1000].se_t("ls"))
    assert b1000 > b300 - 3 * se
    assert b1000 > 10 * mc4[1000].se_t("be")  # and it is far from zero


@pytest.mark.slow
def test_gn_rmse_slope(mc4):
    ns = np.array([50, 100, 300, 1000])
    for metric in ("yaw", "t"):
        vals = [mc4[n].rmse_yaw("gn") if metric == "yaw" else mc4[n].rmse_t("gn") for n in ns]
        slope = mc.loglog_slope(ns, vals)
        assert -0.6 < slope < -0.4, (metric, slope)


@pytest.mark.slow
def test_gn_efficiency_vs_crlb4(mc4):
    # within 10 % of the root-mean CRLB4 for n >= 300 and 20 % at n = 100 (yaw and translation)
    for n, tol in ((100, 0.20), (300, 0.10), (1000, 0.10)):
        r = mc4[n]
        assert r.rmse_yaw("gn") < (1 + tol) * r.bound_yaw(), (n, r.rmse_yaw("gn") / r.bound_yaw())
        assert r.rmse_t("gn") < (1 + tol) * r.bound_t(), (n, r.rmse_t("gn") / r.bound_t())
        # and the bound really is a lower bound up to MC noise (RMSE SE ~ 1/sqrt(2 runs) ~ 3 %)
        assert r.rmse_yaw("gn") > 0.9 * r.bound_yaw()
        # GN improves on BE
        assert r.rmse_yaw("gn") < r.rmse_yaw("be") and r.rmse_t("gn") < r.rmse_t("be")


@pytest.mark.slow
def test_gn_with_be_cov_efficiency(mc4):
    # BE kept along directions where cost (1) is less informative than BE (pnp4_gn be_cov): the
    # heavy tail of the collinear-centre runs disappears; yaw stays at CRLB4, translation goes
    # below the model-(1) bound (the BE part uses the stereo depths, cf. the shared-depth bound)
    for n in (300, 1000):
        r = mc4[n]
        assert 0.9 * r.bound_yaw() < r.rmse_yaw("gn_becov") < 1.1 * r.bound_yaw(), n
        assert r.rmse_t("gn_becov") < 1.1 * r.bound_t(), n
        assert r.rmse_t("gn_becov") <= r.rmse_t("gn"), n


def test_be_cov_calibrated_and_noise_free(rng, scene4):
    s = scene4
    p, cov = _noise_free(s)
    psi, _, C = pnp4_be_cov(p, cov, s.q_o, s.L_k, s.L_c)
    assert abs(psi - s.psi) < 1e-9 and np.all(np.linalg.eigvalsh(C) >= 0)
    args = (s.z_o, s.y_o, s.q_o, s.L_k, s.L_c, s.R_rl, s.t_rl)
    # noise-free fixed point of the BE-informed step
    _, _, C = pnp4_be_cov(*triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s.sigma**2), s.q_o, s.L_k, s.L_c)
    out = pnp4_gn(s.psi, s.t, *args, be_cov=C, sigma2=s.sigma**2)
    assert abs(out[0] - s.psi) < 1e-12 and np.max(np.abs(out[1] - s.t)) < 1e-12
    # first-order covariance vs the empirical spread of BE (200 noisy draws, n = 300)
    nz = []
    for _ in range(200):
        sc = sim.scene4(rng, 300)
        pp, cc = triangulate(sc.z, sc.y, sc.R_rl, sc.t_rl, sc.sigma**2)
        ps, tt, CC = pnp4_be_cov(pp, cc, sc.q, sc.L_k, sc.L_c)
        e = np.r_[wrap_angle(ps - sc.psi), tt - sc.t]
        nz.append(e @ np.linalg.solve(CC, e))
    assert 3.0 < np.mean(nz) < 5.5  # E = 4 for a calibrated 4-dim covariance (BE bias O(sigma^2))


def test_collinear_centre_with_be_cov_keeps_be(rng):
    psi, L_k, L_c, R, _ = sim.pose4_gevi(rng)
    t = -R @ np.array([0.37, 0.0, 0.0])
    s = sim.make_scene(rng, R, t, 100, psi=psi, L_k=L_k, L_c=L_c)
    args = (s.z_o, s.y_o, s.q_o, s.L_k, s.L_c, s.R_rl, s.t_rl)
    _, J = epipolar_residuals_jac(psi, t, *args)
    null = np.linalg.svd(J)[2][3]
    p, cov = triangulate(s.z, s.y, s.R_rl, s.t_rl, s.sigma**2)
    _, _, C = pnp4_be_cov(p, cov, s.q, s.L_k, s.L_c)
    start = np.r_[psi + 0.001, t + 0.001]
    out = pnp4_gn(start[0], start[1:], *args, be_cov=C, sigma2=s.sigma**2)
    truth = np.r_[psi, t]
    err0, err1 = start - truth, np.r_[out[0], out[1]] - truth
    # no blow-up along the unobservable direction (the plain step there would be arbitrary) ...
    assert abs(err1 @ null) <= abs(err0 @ null) + 1e-3 * np.linalg.norm(err0)
    # ... while the observable part of the error is corrected
    P = np.eye(4) - np.outer(null, null)
    assert np.linalg.norm(P @ err1) < 0.2 * np.linalg.norm(P @ err0)
