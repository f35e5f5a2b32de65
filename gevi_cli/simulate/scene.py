"""Scene description: textured planar rectangles with mip-mapped textures.

World frame W: z up (gravity -z), metres.  A :class:`Plane` is the rectangle
``origin + u * axis_u + v * axis_v`` for ``0 <= u <= size_u``, ``0 <= v <= size_v`` (``inf`` for an
unbounded plane); its texture maps texture coordinates (u, v) in metres to brightness, texel (i, j) of
mip level 0 covering ``[i, i+1] * texel_u x [j, j+1] * texel_v`` (j is the row, along ``axis_v``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np


@dataclass(frozen=True)
class Texture:
    """A float32 brightness image with its mip pyramid.

    Attributes:
        levels: level 0 (full resolution) first; level L is ~2^-L the size (area-averaged).
        period_u, period_v: physical size in metres of the whole level-0 image along u (columns)
            and v (rows); texel sizes of level L are ``period / shape``.
        wrap: repeat the texture periodically (unbounded planes) instead of clamping at its border.
    """

    levels: tuple[np.ndarray, ...] = field(repr=False)
    period_u: float
    period_v: float
    wrap: bool = False

    @staticmethod
    def from_image(img: np.ndarray, texel_m: float, wrap: bool = False, min_size: int = 8) -> "Texture":
        img = np.ascontiguousarray(img, dtype=np.float32)
        levels = [img]
        while min(levels[-1].shape) >= 2 * min_size:
            h, w = levels[-1].shape
            levels.append(cv2.resize(levels[-1], ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA))
        h, w = img.shape
        return Texture(tuple(levels), w * texel_m, h * texel_m, wrap)

    @property
    def texel_m(self) -> float:
        return self.period_u / self.levels[0].shape[1]


@dataclass(frozen=True)
class Plane:
    """A textured rectangle (two-sided).

    Attributes:
        origin: (3,) world point with texture coordinates (0, 0) [m].
        axis_u, axis_v: (3,) orthonormal in-plane directions (world).
        size_u, size_v: extent along the axes [m] (``np.inf`` for unbounded).
        texture: the brightness texture (illumination baked in); gain: albedo multiplier.
    """

    origin: np.ndarray
    axis_u: np.ndarray
    axis_v: np.ndarray
    size_u: float
    size_v: float
    texture: Texture
    gain: float = 1.0
    name: str = ""

    @property
    def normal(self) -> np.ndarray:
        return np.cross(self.axis_u, self.axis_v)

    def corners(self) -> np.ndarray | None:
        """(4, 3) world corners, or None for an unbounded plane."""
        if not (np.isfinite(self.size_u) and np.isfinite(self.size_v)):
            return None
        o, u, v = np.asarray(self.origin, float), self.axis_u * self.size_u, self.axis_v * self.size_v
        return np.array([o, o + u, o + u + v, o + v])

    def point(self, u: float, v: float) -> np.ndarray:
        """World point at texture coordinates (u, v) metres."""
        return np.asarray(self.origin, float) + u * np.asarray(self.axis_u) + v * np.asarray(self.axis_v)


def rect_plane(origin, axis_u, axis_v, size_u, size_v, texture, **kw) -> Plane:
    """Plane with normalized float64 axes (axis_v is made exactly orthogonal to axis_u)."""
    u = np.asarray(axis_u, float)
    u = u / np.linalg.norm(u)
    v = np.asarray(axis_v, float)
    v = v - u * (u @ v)
    v = v / np.linalg.norm(v)
    return Plane(np.asarray(origin, float), u, v, float(size_u), float(size_v), texture, **kw)


@dataclass(frozen=True)
class Water:
    """Underwater image formation.

    ``I = J exp(-c r) + veil (1 - exp(-c r))`` for range r [m] along the ray (attenuation plus
    backscatter), then a range-dependent blur ``I + w (G_sigma * I - I)`` with
    ``w = blur_max (1 - exp(-r / blur_range))``, and an artificial-lamp cone ``cos(angle)^lamp_power``.
    """

    attenuation: float = 0.12
    veil: float = 0.35
    blur_sigma_px: float = 1.2
    blur_max: float = 0.8
    blur_range: float = 3.0
    lamp_power: float = 2.5


@dataclass(frozen=True)
class Scene:
    """Planes plus the background seen by rays that hit nothing.

    ``sky`` is the brightness at the horizon and ``sky_gradient`` its change per unit of the ray's
    world z component (brighter upwards when positive).  ``water`` enables underwater formation.
    """

    planes: tuple[Plane, ...]
    sky: float = 0.8
    sky_gradient: float = 0.15
    water: Water | None = None
    name: str = ""
