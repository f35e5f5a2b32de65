"""6-DOF refinement with joint gravity-prior covariance estimation (spec section 8).

State (spec 8.1): chi = [psi, t_CK (3), phi_1, theta_1, ..., phi_K, theta_K] -- relative yaw and
translation of the current camera w.r.t. the keyframe, and the *absolute* IMU roll/pitch at the K
IMU samples of the window (k = 1: keyframe, k = K: current frame). The relative rotation is

    R_CK = R_IC^T R_tilt(phi_K, theta_K)^T Rz(psi) R_tilt(phi_1, theta_1) R_IC.

Residuals (all whitened, stacked into one vector):

1. visual   r_i = q_i - pi(R_CK p_i + t_CK), Sigma_vis_i = J_h Sigma_i J_h^T + sigma^2 I
   (J_h = d pi / d p, fixed at the initial estimate) [PROPOSAL 8.1.1];
2. gravity  r_k = a_k - R_tilt_k^T e3 with the unknown shared covariance Sigma_imu;
3. gyro chain r_k = (phi, theta)_{k+1} - tilt(R_tilt_k dR_k), covariance ``gyro_var`` I_2 [PROPOSAL];
4. keyframe tilt prior r = (phi, theta)_1 - prior_mean, covariance prior_cov [PROPOSAL].

Joint objective (spec 8.2): J = sum of squared whitened residuals + K log det Sigma_imu.
Block coordinate descent (spec 8.3): chi-step = up to ``lm_iters`` Levenberg-Marquardt iterations with
Sigma fixed (a step is accepted only if J decreases, else the damping is raised; one that lowers J by
less than ``rel_tol`` relative ends the chi-step), Sigma-step in
closed form (:func:`sigma_step`), stop at a relative decrease < ``rel_tol`` or ``max_iter``
iterations. Units: angles in rad, translations in m, image coordinates normalized.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from gevi_cli.geometry import (
    drot_z,
    exp_so3,
    project_jacobian,
    rot_x,
    rot_y,
    rot_z,
    rtilt,
    tilt_angles,
    wrap_angle,
)

from ._checks import as_covs, as_matrix, as_points, finite_scalar, need, same_length
from .errors import DegenerateInput, ShapeError


def sigma_step(residuals, lo, hi, prior_scatter=None, prior_dof: float = 0.0) -> np.ndarray:
    """Closed-form minimiser of tr(Sigma^-1 S) + K log det Sigma s.t. lo <= eig(Sigma) <= hi.

    ``residuals`` (K, 3): gravity-prior residuals a_k - R_tilt_k^T e3 (unit-vector differences,
    dimensionless). With S = sum r r^T = V diag(s) V^T the minimiser is
    V diag(clip(s / K, lo, hi)) V^T (spec 8.3). [PROPOSAL] lo = (sigma_a / g)^2, hi = 0.2^2.
    With the conjugate (Wishart-type) prior of spec 8.3 [PROPOSAL], ``prior_scatter`` Psi0 (3, 3) and
    ``prior_dof`` nu0, the objective gains tr(Sigma^-1 Psi0) + nu0 log det Sigma and the minimiser is
    clip((S + Psi0) / (K + nu0)).
    """
    r = as_points(residuals, 3, "residuals")
    K = len(r)
    need(K, 1, "residual vectors")
    lo = finite_scalar(lo, "lo")
    hi = finite_scalar(hi, "hi")
    if not 0 < lo <= hi:
        raise DegenerateInput("sigma_step needs 0 < lo <= hi")
    if prior_scatter is not None and prior_dof > 0:
        prior_scatter = as_matrix(prior_scatter, (3, 3), "prior_scatter")
    return _sigma_step(r, lo, hi, prior_scatter, prior_dof)


def _sigma_step(r, lo, hi, prior_scatter, prior_dof) -> np.ndarray:
    """:func:`sigma_step` on checked inputs."""
    S = r.T @ r
    K = len(r)
    if prior_scatter is not None and prior_dof > 0:
        S = S + prior_scatter
        K = K + float(prior_dof)
    s, V = np.linalg.eigh(S)
    return (V * np.clip(s / K, lo, hi)) @ V.T


def sigma_objective(Sigma, residuals) -> float:
    """tr(Sigma^-1 S) + K log det Sigma (the Sigma-dependent part of the joint cost)."""
    r = np.asarray(residuals, float)
    S = r.T @ r
    sign, logdet = np.linalg.slogdet(Sigma)
    if sign <= 0:
        raise DegenerateInput("Sigma not positive definite")
    return float(np.trace(np.linalg.solve(Sigma, S)) + len(r) * logdet)


# ---------------------------------------------------------------------------------------------
# Window / state containers


@dataclass
class FusionWindow:
    """Measurements of one BCD window (spec 8.1).

    Vision: ``p`` (n, 3) keyframe-left points with covariances ``cov`` (n, 3, 3) (m, m^2), ``q``
    (n, 2) normalized current-left coordinates, ``sigma2`` the normalized image variance (the
    sigma^2 I term of Sigma_vis). ``R_ic`` maps camera vectors into the IMU frame.
    IMU: ``acc_dir`` (K, 3) bias-corrected *unit* accelerometer directions at the K samples
    (k = 0 keyframe, k = K-1 current frame), ``gyro_inc`` (K-1, 3) bias-corrected gyro rotation
    increments (omega_k - b_g) dt [rad] between samples k and k+1, ``gyro_var`` the variance of one
    gyro-chain residual (a number, or one per link: (K-1,)) (sigma_g^2 dt with sigma_g the white-noise density, rad^2).
    Prior: keyframe roll/pitch ``prior_mean`` (2,) and ``prior_cov`` (2, 2) (rad, rad^2), e.g. the
    previous window's last tilt and :attr:`FusionState.cov_last_tilt`.
    ``lo``/``hi``: eigenvalue bounds of Sigma_imu [PROPOSAL lo = (sigma_a/g)^2, hi = 0.2^2].
    ``sigma_prior``/``sigma_prior_dof``: conjugate prior on Sigma_imu (spec 8.3 [PROPOSAL]; the joint
    objective gains nu0 (tr(Sigma^-1 sigma_prior) + log det Sigma)).
    Initial relative pose ``psi0``/``t0`` (spec 6); ``tilts0`` (K, 2) defaults to gyro propagation
    from ``prior_mean``.
    """

    p: np.ndarray
    cov: np.ndarray
    q: np.ndarray
    sigma2: float
    R_ic: np.ndarray
    acc_dir: np.ndarray
    gyro_inc: np.ndarray
    gyro_var: float | np.ndarray
    prior_mean: np.ndarray
    prior_cov: np.ndarray
    psi0: float
    t0: np.ndarray
    lo: float
    hi: float = 0.2**2
    tilts0: np.ndarray | None = None
    sigma_prior: np.ndarray | None = None  # Psi0 / nu0: the prior guess of Sigma_imu (e.g. from recent innovations)
    sigma_prior_dof: float = 0.0  # nu0, its weight in residual-equivalents (0: no prior, the plain spec 8.3)


@dataclass
class FusionState:
    """BCD estimate: relative yaw ``psi`` (rad), ``t`` = t_CK (m), absolute tilts (K, 2) as
    (roll, pitch) per IMU sample (rad); ``cov_last_tilt`` (2, 2) the marginal covariance of the
    last (current-frame) tilt from (J^T J)^-1 at the solution (the next window's prior)."""

    psi: float
    t: np.ndarray
    tilts: np.ndarray
    cov_last_tilt: np.ndarray = field(default_factory=lambda: np.full((2, 2), np.nan))

    def R_ck(self, R_ic) -> np.ndarray:
        R_ic = np.asarray(R_ic, float)
        return R_ic.T @ rtilt(*self.tilts[-1]).T @ rot_z(self.psi) @ rtilt(*self.tilts[0]) @ R_ic

    def as_vector(self) -> np.ndarray:
        return np.r_[self.psi, self.t, self.tilts.ravel()]


def propagate_tilts(tilt1, gyro_inc) -> np.ndarray:
    """Roll/pitch at every sample by gyro propagation from ``tilt1`` (yaw-invariant, spec 8.1.3):
    tilt_{k+1} = tilt(R_tilt(tilt_k) Exp(gyro_inc_k)). Returns (K, 2)."""
    dR = exp_so3(np.asarray(gyro_inc, float))
    out = np.empty((len(dR) + 1, 2))
    out[0] = tilt1
    for k in range(len(dR)):  # sequential by nature (K - 1 <= ~40 samples)
        out[k + 1] = tilt_angles(rtilt(*out[k]) @ dR[k])
    return out


# ---------------------------------------------------------------------------------------------
# Residuals and Jacobians (vectorized over points and samples)


def _gravity_parts(tilts):
    """(K, 3, 3): rows g = R_tilt^T e3 = (-s_th, c_th s_ph, c_th c_ph), d g / d roll, d g / d pitch."""
    c, s = np.cos(tilts), np.sin(tilts)
    cp, ct, sp, st = c[:, 0], c[:, 1], s[:, 0], s[:, 1]
    a, b, e, f = ct * sp, ct * cp, st * sp, st * cp
    G = np.empty((len(tilts), 3, 3))
    G[:, 0, 0], G[:, 0, 1], G[:, 0, 2] = -st, a, b
    G[:, 1, 0], G[:, 1, 1], G[:, 1, 2] = 0.0, b, -a
    G[:, 2, 0], G[:, 2, 1], G[:, 2, 2] = -ct, -e, -f
    return G


def _gravity_dir(tilts):
    """g = R_tilt^T e3 = (-s_th, c_th s_ph, c_th c_ph) and its derivatives (K, 3) each."""
    G = _gravity_parts(tilts)
    return G[:, 0], G[:, 1], G[:, 2]


def _rot_parts(psi, ph1, th1, phK, thK):
    """R_tilt(phi_1, theta_1), R_tilt(phi_K, theta_K), Rz(psi) written out (the products of
    :func:`rtilt` / :func:`rot_z` have one nonzero term per entry: the same numbers)."""
    out = []
    for ph, th in ((ph1, th1), (phK, thK)):
        cp, sp, ct, st = math.cos(ph), math.sin(ph), math.cos(th), math.sin(th)
        out.append(np.array([[ct, st * sp, st * cp], [0.0, cp, -sp], [-st, ct * sp, ct * cp]]))
    cz, sz = math.cos(psi), math.sin(psi)
    return out[0], out[1], np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])


