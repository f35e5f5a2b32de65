"""GeVI's gravity-aided 4-DOF pose step: the bias-eliminated estimate of (psi, t_ck) (spec 6.2) and one
Gauss-Newton step on the point-to-epipolar-line distances in both keyframe images (spec 6.3).

Frames: ``L_k``, ``L_c`` level the keyframe and current rectified-left cameras (roll/pitch from the
IMU); the pose is ``R_ck = L_c^T Rz(psi) L_k``, ``t_ck`` in metres; image coordinates normalized.
"""
from __future__ import annotations

import cv2
import numpy as np

from gevi_cli import estimators as est
from gevi_cli.pipelines.config import FALLBACK_MIN_PX, FALLBACK_SIGMAS, MIN_PARALLAX_PX, OdometryConfig
from gevi_cli.pipelines.pose6 import opencv_pnp, reprojection_median_px
from gevi_cli.pipelines.verification import TrackingFailure


def pose4(m, cov, L_k, L_c, camera, cfg: OdometryConfig, sigma2: float) -> tuple[tuple[float, np.ndarray], bool]:
    """4-DOF BE + one epipolar GN step on the matches ``m`` -> ((psi, t_ck), started from SQPnP).

    The linear 4-DOF model is degenerate for a *level* plane (a pool floor): with the vertical
    coordinate rho_3 = h of every point the same, x = (0, 0, 0, 0, -h) solves A x = b exactly (it
    maps every point to the camera centre), so with noise the estimate mixes the true and the
    spurious solution (psi off by pi, all points behind the camera).  As for the 6-DOF step
    (pose6.estimate_pose6), when the median reprojection error exceeds ``FALLBACK_SIGMAS`` noise
    std, the GN step is redone from SQPnP projected on the 4-DOF model and the better kept.
    """
    f = camera.f
    parallax_px = float(np.median(np.linalg.norm(m.q - m.z, axis=1))) * f
    use_gn = parallax_px >= MIN_PARALLAX_PX  # below: left epipolar lines undefined (t ~ 0)

    def gn(psi, t):
        if not use_gn:
            return psi, t
        return est.pnp4_gn(psi, t, m.z, m.y, m.q, L_k, L_c, camera.R_rl, camera.t_rl)

    def err(psi, t):
        return reprojection_median_px(est.rot4(psi, L_k, L_c), t, m.p, m.q, f)

    best, e_best, fallback = None, np.inf, False
    try:
        best = gn(*est.pnp4_be(m.p, cov, m.q, L_k, L_c))
        e_best = err(*best)
    except est.EstimatorError:
        pass
    limit = max(FALLBACK_SIGMAS * np.sqrt(sigma2) * f, FALLBACK_MIN_PX)
    if e_best > limit:
        try:
            R6, t6 = opencv_pnp(m.p, m.q, cv2.SOLVEPNP_SQPNP, refine=False)
            M = L_c @ R6 @ L_k.T  # = Rz(psi) for an exact 4-DOF pose
            cand = gn(float(np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1])), t6)
            e2 = err(*cand)
            if e2 < e_best:
                best, e_best, fallback = cand, e2, True
        except (est.EstimatorError, cv2.error, TrackingFailure):
            pass
    if best is None:
        raise TrackingFailure("4-DOF PnP failed")
    return best, fallback
