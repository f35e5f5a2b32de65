"""Equidistant (fisheye) stereo: rectification exact on a synthetic rig, and on the real T265 pairs.

Kalibr ``pinhole-equi`` / OpenCV fisheye rigs (TUM-VI, RealSense T265) must rectify and run like
radtan ones.  The synthetic rig is T265-like (848x800, f 285 px, 6.4 cm baseline) with a small
rotation between the cameras, so the rectifying rotations are not trivial.
"""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets import open_sequence
from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.frontend.rectify import Rectifier
from gevi_cli.geometry import invert_pose
from support import shared_path


def _rig() -> StereoRig:
    rot = cv2.Rodrigues(np.array([0.004, -0.006, 0.003]))[0]
    T_C0_C1 = np.eye(4)
    T_C0_C1[:3, :3] = rot
    T_C0_C1[:3, 3] = [0.064, 0.001, -0.0005]
    cam0 = Intrinsics(848, 800, 284.468, 285.51, 424.355, 393.742, "equidistant", (0.0008, 0.031, -0.03, 0.005))
    cam1 = Intrinsics(848, 800, 283.999, 285.266, 417.246, 400.402, "equidistant", (-0.002, 0.039, -0.038, 0.007))
    return StereoRig(cam0, cam1, np.eye(4), T_C0_C1)


def _project(cam: Intrinsics, X_C: np.ndarray) -> np.ndarray:
    uv, _ = cv2.fisheye.projectPoints(X_C.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist_coeffs)
    return uv.reshape(-1, 2)


def _bilinear(m: np.ndarray, uv: np.ndarray) -> np.ndarray:
    return cv2.remap(m, uv[:, 0].astype(np.float32).reshape(-1, 1), uv[:, 1].astype(np.float32).reshape(-1, 1),
                     cv2.INTER_LINEAR).ravel()


def test_fisheye_rectification_puts_a_point_on_one_row_at_the_true_disparity():
    rig = _rig()
    rect = Rectifier(rig)
    cam = rect.camera
    r = rig.rectification
    # the rectified camera keeps the lens's focal (no 37 px OpenCV default) and the image centre
    assert cam.fx == pytest.approx(283.999) and (cam.cx, cam.cy) == (423.5, 399.5)
    assert cam.baseline == pytest.approx(rig.baseline, rel=1e-12)
    # points seen by both cameras, 1..10 m away, anywhere in the rectified field
    rng = np.random.default_rng(3)
    uv_rect = rng.uniform([20, 20], [cam.width - 20, cam.height - 20], size=(300, 2))
    Z = rng.uniform(1.0, 10.0, 300)
    X_C0r = np.column_stack([(uv_rect - [cam.cx, cam.cy]) / cam.fx * Z[:, None], Z])
    X_C0 = X_C0r @ r.R0  # X_C0 = R0^T X_C0r
    X_C1 = (invert_pose(rig.T_B_C1) @ rig.T_B_C0 @ np.column_stack([X_C0, np.ones(300)]).T).T[:, :3]
    raw0, raw1 = _project(rig.cam0, X_C0), _project(rig.cam1, X_C1)
    # the remap tables send each rectified pixel to the raw pixel where the lens imaged that ray
    u1 = uv_rect - np.column_stack([cam.fx * cam.baseline / Z, np.zeros(300)])
    got0 = np.column_stack([_bilinear(r.map0[0], uv_rect), _bilinear(r.map0[1], uv_rect)])
    got1 = np.column_stack([_bilinear(r.map1[0], u1), _bilinear(r.map1[1], u1)])
    # bilinear interpolation of the float maps over one pixel: curvature error well under 0.05 px
    assert np.abs(got0 - raw0).max() < 0.05
    assert np.abs(got1 - raw1).max() < 0.05
    # and back: raw pixels -> rectified pixels (the inverse the pipeline uses for raw observations)
    back0 = cv2.fisheye.undistortPoints(raw0.reshape(-1, 1, 2), rig.cam0.K, rig.cam0.dist_coeffs,
                                        R=r.R0, P=r.P0[:3, :3]).reshape(-1, 2)
    back1 = cv2.fisheye.undistortPoints(raw1.reshape(-1, 1, 2), rig.cam1.K, rig.cam1.dist_coeffs,
                                        R=r.R1, P=r.P1[:3, :3]).reshape(-1, 2)
    assert np.abs(back0 - uv_rect).max() < 1e-3
    assert np.abs(back1[:, 1] - uv_rect[:, 1]).max() < 1e-3  # same row
    np.testing.assert_allclose(back0[:, 0] - back1[:, 0], cam.fx * cam.baseline / Z, atol=1e-3)  # d = f b / Z
    # the rectifier's own rectified-pixel -> raw-ray inverse agrees with the lens model
    np.testing.assert_allclose(rect.rectified_to_raw_normalized(uv_rect), X_C0[:, :2] / X_C0[:, 2:3], atol=1e-9)
    np.testing.assert_allclose(rig.cam0.undistort_points(raw0), X_C0[:, :2] / X_C0[:, 2:3], atol=2e-5)


