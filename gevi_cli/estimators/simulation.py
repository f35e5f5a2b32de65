"""Synthetic stereo scenes for the GeVI / Bias-Eli simulations (spec 5.6 and 11.3).

Rig: rectified stereo, R_RL = I, t_RL = (-b, 0, 0) with b = 0.2 m; f = 1100 px on an 800 x 800
image with the principal point at the centre; depths uniform in [1, 10] m; image noise
sigma_px = 2.5 px added to the keyframe images z, y only (the paper's model) unless
``noise_q`` is set. All returned 2D quantities are normalized coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .lie import exp_so3, project, rot_z, rtilt

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
