"""The renderer's geometry is exact: rendered checkerboard corners sit on the pinhole(+radtan) projection."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from gevi_cli.camera import Intrinsics
from gevi_cli.geometry import make_T, small_rotation
from gevi_cli.simulate import textures as tx
from gevi_cli.simulate.camera import pixel_rays
from gevi_cli.simulate.render import CameraRenderer, SensorModel
from gevi_cli.simulate.scene import Scene, Texture, rect_plane

ROWS, COLS, SQ_PX, TEXEL = 7, 9, 60, 0.001  # 6 cm squares
BASELINE = 0.2
CAM = Intrinsics(640, 480, 500.0, 499.0, 322.3, 238.1, "radtan", (-0.15, 0.03, 2e-4, -1e-4))
NOISE_FREE = SensorModel(vignetting=0.0, noise=False)


def _board_scene(T_W_board: np.ndarray) -> tuple[Scene, np.ndarray]:
    """A checkerboard plane (texture u = board x, v = board y) in front of a grey wall."""
    img = tx.checkerboard(ROWS, COLS, SQ_PX, margin_squares=1)
    tex = Texture.from_image(img, TEXEL)
    R, o = T_W_board[:3, :3], T_W_board[:3, 3]
    board = rect_plane(o, R[:, 0], R[:, 1], tex.period_u, tex.period_v, tex)
    wall_tex = Texture.from_image(np.full((16, 16), 0.5, np.float32), 1.0)
    wall = rect_plane([-10, -10, 5.0], [1, 0, 0], [0, 1, 0], 20, 20, wall_tex)
    # inner corners: (margin + i) squares along u and v
    ii, jj = np.meshgrid(np.arange(1, COLS), np.arange(1, ROWS))
    uv = np.stack([(ii.ravel() + 1) * SQ_PX * TEXEL, (jj.ravel() + 1) * SQ_PX * TEXEL], axis=1)
    corners_W = np.array([board.point(u, v) for u, v in uv])
    return Scene((board, wall), sky=0.5, sky_gradient=0.0), corners_W


def _detect(img: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Sub-pixel corners near the predicted positions (cornerSubPix refines each one).

    cornerSubPix has a "pixel-locking" bias of up to ~0.1 px on very sharp, pixel-integrated corners
    (the renderer itself is exact: see test_edges_are_exact); a symmetric Gaussian pre-blur does not
    move a corner and removes most of that detector bias.
    """
    pts = predicted.astype(np.float32).reshape(-1, 1, 2).copy()
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-5)
    smooth = cv2.GaussianBlur(img.astype(np.float32), (0, 0), 1.5)
    cv2.cornerSubPix(smooth, pts, (6, 6), (-1, -1), crit)
    return pts.reshape(-1, 2).astype(np.float64)


def _check_found(img, predicted):
    ok, found = cv2.findChessboardCorners(img, (COLS - 1, ROWS - 1))
    assert ok, "the rendered board is not detected"
    # every detected corner matches a predicted one to within a pixel (ordering may differ)
    d = np.linalg.norm(found.reshape(-1, 1, 2) - predicted.reshape(1, -1, 2), axis=2).min(axis=1)
    assert d.max() < 1.0


POSES = {
    # board 1.5 m in front of the camera, centred, slightly tilted
    "centre": (small_rotation(8.0, -10.0, 5.0), np.array([-0.27, -0.21, 1.5])),
    # off-centre (strong distortion region), tilted the other way
    "corner": (small_rotation(-12.0, 15.0, -20.0), np.array([0.15, 0.12, 1.5])),
}