def _drtilt(ph, th):
    """d R_tilt / d roll and d R_tilt / d pitch (R_tilt = Ry(th) Rx(ph))."""
    c, s = np.cos(ph), np.sin(ph)
    dRx = np.array([[0.0, 0.0, 0.0], [0.0, -s, -c], [0.0, c, -s]])
    c, s = np.cos(th), np.sin(th)
    dRy = np.array([[-s, 0.0, c], [0.0, 0.0, 0.0], [-c, 0.0, -s]])
    return rot_y(th) @ dRx, dRy @ rot_x(ph)


def _chol2_inv(C):
    """Inverse lower Cholesky factor of 2x2 SPD matrices (..., 2, 2): W with W C W^T = I."""
    a, b, c = C[..., 0, 0], C[..., 1, 0], C[..., 1, 1]
    if np.any(a <= 0):
        raise DegenerateInput("covariance not positive definite")
    l11 = np.sqrt(a)
    l21 = b / l11
    d = c - l21 * l21
    if np.any(d <= 0):
        raise DegenerateInput("covariance not positive definite")
    l22 = np.sqrt(d)
    W = np.zeros(C.shape)
    W[..., 0, 0] = 1.0 / l11
    W[..., 1, 1] = 1.0 / l22
    W[..., 1, 0] = -l21 / (l11 * l22)
    return W


