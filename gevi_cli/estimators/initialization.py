"""Stereo–IMU initialisation with known scale (spec section 9, a [PROPOSAL] reconstruction).

Steps (spec numbering):

1. camera poses in V (first camera frame) -> IMU poses ``R_j = R_VC_j R_IC^T``,
   ``p_j = p_VC_j - R_j p_IC`` (``p_IC`` = camera origin in IMU coordinates);
2. preintegration between consecutive keyframes (:mod:`.preintegration`);
3. gyro bias by Gauss–Newton on ``sum_j ||Log(dR_j^T R_j^T R_{j+1}) - J_R_g,j db_g||^2`` with
   re-preintegration (:func:`init_gyro_bias`);
4. velocities ``v_0..v_N``, gravity ``g_V`` and accelerometer bias by linear LS with the scale fixed
   to 1 (:func:`init_gravity_velocity_accbias`). The increments are re-preintegrated with the step-3
   gyro bias and the accelerometer linearisation point ``b_a_lin`` (default **0**, as the spec
   says); the LS unknown is ``db_a = b_a - b_a_lin`` and the returned bias is ``b_a_lin + db_a``;
5. gravity refinement on the sphere ``g_V = g n``, ``n <- normalize(n + B delta)``
   (:func:`refine_gravity`), then ``R_WV`` = minimal rotation with ``R_WV g_V = -g e3``
   (:func:`gravity_to_R_WV`; yaw arbitrary, here: zero rotation about the gravity axis);
6. a zero-mean prior on ``b_a`` (sigma default 0.05 m/s^2, [PROPOSAL]) in steps 4 and 5.

Weighting (our choice; the spec does not weight the LS): per interval the (dp, dv) rows are
whitened with the covariance of ZOH-integrated white accelerometer noise,
``sigma_a^2 [[T^3/3, T^2/2], [T^2/2, T]] (x) I_3``, plus ``2 sigma_pos^2`` on the position rows if a
camera-position noise is given. The prior row is ``db_a / sigma_ba``. Correlations between
neighbouring intervals (shared pose noise) and pose-rotation noise are ignored.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.geometry import exp_so3, log_so3

from .errors import DegenerateInput, NonFiniteInput, ShapeError, TooFewPoints
from .preintegration import Preintegrated, imu_segment, preintegrate_batch

__all__ = [
    "InitOptions",
    "InitResult",
    "camera_to_imu_poses",
    "init_gyro_bias",
    "init_gravity_velocity_accbias",
    "refine_gravity",
    "gravity_to_R_WV",
    "stereo_imu_init",
]

GRAVITY = 9.81


@dataclass
class InitOptions:
    """Options of :func:`stereo_imu_init` (units: SI, rad)."""

    gravity: float = GRAVITY
    gyro_iters: int = 3  # spec 9.3: 2-3 GN iterations with re-preintegration
    b_g0: np.ndarray | None = None  # initial gyro bias (default 0)
    b_a_lin: np.ndarray | None = None  # accelerometer linearisation point (spec 9.4: 0)
    ba_prior_sigma: float | None = 0.05  # spec 9.6 [PROPOSAL]; None disables the prior
    acc_noise_density: float = 2.0e-3  # (m/s^2)/sqrt(Hz), only used for weighting
    pose_pos_sigma: float = 0.0  # m, camera-position noise, only used for weighting
    refine_iters: int = 10  # spec 9.5 sphere GN (stops at |delta| < 1e-12)
    min_keyframes: int = 4  # hard minimum (3 intervals); spec 9.1 recommends >= 10 over 2-3 s
    rcond: float = 1e-10  # LS singular-value ratio below which DegenerateInput is raised


@dataclass
class InitResult:
    """Result of :func:`stereo_imu_init`. Vectors in V (first camera frame) unless stated."""

    gravity_V: np.ndarray  # (3,), |g| = options.gravity
    R_WV: np.ndarray  # (3, 3), R_WV g_V = -g e3
    b_g: np.ndarray  # (3,) rad/s
    b_a: np.ndarray  # (3,) m/s^2 (full bias, not relative to the linearisation point)
    velocities: np.ndarray  # (N+1, 3) IMU velocities in V at the keyframes
    R_VI: np.ndarray  # (N+1, 3, 3) IMU orientations used (spec 9.1)
    p_VI: np.ndarray  # (N+1, 3) IMU positions used
    gravity_norm_linear: float  # |g_V| of the unconstrained linear step (sanity check)
    rms_rot: float  # rad, gyro-bias residual RMS after step 3
    rms_p: float  # m, position-row residual RMS (final)
    rms_v: float  # m/s, velocity-row residual RMS (final)
    rms_whitened: float  # RMS of the whitened rows (~1 if the weights are right)
    cond: float  # singular-value ratio max/min of the scaled LS matrix (final step)
    preints: list = field(default_factory=list, repr=False)  # final Preintegrated per interval


# --------------------------------------------------------------------------------------------------
# helpers


def _lstsq_checked(A, b, what, rcond):
    """Column-scaled SVD least squares; DegenerateInput if s_min < rcond s_max."""
    d = np.linalg.norm(A, axis=0)
    if np.any(d == 0):
        raise DegenerateInput(f"{what}: unknown not constrained (zero column)")
    As = A / d
    U, s, Vt = np.linalg.svd(As, full_matrices=False)
    if s[-1] <= rcond * s[0]:
        raise DegenerateInput(f"{what}: ill-conditioned system (cond {s[0] / max(s[-1], 1e-300):.3g})")
    x = (Vt.T @ ((U.T @ b) / s)) / d
    if not np.all(np.isfinite(x)):
        raise DegenerateInput(f"{what}: non-finite solution")
    return x, float(s[0] / s[-1])


def _tangent_basis(n):
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    b1 = np.cross(n, a)
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(n, b1)
    return np.column_stack([b1, b2])


def camera_to_imu_poses(R_VC, p_VC, R_IC, p_IC):
    """Spec 9.1: ``R_j = R_VC_j R_IC^T``, ``p_j = p_VC_j - R_j p_IC`` (vectorised over j)."""
    R_VC = np.asarray(R_VC, dtype=float)
    p_VC = np.asarray(p_VC, dtype=float)
    R = R_VC @ np.asarray(R_IC, dtype=float).T
    p = p_VC - R @ np.asarray(p_IC, dtype=float)
    return R, p


def gravity_to_R_WV(g_V, gravity: float = GRAVITY) -> np.ndarray:
    """Minimal rotation with ``R_WV g_V/|g_V| = -e3`` (spec 9.5; yaw about e3 left at zero-twist)."""
    u = np.asarray(g_V, dtype=float)
    u = u / np.linalg.norm(u)
    target = np.array([0.0, 0.0, -1.0])
    ax = np.cross(u, target)
    s = np.linalg.norm(ax)
    c = float(u @ target)
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        return np.diag([1.0, -1.0, -1.0])  # rotation by pi about x
    return exp_so3(ax / s * np.arctan2(s, c))


# --------------------------------------------------------------------------------------------------
# step 3


def init_gyro_bias(R_list, preints: list[Preintegrated], b_g0=None, iters: int = 3, tol: float = 1e-14):
    """Spec 9.3: Gauss–Newton for the gyro bias with re-preintegration.

    ``R_list`` (N+1, 3, 3) IMU orientations (any common frame), ``preints`` N intervals (their raw
    samples are re-integrated at each new bias; the accelerometer linearisation point is kept).
    Returns ``(b_g, preints_at_b_g, rms_rot)`` where ``rms_rot`` [rad] is the RMS rotation residual
    ``|Log(dR_j(b_g)^T R_j^T R_{j+1})|`` after the last re-integration.
    """
    R = np.asarray(R_list, dtype=float)
    N = len(preints)
    if R.shape != (N + 1, 3, 3):
        raise ShapeError(f"R_list must have shape ({N + 1}, 3, 3), got {R.shape}")
    if N < 1:
        raise TooFewPoints(N, 1, "IMU intervals")
    b_g = np.zeros(3) if b_g0 is None else np.asarray(b_g0, dtype=float).copy()
    Rrel = np.swapaxes(R[:-1], -1, -2) @ R[1:]
    segs = [(p.gyro, p.acc, p.dts) for p in preints]
    ba_lin = np.stack([p.b_a for p in preints])
    pre = preintegrate_batch(segs, b_g, ba_lin)
    for _ in range(max(int(iters), 0)):
        dR = np.stack([p.dR for p in pre])
        J = np.stack([p.J_R_g for p in pre])
        r = log_so3(np.swapaxes(dR, -1, -2) @ Rrel)  # (N, 3)
        H = np.einsum("nki,nkj->ij", J, J)
        g = np.einsum("nki,nk->i", J, r)
        delta, _ = _lstsq_checked(H, g, "gyro bias", 1e-12)
        b_g = b_g + delta
        pre = preintegrate_batch(segs, b_g, ba_lin)
        if np.linalg.norm(delta) < tol:
            break
    dR = np.stack([p.dR for p in pre])
    r = log_so3(np.swapaxes(dR, -1, -2) @ Rrel)
    return b_g, pre, float(np.sqrt(np.mean(np.sum(r * r, axis=1))))


# --------------------------------------------------------------------------------------------------
# steps 4-6


def _linear_system(R, p, preints, options: InitOptions):
    """Whitened rows of spec 9.4. Columns: v_0..v_N (3(N+1)), g_V (3), db_a (3)."""
    N = len(preints)
    T = np.array([q.dt for q in preints])
    Rt = np.swapaxes(R[:-1], -1, -2)  # R_j^T
    dP = np.stack([q.dp for q in preints])
    dV = np.stack([q.dv for q in preints])
    Jpa = np.stack([q.J_p_a for q in preints])
    Jva = np.stack([q.J_v_a for q in preints])
    nb = N + 3  # column blocks
    A = np.zeros((N, 2, 3, nb, 3))
    j = np.arange(N)
    A[j, 0, :, j, :] = -T[:, None, None] * Rt
    A[j, 0, :, N + 1, :] = -0.5 * (T**2)[:, None, None] * Rt
    A[j, 0, :, N + 2, :] = -Jpa
    A[j, 1, :, j, :] = -Rt
    A[j, 1, :, j + 1, :] = Rt
    A[j, 1, :, N + 1, :] = -T[:, None, None] * Rt
    A[j, 1, :, N + 2, :] = -Jva
    b = np.zeros((N, 2, 3))
    b[:, 0] = dP - np.einsum("nij,nj->ni", Rt, p[1:] - p[:-1])
    b[:, 1] = dV
    # whitening (module docstring): cov = C (x) I3 with C 2x2 per interval
    sa2 = float(options.acc_noise_density) ** 2
    C = np.empty((N, 2, 2))
    C[:, 0, 0] = sa2 * T**3 / 3.0 + 2.0 * float(options.pose_pos_sigma) ** 2
    C[:, 0, 1] = C[:, 1, 0] = sa2 * T**2 / 2.0
    C[:, 1, 1] = sa2 * T
    try:
        Wt = np.linalg.inv(np.linalg.cholesky(C))  # (N, 2, 2)
    except np.linalg.LinAlgError as exc:
        raise DegenerateInput("acc_noise_density must be > 0") from exc
    Aw = np.einsum("nab,nbkcl->nakcl", Wt, A).reshape(6 * N, 3 * nb)
    bw = np.einsum("nab,nbk->nak", Wt, b).reshape(6 * N)
    A_raw = A.reshape(6 * N, 3 * nb)
    b_raw = b.reshape(6 * N)
    return Aw, bw, A_raw, b_raw


def _prior_rows(n_cols, b_a_lin, sigma):
    P = np.zeros((3, n_cols))
    P[:, -3:] = np.eye(3) / sigma
    return P, -np.asarray(b_a_lin) / sigma


def _stats(A_raw, b_raw, x, Aw, bw):
    r = (A_raw @ x - b_raw).reshape(-1, 2, 3)
    rw = Aw @ x - bw
    return (float(np.sqrt(np.mean(np.sum(r[:, 0] ** 2, -1)))), float(np.sqrt(np.mean(np.sum(r[:, 1] ** 2, -1)))),
            float(np.sqrt(np.mean(rw**2))))


def init_gravity_velocity_accbias(R_list, p_list, preints: list[Preintegrated], options: InitOptions | None = None):
    """Spec 9.4 (+ the 9.6 prior): linear LS for ``v_0..v_N``, ``g_V`` (free norm) and ``b_a``.

    ``preints`` must be integrated at the final gyro bias with accelerometer linearisation point
    ``b_a_lin`` (all intervals the same; normally 0). Returns ``(v (N+1, 3), g_V, b_a, cond)``
    with ``b_a = b_a_lin + db_a``.
    """
    opt = options or InitOptions()
    R = np.asarray(R_list, dtype=float)
    p = np.asarray(p_list, dtype=float)
    N = len(preints)
    b_a_lin = preints[0].b_a
    if any(np.any(q.b_a != b_a_lin) for q in preints):
        raise ShapeError("all intervals must share the accelerometer linearisation point")
    Aw, bw, _, _ = _linear_system(R, p, preints, opt)
    if opt.ba_prior_sigma is not None:
        P, pb = _prior_rows(Aw.shape[1], b_a_lin, float(opt.ba_prior_sigma))
        Aw, bw = np.vstack([Aw, P]), np.concatenate([bw, pb])
    x, cond = _lstsq_checked(Aw, bw, "gravity/velocity/acc-bias LS", opt.rcond)
    v = x[: 3 * (N + 1)].reshape(N + 1, 3)
    return v, x[3 * (N + 1): 3 * (N + 2)], b_a_lin + x[-3:], cond


def refine_gravity(R_list, p_list, preints: list[Preintegrated], g_V0, options: InitOptions | None = None):
    """Spec 9.5: GN on (v, b_a, delta in R^2) with ``g_V = g n``, ``n <- normalize(n + B delta)``.

    The model is linear in (v, b_a) and in g_V, so each GN iteration is one LS solve with the g
    columns replaced by ``A_g g B``; after convergence (|delta| < 1e-12) a final solve with n fixed
    gives (v, b_a). Returns ``(v, g_V, b_a, cond, stats)``; ``stats = (rms_p, rms_v, rms_whitened)``.
    """
    opt = options or InitOptions()
    R = np.asarray(R_list, dtype=float)
    p = np.asarray(p_list, dtype=float)
    N = len(preints)
    b_a_lin = preints[0].b_a
    Aw, bw, A_raw, b_raw = _linear_system(R, p, preints, opt)
    nv = 3 * (N + 1)
    cg = slice(nv, nv + 3)
    if opt.ba_prior_sigma is not None:
        P, pb = _prior_rows(Aw.shape[1], b_a_lin, float(opt.ba_prior_sigma))
    g = float(opt.gravity)
    n = np.asarray(g_V0, dtype=float)
    n = n / np.linalg.norm(n)
    keep = np.r_[0:nv, nv + 3: nv + 6]  # columns of (v, db_a)

    def solve(n, with_delta):
        Ag = Aw[:, cg]
        rhs = bw - g * Ag @ n
        M = Aw[:, keep]
        if with_delta:
            M = np.hstack([M, g * Ag @ _tangent_basis(n)])
        if opt.ba_prior_sigma is not None:
            Pm = P[:, keep]
            if with_delta:
                Pm = np.hstack([Pm, np.zeros((3, 2))])
            M, rhs = np.vstack([M, Pm]), np.concatenate([rhs, pb])
        return _lstsq_checked(M, rhs, "gravity refinement", opt.rcond)

    for _ in range(max(int(opt.refine_iters), 0)):
        y, _ = solve(n, True)
        delta = y[-2:]
        n = n + _tangent_basis(n) @ delta
        n /= np.linalg.norm(n)
        if np.linalg.norm(delta) < 1e-12:
            break
    y, cond = solve(n, False)
    v = y[:nv].reshape(N + 1, 3)
    dba = y[nv:]
    x = np.concatenate([y[:nv], g * n, dba])
    return v, g * n, b_a_lin + dba, cond, _stats(A_raw, b_raw, x, Aw, bw)


# --------------------------------------------------------------------------------------------------
# top level


def stereo_imu_init(t_kf_ns, R_VC, p_VC, imu_t_ns, gyro, acc, R_IC, p_IC, options: InitOptions | None = None) -> InitResult:
    """Stereo–IMU initialisation with known scale (spec 9).

    ``t_kf_ns`` (N+1,) int keyframe stamps [ns], strictly increasing; ``R_VC`` (N+1, 3, 3) and
    ``p_VC`` (N+1, 3) metric camera(-left) poses in V (``X_V = R_VC X_C + p_VC``); ``imu_t_ns`` (m,)
    int stamps, ``gyro`` [rad/s] and ``acc`` [m/s^2] (m, 3) raw samples (zero-order hold, see
    :func:`.imu_segment`); ``R_IC`` maps camera vectors to IMU, ``p_IC`` = camera origin in IMU
    coordinates [m].

    Raises ``TooFewPoints`` (fewer than ``options.min_keyframes``), ``DegenerateInput`` (an interval
    without IMU samples or not covered, non-increasing stamps, ill-conditioned LS e.g. no rotation
    and no b_a prior), ``NonFiniteInput``, ``ShapeError``.
    """
    opt = options or InitOptions()
    t_kf = np.asarray(t_kf_ns)
    R_VC = np.asarray(R_VC, dtype=float)
    p_VC = np.asarray(p_VC, dtype=float)
    n_kf = t_kf.shape[0] if t_kf.ndim == 1 else -1
    if n_kf < 0 or R_VC.shape != (n_kf, 3, 3) or p_VC.shape != (n_kf, 3):
        raise ShapeError(f"stamps (N+1,), R_VC (N+1,3,3), p_VC (N+1,3) expected; got {t_kf.shape}, {R_VC.shape}, {p_VC.shape}")
    if n_kf < max(int(opt.min_keyframes), 4):
        raise TooFewPoints(n_kf, max(int(opt.min_keyframes), 4), "keyframes")
    for name, arr in (("R_VC", R_VC), ("p_VC", p_VC), ("gyro", gyro), ("acc", acc), ("R_IC", R_IC), ("p_IC", p_IC)):
        if not np.all(np.isfinite(np.asarray(arr, dtype=float))):
            raise NonFiniteInput(f"{name} contains non-finite values")
    if np.any(np.diff(t_kf.astype(np.int64)) <= 0):
        raise DegenerateInput("keyframe stamps must be strictly increasing")
    imu_t = np.asarray(imu_t_ns, dtype=np.int64)
    if imu_t.ndim != 1 or np.any(np.diff(imu_t) <= 0):
        raise DegenerateInput("IMU stamps must be 1-D and strictly increasing")

    R, p = camera_to_imu_poses(R_VC, p_VC, R_IC, p_IC)
    segs = [imu_segment(imu_t, gyro, acc, int(t_kf[j]), int(t_kf[j + 1])) for j in range(n_kf - 1)]
    b_a_lin = np.zeros(3) if opt.b_a_lin is None else np.asarray(opt.b_a_lin, dtype=float)
    pre0 = preintegrate_batch(segs, opt.b_g0, b_a_lin)
    b_g, pre, rms_rot = init_gyro_bias(R, pre0, opt.b_g0, opt.gyro_iters)
    # `pre` is integrated at (b_g, b_a_lin): exactly what spec 9.4 asks for
    _, g_lin, _, _ = init_gravity_velocity_accbias(R, p, pre, opt)
    v, g_V, b_a, cond, (rms_p, rms_v, rms_w) = refine_gravity(R, p, pre, g_lin, opt)
    return InitResult(
        gravity_V=g_V, R_WV=gravity_to_R_WV(g_V), b_g=b_g, b_a=b_a, velocities=v, R_VI=R, p_VI=p,
        gravity_norm_linear=float(np.linalg.norm(g_lin)), rms_rot=rms_rot, rms_p=rms_p, rms_v=rms_v,
        rms_whitened=rms_w, cond=cond, preints=pre,
    )
