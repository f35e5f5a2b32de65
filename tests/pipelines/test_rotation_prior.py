"""The rotation prior the odometry hands its front end (rotation-compensated LK, method.md 12.1)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.geometry import exp_so3
from gevi_cli.observations import RectifiedStereo
from gevi_cli.pipelines.config import OdometryConfig
from gevi_cli.pipelines.odometry import KeyframeOdometry
from gevi_cli.pipelines.types import BRIDGED, OK, FrameResult


def _odometry(n_matches: int, n_inliers: int, status: str = OK) -> KeyframeOdometry:
    fe = SimpleNamespace(camera=RectifiedStereo(Intrinsics(752, 480, 450.0, 450.0, 376.0, 240.0), 0.1))
    odo = KeyframeOdometry(fe, OdometryConfig())
    R_pc = exp_so3(np.array([0.01, -0.02, 0.03]))  # pose of the current camera in the previous one
    odo.velocity = np.eye(4)
    odo.velocity[:3, :3] = R_pc
    odo._tail = (None, FrameResult(1, 1, np.eye(4), status=status, n_matches=n_matches, n_inliers=n_inliers))
    return odo


def test_prior_is_the_last_steps_rotation_in_previous_to_current_coordinates():
    odo = _odometry(100, 80)
    R_cp = odo.rotation_prior()
    # R_cp maps previous-camera coordinates into the current camera: the inverse of the pose's rotation
    assert np.allclose(R_cp @ odo.velocity[:3, :3], np.eye(3), atol=1e-12)


def test_no_prior_after_a_poorly_verified_or_bridged_step():
    assert _odometry(100, 49).rotation_prior() is None  # fewer than half the matches kept
    assert _odometry(100, 50).rotation_prior() is not None
    assert _odometry(100, 90, status=BRIDGED).rotation_prior() is None
    odo = _odometry(100, 90)
    odo._tail = None  # nothing tracked yet
    assert odo.rotation_prior() is None


def test_image_prior_config_leaves_the_prediction_to_the_front_end():
    odo = _odometry(100, 90)
    odo.cfg.frontend.derotate_prior = "image"  # gevi_cli/configs/pool.yaml
    assert odo.rotation_prior() is None


def test_gevi_takes_the_gyro_unless_the_config_says_image():
    from gevi_cli.pipelines.gevi import GEVI, FramePlan, GeviOdometry
    from gevi_cli.pipelines.inertial_state import FrameSample

    gevi = GeviOdometry.__new__(GeviOdometry)  # only what rotation_prior reads
    gevi.cfg = OdometryConfig()
    gevi.R_ic = exp_so3(np.array([0.3, -0.2, 1.0]))
    rv = np.array([0.002, -0.001, 0.02])
    sample = FrameSample(1, 0, None, np.zeros(3), rv, 0.05, np.zeros(2))
    gevi.plan, gevi.t_prev, gevi._tail = FramePlan(sample, GEVI), 0, None
    R_cp = gevi.rotation_prior()
    # the camera's rotation since the previous frame, previous -> current coordinates
    assert np.allclose(R_cp, (gevi.R_ic.T @ exp_so3(rv) @ gevi.R_ic).T, atol=1e-12)
    gevi.cfg.frontend.derotate_prior = "image"
    assert gevi.rotation_prior() is None
