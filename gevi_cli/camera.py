"""The one camera-intrinsics type of gevi: image size, pinhole ``K`` and lens distortion.

Everything that describes a camera's intrinsics uses :class:`Intrinsics`: the dataset readers'
calibration (:class:`~gevi_cli.datasets.calibration.StereoRig` holds one per camera beside the
camera's pose), the rectified rig the front end and pipelines see
(:class:`~gevi_cli.observations.RectifiedStereo` holds one with no distortion, beside the baseline)
and the simulator's cameras (the same StereoRig, with a radtan lens).

Frames and units: camera frame x right, y down, z forward (optical axis), metres.  *Normalized*
coordinates are ``(x, y) = (X/Z, Y/Z)`` (unitless); *pixels* ``(u, v)`` have the centre of the
top-left pixel at (0, 0), so pixel (u, v) covers [u - 0.5, u + 0.5] x [v - 0.5, v + 0.5].  The lens
maps ideal normalized coordinates to distorted ones, ``K`` maps those to pixels.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

DISTORTION_MODELS = ("radtan", "equidistant", "none")


@dataclass(frozen=True)
class Intrinsics:
    """One camera's intrinsics.

    Attributes:
        width, height: image size in pixels.
        fx, fy: focal lengths in pixels; cx, cy: principal point in pixels.
        distortion_model: "radtan" (OpenCV's radial-tangential, EuRoC "radial-tangential"),
            "equidistant" (OpenCV's fisheye) or "none".
        distortion: (k1, k2, p1, p2) for radtan, (k1, k2, k3, k4) for equidistant, usually () for none.
            All-zero radtan coefficients are an ideal pinhole (:attr:`has_distortion` is False).
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion_model: str = "none"
    distortion: tuple[float, ...] = ()

    def __post_init__(self):
        if self.distortion_model not in DISTORTION_MODELS:
            raise ValueError(f"distortion model {self.distortion_model!r} is not one of {DISTORTION_MODELS}")
        if self.distortion_model != "none" and len(self.distortion) != 4:
            raise ValueError(f"{self.distortion_model} distortion needs 4 coefficients, got {len(self.distortion)}")
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "distortion", tuple(float(d) for d in self.distortion))

    # ------------------------------------------------------------------------------ pinhole
    @property
    def K(self) -> np.ndarray:
        """3x3 camera matrix (pixels)."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def f(self) -> float:
        """One focal length (pixels) for converting pixel noise to normalized noise (spec 1: sqrt(fx fy))."""
        return float(np.sqrt(self.fx * self.fy))

    @property
    def resolution(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    def normalize(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (n, 2) -> normalized coordinates (n, 2) through ``K^-1`` alone (no lens: for an
        undistorted camera, e.g. the rectified rig; :meth:`undistort_points` also inverts the lens)."""
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        return np.column_stack([(uv[:, 0] - self.cx) / self.fx, (uv[:, 1] - self.cy) / self.fy])

    def pixels(self, xy: np.ndarray) -> np.ndarray:
        """Normalized (distorted) coordinates (n, 2) -> pixels (n, 2) through ``K``; inverse of :meth:`normalize`."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.column_stack([self.fx * xy[:, 0] + self.cx, self.fy * xy[:, 1] + self.cy])

    # --------------------------------------------------------------------------------- lens
    @property
    def dist_coeffs(self) -> np.ndarray:
        """The distortion coefficients as OpenCV takes them."""
        return np.array(self.distortion, dtype=np.float64)

    @property
    def has_distortion(self) -> bool:
        return self.distortion_model != "none" and any(abs(c) > 0 for c in self.distortion)

    def _radtan(self) -> None:
        if self.distortion_model == "equidistant":
            raise NotImplementedError("equidistant lenses are handled by OpenCV (undistort_points, rectification)")

    def distort_normalized(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ideal normalized coordinates (x, y) = (X/Z, Y/Z) -> distorted ones (radtan; identity for none)."""
        self._radtan()
        if self.distortion_model == "none":
            return np.asarray(x, float), np.asarray(y, float)
        k1, k2, p1, p2 = self.distortion
        r2 = x * x + y * y
        radial = 1.0 + k1 * r2 + k2 * r2 * r2
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return xd, yd

    def undistort_normalized(self, xd: np.ndarray, yd: np.ndarray, iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
        """Invert :meth:`distort_normalized` by Newton's method (vectorized, float64).

        Converges to ~1e-15 for the lenses used here; a residual above 1e-9 raises ValueError.
        """
        self._radtan()
        xd = np.asarray(xd, float)
        yd = np.asarray(yd, float)
        if not self.has_distortion:
            return xd.copy(), yd.copy()
        k1, k2, p1, p2 = self.distortion
        x, y = xd.copy(), yd.copy()
        for _ in range(iterations):
            fx_, fy_ = self.distort_normalized(x, y)
            ex, ey = fx_ - xd, fy_ - yd
            if max(np.abs(ex).max(initial=0.0), np.abs(ey).max(initial=0.0)) < 1e-15:
                break
            r2 = x * x + y * y
            radial = 1.0 + k1 * r2 + k2 * r2 * r2
            dradial = 2.0 * k1 + 4.0 * k2 * r2  # d(radial)/d(r2) * 2 ... times x or y below
            j11 = radial + x * dradial * x + 2.0 * p1 * y + 6.0 * p2 * x
            j12 = x * dradial * y + 2.0 * p1 * x + 2.0 * p2 * y
            j21 = y * dradial * x + 2.0 * p1 * x + 2.0 * p2 * y
            j22 = radial + y * dradial * y + 6.0 * p1 * y + 2.0 * p2 * x
            det = j11 * j22 - j12 * j21
            x = x - (j22 * ex - j12 * ey) / det
            y = y - (-j21 * ex + j11 * ey) / det
        fx_, fy_ = self.distort_normalized(x, y)
        if np.max(np.abs(fx_ - xd)) > 1e-9 or np.max(np.abs(fy_ - yd)) > 1e-9:
            raise ValueError("radtan undistortion did not converge; distortion too strong for the field of view")
        return x, y

    # ------------------------------------------------------------------- camera frame <-> pixels
    def project(self, X_C: np.ndarray) -> np.ndarray:
        """Camera-frame points (n, 3), metres -> (n, 2) pixels, lens distortion included."""
        X_C = np.asarray(X_C, float).reshape(-1, 3)
        xd, yd = self.distort_normalized(X_C[:, 0] / X_C[:, 2], X_C[:, 1] / X_C[:, 2])
        return self.pixels(np.column_stack([xd, yd]))

    def undistort_points(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (n, 2) -> ideal normalized coordinates (n, 2): the inverse of :meth:`project` up to depth."""
        if self.distortion_model == "equidistant":
            import cv2

            uv = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
            return cv2.fisheye.undistortPoints(uv, self.K, self.dist_coeffs).reshape(-1, 2)
        x, y = self.undistort_normalized(*self.normalize(uv).T)
        return np.column_stack([x, y])

    # ------------------------------------------------------------------------------ resolution
    def scaled(self, width: int, height: int) -> "Intrinsics":
        """The same horizontal field of view at another resolution (same lens).

        Focal lengths scale with ``width / self.width`` (pixels stay square); the principal point
        keeps its offset from the image centre, scaled the same way (a different aspect ratio crops
        or extends the image vertically).
        """
        s = width / self.width
        cx = (self.cx + 0.5 - self.width / 2.0) * s + width / 2.0 - 0.5
        cy = (self.cy + 0.5 - self.height / 2.0) * s + height / 2.0 - 0.5
        return replace(self, width=int(width), height=int(height), fx=self.fx * s, fy=self.fy * s, cx=cx, cy=cy)
