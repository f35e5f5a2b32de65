"""Epipolar local BA over the last two keyframes (spec section 10).

Window: KF1 (fixed gauge), ordinary frames F_1..F_K (left image only) and KF2 (left + right).
Parameters ``xi_k = (alpha, beta, gamma, t)`` for k = 1..K+1 (the last is KF2) with
``R = Rz(gamma) Ry(beta) Rx(alpha)`` (ZYX, spec 10) giving ``T_K1Fk``: ``X_K1 = R X_Fk + t``.

Residual of an image pair (a, b) and a feature seen in both (spec 10):
``T_ab = T_K1a^-1 T_K1b``, ``E_ab = [t_ab]x R_ab``, ``l = E_ab^T x_a^h``,
``d = l^T x_b^h / ||E12 l||`` (distance to the epipolar line in image b, normalized units).
Right images use ``T_RL``: the right camera of frame k has ``T_K1R = T_K1Fk T_RL^-1``.

Implementation: with bearings rotated into KF1, ``u_a = R_a x_a^h``, and ``D = t_b - t_a``,
``E_ab = R_a^T [D]x R_b`` so ``l = R_b^T w`` with ``w = u_a x D``; the analytic Jacobian follows
from ``dd/dl = x_b/n - (l^T x_b) (l1, l2, 0)/n^3`` (spec 6.3). All residuals of one image pair share
its two poses, so ``l^T = y_a^T G`` with one 3 x 3 ``G = R_a^T [D]x R_b M_b`` per pair (and its 12
derivatives, formed per pair), and the per-residual work is one small matrix product per pair. The
index arrays (which feature, which two images) are built once per window by ``np.intersect1d`` per
image pair (a Python loop over the O(K^2) pairs only).

Robust kernel [PROPOSAL, spec 10]: Huber with ``delta = 3 sigma_hat`` (default); the authors'
truncated kernel ``min(d^2, delta^2)`` (our reading of their ``min(|d|, delta)/delta``; KITTI
``delta = 3e-4``) and no kernel are options. ``sigma_hat`` is ``window.sigma`` if given, else the
MAD of the initial residuals.

Solver (spec: "LM (least_squares), sparse Jacobian, ~10 iterations" [PROPOSAL]): two options.
``solver="lm"`` (default): a small built-in Levenberg–Marquardt with IRLS kernel weights on the
6(K+1)-square normal equations (analytic Jacobian; cost-decrease acceptance). ``solver="scipy"``:
``scipy.optimize.least_squares`` ('trf', the only method with a robust loss and sparse Jacobians;
``method='lm'`` allowed with ``kernel='none'``) with the same analytic Jacobian, dense ('exact') or
CSR ('lsmr'); ``BAProblem.jac_sparsity()`` gives the pattern. Why the default deviates: 'trf'
'exact' takes an SVD of the tall m x 6(K+1) Jacobian per iteration, which under multi-threaded
OpenBLAS on a loaded 2-core machine cost 0.6 s per call (4.5 s per BA; 0.15 s with
OPENBLAS_NUM_THREADS=1), and 'lsmr' needed ~15–17 evaluations to converge; the built-in LM gives
the same minimiser (tests) in < 10 iterations at ~1/10 of the time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.geometry import homogeneous, rot_x, rot_y, rot_z, skew

from .errors import DegenerateInput, NonFiniteInput, ShapeError, TooFewPoints

__all__ = [
    "ImageObs",
    "BAWindow",
    "BAOptions",
    "BAResult",
    "BAProblem",
    "build_ba_problem",
    "epipolar_local_ba",
    "euler_zyx",
    "euler_zyx_from_R",
    "poses_from_tracking",
]

_SKEW_E = skew(np.eye(3))  # [e_j]x for j = 0, 1, 2

# image slots: 0 = KF1-L, 1 = KF1-R, 2..K+1 = F_1..F_K left, K+2 = KF2-L, K+3 = KF2-R


@dataclass
class ImageObs:
    """Observations in one image: ``ids`` (n,) int feature ids (unique) and ``xy`` (n, 2) normalized."""

    ids: np.ndarray
    xy: np.ndarray


@dataclass
class BAWindow:
    """Input of :func:`epipolar_local_ba`.

    ``frames`` are F_1..F_K (left images, may be empty); ``R_init``/``t_init`` ((K+1, 3, 3),
    (K+1, 3)) are the initial ``T_K1Fk`` (pose of frame k in KF1-left coordinates), last = KF2
    (see :func:`poses_from_tracking` for the tracked ``T_CK`` form). ``X_R = R_rl X_L + t_rl``.
    ``sigma`` normalized noise std used for the Huber threshold (None: MAD estimate).
    """

    kf1_left: ImageObs
    kf1_right: ImageObs
    frames: list
    kf2_left: ImageObs
    kf2_right: ImageObs
    R_init: np.ndarray
    t_init: np.ndarray
    R_rl: np.ndarray
    t_rl: np.ndarray
    sigma: float | None = None


@dataclass
class BAOptions:
    kernel: str = "huber"  # "huber" | "truncated" | "none"
    delta: float | None = None  # kernel threshold (normalized); None: 3 sigma_hat
    max_iter: int = 10  # LM iterations ("lm") / max function evaluations ("scipy")
    use_right: bool = True  # include the pairs with right images (they carry the scale)
    solver: str = "lm"  # "lm": built-in IRLS Levenberg-Marquardt; "scipy": scipy.optimize.least_squares
    sparse: bool = False  # scipy only: analytic Jacobian as scipy.sparse CSR (tr_solver lsmr)
    method: str = "trf"  # scipy only: least_squares method ('lm' only with kernel 'none')
    tol: float = 1e-12  # relative step / cost-decrease tolerance (scipy: ftol = xtol = gtol)


@dataclass
class BAResult:
    R: np.ndarray  # (K+1, 3, 3) refined T_K1Fk rotations (last = KF2)
    t: np.ndarray  # (K+1, 3)
    R_ck: np.ndarray  # (K+1, 3, 3) inverse poses T_FkK1 (the tracked relative-pose form)
    t_ck: np.ndarray
    cost_initial: float  # robust cost (least_squares convention 0.5 sum rho) at the start
    cost_final: float
    rms_initial: float  # plain RMS of d (normalized) at the start / end
    rms_final: float
    n_residuals: int
    nfev: int
    status: int
    delta: float  # kernel threshold used
    sigma_hat: float
    pairs: list = field(default_factory=list, repr=False)  # (slot_a, slot_b, n) per used pair


def euler_zyx(angles) -> np.ndarray:
    """``Rz(g) Ry(b) Rx(a)`` for angles (..., 3) = (a, b, g)."""
    angles = np.asarray(angles, dtype=float)
    return rot_z(angles[..., 2]) @ rot_y(angles[..., 1]) @ rot_x(angles[..., 0])


def euler_zyx_from_R(R) -> np.ndarray:
    """Inverse of :func:`euler_zyx` (|beta| < pi/2): (a, b, g) = (atan2(R32,R33), -asin(R31), atan2(R21,R11))."""
    R = np.asarray(R, dtype=float)
    return np.stack([np.arctan2(R[..., 2, 1], R[..., 2, 2]), -np.arcsin(np.clip(R[..., 2, 0], -1, 1)),
                     np.arctan2(R[..., 1, 0], R[..., 0, 0])], axis=-1)


def _euler_derivs(angles):
    """R (F, 3, 3) and dR/d(a, b, g) (F, 3, 3, 3) (derivative index second)."""
    a, b, g = angles[:, 0], angles[:, 1], angles[:, 2]
    Rx, Ry, Rz = rot_x(a), rot_y(b), rot_z(g)

    def d(rot, s, c, i, j):  # derivative of an elementary rotation
        D = np.zeros_like(rot)
        D[:, i, i] = -s
        D[:, j, j] = -s
        D[:, i, j] = -c
        D[:, j, i] = c
        return D

    dRx = d(Rx, np.sin(a), np.cos(a), 1, 2)
    dRy = d(Ry, np.sin(b), np.cos(b), 2, 0)
    dRz = d(Rz, np.sin(g), np.cos(g), 0, 1)
    RzRy = Rz @ Ry
    R = RzRy @ Rx
    dR = np.stack([RzRy @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx], axis=1)
    return R, dR


def poses_from_tracking(R_ck, t_ck):
    """Tracked ``T_CK`` (X_C = R_ck X_K + t_ck, stacked) -> ``T_KC`` = BA parametrisation ``T_K1Fk``."""
    R_ck = np.asarray(R_ck, dtype=float)
    Rt = np.swapaxes(R_ck, -1, -2)
    return Rt, -np.einsum("...ij,...j->...i", Rt, np.asarray(t_ck, dtype=float))


def _check_obs(o, name):
    if not isinstance(o, ImageObs):
        raise ShapeError(f"{name} must be an ImageObs")
    ids = np.asarray(o.ids)
    xy = np.asarray(o.xy, dtype=float)
    if ids.ndim != 1 or xy.shape != (ids.shape[0], 2):
        raise ShapeError(f"{name}: ids (n,) and xy (n, 2) expected, got {ids.shape}, {xy.shape}")
    if not np.all(np.isfinite(xy)):
        raise NonFiniteInput(f"{name} contains non-finite coordinates")
    if np.unique(ids).size != ids.size:
        raise ShapeError(f"{name}: feature ids must be unique")
    return ids, xy


class BAProblem:
    """Residual/Jacobian machinery of one window (index arrays built once)."""

    def __init__(self, window: BAWindow, use_right: bool = True):
        K = len(window.frames)
        self.K = K
        self.n_frames = K + 1  # parametrised frames
        R0 = np.asarray(window.R_init, dtype=float)
        t0 = np.asarray(window.t_init, dtype=float)
        if R0.shape != (K + 1, 3, 3) or t0.shape != (K + 1, 3):
            raise ShapeError(f"R_init (K+1,3,3) / t_init (K+1,3) expected with K={K}, got {R0.shape}, {t0.shape}")
        if not (np.all(np.isfinite(R0)) and np.all(np.isfinite(t0))):
            raise NonFiniteInput("initial poses are not finite")
        R_rl = np.asarray(window.R_rl, dtype=float)
        t_rl = np.asarray(window.t_rl, dtype=float).reshape(3)
        imgs = [_check_obs(window.kf1_left, "kf1_left"), _check_obs(window.kf1_right, "kf1_right")]
        imgs += [_check_obs(f, f"frames[{i}]") for i, f in enumerate(window.frames)]
        imgs += [_check_obs(window.kf2_left, "kf2_left"), _check_obs(window.kf2_right, "kf2_right")]
        # per slot: which parametrised frame (-1 = KF1, fixed) and which camera (0 left, 1 right)
        self.slot_frame = np.array([-1, -1] + list(range(K)) + [K, K])
        slot_cam = np.array([0, 1] + [0] * K + [0, 1])
        # camera offsets: R_img = R_k M_s, t_img = t_k + R_k c_s
        M = np.stack([np.eye(3), R_rl.T])
        c = np.stack([np.zeros(3), -R_rl.T @ t_rl])
        kf2L, kf2R, kf1L, kf1R = K + 2, K + 3, 0, 1
        F = list(range(2, K + 2))
        pairs = []
        for k in F:
            pairs += [(kf2L, k), (k, kf1L)]
            if use_right:
                pairs += [(kf2R, k), (k, kf1R)]
        for j in F:
            for k in F:
                if j > k:
                    pairs.append((j, k))
        pairs += [(kf2L, kf1L)]
        if use_right:
            pairs += [(kf2L, kf1R), (kf2R, kf1L), (kf2R, kf1R)]
        sa, sb, xa, xb, used = [], [], [], [], []
        for a, b in pairs:
            _, ia, ib = np.intersect1d(imgs[a][0], imgs[b][0], assume_unique=True, return_indices=True)
            if ia.size == 0:
                continue
            used.append((a, b, int(ia.size)))
            sa.append(np.full(ia.size, a))
            sb.append(np.full(ia.size, b))
            xa.append(imgs[a][1][ia])
            xb.append(imgs[b][1][ib])
        if not used:
            raise TooFewPoints(0, 1, "epipolar residuals (no shared features)")
        self.pairs = used
        sa, sb = np.concatenate(sa), np.concatenate(sb)
        self.m = sa.size
        self.fa, self.fb = self.slot_frame[sa], self.slot_frame[sb]
        ca = slot_cam[sa]
        xa_h, xb_h = homogeneous(np.concatenate(xa)), homogeneous(np.concatenate(xb))
        self.xb = xb_h
        self.ya = np.einsum("mij,mj->mi", M[ca], xa_h)  # M_a x_a (bearing in the frame of a's body)
        self.x0 = np.concatenate([euler_zyx_from_R(R0), t0], axis=1).reshape(-1)
        self.n_params = 6 * self.n_frames
        # per image pair (residuals are stored pair after pair): its slice, frames, camera offsets, and
        # its 12 columns for the normal equations (KF1's entries point at column 0 with a zero value)
        bounds = np.concatenate([[0], np.cumsum([k for _, _, k in used])])
        self._gslices = list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))
        ga, gb = np.array([a for a, _, _ in used]), np.array([b for _, b, _ in used])
        self._gfa, self._gfb = self.slot_frame[ga], self.slot_frame[gb]
        self._gca, self._gcb, self._gMb = c[slot_cam[ga]], c[slot_cam[gb]], M[slot_cam[gb]]
        six = np.arange(6)
        self._gcols12 = np.concatenate([np.where(self._gfa[:, None] >= 0, 6 * self._gfa[:, None] + six, 0),
                                        np.where(self._gfb[:, None] >= 0, 6 * self._gfb[:, None] + six, 0)], 1)
        self._rows = None  # the sparse pattern, made when asked for (scipy solver, tests)
        self._ghidx = (self._gcols12[:, :, None] * self.n_params + self._gcols12[:, None, :]).reshape(-1)

    def _sparsity(self):
        """Row/column indices of the non-zero Jacobian entries: a residual depends on the 6 parameters
        of frame a (if not KF1) and of frame b."""
        if self._rows is None:
            cols = np.concatenate([6 * self.fa[:, None] + np.arange(6), 6 * self.fb[:, None] + np.arange(6)], 1)
            valid = np.concatenate([np.repeat(self.fa[:, None] >= 0, 6, 1), np.repeat(self.fb[:, None] >= 0, 6, 1)], 1)
            self._valid = valid
            self._rows = np.repeat(np.arange(self.m)[:, None], 12, 1)[valid]
            self._cols = cols[valid]

    def jac_sparsity(self):
        import scipy.sparse as sp  # only the scipy solver path and tests need it (import cost: see _scipy_solve)

        self._sparsity()
        return sp.csr_matrix((np.ones(self._rows.size), (self._rows, self._cols)), shape=(self.m, self.n_params))

    def _poses(self, x):
        P = x.reshape(self.n_frames, 6)
        R, dR = _euler_derivs(P[:, :3])
        # append the fixed KF1 (index -1 -> last row after the append)
        R = np.concatenate([R, np.eye(3)[None]])
        dR = np.concatenate([dR, np.zeros((1, 3, 3, 3))])
        t = np.concatenate([P[:, 3:], np.zeros((1, 3))])
        return R, dR, t

    def _group_matrices(self, x, derivs):
        """Per image pair g: ``G_g = R_a^T [D]x R_b M_b`` (Ng, 3, 3) with ``l = G_g^T u`` for the
        bearings ``y_a = M_a x_a^h``, i.e. ``l^T = y_a^T G_g``; with ``derivs`` also its derivatives by
        the 12 parameters [a angles, a t, b angles, b t]: (Ng, 13, 3, 3), index 0 is ``G_g`` itself.

        Every residual of a pair shares its two poses, so the pose algebra is done once per pair and
        the per-residual work is one (m_g, 3) x (3, 39) product (why: the per-residual (m, 3, 3, 3)
        broadcasts this replaced took 80 % of the BA's time)."""
        R, dR, t = self._poses(x)
        fa, fb = self._gfa, self._gfb
        Ra, Rb = R[fa], R[fb]
        RaT = np.swapaxes(Ra, 1, 2)
        D = t[fb] + np.einsum("gij,gj->gi", Rb, self._gcb) - t[fa] - np.einsum("gij,gj->gi", Ra, self._gca)
        RbM = Rb @ self._gMb
        SD = skew(D)
        G = RaT @ SD @ RbM
        if not derivs:
            return G
        out = np.empty((len(fa), 13, 3, 3))
        out[:, 0] = G
        dRa, dRb = dR[fa], dR[fb]  # (Ng, 3 angles, 3, 3); zero for the fixed KF1
        RaT_ = RaT[:, None]
        RbM_ = RbM[:, None]
        # a side: d(R_a^T)/dk [D]x R_b M_b + R_a^T [dD]x R_b M_b with dD = -dR_a,k c_a
        dDa = -np.einsum("gkij,gj->gki", dRa, self._gca)
        out[:, 1:4] = np.swapaxes(dRa, 2, 3) @ (SD @ RbM)[:, None] + RaT_ @ skew(dDa) @ RbM_
        out[:, 4:7] = -(RaT_ @ _SKEW_E @ RbM_)  # dD/dt_a = -e_j
        # b side: R_a^T [dD]x R_b M_b with dD = dR_b,k c_b, plus R_a^T [D]x dR_b,k M_b
        dDb = np.einsum("gkij,gj->gki", dRb, self._gcb)
        out[:, 7:10] = RaT_ @ skew(dDb) @ RbM_ + (RaT @ SD)[:, None] @ dRb @ self._gMb[:, None]
        out[:, 10:13] = -out[:, 4:7]  # dD/dt_b = e_j
        out[self._gfa < 0, 1:7] = 0.0  # KF1 is fixed (its rotation derivatives are zero already)
        out[self._gfb < 0, 7:13] = 0.0
        return out

    def _evaluate(self, x, jac):
        """Residuals d (m,) and, with ``jac``, the raw Jacobian blocks (m, 12) [a angles, a t, b
        angles, b t] (zero for the fixed KF1)."""
        Gm = self._group_matrices(x, jac)
        ng = Gm.shape[0]
        Gm = Gm.transpose(0, 2, 1, 3).reshape(ng, 3, 39) if jac else Gm
        L = np.empty((self.m, Gm.shape[2]))
        for g, (s, e) in enumerate(self._gslices):
            np.matmul(self.ya[s:e], Gm[g], out=L[s:e])
        lin = L[:, :3]
        n = np.sqrt(lin[:, 0] ** 2 + lin[:, 1] ** 2)
        e = np.einsum("mi,mi->m", lin, self.xb)
        d = e / n
        if not jac:
            return d, None
        # dd/dp = dl/dp . dd/dl with dd/dl = x_b/n - (l.x_b)(l1, l2, 0)/n^3, l = lin (spec 6.3)
        g = self.xb / n[:, None]
        g[:, :2] -= (e / n**3)[:, None] * lin[:, :2]
        return d, np.einsum("mkj,mj->mk", L[:, 3:].reshape(self.m, 12, 3), g)

    def residuals(self, x):
        return self._evaluate(x, False)[0]

    def residuals_and_jacobian(self, x, sparse=False):
        d, vals = self._evaluate(x, True)
        if sparse == "raw":
            return d, vals
        self._sparsity()
        if sparse:
            import scipy.sparse as sp

            J = sp.csr_matrix((vals[self._valid], (self._rows, self._cols)), shape=(self.m, self.n_params))
        else:
            J = np.zeros((self.m, self.n_params))
            J[self._rows, self._cols] = vals[self._valid]
        return d, J

    def normal_equations(self, d, vals, w):
        """``H = J^T W J`` and ``g = J^T W d`` from the raw (m, 12) Jacobian blocks (KF1 entries zero):
        one 12 x 12 product per image pair, scattered into the 6(K+1) square by bincount."""
        n = self.n_params
        wv = vals * w[:, None]
        wd = w * d
        ng = len(self._gslices)
        Hg, gg = np.empty((ng, 12, 12)), np.empty((ng, 12))
        for g, (s, e) in enumerate(self._gslices):
            Vt = vals[s:e].T
            np.matmul(Vt, wv[s:e], out=Hg[g])
            np.matmul(Vt, wd[s:e], out=gg[g])
        H = np.bincount(self._ghidx, weights=Hg.reshape(-1), minlength=n * n)
        g = np.bincount(self._gcols12.reshape(-1), weights=gg.reshape(-1), minlength=n)
        return H.reshape(n, n), g

    def jacobian(self, x, sparse=False):
        return self.residuals_and_jacobian(x, sparse)[1]

    def poses(self, x):
        P = np.asarray(x, dtype=float).reshape(self.n_frames, 6)
        return euler_zyx(P[:, :3]), P[:, 3:].copy()


def build_ba_problem(window: BAWindow, use_right: bool = True) -> BAProblem:
    return BAProblem(window, use_right)


def _truncated_loss(z):
    """Truncated quadratic rho(z) = min(z, 1) in least_squares' scaled form (z = (d/delta)^2)."""
    rho = np.empty((3, z.size))
    inside = z < 1.0
    rho[0] = np.where(inside, z, 1.0)
    rho[1] = inside.astype(float)
    rho[2] = 0.0
    return rho


def _robust_cost(d, kernel, delta):
    """0.5 delta^2 sum rho((d/delta)^2) (least_squares convention)."""
    z = (d / delta) ** 2
    if kernel == "huber":
        rho = np.where(z <= 1, z, 2 * np.sqrt(z) - 1)
    elif kernel == "truncated":
        rho = np.minimum(z, 1.0)
    else:
        rho = z
    return 0.5 * delta**2 * float(np.sum(rho))


def _irls_weights(d, kernel, delta):
    """rho'((d/delta)^2): Huber min(1, delta/|d|), truncated 1{|d| < delta}, none 1."""
    a = np.abs(d)
    if kernel == "huber":
        return np.where(a <= delta, 1.0, delta / np.maximum(a, 1e-300))
    if kernel == "truncated":
        return (a < delta).astype(float)
    return np.ones_like(d)


def _lm_irls(prob, x0, kernel, delta, max_iter, tol):
    """Levenberg–Marquardt on the robust cost with IRLS weights (Marquardt diagonal damping).

    A step is accepted only if the robust cost decreases (else the damping grows x10, up to 8
    tries). Normal equations are (n_params x n_params) = 6(K+1) square, so one iteration costs one
    Jacobian evaluation plus a small solve. Returns (x, n_iterations, status) with status 1 =
    converged (relative step or cost decrease < tol, or zero cost), 0 = iteration limit, 2 = no
    decreasing step found.
    """
    x = x0.copy()
    d, V = prob.residuals_and_jacobian(x, "raw")
    cost = _robust_cost(d, kernel, delta)
    lam = 1e-6
    status = 0
    it = 0
    for it in range(1, max_iter + 1):
        if cost == 0.0:
            status = 1
            break
        H, g = prob.normal_equations(d, V, _irls_weights(d, kernel, delta))
        diag = np.maximum(np.diag(H), 1e-12 * max(np.max(np.diag(H)), 1e-300))
        accepted = False
        for _ in range(8):
            try:
                dx = -np.linalg.solve(H + lam * np.diag(diag), g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            x_new = x + dx
            d_new = prob.residuals(x_new)
            cost_new = _robust_cost(d_new, kernel, delta) if np.all(np.isfinite(d_new)) else np.inf
            if cost_new < cost:
                accepted = True
                break
            lam *= 10.0
        if not accepted:
            status = 2
            break
        small = np.linalg.norm(dx) <= tol * (1.0 + np.linalg.norm(x)) or cost - cost_new <= tol * cost
        x, cost = x_new, cost_new
        lam = max(lam / 10.0, 1e-12)
        if small:
            status = 1
            break
        d, V = prob.residuals_and_jacobian(x, "raw")
    return x, it, status


def _scipy_solve(prob, x0, opt, loss, delta):
    """scipy.optimize.least_squares with the analytic (dense or CSR) Jacobian.

    Imported here, not at module level: the default solver does not need it, and importing
    scipy.optimize costs ~0.09 s of every `gevi run` process (bench_pipeline.py's process budget)."""
    from scipy.optimize import least_squares
    cache = {}

    def fun(x):
        d, J = prob.residuals_and_jacobian(x, opt.sparse)
        cache["x"], cache["J"] = x.copy(), J
        return d

    def jac(x):
        if "x" in cache and np.array_equal(cache["x"], x):
            return cache["J"]
        return prob.jacobian(x, opt.sparse)

    kw = dict(jac=jac, method=opt.method, max_nfev=int(opt.max_iter), ftol=opt.tol, xtol=opt.tol, gtol=opt.tol,
              x_scale="jac")
    if opt.method != "lm":
        kw.update(loss=loss, f_scale=delta, tr_solver="lsmr" if opt.sparse else "exact")
        if opt.sparse:
            kw["tr_options"] = {"atol": 1e-14, "btol": 1e-14}
    elif opt.kernel != "none":
        raise ValueError("method='lm' supports kernel='none' only")
    sol = least_squares(fun, x0, **kw)
    return sol.x, sol.nfev, sol.status


def epipolar_local_ba(window: BAWindow, options: BAOptions | None = None) -> BAResult:
    """Refine the poses of F_1..F_K and KF2 relative to the fixed KF1 (spec 10).

    Returns a :class:`BAResult` with the refined ``T_K1Fk`` and their inverses (tracked form).
    Raises ``ShapeError``/``NonFiniteInput`` on bad input, ``TooFewPoints`` if there are fewer
    residuals than parameters, ``DegenerateInput`` if the solver returns non-finite poses.
    """
    opt = options or BAOptions()
    prob = BAProblem(window, opt.use_right)
    if prob.m < prob.n_params:
        raise TooFewPoints(prob.m, prob.n_params, "epipolar residuals")
    x0 = prob.x0
    d0 = prob.residuals(x0)
    if not np.all(np.isfinite(d0)):
        raise DegenerateInput("non-finite residuals at the initial poses (zero baseline between two images?)")
    if window.sigma is not None:
        sigma_hat = float(window.sigma)
    else:
        sigma_hat = 1.4826 * float(np.median(np.abs(d0)))
    sigma_hat = max(sigma_hat, 1e-9)
    delta = float(opt.delta) if opt.delta is not None else 3.0 * sigma_hat
    if opt.kernel == "huber":
        loss = "huber"
    elif opt.kernel == "truncated":
        loss = _truncated_loss
    elif opt.kernel == "none":
        loss = "linear"
    else:
        raise ValueError(f"unknown kernel {opt.kernel!r}")
    if opt.solver == "lm":
        x_opt, nfev, status = _lm_irls(prob, x0, opt.kernel, delta, int(opt.max_iter), float(opt.tol))
    elif opt.solver == "scipy":
        x_opt, nfev, status = _scipy_solve(prob, x0, opt, loss, delta)
    else:
        raise ValueError(f"unknown solver {opt.solver!r}")
    if not np.all(np.isfinite(x_opt)):
        raise DegenerateInput("BA returned non-finite parameters")
    R, t = prob.poses(x_opt)
    d1 = prob.residuals(x_opt)

    def cost(d):
        return _robust_cost(d, opt.kernel, delta)

    R_ck, t_ck = poses_from_tracking(R, t)  # the inverse map has the same form
    return BAResult(
        R=R, t=t, R_ck=R_ck, t_ck=t_ck, cost_initial=cost(d0), cost_final=cost(d1),
        rms_initial=float(np.sqrt(np.mean(d0**2))), rms_final=float(np.sqrt(np.mean(d1**2))),
        n_residuals=prob.m, nfev=int(nfev), status=int(status), delta=delta, sigma_hat=sigma_hat,
        pairs=prob.pairs,
    )
