"""Epipolar local BA (spec 10): truth, Jacobian, recovery from 8 % scale error, scale observability,
noise reduction, kernels and input errors.

The window simulator is ``simulation.ba_window``.
"""

import numpy as np
import pytest

from gevi_cli.estimators import NonFiniteInput, ShapeError, TooFewPoints
from gevi_cli.estimators.epipolar_ba import (
    BAOptions,
    BAProblem,
    BAWindow,
    ImageObs,
    epipolar_local_ba,
    euler_zyx,
    euler_zyx_from_R,
    poses_from_tracking,
)
from gevi_cli.geometry import rotation_error
from gevi_cli.studies.simulation import R_RL, T_RL
from gevi_cli.studies.simulation import ba_window as make_window
from gevi_cli.studies.simulation import perturb_ba_window as perturb


def pose_errors(R, t, R_true, t_true):
    return np.rad2deg(rotation_error(R, R_true)).mean(), np.linalg.norm(t - t_true, axis=1).mean()


def test_euler_roundtrip_and_tracking_inverse():
    a = np.array([[0.1, -0.2, 0.3], [0.0, 0.0, 0.0], [-1.0, 0.5, 2.5]])
    assert np.allclose(euler_zyx_from_R(euler_zyx(a)), a, atol=1e-14)
    R, t = euler_zyx(a), np.arange(9.0).reshape(3, 3)
    Ri, ti = poses_from_tracking(R, t)
    X = np.array([0.3, -1.0, 2.0])
    assert np.allclose(np.einsum("nij,nj->ni", Ri, np.einsum("nij,j->ni", R, X) + t) + ti, X, atol=1e-13)


def test_zero_residual_at_truth_and_pairs():
    w, R, t = make_window(0)
    prob = BAProblem(w)
    d = prob.residuals(prob.x0)
    assert np.abs(d).max() < 1e-13
    K = 5
    # all pair types of the spec-10 table are present: 4K + K(K-1)/2 + 4
    assert len(prob.pairs) == 4 * K + K * (K - 1) // 2 + 4
    assert len(BAProblem(w, use_right=False).pairs) == 2 * K + K * (K - 1) // 2 + 1


def test_jacobian_vs_central_differences(central_diff):
    w, R, t = make_window(1, K=3, n=40)
    w = perturb(w, 1, scale=1.05, rot_deg=1.0, t_sigma=0.02)
    prob = BAProblem(w)
    x = prob.x0
    d, J = prob.residuals_and_jacobian(x)
    Jn = central_diff(prob.residuals, x, h=1e-6)
    assert np.abs(J - Jn).max() <= 1e-6 * np.abs(J).max()
    Js = prob.jacobian(x, sparse=True)
    assert np.array_equal(Js.toarray(), J)
    # the sparsity pattern covers every non-zero
    assert np.all((prob.jac_sparsity().toarray() > 0) | (J == 0))


@pytest.mark.parametrize("solver", ["lm", "scipy-sparse"])
def test_recovers_truth_from_8pct_scale_error(solver):
    """Noise-free data, start with 8 % scale error + 0.3 deg rotation noise: back to the truth
    (spec [V]: 2e-15) to < 1e-9 within the default 10 LM iterations; the scipy least_squares path
    (CSR Jacobian, lsmr) gets 30 evaluations."""
    w, R, t = make_window(2)
    w = perturb(w, 2)
    opt = BAOptions() if solver == "lm" else BAOptions(solver="scipy", sparse=True, max_iter=30)
    res = epipolar_local_ba(w, opt)
    assert np.abs(res.t - t).max() < 1e-9
    assert rotation_error(res.R, R).max() < 1e-9
    assert res.rms_final < 1e-12 < res.rms_initial


def test_scale_observability():
    """Left images only: the residuals are invariant to a global scaling of all translations, so
    J is rank deficient (spec: sigma_min/sigma_max 1.2e-9). Right images make scale observable."""
    w, R, t = make_window(3)
    x0 = BAProblem(w).x0
    sv_l = np.linalg.svd(BAProblem(w, use_right=False).jacobian(x0), compute_uv=False)
    sv_r = np.linalg.svd(BAProblem(w, use_right=True).jacobian(x0), compute_uv=False)
    assert sv_l[-1] / sv_l[0] < 1e-7
    assert sv_r[-1] / sv_r[0] > 1e-4
    # the null direction of the left-only Jacobian is the translation scale
    P = BAProblem(w, use_right=False)
    v = (x0.reshape(-1, 6) * np.array([0, 0, 0, 1, 1, 1])).reshape(-1)
    assert np.linalg.norm(P.jacobian(x0) @ v) < 1e-10 * np.linalg.norm(v) * sv_l[0]


