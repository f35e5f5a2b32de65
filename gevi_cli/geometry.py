"""The one home of rigid-body geometry (numpy, float64): poses, quaternions, Euler angles, SO(3)
(exp, log, Jacobians), elementary rotations, tilt (roll/pitch), projection.  Used by every layer,
the estimators included; imports nothing of gevi's.

Conventions (docs/method.md section 1): ``T_BA`` is a 4x4 homogeneous matrix mapping coordinates
in frame A into frame B, ``X_B = R_BA X_A + t_BA``.  Rotations are active; right perturbation
``R = R_hat @ exp_so3(dphi)``; ZYX Euler angles ``R_WI = Rz(yaw) Ry(pitch) Rx(roll)``; angles in
radians.  Quaternions are stored w first (Hamilton convention).  Functions accept leading batch
dimensions where noted.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation


def euler_zyx_to_matrix(yaw, pitch, roll) -> np.ndarray:
    """``R = Rz(yaw) Ry(pitch) Rx(roll)`` for arrays of angles (radians); returns (..., 3, 3)."""
    yaw, pitch, roll = np.broadcast_arrays(np.asarray(yaw, float), np.asarray(pitch, float), np.asarray(roll, float))
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    R = np.empty(yaw.shape + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def euler_zyx_rates_to_body_rate(yaw, pitch, roll, dyaw, dpitch, droll) -> np.ndarray:
    """Body-frame angular velocity (rad/s) of ``R_WB = Rz(yaw) Ry(pitch) Rx(roll)`` from Euler rates.

    ``omega_W = dyaw e3 + dpitch Rz e2 + droll Rz Ry e1`` and ``omega_B = R_WB^T omega_W``, i.e.
    ``[droll - dyaw sp, dpitch cr + dyaw cp sr, -dpitch sr + dyaw cp cr]``.  Returns (..., 3).
    """
    sp, cp = np.sin(pitch), np.cos(pitch)
    sr, cr = np.sin(roll), np.cos(roll)
    return np.stack([droll - dyaw * sp, dpitch * cr + dyaw * cp * sr, -dpitch * sr + dyaw * cp * cr], axis=-1)


def make_T(R: np.ndarray, t) -> np.ndarray:
    """4x4 (or (..., 4, 4)) homogeneous matrix from rotation(s) and translation(s)."""
    R = np.asarray(R, float)
    t = np.asarray(t, float)
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def invert_pose(T: np.ndarray) -> np.ndarray:
    """Inverse of (..., 4, 4) rigid transforms."""
    T = np.asarray(T, float)
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    return make_T(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def matrix_to_quat_wxyz(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations -> (..., 4) unit quaternions, w first, w >= 0."""
    R = np.asarray(R, float)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()  # xyzw
    q = np.roll(q, 1, axis=1)
    q[q[:, 0] < 0] *= -1.0
    return q.reshape(R.shape[:-2] + (4,))


def small_rotation(rx_deg: float, ry_deg: float, rz_deg: float) -> np.ndarray:
    """A rotation from a small rotation vector given in degrees."""
    return Rotation.from_rotvec(np.radians([rx_deg, ry_deg, rz_deg])).as_matrix()


