"""Settings of the image front end (:class:`~gevi_cli.frontend.image_frontend.ImageFrontEnd`).

The defaults are the product defaults.  Pixels are pixels of the *rectified* images, depths metres.
Each setting's type and valid domain are declared here (see :mod:`gevi_cli.config`).
"""
from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import ConfigDict, model_validator
from pydantic.dataclasses import dataclass

from gevi_cli.config import Applies, Bool, Float, Int, OddInt, ordered, setting

STRICT = ConfigDict(extra="forbid")


@dataclass(config=STRICT)
class FrontendConfig:
    """Detection, tracking and stereo-matching parameters (units in each setting's help)."""

    APPLIES: ClassVar[Applies] = Applies(inputs="images", why="a track export is its own front end")
    ORDERED: ClassVar[tuple] = (("min_depth_m", "max_depth_m", True),)

    cell_px: Int = setting(32, "grid cell side (px): at most one corner per cell, so features spread over the "
                               "whole image", ge=1)
    quality: Float = setting(0.01, "Shi-Tomasi quality level: a corner needs a minimum eigenvalue >= quality x the "
                                   "reference score (quality_percentile)", gt=0)
    quality_percentile: Float = setting(100.0, "the reference score of quality: this percentile of the grid cells' "
                                               "best scores (100: the image's strongest corner)", gt=0, le=100)
    min_distance_px: Float = setting(8, "minimum distance (px) between a new corner and any other corner, new or "
                                        "tracked", ge=0)
    shading_px: Int = setting(0, "illumination shading removal before detection, LK and stereo: subtract a local "
                                 "mean over a square of this side (px; 0: off; lamp-lit scenes)", ge=0)
    lk_window: OddInt = setting(21, "Lucas-Kanade window side (px, odd), at every pyramid level", ge=3)
    lk_levels: Int = setting(3, "pyramid levels above the base image (OpenCV maxLevel): 3 -> images down to 1/8 "
                                "size", ge=0)
    lk_iters: Int = setting(30, "maximum Lucas-Kanade iterations per pyramid level", ge=1)
    lk_eps: Float = setting(0.01, "Lucas-Kanade convergence: stop when the update is below this (px, at the "
                                  "level's scale)", gt=0)
    derotate: Bool = setting(True, "remove the back end's predicted frame-to-frame rotation from the current image "
                                   "before LK (LK fits a translation, and rotating content biases it)")
    derotate_min_deg: Float = setting(0.3, "smallest predicted rotation (deg) worth the image warp (below it the "
                                           "warp's resampling moves the tracks more than the rotation would)", ge=0)
    derotate_prior: Literal["pose", "image"] = setting(
        "pose", "where the rotation to remove comes from: 'pose' (the back end's: GeVI's gyro, CFO's last step) or "
                "'image' (an in-plane rotation + shift fitted to the last step's tracks; a downward camera)")
    affine: Bool = setting(False, "re-align every frame's tracks to their keyframe patch with an affine warp where "
                                  "their neighbourhood stretched or sheared (slanted planes; ~4 ms per KITTI frame)")
    predict: Bool = setting(True, "start each feature's LK where the back end's motion prediction puts its keyframe "
                                  "point, at its predicted patch scale, instead of at its previous pixel")
    lk_scale_step: Float = setting(1.15, "predicted features whose patch scales by more than about half this factor "
                                         "are tracked from a resized previous image, in groups of this scale step",
                                   gt=1)
    reacquire: Bool = setting(True, "find the keyframe's features again by ORB descriptors when the LK tracks give no "
                                    "pose, and near their predicted pixels when LK kept fewer than keyframe.min_tracked")
    reacquire_features: Int = setting(2000, "ORB detections per image searched for the keyframe's features", ge=1)
    reacquire_fast_threshold: Int = setting(7, "FAST threshold (grey levels) of those detections", ge=1, le=255)
    reacquire_radius_px: Float = setting(40.0, "guided search: a feature matches only detections this close to its "
                                               "predicted pixel (px)", gt=0)
    reacquire_max_hamming: Int = setting(64, "largest Hamming distance (of 256 bits) of a descriptor match", ge=0,
                                         le=256)
    reacquire_ratio: Float = setting(0.8, "Lowe's ratio test: the best match must be closer than this times the "
                                          "second best", gt=0, le=1)
    fb_max_px: Float = setting(0.5, "forward-backward check: tracking back must land within this distance (px) of "
                                    "the start", gt=0)
    stereo_row_max_px: Float = setting(1.5, "rectified stereo: a match must lie within this many pixels of the left "
                                            "feature's row", gt=0)
    stereo_refine: Bool = setting(True, "rectified stereo: refine each LK match by a 1-D LK along the left feature's "
                                        "row and put the right pixel on that row")
    min_depth_m: Float = setting(0.5, "nearest accepted stereo depth (m): disparity <= fx x baseline / min_depth_m",
                                 gt=0)
    max_depth_m: Float = setting(float("inf"), "farthest accepted stereo depth (m; inf: unbounded, the keyframe "
                                               "decides which far points it uses, triangulation.*)", gt=0, inf=True)
    border_px: Int = setting(8, "no corner is detected closer than this to the image edge (px)", ge=0)

    _order = model_validator(mode="after")(ordered)
