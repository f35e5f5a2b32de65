"""Pinhole + radial-tangential camera model and the stereo rig of the simulator.

Camera frame (docs/method.md section 1): x right, y down, z forward (optical axis).  Pixel
coordinates: the centre of the top-left pixel is (0, 0); pixel (u, v) covers
[u - 0.5, u + 0.5] x [v - 0.5, v + 0.5].  Distortion is OpenCV's radial-tangential ("radtan",
EuRoC "radial-tangential") model with coefficients (k1, k2, p1, p2) applied to normalized
coordinates.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.geometry import invert_pose


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics of one camera.

    Attributes:
        width, height: image size in pixels.
        fx, fy, cx, cy: focal lengths and principal point in pixels.
        distortion: radtan coefficients (k1, k2, p1, p2); all zero for an ideal pinhole.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    distortion: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        object.__setattr__(self, "distortion", tuple(float(d) for d in self.distortion))

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def has_distortion(self) -> bool:
        return any(abs(c) > 0 for c in self.distortion)

    # ------------------------------------------------------------------ normalized <-> distorted
    def distort_normalized(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Apply radtan distortion to normalized coordinates (x, y) = (X/Z, Y/Z)."""
        k1, k2, p1, p2 = self.distortion
        r2 = x * x + y * y
        radial = 1.0 + k1 * r2 + k2 * r2 * r2
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        return xd, yd

    def undistort_normalized(self, xd: np.ndarray, yd: np.ndarray, iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
        """Invert :meth:`distort_normalized` by Newton's method (vectorized, float64).

        Converges to ~1e-15 for the mild distortions used here; the residual is checked.
        """
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

    # ------------------------------------------------------------------------------ projection
    def project(self, X_C: np.ndarray) -> np.ndarray:
        """Project (n, 3) camera-frame points to (n, 2) distorted pixel coordinates."""
        X_C = np.asarray(X_C, float).reshape(-1, 3)
        x, y = X_C[:, 0] / X_C[:, 2], X_C[:, 1] / X_C[:, 2]
        xd, yd = self.distort_normalized(x, y)
        return np.stack([self.fx * xd + self.cx, self.fy * yd + self.cy], axis=1)

    def pixel_rays(self, supersample: int = 1) -> np.ndarray:
        """Unit ray directions (camera frame) through sub-pixel sample centres.

        Returns (H*s, W*s, 3) float64 for ``s = supersample``; sample (r, c) lies at pixel coordinates
        ``u = (c + 0.5)/s - 0.5``, ``v = (r + 0.5)/s - 0.5``, so averaging s x s blocks gives a box
        filter centred on each pixel.
        """
        s = int(supersample)
        u = (np.arange(self.width * s) + 0.5) / s - 0.5
        v = (np.arange(self.height * s) + 0.5) / s - 0.5
        uu, vv = np.meshgrid(u, v)
        x, y = self.undistort_normalized((uu - self.cx) / self.fx, (vv - self.cy) / self.fy)
        rays = np.stack([x, y, np.ones_like(x)], axis=-1)
        return rays / np.linalg.norm(rays, axis=-1, keepdims=True)

    def scaled(self, width: int, height: int) -> "CameraModel":
        """The same horizontal field of view at another resolution.

        Focal lengths scale with ``width / self.width`` (pixels stay square); the principal point
        keeps its offset from the image centre, scaled the same way (a different aspect ratio crops
        or extends the image vertically).
        """
        s = width / self.width
        cx = (self.cx + 0.5 - self.width / 2.0) * s + width / 2.0 - 0.5
        cy = (self.cy + 0.5 - self.height / 2.0) * s + height / 2.0 - 0.5
        return CameraModel(int(width), int(height), self.fx * s, self.fy * s, cx, cy, self.distortion)


@dataclass(frozen=True)
class RenderRig:
    """Two cameras rigidly mounted on the body (= IMU) frame B.

    Attributes:
        cam0, cam1: intrinsics of the left and right camera.
        T_B_C0, T_B_C1: 4x4 camera -> body transforms (``X_B = T_B_C X_C``), as EuRoC's ``T_BS``.
    """

    cam0: CameraModel
    cam1: CameraModel
    T_B_C0: np.ndarray = field(repr=False)
    T_B_C1: np.ndarray = field(repr=False)

    @property
    def T_C1_C0(self) -> np.ndarray:
        """Left -> right camera transform (``X_C1 = T_C1_C0 X_C0``)."""
        return invert_pose(self.T_B_C1) @ self.T_B_C0

    @property
    def baseline_m(self) -> float:
        return float(np.linalg.norm(self.T_C1_C0[:3, 3]))

    def cameras(self):
        return [(self.cam0, self.T_B_C0), (self.cam1, self.T_B_C1)]

    def to_stereo_rig(self):
        """The same rig as the dataset layer's :class:`~gevi_cli.datasets.calibration.StereoRig`
        (what the readers will return for the written sequence)."""
        from gevi_cli.datasets.calibration import PinholeCamera, StereoRig

        def pinhole(cam: CameraModel, T_B_C: np.ndarray) -> PinholeCamera:
            model = "radtan" if cam.has_distortion else "none"
            return PinholeCamera(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, model,
                                 cam.distortion if cam.has_distortion else (), T_B_C)

        return StereoRig(pinhole(self.cam0, self.T_B_C0), pinhole(self.cam1, self.T_B_C1))
