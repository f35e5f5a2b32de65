"""Consistent estimators of the 2D (normalized-coordinate) noise variance, spec section 3.

All inputs are normalized image coordinates, shape (n, 2); the result is a variance in
normalized units squared (multiply by f^2 for px^2).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from gevi_cli.geometry import homogeneous, skew

from ._checks import as_points, need, same_length, stereo_inputs
from .errors import DegenerateInput

_D = np.diag([1.0, 1.0, 0.0])


def _smallest_root(Q: np.ndarray, S: np.ndarray) -> float:
    """Smallest non-negative root mu of det(Q - mu S) = 0 (= 1 / lambda_max of S v = lambda Q v)."""
    if not (np.all(np.isfinite(Q)) and np.all(np.isfinite(S))):
        raise DegenerateInput("sigma2: non-finite moment matrices")
    # Scale for conditioning: the root is invariant to a common scale of Q and S only jointly,
    # so normalise each by its own norm and undo afterwards.
    qs, ss = np.linalg.norm(Q), np.linalg.norm(S)
    if qs == 0 or ss == 0:
        raise DegenerateInput("sigma2: zero moment matrix")
    lam = scipy.linalg.eigvals(S / ss, Q / qs)
    # infinite lambda <=> singular Q (noise-free data) <=> sigma^2 = 0
    if np.any(~np.isfinite(lam)):
        return 0.0
    re = np.real(lam)
    lmax = re.max()
    if lmax <= 0:
        raise DegenerateInput("sigma2: no positive generalized eigenvalue (degenerate geometry)")
    mu = 1.0 / lmax * (qs / ss)
    # Noise-free data give a numerically singular Q, i.e. a huge lambda: report 0 then.
    return float(max(mu, 0.0))


def _moments(a: np.ndarray, b: np.ndarray):
    ah, bh = homogeneous(a), homogeneous(b)
    m = (ah[:, :, None] * bh[:, None, :]).reshape(-1, 9)  # kron(a_h, b_h), row-major vec(E)
    Q = m.T @ m / len(m)
    A = ah.T @ ah / len(ah)
    B = bh.T @ bh / len(bh)
    return Q, A, B


def sigma2_onesided(a, b) -> float:
    """One-sided GEP estimator [C]: view ``a`` exact, view ``b`` carries N(0, sigma^2 I) noise.

    In the paper's model a = current frame q, b = keyframe-left z. If both views are noisy it
    returns the *summed* variance (about 2 sigma^2), see :func:`sigma2_symmetric`.
    Needs >= 9 non-degenerate correspondences.
    """
    a = as_points(a, 2, "a")
    b = as_points(b, 2, "b")
    n = same_length(a, b)
    need(n, 9)
    Q, A, _ = _moments(a, b)
    return _smallest_root(Q, np.kron(A, _D))


def sigma2_symmetric(a, b) -> float:
    """Symmetric GEP [PROPOSAL, spec 3]: both views noisy with the same sigma^2 (bias O(sigma^4))."""
    a = as_points(a, 2, "a")
    b = as_points(b, 2, "b")
    n = same_length(a, b)
    need(n, 9)
    Q, A, B = _moments(a, b)
    return _smallest_root(Q, np.kron(A, _D) + np.kron(_D, B))


def sigma2_stereo(z, y, R_rl, t_rl) -> float:
    """Per-image noise variance from the known stereo epipolar geometry [PROPOSAL, spec 3].

    ``z`` keyframe-left, ``y`` keyframe-right (normalized), ``X_R = R_rl X_L + t_rl``.
    sigma^2 = sum r_i^2 / sum(||E12 E z_i||^2 + ||E12 E^T y_i||^2), r_i = y_i^T E z_i.
    Assumes the stereo matches are outlier-free.
    """
    z, y, R_rl, t_rl = stereo_inputs(z, y, R_rl, t_rl)
    E = skew(t_rl) @ R_rl
    zh, yh = homogeneous(z), homogeneous(y)
    Ez = zh @ E.T
    Ety = yh @ E
    r = np.sum(yh * Ez, axis=1)
    den = np.sum(Ez[:, :2] ** 2) + np.sum(Ety[:, :2] ** 2)
    if den <= 0:
        raise DegenerateInput("sigma2_stereo: zero epipolar gradient (zero baseline?)")
    return float(np.sum(r * r) / den)
