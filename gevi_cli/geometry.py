"""Rigid-body helpers shared by datasets, trajectories and the simulator (numpy, float64).

Conventions (docs/method.md section 1): ``T_BA`` is a 4x4 homogeneous matrix mapping coordinates
in frame A into frame B, ``X_B = R_BA X_A + t_BA``.  Rotations are active.  Quaternions are stored
w first (Hamilton convention).  The estimators keep their own Lie-group helpers in
``gevi_cli.estimators.lie`` (pure math with Jacobians).
"""
from __future__ import annotations

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


def quat_wxyz_to_matrix(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, float)
    return Rotation.from_quat(np.roll(q.reshape(-1, 4), -1, axis=1)).as_matrix().reshape(q.shape[:-1] + (3, 3))


def small_rotation(rx_deg: float, ry_deg: float, rz_deg: float) -> np.ndarray:
    """A rotation from a small rotation vector given in degrees."""
    return Rotation.from_rotvec(np.radians([rx_deg, ry_deg, rz_deg])).as_matrix()


def snap(T: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Round entries within ``eps`` of 0, 1 or -1 to those values (removes float dust for files)."""
    T = np.array(T, dtype=float)
    for target in (0.0, 1.0, -1.0):
        T[np.abs(T - target) < eps] = target
    return T
