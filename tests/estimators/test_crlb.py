import numpy as np
import pytest

from gevi_cli.estimators import DegenerateInput, crlb4, crlb6, fisher6, triangulate
from gevi_cli.geometry import project_jacobian, skew
from gevi_cli.studies import simulation as sim


def test_fisher6_equals_raw_stereo_model(rng):
    # raw model: pose + one nuisance depth per point on the exact q-ray, z and y noisy (spec 11.2)
    s = sim.scene6(rng, 60)
    sig2 = s.sigma**2
    p0, cov0 = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, sig2)
    F6 = fisher6(s.R, s.t, p0, cov0)
    R, t = s.R, s.t
    F = np.zeros((6, 6))
    qh = np.c_[s.q_o, np.ones(len(p0))]
    lam = (p0 @ R.T + t)[:, 2]
    for i in range(len(p0)):  # per point 4x7 Jacobian (tiny; test only)
        p = R.T @ (lam[i] * qh[i] - t)
        dp = np.c_[skew(p), -R.T, R.T @ qh[i]]  # d p / d (dphi, dt, dlambda), right perturbation
        Jz = project_jacobian(p) @ dp
        Jy = project_jacobian(s.R_rl @ p + s.t_rl) @ s.R_rl @ dp
        J = np.r_[Jz, Jy] / np.sqrt(sig2)
        M = J.T @ J
        F += M[:6, :6] - np.outer(M[:6, 6], M[6, :6]) / M[6, 6]
    assert np.allclose(F6, F, rtol=5e-3, atol=5e-3 * np.abs(F).max())


def test_crlb4_scaling_and_symmetry(scene4):
    s = scene4
    args = (s.psi, s.t, s.z_o, s.y_o, s.q_o, s.L_k, s.L_c, s.R_rl, s.t_rl)
    C1 = crlb4(*args, s.sigma**2)
    C2 = crlb4(*args, 4 * s.sigma**2)
    assert np.allclose(C2, 4 * C1)
    assert np.allclose(C1, C1.T) and np.all(np.linalg.eigvalsh(C1) > 0)
    # more points -> smaller bound
    s2 = sim.make_scene(np.random.default_rng(0), s.R, s.t, 600, psi=s.psi, L_k=s.L_k, L_c=s.L_c)
    C3 = crlb4(s.psi, s.t, s2.z_o, s2.y_o, s2.q_o, s.L_k, s.L_c, s.R_rl, s.t_rl, s.sigma**2)
    assert C3[0, 0] < C1[0, 0]


def test_crlb6_singular_raises(rng):
    s = sim.scene6(rng, 2)
    p0, cov0 = triangulate(s.z_o, s.y_o, s.R_rl, s.t_rl, s.sigma**2)
    with pytest.raises(Exception):
        crlb6(s.R, s.t, p0, cov0)
    with pytest.raises(DegenerateInput):
        crlb6(s.R, s.t, p0[:1].repeat(3, 0), cov0[:1].repeat(3, 0))