def snap(T: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Round entries within ``eps`` of 0, 1 or -1 to those values (removes float dust for files)."""
    T = np.array(T, dtype=float)
    for target in (0.0, 1.0, -1.0):
        T[np.abs(T - target) < eps] = target
    return T


# ---------------------------------------------------------------- SO(3), elementary rotations, tilt, projection
E3 = np.array([0.0, 0.0, 1.0])


def skew(v) -> np.ndarray:
    """``[v]_x`` for v of shape (..., 3) -> (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1] = -v[..., 2]
    S[..., 0, 2] = v[..., 1]
    S[..., 1, 0] = v[..., 2]
    S[..., 1, 2] = -v[..., 0]
    S[..., 2, 0] = -v[..., 1]
    S[..., 2, 1] = v[..., 0]
    return S


def exp_so3(w) -> np.ndarray:
    """Rodrigues formula, w (..., 3) rad -> R (..., 3, 3). Taylor-expanded near zero."""
    w = np.asarray(w, dtype=float)
    th2 = np.sum(w * w, axis=-1)[..., None, None]
    th = np.sqrt(th2)
    small = th2 < 1e-12
    ths = np.where(small, 1.0, th)
    a = np.where(small, 1.0 - th2 / 6.0, np.sin(ths) / ths)
    b = np.where(small, 0.5 - th2 / 24.0, (1.0 - np.cos(ths)) / (ths * ths))
    K = skew(w)
    return np.eye(3) + a * K + b * (K @ K)


def log_so3(R) -> np.ndarray:
    """Inverse of :func:`exp_so3`: R (..., 3, 3) -> w (..., 3), |w| <= pi."""
    R = np.asarray(R, dtype=float)
    tr = np.trace(R, axis1=-2, axis2=-1)
    c = np.clip((tr - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s = np.sin(th)
    small = th < 1e-6
    fac = np.where(small, 0.5 + th * th / 12.0, th / (2.0 * np.where(small, 1.0, s)))
    w = fac[..., None] * v
    # near pi: use the symmetric part (v is ~0 there)
    near_pi = th > np.pi - 1e-4
    if np.any(near_pi):
        Rp = R[near_pi]
        B = (Rp + np.swapaxes(Rp, -1, -2)) / 2.0 - np.eye(3) * ((np.trace(Rp, axis1=-2, axis2=-1) - 1) / 2)[..., None, None]
        # B = (1 - cos th) a a^T; pick the largest column
        idx = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        col = np.take_along_axis(B, idx[..., None, None].repeat(3, -1), axis=-1)[..., 0]
        a = col / np.linalg.norm(col, axis=-1, keepdims=True)
        vp = v[near_pi]
        sign = np.where(np.sum(a * vp, -1) < 0, -1.0, 1.0)
        w[near_pi] = (sign * th[near_pi])[..., None] * a
    return w


def right_jacobian(w) -> np.ndarray:
    """Right Jacobian of SO(3), w (3,) -> (3, 3)."""
    w = np.asarray(w, dtype=float)
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-6:
        return np.eye(3) - 0.5 * K + K @ K / 6.0
    return np.eye(3) - (1 - np.cos(th)) / th**2 * K + (th - np.sin(th)) / th**3 * (K @ K)


def _elementary(a, i: int, j: int, k: int) -> np.ndarray:
    """Rotation by angle(s) ``a`` about axis ``k``: ``c`` at (i,i), (j,j), ``-s`` at (i,j), ``s`` at (j,i)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., k, k] = 1.0
    R[..., i, i] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    R[..., j, j] = c
    return R


def rot_x(a) -> np.ndarray:
    return _elementary(a, 1, 2, 0)


def rot_y(a) -> np.ndarray:
    return _elementary(a, 2, 0, 1)


def rot_z(a) -> np.ndarray:
    return _elementary(a, 0, 1, 2)


def drot_z(a) -> np.ndarray:
    """d Rz(a) / da = [e3]_x Rz(a)."""
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0] = -s
    R[..., 0, 1] = -c
    R[..., 1, 0] = c
    R[..., 1, 1] = -s
    return R


def rtilt(roll, pitch) -> np.ndarray:
    """``R_tilt(roll, pitch) = Ry(pitch) Rx(roll)`` (yaw-free part of R_WI)."""
    return rot_y(pitch) @ rot_x(roll)


def tilt_angles(M):
    """Yaw-invariant (roll, pitch) of a rotation (..., 3, 3): pitch=-asin(M31), roll=atan2(M32, M33)."""
    M = np.asarray(M, dtype=float)
    pitch = -np.arcsin(np.clip(M[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(M[..., 2, 1], M[..., 2, 2])
    return roll, pitch


def levelling(roll, pitch, R_ic) -> np.ndarray:
    """Levelling rotation ``L = R_tilt(roll, pitch) @ R_ic`` (camera vectors -> yaw-free level frame).

    With it ``R_WC = Rz(yaw) L`` and the 4-DOF model is ``R_CK = L_C^T Rz(psi) L_K``.
    ``R_ic`` maps camera vectors into the IMU frame. Angles in rad.
    """
    return rtilt(roll, pitch) @ np.asarray(R_ic, dtype=float)


def rot4(psi, L_k, L_c) -> np.ndarray:
    """4-DOF relative rotation ``R_CK(psi) = L_C^T Rz(psi) L_K``."""
    return np.asarray(L_c).T @ rot_z(psi) @ np.asarray(L_k)


def project(X) -> np.ndarray:
    """Pinhole projection pi(X) = (X1/X3, X2/X3) for X (..., 3)."""
    X = np.asarray(X, dtype=float)
    return X[..., :2] / X[..., 2:3]


def project_jacobian(X) -> np.ndarray:
    """d pi / d X, X (..., 3) -> (..., 2, 3)."""
    X = np.asarray(X, dtype=float)
    iz = 1.0 / X[..., 2]
    J = np.zeros(X.shape[:-1] + (2, 3))
    J[..., 0, 0] = iz
    J[..., 1, 1] = iz
    J[..., 0, 2] = -X[..., 0] * iz * iz
    J[..., 1, 2] = -X[..., 1] * iz * iz
    return J


def homogeneous(x) -> np.ndarray:
    """(n, 2) -> (n, 3) by appending ones."""
    x = np.asarray(x, dtype=float)
    return np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1)


def wrap_angle(a):
    """Wrap to (-pi, pi]."""
    a = np.asarray(a, dtype=float)
    return -((-a + np.pi) % (2.0 * np.pi) - np.pi)


def rotation_error(R_est, R_true) -> np.ndarray:
    """Geodesic angle ||Log(R_est R_true^T)|| in rad."""
    return np.linalg.norm(log_so3(np.asarray(R_est) @ np.swapaxes(np.asarray(R_true), -1, -2)), axis=-1)


def project_to_so3(M) -> np.ndarray:
    """Nearest rotation (Frobenius) to a 3x3 matrix via SVD."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def orthonormal_pose(T: np.ndarray) -> np.ndarray:
    """``T`` (4x4) with its rotation block replaced by the nearest rotation (SVD): products of many
    poses drift off SO(3) by rounding."""
    U, _, Vt = np.linalg.svd(T[:3, :3])
    out = T.copy()
    out[:3, :3] = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    return out


def exp_so3_and_jr(phi) -> tuple[np.ndarray, np.ndarray]:
    """``Exp(phi)`` and the right Jacobian ``J_r(phi)`` of one rotation vector (3,), together (series
    below 1e-4 rad): the per-sample step of the IMU filters, where batched calls cost more than the math."""
    th2 = float(phi @ phi)
    K = skew(phi)
    K2 = K @ K
    if th2 < 1e-8:
        a, b, c = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0, 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        s, co = math.sin(th), math.cos(th)
        a, b, c = s / th, (1.0 - co) / th2, (th - s) / (th2 * th)
    return np.eye(3) + a * K + b * K2, np.eye(3) - b * K + c * K2