@functools.lru_cache(maxsize=64)
def _normal_indices(K):
    """Columns of the visual block (psi, t, tilt_1, tilt_K) and flat indices into H (dim x dim) of the
    visual 8x8 block, the diagonal 2x2 tilt blocks, the chain blocks (k, k+1) and (k+1, k)."""
    d = 4 + 2 * K
    cols = np.r_[0:6, d - 2, d - 1]
    blk = 4 + 2 * np.arange(K)[:, None, None] + np.arange(2)[None, :, None]  # (K, 2, 1) rows of tilt k
    out = (cols, (cols[:, None] * d + cols[None, :]).ravel(), (blk * d + np.swapaxes(blk, 1, 2)).ravel(),
           (blk[:-1] * d + np.swapaxes(blk[1:], 1, 2)).ravel(), (blk[1:] * d + np.swapaxes(blk[:-1], 1, 2)).ravel())
    for a in out:
        a.flags.writeable = False
    return out


class _Problem:
    """Whitened residual vector and Jacobian of one window for a fixed Sigma_imu.

    ``Wvis`` are the lower-triangular factors of :func:`_chol2_inv` (the structured path uses W_01 = 0)."""

    def __init__(self, w: FusionWindow, Wvis):
        self.w = w
        self.Wvis = Wvis  # (n, 2, 2) inverse Cholesky factors of Sigma_vis
        self.a = w.p @ w.R_ic.T  # points in the keyframe IMU-oriented frame
        self.K = len(w.acc_dir)
        self.dR = exp_so3(w.gyro_inc)  # (K-1, 3, 3)
        self.Wg = np.broadcast_to(1.0 / np.sqrt(w.gyro_var), (len(w.acc_dir) - 1,))  # per chain link
        self.Wp = _chol2_inv(w.prior_cov)
        n = len(w.p)
        self.nv, self.ng, self.nc = 2 * n, 3 * self.K, 2 * (self.K - 1)
        self.dim = 4 + 2 * self.K
        self._last = None  # (x, Sigma-free parts) of the last evaluation with a Jacobian
        # structured normal equations: the lower-triangular whitening factors, the block indices into H
        self.W00, self.W10, self.W11 = Wvis[:, 0, 0], Wvis[:, 1, 0], Wvis[:, 1, 1]
        self.cols_vis, self.idx_vis, self.idx_diag, self.idx_up, self.idx_lo = _normal_indices(self.K)
        self.a1 = np.column_stack([self.a, np.ones(n)])  # homogeneous: d X / d t from the same product
        self._Mc = np.zeros((4, 24))  # [a, 1] @ Mc = d X / d (psi, t, tilt_1, tilt_K), (n, 3 x 8)
        self._Mc[3, [1, 10, 19]] = 1.0  # d X_c / d t_c
        self._dM = np.zeros((8, 3, 3))  # d M / d (psi, t, tilt_1, tilt_K) work array (t: 0)
        self._Av = np.empty((2 * n, 8))  # work array of the visual Jacobian
        self._Dconst = np.zeros((self.K, 2, 2))  # J-independent part of the diagonal tilt blocks of H:
        self._Dconst[1:] = (self.Wg ** 2)[:, None, None] * np.eye(2)  # chain rows of tilt k+1,
        self._Dconst[0] += self.Wp.T @ self.Wp  # prior

    def unpack(self, x):
        return x[0], x[1:4], x[4:].reshape(self.K, 2)

    def _vis_residual(self, psi, t, T):
        """Whitened visual residuals (n, 2) and the intermediates of their Jacobian; None if a point is
        behind the current camera."""
        w = self.w
        B1, BK, Z = _rot_parts(psi, *T[0].tolist(), *T[-1].tolist())
        P = w.R_ic.T @ BK.T
        PZ = P @ Z
        M = PZ @ B1  # X = a @ M^T + t
        X = self.a @ M.T + t
        if X[:, 2].min() <= 0:  # (= np.any(X[:, 2] <= 0), NaN included)
            return None
        u = X[:, :2] / X[:, 2:3]  # project(X)
        return np.einsum("nij,nj->ni", self.Wvis, w.q - u), X, u, B1, BK, Z, P, PZ, M

    def _vis_mats(self, psi, T, B1, BK, Z):
        """d M / d (psi, phi_1, theta_1, phi_K, theta_K) (5 matrices, M = R_IC^T B_K^T Rz(psi) B_1)."""
        Ric = self.w.R_ic
        d1p, d1t = _drtilt(*T[0])
        dKp, dKt = _drtilt(*T[-1])
        return (
            Ric.T @ BK.T @ drot_z(psi) @ B1,
            Ric.T @ BK.T @ Z @ d1p,
            Ric.T @ BK.T @ Z @ d1t,
            Ric.T @ dKp.T @ Z @ B1,
            Ric.T @ dKt.T @ Z @ B1,
        )

    def vis(self, x, jac=True):
        """Dense reference: whitened visual residuals (2n,) [and their (2n, dim) Jacobian]."""
        psi, t, T = self.unpack(x)
        res = self._vis_residual(psi, t, T)
        if res is None:
            return None, None
        rw, X, _, B1, BK, Z = res[:6]
        if not jac:
            return rw.ravel(), None
        mats = self._vis_mats(psi, T, B1, BK, Z)
        dX = np.stack([self.a @ Mj.T for Mj in mats], axis=2)  # (n, 3, 5)
        P = project_jacobian(X)  # (n, 2, 3)
        WP = -self.Wvis @ P  # d rw / d X
        J = np.zeros((len(X), 2, self.dim))
        J[:, :, 1:4] = WP
        Jr = WP @ dX  # (n, 2, 5)
        J[:, :, 0] = Jr[:, :, 0]
        J[:, :, 4:6] += Jr[:, :, 1:3]
        J[:, :, self.dim - 2:] += Jr[:, :, 3:5]
        return rw.ravel(), J.reshape(-1, self.dim)

    def imu_raw(self, x):
        _, _, T = self.unpack(x)
        g, dgp, dgt = _gravity_dir(T)
        return self.w.acc_dir - g, g, dgp, dgt

    def _chain_residual(self, T, g):
        """Whitened gyro-chain residuals (K-1, 2) and m_k = dR_k^T g_k (K-1, 3)."""
        m = np.einsum("kji,kj->ki", self.dR, g[:-1])  # dR_k^T g_k
        roll = np.arctan2(m[:, 1], m[:, 2])
        pitch = -np.arcsin(np.clip(m[:, 0], -1.0, 1.0))
        return np.column_stack([wrap_angle(T[1:, 0] - roll), T[1:, 1] - pitch]) * self.Wg[:, None], m

    def chain(self, T, g, dgp, dgt, jac=True):
        """Dense reference: whitened gyro-chain residuals [and their (2(K-1), dim) Jacobian]."""
        r, m = self._chain_residual(T, g)
        if not jac:
            return r.ravel(), None
        Km = self.K - 1
        h = m[:, 1] ** 2 + m[:, 2] ** 2
        dpred = np.zeros((Km, 2, 3))
        dpred[:, 0, 1] = m[:, 2] / h
        dpred[:, 0, 2] = -m[:, 1] / h
        dpred[:, 1, 0] = -1.0 / np.sqrt(np.maximum(1.0 - m[:, 0] ** 2, 1e-300))
        dm = np.einsum("kji,kjc->kic", self.dR, np.stack([dgp[:-1], dgt[:-1]], axis=2))  # (Km, 3, 2)
        J = np.zeros((Km, 2, self.dim))
        rows = np.arange(Km)
        Jk = -self.Wg[:, None, None] * (dpred @ dm)  # w.r.t. tilt k
        for c in range(2):
            J[rows, :, 4 + 2 * rows + c] = Jk[:, :, c]
            J[rows, c, 4 + 2 * (rows + 1) + c] = self.Wg
        return r.ravel(), J.reshape(-1, self.dim)

    def evaluate(self, x, Lsig_inv, jac=True):
        """Stacked whitened residuals (vis, gravity, chain, prior) [and Jacobian]; None if invalid.

        The dense reference of :meth:`at` / :meth:`residual` / :meth:`normal` (which :func:`bcd_refine`
        uses). Only the gravity block depends on Sigma: the parts of the last state evaluated with a Jacobian
        are kept, so the Sigma-step's re-evaluation at an unchanged state costs just the re-whitening."""
        if jac and self._last is not None and np.array_equal(self._last[0], x):
            rv, Jv, ri, dgp, dgt, rc, Jc, rp = self._last[1:]
        else:
            rv, Jv = self.vis(x, jac)
            if rv is None:
                return None, None, None
            _, _, T = self.unpack(x)
            ri, g, dgp, dgt = self.imu_raw(x)
            rc, Jc = self.chain(T, g, dgp, dgt, jac)
            rp = self._prior_residual(T)
            if jac:
                self._last = (x.copy(), rv, Jv, ri, dgp, dgt, rc, Jc, rp)
        r = np.concatenate([rv, (ri @ Lsig_inv.T).ravel(), rc, rp])
        if not jac:
            return r, ri, None
        Ji = np.zeros((self.K, 3, self.dim))
        rows = np.arange(self.K)
        Ji[rows, :, 4 + 2 * rows] = -dgp @ Lsig_inv.T
        Ji[rows, :, 5 + 2 * rows] = -dgt @ Lsig_inv.T
        Jp = np.zeros((2, self.dim))
        Jp[:, 4:6] = self.Wp
        J = np.concatenate([Jv, Ji.reshape(-1, self.dim), Jc, Jp])
        return r, ri, J

    def _prior_residual(self, T):
        return self.Wp @ np.array([wrap_angle(T[0, 0] - self.w.prior_mean[0]), T[0, 1] - self.w.prior_mean[1]])

    # --- structured path: the same residuals, normal equations assembled from the Jacobian's blocks

    def at(self, x):
        """The Sigma-free residuals at state ``x`` (a :class:`_Point`; its Jacobian parts are formed on
        demand by :meth:`normal`), or None if a point is behind the current camera."""
        psi, t, T = self.unpack(x)
        res = self._vis_residual(psi, t, T)
        if res is None:
            return None
        G = _gravity_parts(T)
        rc, m = self._chain_residual(T, G[:, 0])
        return _Point(x, res[0].ravel(), self.w.acc_dir - G[:, 0], G[:, 1:], rc.ravel(), self._prior_residual(T),
                      res[1:], m)

    def residual(self, pt, Lsig_inv):
        """Stacked whitened residual vector (vis, gravity, chain, prior), as :meth:`evaluate`."""
        return np.concatenate([pt.rv, (pt.ri @ Lsig_inv.T).ravel(), pt.rc, pt.rp])

    def normal(self, pt, Lsig_inv):
        """Gauss-Newton normal equations (H = J^T J, g = J^T r) at ``pt`` for Sigma_imu = L L^T.

        Assembled from the blocks of J: the visual rows touch only psi, t, tilt_1, tilt_K (an 8x8
        normal matrix), the gravity rows of sample k only tilt k (2x2 blocks), a chain link tilts k and
        k+1 (block-tridiagonal), the prior tilt_1. The Sigma-free part is kept in ``pt``."""
        if pt.H0 is None:
            pt.H0, pt.g0 = self._normal_free(pt)
        L3 = pt.D @ Lsig_inv.T  # (K, 2, 3): whitened d g_k / d (phi_k, theta_k), up to the sign
        rg = pt.ri @ Lsig_inv.T
        H = pt.H0.copy()
        H.ravel()[self.idx_diag] += (L3 @ np.swapaxes(L3, 1, 2)).ravel()
        g = pt.g0.copy()
        g[4:] -= np.einsum("kcj,kj->kc", L3, rg).ravel()
        return H, g

    def _normal_free(self, pt):
        """H and g of the visual, chain and prior rows (everything but the gravity rows)."""
        X, u, B1, BK, Z, P, PZ, M = pt.vis
        n, d, K = len(X), self.dim, self.K
        # visual: d M / d (psi, phi_1, theta_1, phi_K, theta_K) by the generators of Rz and R_tilt
        # (d Rz = [e3]x Rz, d R_tilt / d phi = R_tilt [e1]x, d R_tilt / d theta = [e2]x R_tilt), the
        # skew products written out as row / column permutations
        Q = Z @ B1
        V = BK.T @ Q
        dM = self._dM  # (8, 3, 3) by parameter; the translation entries stay 0
        dM[0] = P @ np.array([-Q[1], Q[0], np.zeros(3)])  # P [e3]x Q
        dM[4, :, 1] = M[:, 2]  # M [e1]x (column 0 stays 0)
        dM[4, :, 2] = -M[:, 1]
        dM[5] = PZ @ np.array([B1[2], np.zeros(3), -B1[0]])  # P Z [e2]x B1
        dM[6] = -self.w.R_ic.T @ np.array([np.zeros(3), -V[2], V[1]])  # -R_IC^T [e1]x BK^T Q
        dM[7] = -P @ np.array([Q[2], np.zeros(3), -Q[0]])  # -P [e2]x Q
        # d X_c / d (psi, t, phi_1, theta_1, phi_K, theta_K) = ([a, 1] @ Mc)[:, 8 c: 8 c + 8]
        Mc = self._Mc
        Mc[:3] = dM.transpose(2, 1, 0).reshape(3, 24)
        Y = self.a1 @ Mc
        # d rw / d param = -W d pi / d X dX (W lower triangular), rows 0 then rows 1: A (2n, 8) = -J
        iz = 1.0 / X[:, 2]
        du = Y[:, :8] - u[:, 0:1] * Y[:, 16:]
        dv = Y[:, 8:16] - u[:, 1:2] * Y[:, 16:]
        A = self._Av
        np.multiply((self.W00 * iz)[:, None], du, out=A[:n])
        np.multiply((self.W10 * iz)[:, None], du, out=A[n:])
        A[n:] += (self.W11 * iz)[:, None] * dv
        H = np.zeros((d, d))
        Hf = H.ravel()
        Hf[self.idx_vis] = (A.T @ A).ravel()
        g = np.zeros(d)
        g[self.cols_vis] = -(A.T @ pt.rv.reshape(n, 2).T.ravel())
        # chain link k: A_k on tilt k, Wg_k I on tilt k+1
        m = pt.m
        h = m[:, 1] ** 2 + m[:, 2] ** 2
        dm = pt.D[:-1] @ self.dR  # (K-1, 2, 3): d m_k / d (phi_k, theta_k), one row per angle
        Wg = self.Wg[:, None]
        A = np.empty((K - 1, 2, 2))
        A[:, 0] = -Wg * (m[:, 2:3] * dm[:, :, 1] - m[:, 1:2] * dm[:, :, 2]) / h[:, None]
        A[:, 1] = Wg * dm[:, :, 0] / np.sqrt(np.maximum(1.0 - m[:, 0:1] ** 2, 1e-300))
        rc = pt.rc.reshape(K - 1, 2)
        AT = np.swapaxes(A, 1, 2)
        Dg = self._Dconst.copy()
        Dg[:-1] += AT @ A
        Off = AT * Wg[:, :, None]
        Hf[self.idx_diag] += Dg.ravel()
        Hf[self.idx_up] += Off.ravel()  # (+=: with K = 2 the visual tilt_1 / tilt_K block is this one)
        Hf[self.idx_lo] += np.swapaxes(Off, 1, 2).ravel()
        gt = np.zeros((K, 2))
        gt[:-1] = np.einsum("kji,kj->ki", A, rc)
        gt[1:] += Wg * rc
        gt[0] += self.Wp.T @ pt.rp
        g[4:] += gt.ravel()
        return H, g


