"""Typed values a front end (the LK front end, a recorded track export) hands an odometry back end.

Pixels are in the **rectified** left/right images of the rig (see :class:`RectifiedStereo`);
feature ids are int64 and persistent: the same physical feature keeps its id from the keyframe where
it was detected to the last frame that tracks it, so a back end matches current observations to the
keyframe by id, whatever produced them (our LK front end or an exported track file).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.camera import Intrinsics


@dataclass(frozen=True)
class RectifiedStereo:
    """The rig as the pipelines see it: a rectified pinhole pair with the right camera at +b on x.

    ``intrinsics`` (no distortion, pixels) is shared by both rectified images; ``baseline`` in metres;
    ``T_B_C0`` (4x4) maps *rectified* cam0 coordinates into the body frame.  In spec notation the
    stereo extrinsic is ``X_R = R_rl X_L + t_rl`` with ``R_rl = I`` and ``t_rl = (-b, 0, 0)``.
    ``width``, ``height``, ``fx``, ``fy``, ``cx``, ``cy``, ``K``, ``f`` and :meth:`normalize` are the
    intrinsics' own.
    """

    intrinsics: Intrinsics
    baseline: float
    T_B_C0: np.ndarray = field(default_factory=lambda: np.eye(4), compare=False)

    def __post_init__(self):
        if self.intrinsics.has_distortion:
            raise ValueError("a rectified rig has no lens distortion")

    width = property(lambda self: self.intrinsics.width)
    height = property(lambda self: self.intrinsics.height)
    fx = property(lambda self: self.intrinsics.fx)
    fy = property(lambda self: self.intrinsics.fy)
    cx = property(lambda self: self.intrinsics.cx)
    cy = property(lambda self: self.intrinsics.cy)
    K = property(lambda self: self.intrinsics.K)
    f = property(lambda self: self.intrinsics.f)

    def normalize(self, uv: np.ndarray) -> np.ndarray:
        """Rectified pixels (n, 2) -> normalized coordinates (n, 2) (:meth:`Intrinsics.normalize`)."""
        return self.intrinsics.normalize(uv)

    @property
    def R_rl(self) -> np.ndarray:
        return np.eye(3)

    @property
    def t_rl(self) -> np.ndarray:
        """Left -> right translation (metres): ``(-b, 0, 0)``."""
        return np.array([-self.baseline, 0.0, 0.0])

    def depth_from_disparity(self, disparity_px: np.ndarray) -> np.ndarray:
        """Depth (metres, rectified cam0 z) of disparities in pixels: ``fx b / d``, inf where d <= 0."""
        d = np.asarray(disparity_px, dtype=np.float64)
        with np.errstate(divide="ignore"):
            return np.where(d > 0, self.fx * self.baseline / np.where(d > 0, d, 1.0), np.inf)


@dataclass(frozen=True)
class FeatureObs:
    """Features observed in one (rectified, left) image: ``ids`` (n,) int64, ``uv`` (n, 2) pixels."""

    ids: np.ndarray
    uv: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)

    @staticmethod
    def empty() -> "FeatureObs":
        return FeatureObs(np.empty(0, dtype=np.int64), np.empty((0, 2)))


@dataclass(frozen=True)
class Prediction:
    """The back end's prediction of some features in the frame about to be tracked: ``ids`` (n,),
    ``uv`` (n, 2) rectified-left pixels, ``scale`` (n,) how much larger their image patch appears than
    in the previous frame (depth in the previous frame over predicted depth: > 1 when approaching)."""

    ids: np.ndarray
    uv: np.ndarray
    scale: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)


@dataclass(frozen=True)
class StereoObs:
    """Keyframe stereo matches: ``ids`` (n,), ``uv_left``/``uv_right`` (n, 2) rectified pixels."""

    ids: np.ndarray
    uv_left: np.ndarray
    uv_right: np.ndarray

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def disparity(self) -> np.ndarray:
        return self.uv_left[:, 0] - self.uv_right[:, 0]