@pytest.mark.parametrize("pose", sorted(POSES))
def test_corners_on_projection_and_stereo_triangulation(pose):
    R, t = POSES[pose]
    T_C0_board = make_T(R, t)
    T_W_C0 = make_T(small_rotation(3.0, -2.0, 40.0), [0.3, -0.2, 0.1])  # arbitrary camera pose
    scene, corners_W = _board_scene(T_W_C0 @ T_C0_board)
    T_W_C1 = T_W_C0 @ make_T(np.eye(3), [BASELINE, 0, 0])
    renderer = CameraRenderer(CAM, supersample=2)
    X_C0 = (corners_W - T_W_C0[:3, 3]) @ T_W_C0[:3, :3]
    X_C1 = (corners_W - T_W_C1[:3, 3]) @ T_W_C1[:3, :3]
    uv0, uv1 = CAM.project(X_C0), CAM.project(X_C1)
    img0 = renderer.render(scene, T_W_C0, NOISE_FREE, None)
    img1 = renderer.render(scene, T_W_C1, NOISE_FREE, None)
    _check_found(img0, uv0)
    _check_found(img1, uv1)
    d0, d1 = _detect(img0, uv0), _detect(img1, uv1)
    err0 = np.linalg.norm(d0 - uv0, axis=1)
    err1 = np.linalg.norm(d1 - uv1, axis=1)
    print(f"{pose}: corner error left max {err0.max():.4f} px (mean {err0.mean():.4f}), "
          f"right max {err1.max():.4f} px")
    assert err0.max() < 0.1 and err1.max() < 0.1

    # stereo triangulation with the known rig (undistort, then linear triangulation)
    x0, x1 = CAM.undistort_points(d0), CAM.undistort_points(d1)
    P0 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P1 = np.hstack([np.eye(3), np.array([[-BASELINE], [0.0], [0.0]])])
    Xh = cv2.triangulatePoints(P0, P1, x0.T, x1.T)
    X = (Xh[:3] / Xh[3]).T
    err3 = np.linalg.norm(X - X_C0, axis=1)
    print(f"{pose}: triangulation error max {err3.max() * 1e3:.3f} mm at range {np.linalg.norm(X_C0, axis=1).mean():.2f} m")
    assert err3.max() < 1e-3


def test_rays_reproject_to_their_pixels():
    rays = pixel_rays(CAM, 2).reshape(-1, 3)
    uv = CAM.project(rays)
    s = 2
    u = (np.arange(CAM.width * s) + 0.5) / s - 0.5
    v = (np.arange(CAM.height * s) + 0.5) / s - 0.5
    uu, vv = np.meshgrid(u, v)
    assert np.abs(uv[:, 0] - uu.ravel()).max() < 1e-9
    assert np.abs(uv[:, 1] - vv.ravel()).max() < 1e-9


def test_depth_is_exact_for_a_fronto_parallel_plane():
    """The ray-cast range equals the analytic distance to the plane for every pixel."""
    cam = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    tex = Texture.from_image(np.full((8, 8), 0.5, np.float32), 1.0)
    plane = rect_plane([-50, -50, 2.0], [1, 0, 0], [0, 1, 0], 100, 100, tex)
    r = CameraRenderer(cam, supersample=1)
    _, rng_m = r.radiance(Scene((plane,), water=__import__("gevi_cli.simulate.scene", fromlist=["Water"]).Water(blur_max=0.1)), np.eye(4))
    rays = pixel_rays(cam, 1)
    np.testing.assert_allclose(rng_m, 2.0 / rays[..., 2], rtol=1e-6)


@pytest.mark.parametrize("texel_count", [100, 101])
@pytest.mark.parametrize("depth", [0.3, 1.0, 2.0])
def test_edges_are_exact(texel_count, depth):
    """The gradient centroid of a rendered step edge (exact for pixel-integrated edges) is the projection."""
    cam = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    img = np.zeros((40, texel_count), np.float32)
    img[:, texel_count // 2:] = 1.0
    tex = Texture.from_image(img, 0.01)
    x0 = -tex.period_u / 2 + 0.0123
    plane = rect_plane([x0, -0.2, depth], [1, 0, 0], [0, 1, 0], tex.period_u, tex.period_v, tex)
    im, _ = CameraRenderer(cam, 8).radiance(Scene((plane,), sky=0.0, sky_gradient=0.0), np.eye(4))
    expected = cam.fx * (x0 + (texel_count // 2) * 0.01) / depth + cam.cx
    i0 = int(expected) - 6
    g = np.diff(im[24, i0:i0 + 14].astype(np.float64))
    found = i0 + 0.5 + np.sum(np.arange(len(g)) * g) / g.sum()
    assert abs(found - expected) < 0.005