class _Point:
    """Sigma-free residual parts of one state (see :meth:`_Problem.at`)."""

    __slots__ = ("D", "H0", "g0", "m", "rc", "ri", "rp", "rv", "vis", "x")

    def __init__(self, x, rv, ri, D, rc, rp, vis, m):
        self.x, self.rv, self.ri, self.D, self.rc, self.rp, self.vis, self.m = x, rv, ri, D, rc, rp, vis, m
        self.H0 = self.g0 = None  # D (K, 2, 3): d g_k / d (phi_k, theta_k)


def _vis_covariance(w: FusionWindow, x0):
    """Sigma_vis_i = J_h Sigma_i J_h^T + sigma^2 I at the initial estimate (spec 8.1.1 PROPOSAL)."""
    K = len(w.acc_dir)
    T = x0[4:].reshape(K, 2)
    R = w.R_ic.T @ rtilt(*T[-1]).T @ rot_z(x0[0]) @ rtilt(*T[0]) @ w.R_ic
    X = w.p @ R.T + x0[1:4]
    if np.any(X[:, 2] <= 0):
        raise DegenerateInput("bcd_refine: point behind the current camera at the initial estimate")
    Jh = project_jacobian(X) @ R
    S = Jh @ w.cov @ np.swapaxes(Jh, 1, 2) + w.sigma2 * np.eye(2)
    return S


