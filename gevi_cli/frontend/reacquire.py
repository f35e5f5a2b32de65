"""Re-acquisition: the last keyframe's features found again in a frame by ORB descriptors (OpenCV).

LK follows a feature from frame to frame by its patch; when the motion between frames is large
(a fast car, a low frame rate) the patch changes scale and LK loses it or lands on a look-alike.
Then the features are re-matched against the *keyframe*: ORB descriptors of the keyframe's features
(computed on the keyframe's rectified left image, at the features' own pixels) against ORB features
detected in the current image over a scale pyramid, so a feature that grew by 1.5x as the camera
approached still matches.  The descriptors are upright (no orientation): the keyframe's features
have none of their own, and between a keyframe and the frames after it the image rotates little
(what it does rotate, the rotation-compensated LK handles).  Where the back end predicts a pixel for a feature, the search is limited
to a disc around it (guided matching, as ORB-SLAM's motion-model search); without a prediction the
whole image is searched and Lowe's ratio test keeps the unambiguous matches.

Pixels are rectified-left pixels; descriptor distances are Hamming distances (bits of 256).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from gevi_cli.frontend.config import (
    REACQUIRE_FAST_THRESHOLD,
    REACQUIRE_FEATURES,
    REACQUIRE_MAX_HAMMING,
    REACQUIRE_RADIUS_PX,
    REACQUIRE_RATIO,
    FrontendConfig,
)
from gevi_cli.observations import Prediction

_PATCH = 31.0  # ORB's patch size (px at level 0): the keypoint size of a level-0 descriptor


@dataclass(frozen=True)
class KeyframePatches:
    """ORB descriptors of a keyframe's features: ``ids`` (n,), ``uv`` (n, 2) keyframe pixels, ``desc`` (n, 32) uint8."""

    ids: np.ndarray
    uv: np.ndarray
    desc: np.ndarray


def _orb(cfg: FrontendConfig, n_features: int) -> cv2.ORB:
    # FAST threshold low, the count capped: ORB keeps the n strongest (Harris score) corners, so the
    # threshold that counts follows the image's own contrast instead of a fixed grey-level step
    return cv2.ORB_create(nfeatures=int(n_features), scaleFactor=1.2, nlevels=8, edgeThreshold=19,
                          patchSize=int(_PATCH), fastThreshold=int(REACQUIRE_FAST_THRESHOLD))


def describe(image: np.ndarray, ids: np.ndarray, uv: np.ndarray, cfg: FrontendConfig) -> KeyframePatches:
    """ORB descriptors of the features ``ids`` at pixels ``uv`` (n, 2) of ``image`` (uint8); the
    features too close to the border for a descriptor are left out."""
    kps = [cv2.KeyPoint(float(u), float(v), _PATCH, 0.0, 0.0, 0, i) for i, (u, v) in enumerate(uv)]
    kps, desc = _orb(cfg, max(len(kps), 1)).compute(image, kps)
    if desc is None or not kps:
        return KeyframePatches(np.empty(0, np.int64), np.empty((0, 2)), np.empty((0, 32), np.uint8))
    idx = np.array([k.class_id for k in kps], dtype=np.int64)
    return KeyframePatches(np.asarray(ids, np.int64)[idx], np.asarray(uv, np.float64)[idx], desc)


def match(kf: KeyframePatches, image: np.ndarray, cfg: FrontendConfig,
          predicted: Prediction | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The keyframe's features found in ``image``: (ids (m,), pixels (m, 2), scales (m,)), a scale
    being the size of the matched detection over the keyframe descriptor's (the ORB pyramid level's
    scale: how much larger the feature appears than in the keyframe).  The pixels are those of ORB's
    detections (FAST corners, ~1 px from the keyframe feature's own corner): a coarse position.

    ``predicted``: features' predicted pixels in ``image`` (ids and (k, 2) pixels); such a feature is matched only to a
    detection within ``REACQUIRE_RADIUS_PX`` of it.  A match needs a Hamming distance of at most
    ``REACQUIRE_MAX_HAMMING``, and, among the candidates it was allowed, the best distance below
    ``REACQUIRE_RATIO`` times the second best; a detection claimed by two features goes to neither."""
    empty = (np.empty(0, np.int64), np.empty((0, 2)), np.empty(0))
    if len(kf.ids) == 0:
        return empty
    orb = _orb(cfg, REACQUIRE_FEATURES)
    kps = orb.detect(image, None)
    for k in kps:
        k.angle = 0.0  # upright, as the keyframe's descriptors
    kps, desc = orb.compute(image, kps)
    if desc is None or len(kps) < 2:
        return empty
    pts = np.array([k.pt for k in kps], dtype=np.float64)
    sizes = np.array([k.size for k in kps], dtype=np.float64) / _PATCH
    mask = None
    if predicted is not None and len(predicted):
        # guided: a feature with a predicted pixel may only match detections within the radius
        mask = np.ones((len(kf.ids), len(pts)), np.uint8)
        _, rows, j = np.intersect1d(kf.ids, predicted.ids, assume_unique=True, return_indices=True)
        d2 = ((predicted.uv[j, None, :] - pts[None, :, :]) ** 2).sum(2)
        mask[rows] = d2 <= float(REACQUIRE_RADIUS_PX) ** 2
    knn = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(kf.desc, desc, k=2, mask=mask)
    n = len(kf.ids)
    best, second = np.full(n, np.inf), np.full(n, np.inf)
    col = np.full(n, -1, np.int64)
    for cands in knn:  # one list per keyframe feature (empty where the mask allows none)
        if cands:
            best[cands[0].queryIdx] = cands[0].distance
            col[cands[0].queryIdx] = cands[0].trainIdx
            if len(cands) > 1:
                second[cands[0].queryIdx] = cands[1].distance
    ok = (col >= 0) & (best <= REACQUIRE_MAX_HAMMING) & (best < REACQUIRE_RATIO * second)
    # one detection, one feature
    taken, counts = np.unique(col[ok], return_counts=True)
    ok &= ~np.isin(col, taken[counts > 1])
    return kf.ids[ok], pts[col[ok]], sizes[col[ok]]
