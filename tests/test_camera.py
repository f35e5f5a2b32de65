"""The one intrinsics type (issue 37): pinhole maps and the lens, their inverses to float64 round-off."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from gevi_cli.camera import Intrinsics
from gevi_cli.observations import RectifiedStereo

EPS = np.finfo(np.float64).eps
RADTAN = Intrinsics(752, 480, 458.654, 457.296, 367.215, 248.375, "radtan", (-0.28, 0.07, 2e-4, 1.8e-5))


def _pixels(cam: Intrinsics, n: int = 500, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform([-0.5, -0.5], [cam.width - 0.5, cam.height - 0.5], size=(n, 2))


def test_normalize_and_pixels_are_inverse():
    cam = Intrinsics(1241, 376, 718.856, 718.856, 607.1928, 185.2157)
    uv = _pixels(cam)
    xy = cam.normalize(uv)
    np.testing.assert_array_equal(xy, (uv - [cam.cx, cam.cy]) / [cam.fx, cam.fy])
    # two roundings each way: a few ulp of the largest pixel coordinate
    np.testing.assert_allclose(cam.pixels(xy), uv, rtol=0, atol=4 * EPS * cam.width)
    np.testing.assert_allclose(cam.normalize(cam.pixels(xy)), xy, rtol=0, atol=8 * EPS * cam.width / cam.fx)
    assert cam.normalize([cam.cx, cam.cy]).tolist() == [[0.0, 0.0]]


def test_K_and_f():
    cam = Intrinsics(640, 480, 500, 498, 320, 240)
    assert isinstance(cam.fx, float) and isinstance(cam.width, int)
    np.testing.assert_array_equal(cam.K, [[500.0, 0, 320.0], [0, 498.0, 240.0], [0, 0, 1]])
    assert cam.f == pytest.approx(np.sqrt(500 * 498), rel=1e-15)
    assert cam.resolution == (640, 480)


def test_project_undistort_round_trip_radtan():
    """undistort_points inverts project (up to depth) to float64 round-off, over the whole image."""
    xy = RADTAN.undistort_points(_pixels(RADTAN))
    X = np.column_stack([xy, np.ones(len(xy))]) * np.linspace(0.5, 20, len(xy))[:, None]
    uv = RADTAN.project(X)
    np.testing.assert_allclose(RADTAN.undistort_points(uv), X[:, :2] / X[:, 2:], rtol=0, atol=1e-12)
    # the lens agrees with OpenCV's radtan model
    uv_cv = cv2.projectPoints(X, np.zeros(3), np.zeros(3), RADTAN.K, RADTAN.dist_coeffs)[0].reshape(-1, 2)
    np.testing.assert_allclose(uv, uv_cv, rtol=0, atol=1e-9)


def test_undistort_points_equidistant_is_opencv():
    cam = Intrinsics(848, 800, 284.468, 285.51, 424.355, 393.742, "equidistant", (0.0008, 0.031, -0.03, 0.005))
    rng = np.random.default_rng(1)
    X = np.column_stack([rng.uniform(-1, 1, (200, 2)), np.ones(200)])
    uv = cv2.fisheye.projectPoints(X.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist_coeffs)[0]
    np.testing.assert_allclose(cam.undistort_points(uv.reshape(-1, 2)), X[:, :2], rtol=0, atol=1e-6)
    with pytest.raises(NotImplementedError):
        cam.project(X)


def test_no_lens_is_the_pinhole():
    for cam in (Intrinsics(640, 480, 500, 498, 320, 240), Intrinsics(640, 480, 500, 498, 320, 240, "radtan", (0,) * 4)):
        assert not cam.has_distortion
        uv = _pixels(cam)
        np.testing.assert_array_equal(cam.undistort_points(uv), cam.normalize(uv))


def test_scaled_keeps_the_field_of_view():
    small = RADTAN.scaled(376, 240)
    assert (small.width, small.height, small.distortion) == (376, 240, RADTAN.distortion)
    corners = np.array([[-0.5, -0.5], [RADTAN.width - 0.5, RADTAN.height - 0.5]])
    np.testing.assert_allclose(small.normalize(corners / 2 - 0.25), RADTAN.normalize(corners), rtol=0, atol=1e-15)


def test_invalid_lens_is_refused():
    with pytest.raises(ValueError, match="not one of"):
        Intrinsics(10, 10, 5, 5, 5, 5, "fisheye")
    with pytest.raises(ValueError, match="4 coefficients"):
        Intrinsics(10, 10, 5, 5, 5, 5, "radtan", (0.1, 0.2))


def test_rectified_stereo_is_its_intrinsics_plus_the_baseline():
    cam = Intrinsics(752, 480, 450.0, 449.0, 376.0, 240.0)
    rig = RectifiedStereo(cam, 0.1)
    assert (rig.width, rig.height, rig.fx, rig.fy, rig.cx, rig.cy, rig.f) == (
        cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, cam.f)
    np.testing.assert_array_equal(rig.K, cam.K)
    uv = _pixels(cam)
    np.testing.assert_array_equal(rig.normalize(uv), cam.normalize(uv))
    np.testing.assert_array_equal(rig.t_rl, [-0.1, 0.0, 0.0])
    np.testing.assert_allclose(rig.depth_from_disparity([45.0, 0.0]), [1.0, np.inf])
    with pytest.raises(ValueError, match="no lens distortion"):
        RectifiedStereo(RADTAN, 0.1)