def _check_window(w: FusionWindow) -> FusionWindow:
    p = as_points(w.p, 3, "p")
    q = as_points(w.q, 2, "q")
    n = same_length(p, q)
    need(n, 3)
    cov = as_covs(w.cov, n, 3, "cov")
    acc = as_points(w.acc_dir, 3, "acc_dir")
    K = len(acc)
    need(K, 2, "IMU samples")
    gyr = as_points(w.gyro_inc, 3, "gyro_inc")
    if len(gyr) != K - 1:
        raise ShapeError(f"gyro_inc must have K-1 = {K - 1} rows, got {len(gyr)}")
    tilts0 = None if w.tilts0 is None else as_points(w.tilts0, 2, "tilts0")
    if tilts0 is not None and len(tilts0) != K:
        raise ShapeError("tilts0 must have shape (K, 2)")
    lo, hi = finite_scalar(w.lo, "lo"), finite_scalar(w.hi, "hi")
    if not 0 < lo <= hi:
        raise DegenerateInput("bcd_refine needs 0 < lo <= hi")
    gv = np.asarray(w.gyro_var, dtype=float)
    if gv.ndim == 0:
        gv = float(finite_scalar(gv, "gyro_var"))
    elif gv.shape != (K - 1,) or not np.all(np.isfinite(gv)):
        raise ShapeError(f"gyro_var must be a number or have K-1 = {K - 1} finite entries")
    s2 = finite_scalar(w.sigma2, "sigma2")
    if np.any(np.asarray(gv) <= 0) or s2 < 0:
        raise DegenerateInput("gyro_var must be > 0 and sigma2 >= 0")
    return FusionWindow(
        p=p, cov=cov, q=q, sigma2=s2, R_ic=as_matrix(w.R_ic, (3, 3), "R_ic"), acc_dir=acc, gyro_inc=gyr,
        gyro_var=gv, prior_mean=as_matrix(w.prior_mean, (2,), "prior_mean"),
        prior_cov=as_matrix(w.prior_cov, (2, 2), "prior_cov"), psi0=finite_scalar(w.psi0, "psi0"),
        t0=as_matrix(w.t0, (3,), "t0"), lo=lo, hi=hi, tilts0=tilts0,
        sigma_prior=None if w.sigma_prior is None else as_matrix(w.sigma_prior, (3, 3), "sigma_prior"),
        sigma_prior_dof=finite_scalar(w.sigma_prior_dof, "sigma_prior_dof"))


