"""Estimators of GeVI-SLAM and Bias-Eliminated PnP as pure numpy functions.

See ``docs/method.md`` (the method as implemented) and ``docs/estimators_notes.md`` (choices made
where the spec left a gap, measured numbers). Conventions (spec section 1): normalized image
coordinates (n, 2); ``(R_ck, t_ck)`` maps keyframe-left coordinates into current-left
(``X_C = R_ck X_K + t_ck``, metres); stereo extrinsic ``X_R = R_rl X_L + t_rl``; the 4-DOF
rotation model is ``R_ck = L_c^T Rz(psi) L_k``; angles in radians.
"""

from gevi_cli.geometry import (
    exp_so3,
    levelling,
    log_so3,
    project,
    rot4,
    rot_x,
    rot_y,
    rot_z,
    rotation_error,
    rtilt,
    skew,
    tilt_angles,
    wrap_angle,
)

from .crlb import crlb4, crlb6, fisher6
from .errors import DegenerateInput, EstimatorError, NonFiniteInput, ShapeError, TooFewPoints
from .minimal3pt import (
    essential_upright,
    ransac_3pt_upright,
    ransac_iterations,
    sampson_distances,
    solve_3pt_upright,
)
from .noise import sigma2_onesided, sigma2_stereo, sigma2_symmetric
from .pnp4 import bias_terms, build_A, epipolar_residuals_jac, pnp4_be, pnp4_gn, pnp4_ls, row_vectors
from .pnp6 import (
    bearing_only,
    bias_matrix_G,
    build_H,
    depth_weights,
    pnp6_be,
    pnp6_l1,
    pnp6_ls,
    pnp6_refine,
    pnp6_whitened_sq,
    pnp_l1_filter,
    recover_pose,
)
from .triangulation import triangulate, triangulate_jacobian

__all__ = [
    "bearing_only",
    "EstimatorError",
    "DegenerateInput",
    "TooFewPoints",
    "NonFiniteInput",
    "ShapeError",
    "skew",
    "exp_so3",
    "log_so3",
    "rot_x",
    "rot_y",
    "rot_z",
    "rtilt",
    "tilt_angles",
    "levelling",
    "rot4",
    "project",
    "wrap_angle",
    "rotation_error",
    "sigma2_onesided",
    "sigma2_symmetric",
    "sigma2_stereo",
    "triangulate",
    "triangulate_jacobian",
    "build_H",
    "bias_matrix_G",
    "recover_pose",
    "pnp6_ls",
    "pnp6_be",
    "pnp6_refine",
    "pnp6_whitened_sq",
    "pnp6_l1",
    "pnp_l1_filter",
    "depth_weights",
    "row_vectors",
    "build_A",
    "bias_terms",
    "pnp4_ls",
    "pnp4_be",
    "epipolar_residuals_jac",
    "pnp4_gn",
    "solve_3pt_upright",
    "ransac_3pt_upright",
    "ransac_iterations",
    "essential_upright",
    "sampson_distances",
    "crlb4",
    "crlb6",
    "fisher6",
]

# spec 9 (preintegration, stereo-IMU initialisation) and spec 10 (epipolar local BA)
from .epipolar_ba import BAOptions, BAProblem, BAResult, BAWindow, ImageObs, epipolar_local_ba, poses_from_tracking
from .fusion import FusionState, FusionWindow, bcd_refine, propagate_tilts, sigma_step  # spec 8 (BCD)
from .initialization import (
    InitOptions,
    InitResult,
    camera_to_imu_poses,
    gravity_to_R_WV,
    init_gravity_velocity_accbias,
    init_gyro_bias,
    refine_gravity,
    stereo_imu_init,
)
from .preintegration import Preintegrated, imu_segment, preintegrate, preintegrate_batch

__all__ += [
    "Preintegrated",
    "preintegrate",
    "preintegrate_batch",
    "imu_segment",
    "InitOptions",
    "InitResult",
    "camera_to_imu_poses",
    "init_gyro_bias",
    "init_gravity_velocity_accbias",
    "refine_gravity",
    "gravity_to_R_WV",
    "stereo_imu_init",
    "ImageObs",
    "BAWindow",
    "BAOptions",
    "BAResult",
    "BAProblem",
    "epipolar_local_ba",
    "poses_from_tracking",
]

__all__ += ["FusionWindow", "FusionState", "bcd_refine", "propagate_tilts", "sigma_step"]  # spec 8