def test_noise_reduces_pose_error():
    """1 px noise on every image, start = 8 % scale error + 0.3 deg + 2 cm: BA lowers the mean
    rotation and translation error (mean over 6 seeds, K = 4, 150 features)."""
    before, after = [], []
    for seed in range(6):
        w, R, t = make_window(10 + seed, K=4, sigma_px=1.0)
        w = perturb(w, seed, t_sigma=0.02)
        before.append(pose_errors(w.R_init, w.t_init, R, t))
        res = epipolar_local_ba(w)
        after.append(pose_errors(res.R, res.t, R, t))
    before, after = np.mean(before, axis=0), np.mean(after, axis=0)
    assert after[0] < 0.5 * before[0], (before, after)
    assert after[1] < 0.5 * before[1], (before, after)


def test_scipy_dense_matches_lm():
    """Same minimiser from both solvers (small window: the dense 'exact' trf path is SVD-bound)."""
    w, R, t = make_window(6, K=2, n=60, sigma_px=1.0)
    w = perturb(w, 6, t_sigma=0.01)
    a = epipolar_local_ba(w, BAOptions(max_iter=30))
    b = epipolar_local_ba(w, BAOptions(solver="scipy", max_iter=50))
    assert np.abs(a.t - b.t).max() < 1e-7 and rotation_error(a.R, b.R).max() < 1e-7
    assert abs(a.cost_final - b.cost_final) <= 1e-8 * a.cost_final


def test_kernels_and_outliers():
    """Truncated kernel (authors') and Huber both survive 5 % gross outliers in F_k; plain LS is worse."""
    w, R, t = make_window(4, K=4, sigma_px=0.5)
    rng = np.random.default_rng(44)
    for f in w.frames:
        bad = rng.random(f.ids.size) < 0.05
        f.xy[bad] += rng.uniform(-0.05, 0.05, (bad.sum(), 2))
    w = perturb(w, 4)
    errs = {}
    for kern in ("huber", "truncated", "none"):
        res = epipolar_local_ba(w, BAOptions(kernel=kern, max_iter=20))
        errs[kern] = pose_errors(res.R, res.t, R, t)
    assert errs["huber"][1] < 0.02 and errs["truncated"][1] < 0.02, errs
    assert errs["huber"][1] < errs["none"][1], errs


def test_input_errors():
    w, R, t = make_window(5, K=2, n=30)
    bad = BAWindow(**{**w.__dict__, "R_init": w.R_init[:2]})
    with pytest.raises(ShapeError):
        epipolar_local_ba(bad)
    xy = w.frames[0].xy.copy()
    xy[0, 0] = np.nan
    bad = BAWindow(**{**w.__dict__, "frames": [ImageObs(w.frames[0].ids, xy), w.frames[1]]})
    with pytest.raises(NonFiniteInput):
        epipolar_local_ba(bad)
    empty = ImageObs(np.zeros(0, int), np.zeros((0, 2)))
    bad = BAWindow(empty, empty, [empty, empty], empty, empty, w.R_init, w.t_init, R_RL, T_RL)
    with pytest.raises(TooFewPoints):
        epipolar_local_ba(bad)


def test_scale_is_unbiased_under_gaussian_noise():
    """The BA's scale comes from the right-image pairs only; with Gaussian image noise it must not be
    biased.  400 windows (K = 3, 1 px noise, perturbed start), the pipeline's kernel and stopping
    rule: the mean ratio |t_KF2| / |t_KF2 true| is within 4 standard errors of 1, and those 4 SE
    (~9e-4) are below 0.15 %, the size of the LK track shortening measured on the euroc-like renders
    (docs/method.md, simulated sequences), so an estimator bias of that size fails here."""
    ratios = []
    for seed in range(400):
        w, R, t = make_window(1000 + seed, K=3, sigma_px=1.0)
        w = perturb(w, seed, t_sigma=0.02)
        res = epipolar_local_ba(w, BAOptions(kernel="truncated", max_iter=10, tol=1e-4))
        ratios.append(np.linalg.norm(res.t[-1]) / np.linalg.norm(t[-1]))
    ratios = np.array(ratios)
    se = ratios.std() / np.sqrt(len(ratios))
    assert 4 * se < 1.5e-3, se
    assert abs(ratios.mean() - 1.0) < 4 * se, (ratios.mean(), se)
