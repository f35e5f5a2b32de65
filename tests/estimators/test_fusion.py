import numpy as np
import pytest
from scipy.optimize import minimize

from gevi_cli.estimators import DegenerateInput
from gevi_cli.estimators.fusion import sigma_objective, sigma_step


@pytest.mark.parametrize("case", range(3))
def test_sigma_step_is_constrained_minimiser(case):
    rng = np.random.default_rng(case)
    K = 20
    A = rng.standard_normal((3, 3)) * np.array([0.05, 0.01, 0.0005])
    r = rng.standard_normal((K, 3)) @ A.T
    lo, hi = 1e-6, 0.2**2
    Sig = sigma_step(r, lo, hi)
    ev = np.linalg.eigvalsh(Sig)
    assert ev.min() >= lo * (1 - 1e-12) and ev.max() <= hi * (1 + 1e-12)
    f_star = sigma_objective(Sig, r)

    # numerical optimum over Sigma = Q diag(lam) Q^T, lam in [lo, hi] (log-parametrised)
    def f(x):
        from gevi_cli.estimators.lie import exp_so3

        Q = exp_so3(x[:3])
        lam = lo + (hi - lo) / (1 + np.exp(-x[3:]))
        return sigma_objective(Q @ np.diag(lam) @ Q.T, r)

    best = np.inf
    for k in range(6):
        x0 = np.r_[rng.standard_normal(3), rng.standard_normal(3)]
        best = min(best, minimize(f, x0, method="Nelder-Mead", options=dict(maxiter=6000, xatol=1e-10, fatol=1e-12)).fun)
    assert f_star <= best + 1e-6


def test_sigma_step_bad_bounds():
    with pytest.raises(DegenerateInput):
        sigma_step(np.zeros((3, 3)), 0.0, 1.0)
