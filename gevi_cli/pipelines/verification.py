"""Geometric verification of keyframe<->current matches: the stage a pipeline chooses.

CurrentFeature Odometry (spec 12.1, 5.5): (1) 5-point essential-matrix RANSAC (OpenCV) between
keyframe-left and current-left, then (2) the l1-norm PnP on the survivors and the drop of the
``L1_DROP`` fraction with the largest reprojection errors.  GeVI replaces stage (1) with its 3-point
RANSAC with known roll/pitch (and its defaults turn (2) off, spec 2); both expose
``__call__(z, q, p, rng) -> keep-mask`` (``rng``: the frame's ``numpy.random.Generator``, seeded per frame).
"""
from __future__ import annotations

import cv2
import numpy as np

from gevi_cli import estimators as est
from gevi_cli.observations import RectifiedStereo
from gevi_cli.pipelines.config import L1_DROP, MIN_PARALLAX_PX, RANSAC_PROB, THRESHOLD_SIGMAS, VerifyConfig


class TrackingFailure(Exception):
    """The frame cannot be tracked against the keyframe (too few points, estimator failure)."""


def l1_stage(p: np.ndarray, q: np.ndarray, cfg: VerifyConfig) -> np.ndarray:
    """Keep-mask of the l1-PnP pre-filter (spec 5.5); all-true when disabled, and when the l1 pose
    itself is degenerate [gap in the spec: we keep the RANSAC survivors].  The l1 stage only drops
    the worst 10 %; its linear start can fail on a planar floor seen by few points (pool-hard_s2
    frame 449: "recover_pose: kappa <= 0", the one frame of that render CFO could not track), and
    the pose step after it has its own outlier test (the chi-square gate, method.md 5.4)."""
    if cfg.l1 == "none" or L1_DROP <= 0:
        return np.ones(len(p), dtype=bool)
    try:
        return est.pnp_l1_filter(p, q, drop=L1_DROP, method=cfg.l1)
    except est.EstimatorError:
        return np.ones(len(p), dtype=bool)


class TwoStageVerification:
    """Stage (1), a RANSAC the subclass provides (``ransac(z, q, rng) -> mask``), then stage (2), the l1 drop."""

    label = "RANSAC"
    iterations = 0  # minimal samples drawn in the last call, where the RANSAC counts them

    def __call__(self, z: np.ndarray, q: np.ndarray, p: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        keep = self.ransac(z, q, rng)
        idx = np.flatnonzero(keep)
        if len(idx) < 6:
            raise TrackingFailure(f"only {len(idx)} matches survive {self.label}")
        sub = l1_stage(p[idx], q[idx], self.cfg)
        out = np.zeros(len(z), dtype=bool)
        out[idx[sub]] = True
        return out

    def parallax_px(self, z: np.ndarray, q: np.ndarray) -> float:
        """Median keyframe -> current displacement of the matches (px): np.median's value (the mean of the two
        middle values for an even count) from a partial sort, a ninth of its cost at a few hundred matches."""
        d = q - z
        d *= d
        r = np.sqrt(d[:, 0] + d[:, 1])  # = np.linalg.norm(q - z, axis=1)
        m = len(r) // 2
        if len(r) % 2:
            med = np.partition(r, m)[m]
        else:
            lo_hi = np.partition(r, (m - 1, m))[m - 1:m + 1]
            med = np.add.reduce(lo_hi) / 2.0
        return med * self.camera.f


class FivePointL1Verification(TwoStageVerification):
    """CFO's two-stage verification (5-point RANSAC, then l1-PnP drop)."""

    def __init__(self, cfg: VerifyConfig, camera: RectifiedStereo):
        self.cfg = cfg
        self.camera = camera

    def ransac(self, z: np.ndarray, q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        cfg = self.cfg
        n = len(z)
        if cfg.ransac == "none" or n < 5:
            return np.ones(n, dtype=bool)
        if self.parallax_px(z, q) < MIN_PARALLAX_PX:
            # No translation to speak of: every E = [t]x R fits, so RANSAC cannot classify.
            return np.ones(n, dtype=bool)
        # (findEssentialMat's RANSAC draws from a generator of its own with a fixed seed, not from ``rng``: its
        # result does not change with cv2.setRNGSeed either, measured with OpenCV 5.1, so CFO's runs do not
        # depend on --seed)
        E, mask = cv2.findEssentialMat(z.reshape(-1, 1, 2), q.reshape(-1, 1, 2), np.eye(3), method=cv2.RANSAC,
                                       prob=RANSAC_PROB, threshold=cfg.ransac_threshold_px / self.camera.f)
        if E is None or mask is None:
            raise TrackingFailure("5-point RANSAC found no essential matrix")
        return mask.ravel().astype(bool)



class ThreePointVerification(TwoStageVerification):
    """GeVI's verification (spec 7): upright 3-point RANSAC on keyframe-left / current-left with the
    IMU roll/pitch of both frames, Sampson threshold max(``THRESHOLD_SIGMAS`` sigma, the px threshold);
    then the optional l1 stage as in CFO (off in GeVI's defaults).

    ``levelling()`` returns ``(L_k, L_c, sigma)``: the levelling rotations of keyframe and current
    camera (camera -> yaw-free level frame) and the current normalized noise std.
    """

    label = "3-point RANSAC"

    def __init__(self, cfg: VerifyConfig, camera: RectifiedStereo, levelling):
        self.cfg = cfg
        self.camera = camera
        self.levelling = levelling
        self.iterations = 0  # minimal samples drawn in the last call (for the --ransac ablation)

    def ransac(self, z: np.ndarray, q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        cfg, n = self.cfg, len(z)
        if n < 3:
            return np.ones(n, dtype=bool)
        if self.parallax_px(z, q) < MIN_PARALLAX_PX:
            return np.ones(n, dtype=bool)  # as for 5-point: no translation, the model cannot classify
        L_k, L_c, sigma = self.levelling()
        thr = max(THRESHOLD_SIGMAS * sigma, cfg.ransac_threshold_px / self.camera.f)
        try:
            _, _, inliers, it = est.ransac_3pt_upright(z, q, L_k, L_c, thr, seed=rng,
                                                       confidence=RANSAC_PROB)
        except est.EstimatorError as err:
            raise TrackingFailure(f"3-point RANSAC: {err}") from None
        self.iterations = int(it)
        return inliers

