import numpy as np
import pytest

from gevi_cli.estimators import (
    DegenerateInput,
    NonFiniteInput,
    TooFewPoints,
    bias_matrix_G,
    build_H,
    depth_weights,
    pnp6_be,
    pnp6_l1,
    pnp6_ls,
    pnp6_refine,
    pnp6_whitened_sq,
    pnp_l1_filter,
    sigma2_onesided,
    triangulate,
)
from gevi_cli.geometry import exp_so3, project, rotation_error
from gevi_cli.studies import montecarlo as mc
from gevi_cli.studies import simulation as sim


@pytest.fixture
def s6(rng):
    return sim.scene6(rng, 200)


def test_noise_free_ls_be(s6):
    s = s6
    # pipeline-style: sigma^2 estimated from noise-free data is 0, BE reduces to LS
    s2 = sigma2_onesided(s.q_o, s.z_o)
    p, cov = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s2)
    for R, t in (pnp6_ls(p, s.q_o), pnp6_be(p, cov, s.q_o), pnp6_be(p, cov, s.q_o, depth_weights(p))):
        assert np.max(np.abs(R - s.R)) < 1e-9 and np.max(np.abs(t - s.t)) < 1e-9


def test_noise_free_l1(s6):
    s = s6
    R, t = pnp6_l1(s.P, s.q_o)
    assert np.max(np.abs(R - s.R)) < 1e-9 and np.max(np.abs(t - s.t)) < 1e-9


def test_G_matches_monte_carlo(rng):
    # E[H^T H]/n - H_o^T H_o/n = G for H built with noisy p (centroid noise ignored: use many draws)
    s = sim.scene6(rng, 30)
    _, cov = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s.sigma**2)
    w = depth_weights(s.P)
    Ho, _, pbar = build_H(s.P, s.q_o, w)
    acc = np.zeros((11, 11))
    draws = 4000
    L = np.linalg.cholesky(cov)
    for _ in range(draws):
        p = s.P + np.einsum("nij,nj->ni", L, rng.standard_normal(s.P.shape))
        H, _, _ = build_H(p, s.q_o, w)
        # use the true centroid, as in the derivation
        H = H.copy()
        pc = p - pbar
        H[0::2, 0:3] = -(s.q_o[:, :1] * pc) * w[:, None]
        H[1::2, 0:3] = -(s.q_o[:, 1:] * pc) * w[:, None]
        acc += H.T @ H
    emp = acc / draws / 30 - Ho.T @ Ho / 30
    G = bias_matrix_G(cov, s.q_o, w)
    assert np.max(np.abs(emp - G)) < 0.1 * np.max(np.abs(G))


def test_refine_converges_from_perturbed_start(s6):
    s = s6
    p, cov = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s.sigma**2)
    R0 = s.R @ exp_so3([0.01, -0.02, 0.005])
    t0 = s.t + np.array([0.02, -0.01, 0.03])
    e0 = rotation_error(R0, s.R)
    R1, t1 = pnp6_refine(R0, t0, p, cov, s.q_o)
    R2, t2 = pnp6_refine(R1, t1, p, cov, s.q_o)
    R3, t3 = pnp6_refine(*pnp6_refine(R2, t2, p, cov, s.q_o), p, cov, s.q_o)  # LM damping 1e-6 slows the tail
    # quadratic convergence of Gauss-Newton on a zero-residual problem
    e1, e2 = rotation_error(R1, s.R), rotation_error(R2, s.R)
    assert e1 < 0.05 * e0 and e2 < 0.05 * e1
    assert rotation_error(R3, s.R) < 1e-9 and np.linalg.norm(t3 - s.t) < 1e-9


def test_be_removes_bias_gaussian3d():
    # spec 15: Gaussian-3D model, n = 1600: |t-bias| < 0.2 LS bias and < 0.2 cm.
    # 200 runs: per-axis SE ~ 1.0 cm / sqrt(200) = 0.07 cm, so an unbiased estimator's |mean|
    # is ~0.12 cm (chi_3), comfortably below 0.2 cm.
    r = mc.run6(1600, 200, seed=11, gaussian3d=True)
    assert r.bias_t("be") < 0.2 * r.bias_t("ls")
    assert r.bias_t("be") < 0.002


