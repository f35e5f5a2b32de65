"""Keyframe -> current 6-DOF pose from triangulated keyframe points (spec 5) and its ablations.

``be-w`` is the CurrentFeature estimator: Bias-Eli PnP (spec 5.2-5.3) + the weighted LM step of
5.4 (the paper's one, and more while a step is longer than ``STEP_TOL``).  ``be`` stops after
the bias-eliminated linear step, ``ls`` uses the plain CPnP least squares (no bias elimination) +
the same weighted steps, so the two ablations isolate the two ingredients.  ``epnp``/``sqpnp`` are
the textbook alternative: OpenCV's EPnP / SQPnP followed by OpenCV's (unweighted, iterated) LM
refinement.
"""
from __future__ import annotations

import cv2
import numpy as np

from gevi_cli import estimators as est
from gevi_cli.pipelines.config import (
    CHI2_GATE,
    FALLBACK_MIN_PX,
    FALLBACK_SIGMAS,
    MAX_MEDIAN_PX,
    MAX_REFINE_STEPS,
    MIN_PNP_POINTS,
    REFINE_STEPS,
    REVERIFY_SIGMAS,
    STEP_TOL,
    PnPConfig,
)
from gevi_cli.pipelines.verification import TrackingFailure


def estimate_pose6(p: np.ndarray, cov: np.ndarray, q: np.ndarray, cfg: PnPConfig, sigma2: float, f: float = 1.0):
    """``(R_ck, t_ck, used_fallback)``: maps keyframe-left points ``p`` (n, 3, m) onto current
    normalized ``q`` (n, 2).

    ``cov`` (n, 3, 3) point covariances (normalized-noise units already applied); ``sigma2`` the
    normalized image-noise variance; ``f`` the focal length (px) for the fallback test.

    The CPnP linear model (spec 5.1) is degenerate for coplanar points (a pool floor seen from
    above: measured median reprojection errors of 5-13 px after the step on a planar render).  So for
    ``be-w``/``ls``, when the refined pose's median reprojection error exceeds
    ``FALLBACK_SIGMAS`` times the image noise (at least ``FALLBACK_MIN_PX``), the step is
    redone from SQPnP (spec 5.5 [PROPOSAL]: "any robust PnP
    followed by LM") and the better of the two is kept.  Raises :class:`TrackingFailure`.
    """
    R, t, fallback, _ = _pose6_and_median(p, cov, q, cfg, sigma2, f)
    return R, t, fallback


def _pose6_and_median(p, cov, q, cfg: PnPConfig, sigma2: float, f: float):
    """:func:`estimate_pose6` and the median reprojection error (px) of its pose over all matches
    when the fallback test had to compute it (None otherwise), so the tracking gates need not
    compute it again."""
    if cfg.method not in ("be-w", "ls") or FALLBACK_SIGMAS <= 0:
        R, t = _estimate(p, cov, q, cfg, sigma2)
        return R, t, False, None
    try:
        R, t = _estimate(p, cov, q, cfg, sigma2)
        err = reprojection_median_px(R, t, p, q, f)
        first_failure = None
    except TrackingFailure as failure:  # e.g. the step from a degenerate linear start put points behind
        R = t = None
        err, first_failure = float("inf"), failure
    if err <= converged_limit_px(cfg, sigma2, f):
        return R, t, False, err
    try:
        R2, t2 = _weighted_steps(*opencv_pnp(p, q, cv2.SOLVEPNP_SQPNP, refine=False), p, cov, q, cfg, sigma2)
        err2 = reprojection_median_px(R2, t2, p, q, f)
    except (est.EstimatorError, cv2.error, TrackingFailure):
        err2 = float("inf")
    if err2 < err:
        return R2, t2, True, err2
    if first_failure is not None:
        raise first_failure
    return R, t, False, err


def converged_limit_px(cfg: PnPConfig, sigma2: float, f: float) -> float:
    """Median reprojection error (px) above which a pose is not the converged fit of its matches:
    ``FALLBACK_SIGMAS`` noise std, at least ``FALLBACK_MIN_PX``.  The median |r| of 2-D
    Gaussian noise is 1.18 sigma, so well above it the steps have not converged (SQPnP fallback) or a
    minority of outliers drags the pose (re-verification)."""
    return max(FALLBACK_SIGMAS * np.sqrt(sigma2) * f, FALLBACK_MIN_PX)



