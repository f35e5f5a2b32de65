"""Align an estimate to the ground truth before computing absolute errors.

Methods (``ALIGN_METHODS``), all estimating a transform ``S`` applied on the left of the estimate
poses, ``T_W_S' = S @ T_V_S`` (V = the estimate's world frame, W = the GT world frame):

* ``none``: identity.
* ``origin``: ``S = T_gt[0] @ inv(T_est[0])`` (evo's ``align_origin``): first poses coincide.
* ``se3``: rigid Umeyama on the positions (evo ``geometry.umeyama_alignment``).
* ``sim3``: Umeyama with scale (evo); positions become ``s R p + t``.
* ``posyaw``: 4-DOF, translation + rotation about the gravity axis z, closed form (evo has none).
  This is rpg_trajectory_evaluation's ``align_posyaw``: yaw from the 2x2 xy cross-covariance of the
  centred positions, ``theta = atan2(sum(e_x g_y - e_y g_x), sum(e_x g_x + e_y g_y))``; with a
  single pose (``n_align=1``) the yaw of ``R_gt0 R_est0^T`` is used instead.  Requires both world
  frames to have z along gravity (true for VIO estimates and EuRoC/TUM ground truth).

``n_align`` limits the poses used to estimate ``S`` to the first N matched pairs (-1 = all).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.geometry import rot_z
from gevi_cli.trajectory import Trajectory

ALIGN_METHODS = ("none", "origin", "se3", "sim3", "posyaw")


@dataclass(frozen=True)
class Alignment:
    """``p_W = scale * R @ p_V + t`` and ``R_W_S = R @ R_V_S`` (R 3x3, t metres, scale unitless)."""

    method: str
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    n_used: int = 0

    @property
    def yaw_deg(self) -> float:
        return float(np.degrees(np.arctan2(self.R[1, 0], self.R[0, 0])))

    def apply(self, traj: Trajectory) -> Trajectory:
        """The trajectory expressed in the GT world frame."""
        T = traj.matrices
        out = np.tile(np.eye(4), (len(T), 1, 1))
        out[:, :3, :3] = self.R @ T[:, :3, :3]
        out[:, :3, 3] = self.scale * T[:, :3, 3] @ self.R.T + self.t
        return Trajectory.from_matrices(traj.t_ns, out, frame=traj.frame, indexed=traj.indexed, name=traj.name,
                                        meta=traj.meta)

    def as_dict(self) -> dict:
        return {"method": self.method, "R": self.R.tolist(), "t": self.t.tolist(), "scale": self.scale,
                "yaw_deg": self.yaw_deg, "n_used": self.n_used}


def best_yaw(C: np.ndarray) -> float:
    """Yaw maximizing ``trace(R_z(theta)^T ... )`` for a 3x3 (or 2x2) matrix C = sum(g e^T)-like.

    For ``C = R_gt R_est^T`` this is the yaw of the rotation closest to C about z.
    """
    return float(np.arctan2(C[1, 0] - C[0, 1], C[0, 0] + C[1, 1]))


def posyaw_umeyama(est_xyz: np.ndarray, gt_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form 4-DOF least squares: ``min sum |gt_i - (R_z(theta) est_i + t)|^2``.

    Args: (n, 3) positions in metres.  Returns (R 3x3, t 3).
    """
    mu_e, mu_g = est_xyz.mean(axis=0), gt_xyz.mean(axis=0)
    e, g = est_xyz - mu_e, gt_xyz - mu_g
    C = g[:, :2].T @ e[:, :2]  # C[i, j] = sum g_i e_j
    R = rot_z(best_yaw(C))
    return R, mu_g - R @ mu_e


def posyaw_single(est_T0: np.ndarray, gt_T0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """4-DOF alignment from one pose pair (rpg ``align_posyaw_single``)."""
    R = rot_z(best_yaw(gt_T0[:3, :3] @ est_T0[:3, :3].T))
    return R, gt_T0[:3, 3] - R @ est_T0[:3, 3]


def estimate_alignment(gt: Trajectory, est: Trajectory, method: str, n_align: int = -1) -> Alignment:
    """Estimate the alignment of matched ``est`` onto ``gt`` (same length, see :mod:`associate`)."""
    if method not in ALIGN_METHODS:
        raise GeviError("--align", f"unknown alignment {method!r}; choose one of {', '.join(ALIGN_METHODS)}")
    n = len(gt) if n_align is None or n_align < 0 else min(int(n_align), len(gt))
    if n < 1:
        raise GeviError("--n-align", "must be -1 (all) or a positive number of poses")
    g, e = gt.positions[:n], est.positions[:n]
    if method == "none":
        return Alignment("none", n_used=0)
    if method == "origin" or (method == "se3" and n == 1):
        S = gt.matrices[0] @ np.linalg.inv(est.matrices[0])
        return Alignment(method, S[:3, :3], S[:3, 3], 1.0, 1)
    if method == "posyaw":
        if n == 1:
            R, t = posyaw_single(est.matrices[0], gt.matrices[0])
        else:
            R, t = posyaw_umeyama(e, g)
        return Alignment("posyaw", R, t, 1.0, n)
    min_n = 3
    if n < min_n:
        raise GeviError("--n-align", f"{method} alignment needs at least {min_n} matched poses, got {n}")
    from gevi_cli.evaluation.evo_compat import geometry

    try:
        R, t, s = geometry.umeyama_alignment(e.T, g.T, method == "sim3")
    except geometry.GeometryException as exc:
        raise GeviError(est.meta.get("path", est.name), f"{method} alignment failed: {exc}") from None
    return Alignment(method, np.asarray(R), np.asarray(t), float(s), n)


#: Below this ratio of the second to the largest singular value of the centred aligned positions, the
#: rotation about the direction of travel is practically undetermined by a position-only alignment.
COLLINEAR_RATIO = 0.02


def collinearity_warning(gt: Trajectory, method: str, n_align: int = -1) -> str | None:
    """Warn when an se3/sim3 alignment rests on nearly collinear positions.

    Umeyama uses positions only: on a straight drive (KITTI 04) the roll about the direction of
    travel is free, so the rotation ATE reflects an arbitrary alignment roll, not the estimate.
    posyaw is immune (only yaw about gravity is estimated), as are none/origin.
    """
    if method not in ("se3", "sim3"):
        return None
    n = len(gt) if n_align is None or n_align < 0 else min(int(n_align), len(gt))
    g = gt.positions[:n] - gt.positions[:n].mean(axis=0)
    s = np.linalg.svd(g, compute_uv=False)
    if n < 3 or s[0] == 0 or s[1] / s[0] >= COLLINEAR_RATIO:
        return None
    return (f"the aligned ground-truth positions are nearly collinear (spread ratio {s[1] / s[0]:.3g}): "
            f"the {method} rotation about the direction of travel is undetermined, so the rotation ATE "
            "is not meaningful (translation ATE and RPE are); use --align origin, or posyaw for z-up "
            "(gravity-aligned) data")


def align(gt: Trajectory, est: Trajectory, method: str, n_align: int = -1) -> tuple[Trajectory, Alignment]:
    """Return ``(aligned estimate, alignment)``."""
    a = estimate_alignment(gt, est, method, n_align)
    return a.apply(est), a
