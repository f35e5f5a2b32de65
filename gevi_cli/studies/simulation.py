"""Synthetic stereo scenes for the GeVI / Bias-Eli simulations (spec 5.6 and 11.3).

Rig: rectified stereo, R_RL = I, t_RL = (-b, 0, 0) with b = 0.2 m; f = 1100 px on an 800 x 800
image with the principal point at the centre; depths uniform in [1, 10] m; image noise
sigma_px = 2.5 px added to the keyframe images z, y only (the paper's model) unless
``noise_q`` is set. All returned 2D quantities are normalized coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.estimators.initialization import GRAVITY
from gevi_cli.geometry import exp_so3, project, rot_x, rot_y, rot_z, rtilt

F_PX = 1100.0
IMAGE = 800
BASELINE = 0.2
SIGMA_PX = 2.5
R_RL = np.eye(3)
T_RL = np.array([-BASELINE, 0.0, 0.0])
# forward-looking camera: camera z -> IMU x, camera x -> IMU -y, camera y -> IMU -z (IMU z up)
R_IC_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass
class Scene:
    """One simulated keyframe/current pair. Ground truth has suffix ``_o``."""

    R: np.ndarray  # R_CK
    t: np.ndarray  # t_CK (m)
    P: np.ndarray  # true points, keyframe-left (n, 3)
    z_o: np.ndarray
    y_o: np.ndarray
    q_o: np.ndarray
    z: np.ndarray
    y: np.ndarray
    q: np.ndarray
    sigma: float  # normalized noise std
    psi: float = np.nan  # 4-DOF scenes only
    L_k: np.ndarray = field(default_factory=lambda: np.eye(3))
    L_c: np.ndarray = field(default_factory=lambda: np.eye(3))
    R_rl: np.ndarray = field(default_factory=lambda: R_RL.copy())
    t_rl: np.ndarray = field(default_factory=lambda: T_RL.copy())


def _inside(x, f=F_PX, size=IMAGE):
    half = size / 2.0 / f
    return np.all(np.abs(x) <= half, axis=1)


def sample_points(rng, R, t, n, depth=(1.0, 10.0), min_depth_c=0.0, max_tries=50):
    """n points visible in KF-left, KF-right and the current image (depth > min_depth_c there)."""
    half = IMAGE / 2.0 / F_PX
    out = []
    got = 0
    for _ in range(max_tries):
        m = max(2 * (n - got), 64)
        xy = rng.uniform(-half, half, size=(m, 2))
        Z = rng.uniform(depth[0], depth[1], size=m)
        P = np.column_stack([xy * Z[:, None], Z])
        PR = P @ R_RL.T + T_RL
        PC = P @ R.T + t
        ok = (PR[:, 2] > 0) & (PC[:, 2] > max(min_depth_c, 1e-6))
        ok &= _inside(project(np.where(ok[:, None], PR, 1.0))) & _inside(project(np.where(ok[:, None], PC, 1.0)))
        out.append(P[ok])
        got += int(ok.sum())
        if got >= n:
            break
    P = np.concatenate(out)[:n]
    if len(P) < n:
        raise RuntimeError("could not sample enough visible points for this pose")
    return P


def make_scene(rng, R, t, n, sigma_px=SIGMA_PX, noise_q=False, min_depth_c=0.0, **extra) -> Scene:
    P = sample_points(rng, R, t, n, min_depth_c=min_depth_c)
    sigma = sigma_px / F_PX
    z_o = project(P)
    y_o = project(P @ R_RL.T + T_RL)
    q_o = project(P @ R.T + t)
    z = z_o + sigma * rng.standard_normal(z_o.shape)
    y = y_o + sigma * rng.standard_normal(y_o.shape)
    q = q_o + (sigma * rng.standard_normal(q_o.shape) if noise_q else 0.0)
    return Scene(R=R, t=t, P=P, z_o=z_o, y_o=y_o, q_o=q_o, z=z, y=y, q=q, sigma=sigma, **extra)


def pose4_gevi(rng, R_ic=None, yaw_deg=20.0, tilt_deg=5.0, t_range=0.5):
    """Spec 11.3 [PROPOSAL] pose: yaw U(+-20 deg), keyframe roll/pitch U(+-5 deg), L_C = I (S1 form),
    t_CK ~ U[-0.5, 0.5]^3 m. With ``R_ic`` given (e.g. R_IC_FORWARD) both frames get their own
    tilt and L = R_tilt R_ic (general form). Returns psi, L_k, L_c, R_CK, t_CK."""
    d2r = np.pi / 180.0
    psi = rng.uniform(-yaw_deg, yaw_deg) * d2r
    rk, pk = rng.uniform(-tilt_deg, tilt_deg, 2) * d2r
    if R_ic is None:
        L_k = rtilt(rk, pk)
        L_c = np.eye(3)
    else:
        rc, pc = rng.uniform(-tilt_deg, tilt_deg, 2) * d2r
        L_k = rtilt(rk, pk) @ R_ic
        L_c = rtilt(rc, pc) @ R_ic
    R = L_c.T @ rot_z(psi) @ L_k
    t = rng.uniform(-t_range, t_range, 3)
    return psi, L_k, L_c, R, t


def scene4(rng, n, R_ic=None, **kw) -> Scene:
    """A 4-DOF scene with the pose of :func:`pose4_gevi`."""
    psi, L_k, L_c, R, t = pose4_gevi(rng, R_ic=R_ic)
    return make_scene(rng, R, t, n, psi=psi, L_k=L_k, L_c=L_c, **kw)


def pose6(rng):
    """Spec 5.6 [PROPOSAL] pose: R = Exp(w), w ~ N(0, 0.1^2 I) rad; t ~ U[-0.5, 0.5]^3 m."""
    return exp_so3(0.1 * rng.standard_normal(3)), rng.uniform(-0.5, 0.5, 3)


def scene6(rng, n, **kw) -> Scene:
    R, t = pose6(rng)
    return make_scene(rng, R, t, n, min_depth_c=0.5, **kw)


def gaussian3d_points(rng, P, cov):
    """Points perturbed by N(0, cov_i) (the 'Gaussian-3D' noise model of spec 5.6)."""
    Lc = np.linalg.cholesky(cov)
    return P + np.einsum("nij,nj->ni", Lc, rng.standard_normal(P.shape))


def add_outliers(rng, q, ratio):
    """Replace a fraction ``ratio`` of q by uniformly random image points [PROPOSAL spec 11.3].
    Returns (q_out, outlier_mask)."""
    n = len(q)
    k = int(round(ratio * n))
    mask = np.zeros(n, bool)
    mask[rng.choice(n, k, replace=False)] = True
    half = IMAGE / 2.0 / F_PX
    q2 = q.copy()
    q2[mask] = rng.uniform(-half, half, size=(k, 2))
    return q2, mask


# ---------------------------------------------------------------------------------------------
# Adaptive-fusion trajectory (spec 8.3 / 11.3 "Adaptive fusion", S1 Fig. 4d) [PROPOSAL]


@dataclass
class FusionTrajectory:
    """IMU-rate ground truth and measurements. ``R_wi`` (N, 3, 3) ZYX attitude, ``pos`` (N, 3) m,
    ``acc_w`` (N, 3) true kinematic acceleration (world, m/s^2), ``f_meas`` (N, 3) measured specific
    force in the IMU frame (bias already removed: the spec-8.1 bias correction with a perfect
    accelerometer-bias estimate), ``omega_meas`` (N-1, 3) measured body rate between samples k and
    k+1 (rad/s, incl. the drifting bias ``b_g``), ``b_g_est`` (N-1, 3) the gyro-bias estimate used
    for the correction."""

    times: np.ndarray
    R_wi: np.ndarray
    pos: np.ndarray
    acc_w: np.ndarray
    f_meas: np.ndarray
    omega_meas: np.ndarray
    b_g: np.ndarray
    b_g_est: np.ndarray
    roll: np.ndarray
    pitch: np.ndarray
    yaw: np.ndarray
    dt: float
    sigma_a: float
    sigma_g: float  # gyro white-noise density rad/(s sqrt(Hz))


def fusion_trajectory(rng, duration=150.0, rate=100.0, sigma_a=0.02, sigma_g=1.0e-4, bias_rw=2.0e-5,
                      b_g0=(3e-3, -2e-3, 2.5e-3), b_g_err=1e-4, acc_period=2.0, v_cruise=0.5, track_bias=True):
    """[PROPOSAL] trajectory of spec 8.3 / 11.3: roll/pitch sinusoids (5 deg / 4 deg), a slowly
    varying yaw, kinematic acceleration of magnitude |a| = 0.5 + 0.5 sin(2 pi t / 50) <= 1 m/s^2
    whose (horizontal) direction turns with period ``acc_period`` s (surge/sway oscillation; a
    horizontal acceleration is the worst case for the gravity direction), plus a constant cruise
    velocity ``v_cruise`` m/s along world x. Accelerometer: white noise ``sigma_a`` m/s^2 per
    sample. Gyro: white noise of density ``sigma_g`` rad/(s sqrt Hz) (per-sample std
    sigma_g sqrt(rate)) and a random-walk bias (``bias_rw`` rad/s/sqrt(s)) starting at ``b_g0``.
    Gyro-bias estimate used for the correction (spec 8.1.3 "bias-corrected with the current
    gyro-bias estimate"; the estimator of that bias -- initialisation / local BA -- is outside this
    simulation): ``track_bias=True`` models it as the true bias plus a constant error
    e ~ N(0, b_g_err^2) per axis; ``track_bias=False`` keeps the initial estimate b_g0 + e, so the
    random-walk part stays uncorrected.
    """
    dt = 1.0 / rate
    N = int(round(duration * rate)) + 1
    tt = np.arange(N) * dt
    d2r = np.pi / 180.0
    roll = 5.0 * d2r * np.sin(2 * np.pi * tt / 7.0 + 0.3)
    pitch = 4.0 * d2r * np.sin(2 * np.pi * tt / 11.0 + 1.1)
    yaw = 30.0 * d2r * np.sin(2 * np.pi * tt / 60.0) + 0.2 * d2r * tt
    R_wi = rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)
    mag = 0.5 + 0.5 * np.sin(2 * np.pi * tt / 50.0)
    ang = 2 * np.pi * tt / acc_period + 0.7 * np.sin(2 * np.pi * tt / 13.0)
    acc_w = mag[:, None] * np.column_stack([np.cos(ang), np.sin(ang), np.zeros(N)])
    # velocity / position by trapezoidal integration (exact enough: vision truth uses pos itself)
    vel = np.zeros((N, 3))
    vel[1:] = np.cumsum(0.5 * (acc_w[1:] + acc_w[:-1]) * dt, axis=0)
    vel -= vel.mean(axis=0)
    vel[:, 0] += v_cruise
    pos = np.zeros((N, 3))
    pos[1:] = np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt, axis=0)
    f_true = np.einsum("nji,nj->ni", R_wi, acc_w + np.array([0.0, 0.0, GRAVITY]))
    f_meas = f_true + sigma_a * rng.standard_normal(f_true.shape)
    from gevi_cli.geometry import log_so3

    omega = log_so3(np.swapaxes(R_wi[:-1], 1, 2) @ R_wi[1:]) / dt
    b_g = np.asarray(b_g0, float) + np.cumsum(bias_rw * np.sqrt(dt) * rng.standard_normal((N - 1, 3)), axis=0)
    omega_meas = omega + b_g + sigma_g * np.sqrt(rate) * rng.standard_normal((N - 1, 3))
    e = b_g_err * rng.standard_normal(3)
    b_g_est = (b_g if track_bias else np.broadcast_to(np.asarray(b_g0, float), b_g.shape)) + e
    return FusionTrajectory(times=tt, R_wi=R_wi, pos=pos, acc_w=acc_w, f_meas=f_meas, omega_meas=omega_meas,
                            b_g=b_g, b_g_est=b_g_est, roll=roll, pitch=pitch, yaw=yaw, dt=dt, sigma_a=sigma_a,
                            sigma_g=sigma_g)


@dataclass
class FusionRun:
    """Per-window results of :func:`run_fusion` (time = end of the window). Errors in rad / m;
    ``err[mode]`` is (windows, 4): roll, pitch, yaw (absolute, chained) and |t_CK error|."""

    times: np.ndarray
    err: dict
    sqrt_tr_sigma: np.ndarray
    acc_mag: np.ndarray
    max_cost_increase: float
    windows: int

    def rmse_deg(self, mode, col):
        return float(np.degrees(np.sqrt(np.mean(self.err[mode][:, col] ** 2))))

    def max_deg(self, mode, col):
        return float(np.degrees(np.max(np.abs(self.err[mode][:, col]))))


def run_fusion(traj: FusionTrajectory, rng, n=200, window=0.2, R_ic=None, modes=("adaptive", "fixed", "vision"),
               lo=None, hi=0.2**2, prior_std0_deg=0.05):
    """Sliding 0.2 s windows over ``traj`` (keyframe = window start, current = window end).

    Vision per window: spec-11.3 scene (f = 1100, 2.5 px on z, y and q, b = 0.2 m, depths 1-10 m,
    points at least 0.5 m in front of the current camera) for the true relative camera pose;
    forward-looking camera (``R_IC_FORWARD``). Modes: ``adaptive`` (BCD, spec 8.3),
    ``fixed`` (same chi-steps, Sigma_imu = lo I), ``vision`` (6-DOF Bias-Eli-W + one refinement
    step, relative rotations chained). The BCD modes start every window from BE+GN 4-DOF (spec 6)
    with L_K, L_C from the prior tilt and the gyro-propagated current tilt, and pass their last
    tilt and its marginal covariance on as the next keyframe prior. All modes start from the true
    attitude at t = 0 with prior std ``prior_std0_deg`` (an accurate initial tilt, as after the
    spec-9 initialisation; with 0.5 deg at |a| = 0.5 m/s^2 the first window locks onto the
    accelerometer direction, see docs/estimators_notes.md).
    """
    from gevi_cli.estimators.fusion import FusionWindow, bcd_refine, propagate_tilts
    from gevi_cli.estimators.pnp4 import pnp4_be, pnp4_gn
    from gevi_cli.estimators.pnp6 import pnp6_be, pnp6_refine
    from gevi_cli.estimators.triangulation import triangulate
    from gevi_cli.geometry import levelling
    from gevi_cli.geometry import tilt_angles as _tilt

    R_ic = R_IC_FORWARD if R_ic is None else np.asarray(R_ic, float)
    lo = (traj.sigma_a / GRAVITY) ** 2 if lo is None else lo
    W = int(round(window / traj.dt))
    nw = (len(traj.times) - 1) // W
    R_wc = traj.R_wi @ R_ic
    tilt_true = np.column_stack([traj.roll, traj.pitch])
    st = {}
    for m in modes:
        if m == "vision":
            st[m] = dict(R_wc=R_wc[0].copy())
        else:
            st[m] = dict(tilt=tilt_true[0].copy(), cov=np.eye(2) * np.radians(prior_std0_deg) ** 2, yaw=traj.yaw[0])
    err = {m: np.empty((nw, 4)) for m in modes}
    sig = np.full(nw, np.nan)
    amag = np.empty(nw)
    worst = -np.inf
    for j in range(nw):
        i0, i1 = j * W, (j + 1) * W
        R = R_wc[i1].T @ R_wc[i0]
        t = R_wc[i1].T @ (traj.pos[i0] - traj.pos[i1])
        s = make_scene(rng, R, t, n, noise_q=True, min_depth_c=0.5)
        p, cov = triangulate(s.z, s.y, s.R_rl, s.t_rl, s.sigma**2)
        f = traj.f_meas[i0:i1 + 1]
        acc_dir = f / np.linalg.norm(f, axis=1, keepdims=True)
        ginc = (traj.omega_meas[i0:i1] - traj.b_g_est[i0:i1]) * traj.dt
        amag[j] = np.linalg.norm(traj.acc_w[i1])
        truth = np.r_[tilt_true[i1], traj.yaw[i1]]
        for m in modes:
            S = st[m]
            if m == "vision":
                Rv, tv = pnp6_refine(*pnp6_be(p, cov, s.q), p, cov, s.q)
                S["R_wc"] = S["R_wc"] @ Rv.T
                R_wi = S["R_wc"] @ R_ic.T
                rl, pt = _tilt(R_wi)
                yw = np.arctan2(R_wi[1, 0], R_wi[0, 0])
                err[m][j] = [wrap_angle_np(rl - truth[0]), pt - truth[1], wrap_angle_np(yw - truth[2]),
                             np.linalg.norm(tv - t)]
                continue
            tilts0 = propagate_tilts(S["tilt"], ginc)
            L_k, L_c = levelling(*tilts0[0], R_ic), levelling(*tilts0[-1], R_ic)
            psi0, t0 = pnp4_gn(*pnp4_be(p, cov, s.q, L_k, L_c), s.z, s.y, s.q, L_k, L_c, s.R_rl, s.t_rl)
            wdw = FusionWindow(p=p, cov=cov, q=s.q, sigma2=s.sigma**2, R_ic=R_ic, acc_dir=acc_dir, gyro_inc=ginc,
                               gyro_var=traj.sigma_g**2 * traj.dt, prior_mean=S["tilt"], prior_cov=S["cov"],
                               psi0=psi0, t0=t0, lo=lo, hi=hi, tilts0=tilts0)
            x, Sigma, hist = bcd_refine(wdw, adaptive=(m == "adaptive"))
            worst = max(worst, float(np.max(np.diff(hist))) if len(hist) > 1 else -np.inf)
            S["tilt"], S["cov"] = x.tilts[-1].copy(), x.cov_last_tilt
            S["yaw"] = S["yaw"] - x.psi
            if m == "adaptive":
                sig[j] = np.sqrt(np.trace(Sigma))
            err[m][j] = [wrap_angle_np(x.tilts[-1, 0] - truth[0]), x.tilts[-1, 1] - truth[1],
                         wrap_angle_np(S["yaw"] - truth[2]), np.linalg.norm(x.t - t)]
    return FusionRun(times=traj.times[W::W][:nw], err=err, sqrt_tr_sigma=sig, acc_mag=amag, max_cost_increase=worst,
                     windows=nw)


def wrap_angle_np(a):
    return float((a + np.pi) % (2 * np.pi) - np.pi)


# ----------------------------------------------------------------------------- IMU (spec 9)
#: Gravity in the z-up world frame (m/s^2).
G_W = np.array([0.0, 0.0, -GRAVITY])


class SinTraj:
    """Sinusoidal position and ZYX attitude ``R_WI = Rz(yaw) Ry(pitch) Rx(roll)`` (world z up).

    Every quantity (rate, specific force, their derivatives) is in closed form.
    """

    def __init__(self, rot_amp=(0.3, 0.25, 0.6), rot_w=(1.3, 1.7, 0.9), pos_amp=(1.0, 0.8, 0.3),
                 pos_w=(0.9, 1.1, 1.6), phase=(0.1, 0.7, 1.3)):
        self.ra, self.rw = np.array(rot_amp, float), np.array(rot_w, float)
        self.pa, self.pw = np.array(pos_amp, float), np.array(pos_w, float)
        self.ph = np.array(phase, float)

    def euler(self, t, d=0):
        """(roll, pitch, yaw) and their d-th time derivative, t (n,) -> (n, 3)."""
        arg = np.outer(t, self.rw) + self.ph
        return self.ra * self.rw**d * np.sin(arg + d * np.pi / 2)

    def R(self, t):
        e = self.euler(np.atleast_1d(t))
        return rot_z(e[:, 2]) @ rot_y(e[:, 1]) @ rot_x(e[:, 0])

    def pos(self, t, d=0):
        arg = np.outer(np.atleast_1d(t), self.pw) + self.ph[::-1]
        return self.pa * self.pw**d * np.sin(arg + d * np.pi / 2)

    def omega(self, t):
        """Body rate for ZYX Euler angles: [r' - y' sp, p' cr + y' cp sr, -p' sr + y' cp cr]."""
        t = np.atleast_1d(t)
        r, p, _ = self.euler(t).T
        dr, dp, dy = self.euler(t, 1).T
        return np.column_stack([dr - dy * np.sin(p), dp * np.cos(r) + dy * np.cos(p) * np.sin(r),
                                -dp * np.sin(r) + dy * np.cos(p) * np.cos(r)])

    def specific_force(self, t):
        """a_I = R_WI^T (p'' - g_W)."""
        t = np.atleast_1d(t)
        return np.einsum("nji,nj->ni", self.R(t), self.pos(t, 2) - G_W)


# --------------------------------------------------------------------- BA window (spec 10)
def ba_window(seed, K=5, n=150, sigma_px=0.0, drop=0.1):
    """A simulated spec-10 BA window with its true poses: ``(BAWindow, R_true, t_true)``.

    Forward-moving stereo rig (b = 0.2 m, R_RL = I, t_RL = (-b, 0, 0)), KF2 about 1 m ahead of KF1,
    K intermediate frames on the way with small rotations (< 3 deg); points at depth 3-15 m in KF1;
    each feature is dropped from each image with probability ``drop`` (and only kept where it
    projects inside the 800x800 image at f = 1100); ids shuffled per image.  Poses are frame-in-KF1.
    """
    from gevi_cli.estimators.epipolar_ba import BAWindow, ImageObs, euler_zyx

    HALF = IMAGE / 2 / F_PX
    rng = np.random.default_rng(seed)
    s = np.arange(1, K + 2) / (K + 1)
    t = s[:, None] * np.array([0.15, -0.05, 1.0]) + rng.normal(size=(K + 1, 3)) * 0.02
    R = euler_zyx(s[:, None] * np.deg2rad([1.5, 3.0, 2.0]) + rng.normal(size=(K + 1, 3)) * 0.005)
    Z = rng.uniform(3.0, 15.0, 4 * n)
    P = np.column_stack([rng.uniform(-HALF, HALF, (4 * n, 2)) * Z[:, None], Z])
    # image slots: KF1-L, KF1-R, F_1..F_K, KF2-L, KF2-R
    slot_pose = [(np.eye(3), np.zeros(3), False), (np.eye(3), np.zeros(3), True)]
    slot_pose += [(R[k], t[k], False) for k in range(K)] + [(R[K], t[K], False), (R[K], t[K], True)]
    proj, ok = [], np.ones(len(P), bool)
    for Rk, tk, right in slot_pose:
        X = (P - tk) @ Rk  # R^T (P - t)
        if right:
            X = X @ R_RL.T + T_RL
        x = X[:, :2] / X[:, 2:3]
        ok &= (X[:, 2] > 0.5) & np.all(np.abs(x) < HALF, axis=1)
        proj.append(x)
    idx = np.flatnonzero(ok)[:n]
    if idx.size < n:
        raise ValueError(f"only {idx.size} of {n} points visible in every image")
    ids_all = rng.permutation(10_000)[:n]
    sigma = sigma_px / F_PX
    obs = []
    for x in proj:
        keep = rng.random(n) > drop
        order = rng.permutation(np.flatnonzero(keep))
        obs.append(ImageObs(ids_all[order], x[idx][order] + rng.normal(size=(order.size, 2)) * sigma))
    w = BAWindow(obs[0], obs[1], obs[2:2 + K], obs[K + 2], obs[K + 3], R, t, R_RL, T_RL,
                 sigma=sigma if sigma_px > 0 else None)
    return w, R, t


def perturb_ba_window(w, seed, scale=1.08, rot_deg=0.3, t_sigma=0.0):
    """Perturb the initial poses of a BA window in place: scale error, rotation noise (deg), translation noise (m)."""
    rng = np.random.default_rng(seed + 1000)
    K1 = w.R_init.shape[0]
    w.R_init = w.R_init @ exp_so3(rng.normal(size=(K1, 3)) * np.deg2rad(rot_deg) / np.sqrt(3))
    w.t_init = w.t_init * scale + rng.normal(size=(K1, 3)) * t_sigma
    return w