def _estimate(p, cov, q, cfg: PnPConfig, sigma2: float):
    """The pose step of ``cfg.method`` with the stereo covariances ``cov``."""
    try:
        if cfg.method in ("epnp", "sqpnp"):
            return opencv_pnp(p, q, cv2.SOLVEPNP_EPNP if cfg.method == "epnp" else cv2.SOLVEPNP_SQPNP, refine=True)
        w = est.depth_weights(p) if cfg.depth_weights else None
        if cfg.method == "ls":
            R, t = est.pnp6_ls(p, q, weights=w)
        else:
            R, t = est.pnp6_be(p, cov, q, weights=w)
        if cfg.method in ("be-w", "ls"):
            R, t = _weighted_steps(R, t, p, cov, q, cfg, sigma2)
        return R, t
    except est.EstimatorError as err:
        raise TrackingFailure(f"{cfg.method}: {err}") from None
    except cv2.error as err:
        raise TrackingFailure(f"OpenCV {cfg.method}: {str(err).strip().splitlines()[-1]}") from None


def _weighted_steps(R, t, p, cov, q, cfg: PnPConfig, sigma2: float):
    """The weighted LM step(s) of spec 5.4 from the start ``(R, t)``.

    S2's one step is efficient when the start lies within the noise of the optimum (a
    sqrt(n)-consistent start).  Whether it did is measured by the step itself: ``delta^T H delta`` is
    its squared length in standard deviations of the pose.  Above ``STEP_TOL`` the start was
    farther than the one-step argument allows (a planar floor, where the linear model is
    degenerate), so the steps go on until one is that short [PROPOSAL].  On the 8 sweep renders this
    took 1.7-2.6 steps per frame on average and halved pool-easy's tracking error (docs/method.md 5.4).
    """
    s2q = sigma2
    for k in range(MAX_REFINE_STEPS):
        R, t, m = est.pnp6_refine(R, t, p, cov, q, sigma2_q=s2q, return_step=True)
        if k + 1 >= REFINE_STEPS and (STEP_TOL <= 0 or m <= STEP_TOL):
            break
    return R, t


def _cv_points(p: np.ndarray, q: np.ndarray):
    """Points (n, 3) and normalized image points (n, 2) in the layout OpenCV's PnP functions take."""
    return (np.ascontiguousarray(p, dtype=np.float64).reshape(-1, 1, 3),
            np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 1, 2))


def opencv_pnp(p: np.ndarray, q: np.ndarray, flag: int, refine: bool):
    """OpenCV PnP on normalized coordinates (K = I), optionally + OpenCV's LM -> (R, t)."""
    obj, img = _cv_points(p, q)
    ok, rvec, tvec = cv2.solvePnP(obj, img, np.eye(3), None, flags=flag)
    if not ok:
        raise TrackingFailure("OpenCV PnP failed")
    if refine:
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, np.eye(3), None, rvec, tvec)
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def pnp_ransac_inliers(p: np.ndarray, q: np.ndarray, threshold: float) -> np.ndarray | None:
    """Inlier mask of OpenCV's P3P RANSAC on the reprojection error (normalized ``threshold``), or
    None when it finds no pose."""
    obj, img = _cv_points(p, q)
    try:
        ok, _, _, idx = cv2.solvePnPRansac(obj, img, np.eye(3), None, reprojectionError=float(threshold),
                                           confidence=0.999, iterationsCount=200, flags=cv2.SOLVEPNP_AP3P)
    except cv2.error:
        return None
    if not ok or idx is None:
        return None
    keep = np.zeros(len(p), dtype=bool)
    keep[idx.ravel()] = True
    return keep


def reprojection_median_px(R: np.ndarray, t: np.ndarray, p: np.ndarray, q: np.ndarray, f: float) -> float:
    """Median reprojection error (px); a robust sanity check of a pose (a few outliers survive the
    verification, so an RMS would flag good poses)."""
    X = p @ R.T + t
    front = X[:, 2] > 0
    if front.sum() < 0.5 * len(X):
        return float("inf")
    r = q[front] - X[front, :2] / X[front, 2:3]
    return float(np.median(np.linalg.norm(r, axis=1))) * f


def _finite(R: np.ndarray, t: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(R)) and np.all(np.isfinite(t)))