def _sigma_parts(Sigma, w: FusionWindow):
    """(L^-1 with Sigma = L L^T, the Sigma-dependent part of J): K log det Sigma, plus with the
    conjugate prior nu0 (tr(Sigma^-1 sigma_prior) + log det Sigma)."""
    Lc = np.linalg.cholesky(Sigma)
    Linv = np.linalg.inv(Lc)
    logdet = 2.0 * float(np.sum(np.log(np.diag(Lc))))
    cost = len(w.acc_dir) * logdet
    if w.sigma_prior is not None and w.sigma_prior_dof > 0:
        cost += w.sigma_prior_dof * (float(np.trace(Linv @ w.sigma_prior @ Linv.T)) + logdet)
    return Linv, cost


def bcd_refine(window: FusionWindow, adaptive=True, max_iter=6, rel_tol=1e-6, lm_iters=2, mu0=1e-4):
    """Block coordinate descent of spec 8.3 -> (FusionState, Sigma_imu (3, 3), cost_history).

    ``cost_history`` lists J(chi, Sigma) at the start and after every chi-step and Sigma-step
    (non-increasing by construction). ``adaptive=False`` keeps Sigma_imu = lo I (the fixed-weight
    baseline; only chi-steps). LM: (H + mu diag H) d = -g, mu starts at ``mu0``, x10 on a rejected
    step (up to 10 tries), /10 on an accepted one.
    """
    w = _check_window(window)
    K = len(w.acc_dir)
    tilts0 = propagate_tilts(w.prior_mean, w.gyro_inc) if w.tilts0 is None else w.tilts0
    x = np.r_[w.psi0, w.t0, tilts0.ravel()]
    prob = _Problem(w, _chol2_inv(_vis_covariance(w, x)))
    Sigma = w.lo * np.eye(3)
    Linv, c_sig = _sigma_parts(Sigma, w)
    pt = prob.at(x)
    if pt is None:
        raise DegenerateInput("bcd_refine: invalid initial estimate")
    r = prob.residual(pt, Linv)
    cost = float(r @ r) + c_sig
    scatter = None if w.sigma_prior is None else w.sigma_prior * w.sigma_prior_dof
    hist = [cost]
    mu = mu0
    for _ in range(max_iter):
        start = cost
        # chi-step: LM with Sigma fixed, accept only decreases; a step that lowered J by less than
        # rel_tol ends it (spec 8.3 allows 1-2 iterations: near the optimum a further Gauss-Newton step
        # gains less still, and measured on the pipeline's windows it changed the state by < 1e-7 rel.)
        for _ in range(lm_iters):
            before = cost
            H, gvec = prob.normal(pt, Linv)
            dH = np.diag(H).copy()
            accepted = False
            for _ in range(10):
                try:
                    d = np.linalg.solve(H + mu * np.diag(dH), -gvec)
                except np.linalg.LinAlgError:
                    mu *= 10.0
                    continue
                ptn = prob.at(pt.x + d)
                if ptn is not None:
                    rn = prob.residual(ptn, Linv)
                    cn = float(rn @ rn) + c_sig
                    if cn < cost:
                        pt, cost = ptn, cn
                        mu = max(mu / 10.0, 1e-12)
                        accepted = True
                        break
                mu *= 10.0
            if not accepted or before - cost < rel_tol * abs(before):
                break
        hist.append(cost)
        if adaptive:
            # exact block minimiser; a recomputed cost above the old one can only be rounding
            # (same Sigma up to 1e-16), in which case the old Sigma is kept
            Sig_n = _sigma_step(pt.ri, w.lo, w.hi, scatter, w.sigma_prior_dof)
            Linv_n, c_sig_n = _sigma_parts(Sig_n, w)
            r_n = prob.residual(pt, Linv_n)  # only the gravity rows depend on Sigma
            c_n = float(r_n @ r_n) + c_sig_n
            if c_n <= cost:
                Sigma, Linv, c_sig, cost = Sig_n, Linv_n, c_sig_n, c_n
            hist.append(cost)
        if start - cost < rel_tol * abs(start):
            break
    x = pt.x
    H, _ = prob.normal(pt, Linv)
    try:  # the last 2x2 block of H^-1: H^-1 applied to the last two unit vectors
        cov_last = np.linalg.solve(H, np.eye(prob.dim)[:, -2:])[-2:]
    except np.linalg.LinAlgError:
        cov_last = np.full((2, 2), np.nan)
    state = FusionState(psi=float(wrap_angle(x[0])), t=x[1:4].copy(), tilts=x[4:].reshape(K, 2).copy(),
                        cov_last_tilt=cov_last)
    return state, Sigma, hist


def joint_cost(window: FusionWindow, state: FusionState, Sigma, x_init=None) -> float:
    """J(chi, Sigma) of spec 8.2 for a state (Sigma_vis fixed at ``x_init``, default the window's
    initial estimate as in :func:`bcd_refine`)."""
    w = _check_window(window)
    if x_init is None:
        tilts0 = propagate_tilts(w.prior_mean, w.gyro_inc) if w.tilts0 is None else w.tilts0
        x_init = np.r_[w.psi0, w.t0, tilts0.ravel()]
    prob = _Problem(w, _chol2_inv(_vis_covariance(w, x_init)))
    Linv, c_sig = _sigma_parts(np.asarray(Sigma, float), w)
    r, _, _ = prob.evaluate(state.as_vector(), Linv, jac=False)
    if r is None:
        return np.inf
    return float(r @ r) + c_sig
