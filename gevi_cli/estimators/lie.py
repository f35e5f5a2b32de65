"""SO(3) helpers, elementary rotations, tilt (roll/pitch) and projection (spec section 1).

Conventions: ``R_BA`` maps frame-A coordinates to frame B; right perturbation
``R = R_hat @ exp_so3(dphi)``; ZYX Euler angles ``R_WI = Rz(yaw) Ry(pitch) Rx(roll)``;
angles in radians. All functions accept leading batch dimensions where noted.
"""

from __future__ import annotations

import numpy as np

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


def rot_x(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0] = 1.0
    R[..., 1, 1] = c
    R[..., 1, 2] = -s
    R[..., 2, 1] = s
    R[..., 2, 2] = c
    return R


def rot_y(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 1, 1] = 1.0
    R[..., 0, 0] = c
    R[..., 0, 2] = s
    R[..., 2, 0] = -s
    R[..., 2, 2] = c
    return R


def rot_z(a) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 2, 2] = 1.0
    R[..., 0, 0] = c
    R[..., 0, 1] = -s
    R[..., 1, 0] = s
    R[..., 1, 1] = c
    return R


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