def test_refine_efficiency_real_triangulation():
    # spec 5.6 / 15: rotation within 35 % of the root-mean CRLB6 at n = 1600 (observed ~1.2),
    # translation below the 0.7 cm floor. The per-run errors are heavy-tailed relative to the
    # per-run bound (100-run ratios ranged 1.20-1.41 over seeds 0, 5, 6, 7; 400 runs gave
    # 1.22 and 1.24), so 300 runs are used to keep the SE of the ratio ~0.04.
    r = mc.run6(1600, 300, seed=1)
    assert r.rmse_rot("ref") < 1.35 * r.bound_rot()
    assert r.rmse_t("ref") < 0.007
    assert r.rmse_rot("ref") < r.rmse_rot("be")  # the step improves on BE


def test_l1_filter_removes_gross_outliers(rng):
    s = sim.scene6(rng, 200)
    p, _ = triangulate(s.z, s.y, s.R_rl, s.t_rl, s.sigma**2)
    q = s.q.copy()
    bad = rng.choice(200, 14, replace=False)  # 7 % gross outliers
    q[bad] += rng.choice([-1, 1], (14, 2)) * rng.uniform(0.05, 0.2, (14, 2))
    keep = pnp_l1_filter(p, q)
    assert keep.sum() == 180
    assert np.sum(~keep[bad]) >= 12


def test_degenerate_inputs(s6):
    s = s6
    p, cov = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s.sigma**2)
    with pytest.raises(TooFewPoints):
        pnp6_be(p[:5], cov[:5], s.q_o[:5])
    q = s.q_o.copy()
    q[0, 0] = np.inf
    with pytest.raises(NonFiniteInput):
        pnp6_ls(p, q)
    # points behind the camera: kappa <= 0
    # (projections are sign-blind, so build a pose that puts every point at negative depth:
    # the linear solution then has det < 0, i.e. kappa <= 0)
    Xc = s.P @ s.R.T + s.t - np.array([0.0, 0.0, 30.0])
    assert np.all(Xc[:, 2] < 0)
    with pytest.raises(DegenerateInput, match="kappa"):
        pnp6_ls(s.P, project(Xc))
    # coplanar-collinear: all points on one line -> singular system
    line = np.outer(np.linspace(1, 5, 20), [0.1, 0.2, 1.0])
    with pytest.raises(DegenerateInput):
        pnp6_ls(line, project(line @ s.R.T + s.t))


def test_refine_step_length_is_quadratic_in_the_offset(s6):
    """``return_step`` gives delta^T H delta: zero at the optimum of noise-free data and, to first
    order, quadratic in the start's offset from it (GN on a zero-residual problem lands on it)."""
    s = s6
    p, cov = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s.sigma**2)
    *_, m0 = pnp6_refine(s.R, s.t, p, cov, s.q_o, sigma2_q=s.sigma**2, return_step=True)
    assert m0 < 1e-12
    d = np.array([1.0, -2.0, 0.5, 3.0, -1.0, 2.0])
    d /= np.linalg.norm(d)
    m = []
    for h in (1e-5, 2e-5):
        R0, t0 = s.R @ exp_so3(h * d[:3]), s.t + h * d[3:]
        R1, t1, mk = pnp6_refine(R0, t0, p, cov, s.q_o, sigma2_q=s.sigma**2, return_step=True)
        m.append(mk)
        assert rotation_error(R1, s.R) < 1e-3 * h * 180 / np.pi and np.linalg.norm(t1 - s.t) < 1e-3 * h
    assert abs(m[1] / m[0] - 4.0) < 1e-3
    # the plain call is unchanged
    R2, t2 = pnp6_refine(R0, t0, p, cov, s.q_o, sigma2_q=s.sigma**2)
    assert np.array_equal(R2, R1) and np.array_equal(t2, t1)