def reverified(p: np.ndarray, q: np.ndarray, med: float, cfg: PnPConfig, sigma2: float, f: float, pose_of):
    """The pose step redone without the outliers of a 3D-2D RANSAC [PROPOSAL; docs/method.md 5.4], or None.

    Outliers that the epipolar verification cannot see (a group shifted along its epipolar lines:
    measured on pool-hard_s2, 9 of 63 tracks 38 px off; wrong stereo depths) drag every least-squares
    pose.  OpenCV's AP3P RANSAC on the reprojection error (``REVERIFY_SIGMAS`` noise std, at least
    1 px) finds them; ``pose_of(keep)`` redoes the pose step on the inliers and returns a tuple whose
    first two items are ``R, t``.  Returned, with its median reprojection error over *all* matches,
    only when that error at least halves ``med`` (a minority of gross outliers drags the pose of all:
    without them the median collapses; tracks merely noisier than sigma_hat do not do that -- KITTI
    04's exported colour tracks: 3 frames, 60 % kept, the median barely lower).
    """
    keep = pnp_ransac_inliers(p, q, max(REVERIFY_SIGMAS * np.sqrt(sigma2), 1.0 / f))
    if keep is None or not MIN_PNP_POINTS <= keep.sum() < len(p):
        return None
    try:
        pose = pose_of(keep)
    except (TrackingFailure, est.EstimatorError):
        return None
    med2 = reprojection_median_px(pose[0], pose[1], p, q, f)
    if np.isfinite(med2) and (med2 < 0.5 * med or not np.isfinite(med)):
        return pose, med2
    return None


def tracked_pose6(p: np.ndarray, cov: np.ndarray, q: np.ndarray, cfg: PnPConfig, sigma2: float, f: float):
    """The 6-DOF tracking step of the pipelines: (R_ck, t_ck, fell_back) or :class:`TrackingFailure`.

    :func:`estimate_pose6`, then the sanity gates: finite, median reprojection error below
    ``MAX_MEDIAN_PX``.  CurrentFeature Odometry uses it for every frame, GeVI before its
    initialisation and where the IMU has a gap.
    """
    R, t, fallback, med = _pose6_and_median(p, cov, q, cfg, sigma2, f)
    if not _finite(R, t):
        raise TrackingFailure("non-finite pose")
    if med is None:
        med = reprojection_median_px(R, t, p, q, f)
    if med > converged_limit_px(cfg, sigma2, f):
        again = reverified(p, q, med, cfg, sigma2, f,
                           lambda keep: estimate_pose6(p[keep], cov[keep], q[keep], cfg, sigma2, f))
        if again is not None:
            (R, t, fallback), med = again
    if CHI2_GATE > 0 and cfg.method in ("be-w", "ls"):
        R, t, med = _chi2_refit(R, t, p, cov, q, cfg, sigma2, f, med)
    if med > MAX_MEDIAN_PX:
        raise TrackingFailure(f"median reprojection error {med:.2f} px after the pose step")
    return R, t, fallback


CHI2_ROUNDS = 10
"""At most this many rounds of :func:`_chi2_refit` (each: test every match at the current pose, refit on
the ones that pass).  Gross errors mask each other at a dragged pose, so each round finds a few more;
on a synthetic floor with 15 % wrong depths the kept set stopped changing after 8."""


def _chi2_refit(R, t, p, cov, q, cfg: PnPConfig, sigma2: float, f: float, med: float):
    """Matches the weighted model cannot explain out, the weighted steps again on the rest [PROPOSAL].

    The weights of spec 5.4 say how far each residual may be: ``r^T Sigma_bar^-1 r`` is chi-square
    with 2 dof.  A match far beyond ``CHI2_GATE`` is not noise but a wrong stereo depth, which no
    2D-2D verification can see (its tracks are right) and the l1 drop of a fixed fraction removes
    only in part: on pool-hard_s1 a third of the keyframe stereo matches are more than 1 px off and
    18 % more than 10 px (``scripts/track_bias.py``), and every tracked rotation there is off by the
    same ~0.05 deg (``scripts/pnp_study.py``).  Every round tests *all* matches at the current pose
    (a match dropped while the pose was dragged may come back) and refits from it on those that pass,
    until the set stops changing.  Returns ``(R, t, median reprojection error px over all matches)``;
    the pose stays as it was when too few matches would remain or a step fails.
    """
    s2q = sigma2
    kept = np.ones(len(p), dtype=bool)
    for _ in range(CHI2_ROUNDS):
        try:
            keep = est.pnp6_whitened_sq(R, t, p, cov, q, s2q) <= CHI2_GATE
        except est.EstimatorError:
            break
        if np.array_equal(keep, kept) or keep.sum() < MIN_PNP_POINTS:
            break
        try:
            R2, t2 = _weighted_steps(R, t, p[keep], cov[keep], q[keep], cfg, sigma2)
        except est.EstimatorError:
            break
        if not _finite(R2, t2):
            break
        R, t, kept = R2, t2, keep
    if kept.all():
        return R, t, med
    return R, t, reprojection_median_px(R, t, p, q, f)