@pytest.fixture(scope="module")
def t265():
    bag = shared_path("real_bags", "kapture_t265_stereo_imu", "trimmed_locoffice.bag")
    seq = open_sequence(bag, topics="gt=none")  # its camchain lies next to it
    return seq, [seq.read_pair(i) for i in range(len(seq))]


def _row_offsets(rig, frames):
    rect = Rectifier(rig)
    assert not rect.passthrough and rect.camera.fx > 280
    dy_rect, dy_raw = [], []
    for f in frames:
        left, right = rect.rectify(f.left, f.right)
        # LK left -> right with a forward-backward check, no row gate (the gate is what is measured)
        p0 = cv2.goodFeaturesToTrack(left, 400, 0.01, 10)
        p1, st, _ = cv2.calcOpticalFlowPyrLK(left, right, p0, None, winSize=(21, 21), maxLevel=3)
        pb, sb, _ = cv2.calcOpticalFlowPyrLK(right, left, p1, None, winSize=(21, 21), maxLevel=3)
        ok = (st.ravel() == 1) & (sb.ravel() == 1) & (np.linalg.norm(pb - p0, axis=2).ravel() < 0.5)
        assert ok.sum() > 50
        dy_rect.append((p1 - p0).reshape(-1, 2)[ok, 1])
        p0 = cv2.goodFeaturesToTrack(f.left, 300, 0.01, 10)
        p1, st, _ = cv2.calcOpticalFlowPyrLK(f.left, f.right, p0, None, winSize=(21, 21), maxLevel=3)
        dy_raw.append((p1 - p0).reshape(-1, 2)[st.ravel() == 1, 1])
    return np.concatenate(dy_rect), np.concatenate(dy_raw)


def test_t265_fisheye_pairs_rectify_and_match_on_rows(t265):
    seq, frames = t265
    assert len(frames) == 3
    dy_rect, dy_raw = _row_offsets(seq.calibration, frames)
    # Raw fisheye rows disagree by ~8 px (the principal points differ by 6.7 px); rectified ones agree
    # up to one constant offset of ~1.8 px, the same on all three pairs: the camchain's extrinsic has no
    # rotation (kapture's rigs.txt gives none), and a 6 mrad pitch between the real T265 lenses is
    # exactly such an offset (1.8 px / 284 px).  What the rectification itself must get right, the
    # row agreement about that offset, is held to 0.5 px.
    assert np.median(np.abs(dy_raw)) > 5.0
    assert np.median(np.abs(dy_rect - np.median(dy_rect))) < 0.5
    assert np.median(np.abs(dy_rect)) < 2.5
    # The offset is the calibration's, not the rectification's: the same rig with the right lens pitched
    # by 6 mrad (and nothing else changed) puts the matches on their rows to a median of 0.5 px.
    T = seq.calibration.T_B_C1.copy()
    T[:3, :3] = T[:3, :3] @ cv2.Rodrigues(np.array([0.006, 0.0, 0.0]))[0]
    pitched = replace(seq.calibration, T_B_C1=T)
    dy_pitched, _ = _row_offsets(pitched, frames)
    assert np.median(np.abs(dy_pitched)) < 0.5