def test_whitened_residuals_are_chi_square_2(rng):
    """Gaussian-3D points and a noisy current frame (the weights' own model): at the true pose the
    squared Mahalanobis norms average 2 (chi-square, 2 dof) to within their Monte Carlo error, 99.9 %
    of them lie below 13.8, and each equals r^T Sigma_bar^-1 r computed directly."""
    s = sim.scene6(rng, 4000)
    P = s.P
    cov = np.tile(np.diag([4e-6, 4e-6, 1e-4]), (len(P), 1, 1))
    p = sim.gaussian3d_points(rng, P, cov)
    s2 = (0.5 / sim.F_PX) ** 2
    q = project(P @ s.R.T + s.t) + np.sqrt(s2) * rng.standard_normal((len(P), 2))
    m2 = pnp6_whitened_sq(s.R, s.t, p, cov, q, s2)
    # (first order in the point noise: the projection's curvature adds O(sigma_p^2 / Z^2), negligible here)
    assert abs(m2.mean() - 2.0) < 4 * 2.0 / np.sqrt(len(m2))
    assert np.mean(m2 > 13.8) < 0.004
    X = p @ s.R.T + s.t
    i = 7
    J = np.array([[1 / X[i, 2], 0, -X[i, 0] / X[i, 2] ** 2], [0, 1 / X[i, 2], -X[i, 1] / X[i, 2] ** 2]]) @ s.R
    S = J @ cov[i] @ J.T + s2 * np.eye(2)
    r = q[i] - X[i, :2] / X[i, 2]
    assert m2[i] == pytest.approx(r @ np.linalg.solve(S, r), rel=1e-9)
    behind = p.copy()
    behind[0] = -(s.R.T @ (s.t + np.array([0.0, 0.0, 1.0])))  # 1 m behind the current camera
    assert np.isinf(pnp6_whitened_sq(s.R, s.t, behind, cov, q, s2)[0])


def test_bearing_only_far_depth_errors_do_not_move_the_weighted_step(rng):
    """A far point whose stereo depth is wrong (here 20 % too far) still lies on its keyframe ray, so its
    reprojection slides along its epipolar line only.  With its depth made unknown (bearing_only) the
    weighted step gives that direction no weight: from the true pose it stays at the true pose (the
    near points and every bearing are exact), whereas with the stereo covariance it is dragged."""
    from gevi_cli.estimators import bearing_only

    s = sim.scene6(rng, 200)
    p = s.P.copy()
    far = p[:, 2] > np.median(p[:, 2])
    p[far] *= 1.2
    cov = np.broadcast_to(1e-6 * np.eye(3), (len(p), 3, 3)).copy()
    R0, t0 = pnp6_refine(s.R, s.t, p, cov, s.q_o)
    R1, t1 = pnp6_refine(s.R, s.t, p, bearing_only(p, cov, far), s.q_o)
    assert np.linalg.norm(t0 - s.t) > 1e-3  # the wrong depths pull the stereo-weighted step
    assert np.linalg.norm(t1 - s.t) < 1e-6 * np.linalg.norm(s.t)
    assert rotation_error(R1, s.R) < 1e-6
    # the near points keep their covariance, the far ones gain (k |p|)^2 along their ray only
    out = bearing_only(p, cov, far)
    assert np.array_equal(out[~far], cov[~far])
    r = p[far] / np.linalg.norm(p[far], axis=1)[:, None]
    perp = np.cross(r, [0.0, 0.0, 1.0])
    perp /= np.linalg.norm(perp, axis=1)[:, None]
    assert np.allclose(np.einsum("ni,nij,nj->n", perp, out[far], perp), 1e-6)
    assert np.all(np.einsum("ni,nij,nj->n", r, out[far], r) > 1e5 * np.einsum("ij,ij->i", p[far], p[far]))
