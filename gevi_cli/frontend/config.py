"""Settings of the image front end (:class:`~gevi_cli.frontend.image_frontend.ImageFrontEnd`).

The defaults are the product defaults.  Pixels are pixels of the *rectified* images, depths metres.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class FrontendConfig:
    """Detection, tracking and stereo-matching parameters (units in each field's docstring)."""

    cell_px: int = 32
    """Grid cell side (px): at most one corner per cell, so features spread over the whole image."""

    quality: float = 0.01
    """Shi-Tomasi quality level: a corner needs a minimum eigenvalue >= quality * the reference score."""

    quality_percentile: float = 100.0
    """The reference score of ``quality``: this percentile of the grid cells' best scores (100 = the
    image's strongest corner)."""

    min_distance_px: float = 8
    """Minimum distance (px) between a new corner and any other corner, new or tracked."""

    shading_px: int = 0
    """Illumination shading removal before detection, LK and stereo: subtract a local mean over a
    square of this side (px; 0 = off, see :mod:`~gevi_cli.frontend.shading`).  For lamp-lit scenes."""

    lk_window: int = 21
    """Lucas-Kanade window side (px, odd), at every pyramid level."""

    lk_levels: int = 3
    """Pyramid levels above the base image (OpenCV ``maxLevel``): 3 -> images down to 1/8 size."""

    lk_iters: int = 30
    """Maximum Lucas-Kanade iterations per pyramid level."""

    lk_eps: float = 0.01
    """Lucas-Kanade convergence: stop when the update is below this (px, at the level's scale)."""

    derotate: bool = True
    """Remove the back end's predicted frame-to-frame rotation from the current image before LK
    (:mod:`~gevi_cli.frontend.derotate`): LK fits a translation, and rotating content biases it."""

    derotate_min_deg: float = 0.3
    """Smallest predicted rotation (degrees) worth the image warp: below it the warp's resampling moves
    the tracks more than the rotation would bias them, and gyro vibration at rest does not warp."""

    derotate_prior: str = "pose"
    """Where the rotation to remove comes from: "pose", the back end's (GeVI: the gyro's; CFO: the last
    step's, when at least half its matches passed the verification, else as "image"), or "image", a fit
    of the last step's tracks with an in-plane rotation plus a shift (for a downward camera over a
    floor, gevi_cli/configs/pool.yaml; wrong for a forward camera, where a turn's parallax reads as rotation)."""

    affine: bool = False
    """Re-align every frame's tracks to their patch in the keyframe's image with an affine warp where
    their neighbourhood stretched or sheared since the keyframe (:mod:`~gevi_cli.frontend.affine`).
    Opt-in: it helps renders of slanted planes, not the real KITTI frames, and costs ~4 ms per KITTI frame."""

    predict: bool = True
    """Start each feature's LK where the back end's motion prediction puts its keyframe point (constant
    velocity; GeVI's rotation from the gyro) instead of at its previous pixel, at its predicted patch
    scale (``lk_scale_step``)."""

    lk_scale_step: float = 1.15
    """Predicted features whose patch grows or shrinks by more than about half this factor between
    frames are tracked from a resized previous image, in groups of this scale step
    (:func:`~gevi_cli.frontend.klt.track_lk_scaled`)."""

    reacquire: bool = True
    """Find the keyframe's features again by ORB descriptors (:mod:`~gevi_cli.frontend.reacquire`)
    when a frame's pose cannot be found from its LK tracks (then retry before bridging the frame), and
    near their predicted pixels when LK kept fewer than ``keyframe.min_tracked`` of them (top-up)."""

    reacquire_features: int = 2000
    """ORB detections per image searched for the keyframe's features (the strongest by Harris score)."""

    reacquire_fast_threshold: int = 7
    """FAST threshold (grey levels) of those detections: low, so that the count, not the threshold,
    decides which corners are kept in a low-contrast image."""

    reacquire_radius_px: float = 40.0
    """Guided search: a feature with a predicted pixel matches only detections this close to it (px)."""

    reacquire_max_hamming: int = 64
    """Largest Hamming distance (of 256 bits) of a descriptor match."""

    reacquire_ratio: float = 0.8
    """Lowe's ratio test: the best match must be closer than this times the second best."""

    fb_max_px: float = 0.5
    """Forward-backward check: tracking back must land within this distance (px) of the start."""

    stereo_row_max_px: float = 1.5
    """Rectified stereo: a match must lie within this many pixels of the left feature's row."""

    stereo_refine: bool = True
    """Rectified stereo: refine each LK match by a 1-D LK along the left feature's row (level 0) and
    put the right pixel on that row (:func:`~gevi_cli.frontend.stereo.refine_on_row`)."""

    min_depth_m: float = 0.5
    """Nearest accepted stereo depth (m): disparity <= fx * baseline / min_depth_m."""

    max_depth_m: float = float("inf")
    """Farthest accepted stereo depth (m): disparity >= fx * baseline / max_depth_m.  Unbounded by
    default: the keyframe decides which far points it uses (``triangulation.*``)."""

    border_px: int = 8
    """No corner is detected closer than this to the image edge (px)."""

    def __post_init__(self):
        if self.cell_px < 1 or self.lk_window < 3 or self.lk_levels < 0 or self.lk_iters < 1:
            raise ValueError(f"invalid front-end config: {self}")
        if not 0.0 < self.quality_percentile <= 100.0 or self.shading_px < 0:
            raise ValueError(f"need 0 < quality_percentile <= 100 and shading_px >= 0, got "
                             f"{self.quality_percentile}, {self.shading_px}")
        if self.derotate_prior not in ("pose", "image"):
            raise ValueError(f"derotate_prior must be 'pose' or 'image', got {self.derotate_prior!r}")
        if self.derotate_min_deg < 0:
            raise ValueError(f"need derotate_min_deg >= 0, got {self.derotate_min_deg}")
        if not self.lk_scale_step > 1.0:
            raise ValueError(f"need lk_scale_step > 1 (a factor), got {self.lk_scale_step}")
        if (self.reacquire_features < 1 or self.reacquire_fast_threshold < 1 or not self.reacquire_radius_px > 0
                or not 0 <= self.reacquire_max_hamming <= 256 or not 0.0 < self.reacquire_ratio <= 1.0):
            raise ValueError("need reacquire_features >= 1, reacquire_fast_threshold >= 1, reacquire_radius_px > 0, "
                             f"0 <= reacquire_max_hamming <= 256, 0 < reacquire_ratio <= 1; got {self.reacquire_features}, "
                             f"{self.reacquire_fast_threshold}, {self.reacquire_radius_px}, {self.reacquire_max_hamming}, "
                             f"{self.reacquire_ratio}")
        if not 0.0 < self.min_depth_m < self.max_depth_m:
            raise ValueError(f"need 0 < min_depth_m < max_depth_m, got {self.min_depth_m}, {self.max_depth_m}")
