"""Settings of the image front end (:class:`~gevi_cli.frontend.image_frontend.ImageFrontEnd`).

The defaults are the product defaults.  Pixels are pixels of the *rectified* images, depths metres.
Each setting's type and valid domain are declared here (see :mod:`gevi_cli.config`).
"""
from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import ConfigDict
from pydantic.dataclasses import dataclass

from gevi_cli.config import Applies, Bool, Float, Int, OddInt, setting

STRICT = ConfigDict(extra="forbid")


@dataclass(config=STRICT)
class FrontendConfig:
    """Detection, tracking and stereo-matching parameters (units in each setting's help)."""

    APPLIES: ClassVar[Applies] = Applies(inputs="images", why="a track export is its own front end")

    cell_px: Int = setting(32, "grid cell side (px): at most one corner per cell, so features spread over the "
                               "whole image", ge=1)
    quality: Float = setting(0.01, "Shi-Tomasi quality level: a corner needs a minimum eigenvalue >= quality x the "
                                   "reference score (quality_percentile)", gt=0)
    quality_percentile: Float = setting(100.0, "the reference score of quality: this percentile of the grid cells' "
                                               "best scores (100: the image's strongest corner)", gt=0, le=100)
    shading_px: Int = setting(0, "illumination shading removal before detection, LK and stereo: subtract a local "
                                 "mean over a square of this side (px; 0: off)", ge=0)
    lk_window: OddInt = setting(21, "Lucas-Kanade window side (px, odd), at every pyramid level", ge=3)
    derotate: Bool = setting(True, "remove the back end's predicted frame-to-frame rotation from the current image "
                                   "before LK (LK fits a translation, and rotating content biases it)")
    derotate_prior: Literal["pose", "image"] = setting(
        "pose", "where the rotation to remove comes from: 'pose' (the back end's: GeVI's gyro, CFO's last step) or "
                "'image' (an in-plane rotation + shift fitted to the last step's tracks; a downward camera)")
    affine: Bool = setting(False, "re-align every frame's tracks to their keyframe patch with an affine warp where "
                                  "their neighbourhood stretched or sheared (slanted planes)")
    predict: Bool = setting(True, "start each feature's LK where the back end's motion prediction puts its keyframe "
                                  "point, at its predicted patch scale, instead of at its previous pixel")
    reacquire: Bool = setting(True, "find the keyframe's features again by ORB descriptors when the LK tracks give no "
                                    "pose, and near their predicted pixels when LK kept fewer than keyframe.min_tracked")
    stereo_refine: Bool = setting(True, "rectified stereo: refine each LK match by a 1-D LK along the left feature's "
                                        "row and put the right pixel on that row")


# Fixed values of the front end (former settings, each at its former default; issue 46).  Pixels of the
# rectified images.
MIN_DISTANCE_PX = 8.0  # minimum distance (px) between a new corner and any other corner, new or tracked
BORDER_PX = 8  # no corner is detected closer than this to the image edge (px)
LK_LEVELS = 3  # pyramid levels above the base image (OpenCV maxLevel): images down to 1/8 size
LK_ITERS = 30  # maximum Lucas-Kanade iterations per pyramid level
LK_EPS = 0.01  # Lucas-Kanade convergence: stop when the update is below this (px, at the level's scale)
LK_SCALE_STEP = 1.15  # predicted features whose patch scales by more than half this are tracked from a resized image
DEROTATE_MIN_DEG = 0.3  # smallest rotation (deg) worth the derotation warp (below it resampling moves tracks more)
FB_MAX_PX = 0.5  # forward-backward check: tracking back must land within this distance (px) of the start
STEREO_ROW_MAX_PX = 1.5  # rectified stereo: a match must lie within this many pixels of the left feature's row
STEREO_MIN_DEPTH_M = 0.5  # nearest stereo depth (m) a match may have: disparity <= fx x baseline / this
STEREO_MAX_DEPTH_M = float("inf")  # no far cut on stereo matches: the keyframe's triangulation gate decides
REACQUIRE_FEATURES = 2000  # ORB detections per image searched for the keyframe's features
REACQUIRE_FAST_THRESHOLD = 7  # FAST threshold (grey levels) of those detections
REACQUIRE_RADIUS_PX = 40.0  # guided search: a feature matches only detections this close to its predicted pixel
REACQUIRE_MAX_HAMMING = 64  # largest Hamming distance (of 256 bits) of a descriptor match
REACQUIRE_RATIO = 0.8  # Lowe's ratio test: the best match must be closer than this times the second best
