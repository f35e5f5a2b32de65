"""Per-stage configuration of the odometry pipelines (defaults are the product; see gevi_cli.config).

Units: pixels (px) in the rectified images, metres (m), seconds (s).  ``gevi run --dump-config``
lists every key with its type, default and valid domain; ``gevi_cli/configs/<kind>.yaml`` overrides
them per dataset kind.  Each setting's type and domain are declared here, once (see :mod:`gevi_cli.config`):
ordered pairs in a stage's ``ORDERED``, what applies to one method or input only in ``APPLIES`` /
``applies=``.
"""
from __future__ import annotations

from typing import Annotated, ClassVar, Literal, Optional, get_args

from pydantic import BeforeValidator, model_validator
from pydantic.dataclasses import dataclass

from gevi_cli.config import Applies, Bool, Float, Int, integer_choice, ordered, setting, stage
from gevi_cli.frontend.config import STRICT, FrontendConfig

PnPMethod = Literal["be-w", "be", "ls", "epnp", "sqpnp"]
RansacMethod = Literal["5pt", "3pt", "none"]
L1Method = Literal["lp", "irls", "none"]
NoiseMethod = Literal["symmetric", "onesided", "stereo"]
PNP_METHODS = get_args(PnPMethod)
RANSAC_METHODS = get_args(RansacMethod)
L1_METHODS = get_args(L1Method)
NOISE_METHODS = get_args(NoiseMethod)
METHODS = ("gevi", "cfo")

#: GeVI's stereo-inertial stages: nothing in them is read by CFO (stereo only)
GEVI_ONLY = "GeVI only: {} of the stereo-inertial odometry"
#: the verification each method can run: the upright 3-point RANSAC needs the IMU's roll/pitch (GeVI only)
RANSAC_APPLIES = Applies(values={"cfo": ("5pt", "none")}, why="3pt is GeVI's upright RANSAC, it needs the IMU's "
                                                              "roll/pitch; cfo verifies with 5pt or none")
GEVI_ONLY_3PT = Applies(methods=("gevi",), why="the threshold of GeVI's 3-point RANSAC")
TRACKS_ONLY = Applies(inputs="tracks", why="the outlier flags of a track export")


@dataclass(config=STRICT)
class VerifyConfig:
    """Two-stage verification of keyframe<->current matches (spec 12.1 / 5.5)."""

    ransac: RansacMethod = setting("5pt", "first stage: '5pt' (OpenCV 5-point essential-matrix RANSAC), '3pt' (GeVI: upright "
                             "3-point RANSAC with the IMU roll/pitch, spec 7) or 'none'", applies=RANSAC_APPLIES)
    ransac_threshold_px: Float = setting(1.0, "RANSAC inlier threshold (Sampson distance, px); 3pt: the larger of this "
                                          "and threshold_sigmas x the noise std", gt=0)
    threshold_sigmas: Float = setting(3.0, "3pt: inlier threshold in noise std (spec 7 [PROPOSAL] 3 sigma)", gt=0, applies=GEVI_ONLY_3PT)
    ransac_prob: Float = setting(0.999, "RANSAC confidence", gt=0, lt=1)
    min_parallax_px: Float = setting(0.5, "below this median KF->current displacement the essential matrix "
                                      "is undefined (no translation): the 5-point stage is skipped", ge=0)
    l1: L1Method = setting("irls", "second stage: l1-PnP drop of the worst fraction: 'irls' (exact l1 by IRLS + simplex polish, "
                          "same keep-mask as the LP), 'lp' (HiGHS), 'none'")
    l1_drop: Float = setting(0.10, "fraction of largest l1-PnP reprojection errors dropped", ge=0, lt=1)
    use_export_flags: Bool = setting(False, "track exports only: drop the exporter's own outlier flags first", applies=TRACKS_ONLY)


@dataclass(config=STRICT)
class TriangulationConfig:
    """Keyframe stereo triangulation with covariance (spec 4)."""

    ORDERED: ClassVar[tuple] = (("min_depth_m", "max_depth_m", True),)

    min_depth_m: Float = setting(0.5, "points nearer than this are not used (m)", gt=0)
    max_depth_m: Float = setting(100.0, "points farther than this are not used (m)", gt=0, inf=True)
    min_disparity_px: Float = setting(0.0, "points with less stereo disparity than this are not used (px): a depth cap the "
                                       "same for every baseline", ge=0)
    fill_points: Int = setting(100, "a keyframe with fewer points inside the far gate (max_depth_m, min_disparity_px) "
                                "keeps the points beyond it too (0: never)", ge=0)
    min_points: Int = setting(20, "a keyframe with fewer triangulated points cannot be tracked against", ge=1)
    self_calibrate: Bool = setting(True, "estimate the stereo pair's disparity offset from the tracked frames' two-view "
                                     "geometry and add it to the keyframes' disparities")

    _order = model_validator(mode="after")(ordered)


@dataclass(config=STRICT)
class NoiseConfig:
    """Image-noise variance from the data (spec 3)."""

    ORDERED: ClassVar[tuple] = (("min_px", "max_px", True),)

    method: NoiseMethod = setting("symmetric", "'symmetric' (GEP with both views noisy), 'onesided' (paper model), "
                                   "'stereo' (keyframe stereo epipolar residuals)")
    min_px: Float = setting(0.05, "clamp of the estimated std (px): below, the estimate is degenerate", gt=0)
    max_px: Float = setting(5.0, "clamp of the estimated std (px)", gt=0)
    default_px: Float = setting(0.5, "std used until a first valid estimate exists (px)", gt=0)

    _order = model_validator(mode="after")(ordered)


@dataclass(config=STRICT)
class PnPConfig:
    """Keyframe -> current pose (spec 5)."""

    ORDERED: ClassVar[tuple] = (("refine_steps", "max_refine_steps", False),)

    method: PnPMethod = setting("be-w", "'be-w' (Bias-Eli + weighted LM step), 'be' (Bias-Eli only), 'ls' (CPnP LS + "
                              "weighted step), 'epnp' / 'sqpnp' (OpenCV + LM)")
    refine_steps: Int = setting(1, "weighted LM steps after the linear estimate, at least (the method: 1)", ge=1)
    far_baselines: Float = setting(0.0, "points farther than this many stereo baselines constrain the weighted step by "
                                    "bearing only (ORB-SLAM's close/far rule uses 35-40); 0: every point by its stereo "
                                    "depth", ge=0)
    step_tol: Float = setting(4.0, "[PROPOSAL] more steps while the last one exceeded this in the pose's own metric "
                               "(delta^T H delta); 0: exactly refine_steps steps", ge=0)
    max_refine_steps: Int = setting(10, "at most this many weighted steps", ge=1)
    depth_weights: Bool = setting(False, "linear-step row weights Z^-3/2 (the authors' code) instead of 1")
    current_noise: Bool = setting(True, "add the current frame's noise sigma^2 I to the step's weights (spec 5.4 "
                                    "[PROPOSAL])")
    min_points: Int = setting(12, "fewer verified matches than this is a tracking failure", ge=4)
    fallback_sigmas: Float = setting(4.0, "be-w/ls: redo the step from SQPnP (the better pose kept) when the median "
                                      "reprojection error exceeds this many noise std; 0: never", ge=0)
    fallback_min_px: Float = setting(0.5, "... but never below this error (px)", ge=0)
    reverify: Bool = setting(True, "[PROPOSAL] when the pose's median reprojection error exceeds that limit, drop the "
                               "outliers of a 3D-2D RANSAC (AP3P) and redo the pose; the better kept")
    reverify_sigmas: Float = setting(3.0, "... its inlier threshold in noise std (at least 1 px)", gt=0)
    chi2_gate: Float = setting(13.8, "[PROPOSAL] be-w/ls: drop matches beyond this squared Mahalanobis residual "
                                 "(chi-square 2 dof; 13.8 = 99.9 %) and redo the steps, until the set is stable; 0: "
                                 "off", ge=0)
    max_median_px: Float = setting(10.0, "a pose whose median reprojection error exceeds this is a failure (px); "
                                           "loose, so ablations without the LM step (be) are not judged by it", gt=0)

    _order = model_validator(mode="after")(ordered)


@dataclass(config=STRICT)
class KeyframeConfig:
    """When a new keyframe is inserted (spec 12.1)."""

    min_tracked_ratio: Float = setting(0.5, "new keyframe when verified matches < ratio * keyframe points ...", ge=0, le=1)
    min_tracked: Int = setting(100, "... or < this count", ge=0)
    max_mean_disp_px: Float = setting(30.0, "... or the mean displacement since the keyframe exceeds this (px)", gt=0)
    max_frames: Int = setting(0, "... or this many frames since the keyframe (0: no limit)", ge=0)


@dataclass(config=STRICT)
class BAConfig:
    """Epipolar local BA over the last two keyframes and the frames between (spec 10)."""

    enabled: Bool = setting(True, "run the BA at each keyframe insertion")
    kernel: Literal["truncated", "huber", "none"] = setting("truncated", "'truncated' (the authors' choice) or 'huber' (the same delta in both), 'none'")
    delta_sigmas: Float = setting(3.0, "kernel threshold delta = this x the noise std sigma_hat", gt=0)
    max_iter: Int = setting(10, "LM iterations", ge=1)
    tol: Float = setting(1e-4, "stop when the relative step or the relative robust-cost decrease is below this", gt=0)
    max_reproj_ratio: Float = setting(1.5, "reject a BA whose new-keyframe pose reprojects the keyframe points with a "
                                       "median error above ratio x the tracking pose's + 0.05 px (0: never)", ge=0)
    max_gap: Int = setting(0, "frame-frame pairs F_j -> F_k only for j - k <= this (0: all j > k, the authors' pairs)", ge=0)
    max_features: Int = setting(0, "at most this many feature ids in a BA window (evenly thinned; 0: all)", ge=0)
    max_step_ratio: Float = setting(0.5, "reject a BA that moves the new keyframe by more than this fraction of "
                                     "the window's translation plus 5 cm", ge=0)


@dataclass(config=STRICT)
class ImuConfig:
    """The IMU as GeVI uses it."""

    APPLIES: ClassVar[Applies] = Applies(methods=("gevi",), why=GEVI_ONLY.format("the IMU settings"))

    time_offset_s: Optional[Float] = setting(None, "camera-IMU time shift, t_imu = t_cam + shift (s); empty: the "
                                               "calibration's (Kalibr timeshift_cam_imu), else 0")
    max_gap_factor: Float = setting(5.0, "an IMU interval longer than this many sample periods is a gap: the frame "
                                     "is tracked visually (6-DOF) and status.json says so", gt=1)


@dataclass(config=STRICT)
class InitConfig:
    """Stereo-IMU initialisation with known scale (spec 9 [PROPOSAL])."""

    APPLIES: ClassVar[Applies] = Applies(methods=("gevi",), why=GEVI_ONLY.format("the initialisation"))
    ORDERED: ClassVar[tuple] = (("still_lag_s", "still_min_s", True), ("window_s", "max_window_s", False))

    still_min_s: Float = setting(1.0, "a standstill start is initialised after this long at rest (s); gravity and gyro "
                                  "bias re-estimated over the standstill while it lasts", gt=0)
    still_max_flow_px: Float = setting(2.0, "at rest: image motion since a reference frame below this (px, 90th percentile "
                                        "over the features of a fitted similarity transform)", gt=0)
    still_lag_s: Float = setting(0.5, "the gyro bias of a standstill leaves out its last this many seconds (its end is "
                                   "detected late)", ge=0)
    still_persist: Int = setting(3, "... on this many consecutive frames before the images say 'moving'", ge=1)
    still_max_gyro_std: Float = setting(0.1, "at rest: gyro std per axis below this (rad/s; vibrating platforms reach "
                                         "0.06)", gt=0)
    still_max_acc_std: Float = setting(0.5, "at rest: std of |a| below this (m/s^2)", gt=0)
    still_max_gravity_err: Float = setting(0.5, "at rest: | mean |a| - 9.81 | below this (m/s^2)", gt=0)
    window_s: Float = setting(2.0, "moving start: seconds of stereo odometry used by the stereo-IMU initialisation", gt=0)
    max_window_s: Float = setting(6.0, "moving start: retry with a growing window up to this long (s)", gt=0)
    stride: Int = setting(2, "moving start: every this many frames is an initialisation pose", ge=1)
    refine_acc_bias: Bool = setting(True, "standstill start: estimate the accelerometer bias from the first window_s of "
                                      "motion after it (stereo-IMU initialisation, only b_a adopted)")
    ba_prior_sigma: Float = setting(0.05, "zero-mean prior on the accelerometer bias (m/s^2, spec 9.6)", gt=0)
    pose_sigma_m: Float = setting(0.001, "position noise of the stereo-odometry poses in the initialisation's weights (m); "
                                     "0: the poses are taken as exact", ge=0)

    _order = model_validator(mode="after")(ordered)


@dataclass(config=STRICT)
class FusionConfig:
    """GeVI per-frame attitude / pose refinement (spec 8)."""

    APPLIES: ClassVar[Applies] = Applies(methods=("gevi",), why=GEVI_ONLY.format("the gravity fusion"))

    mode: Literal["bcd", "4dof"] = setting("bcd", "'bcd' (6-DOF refinement with the jointly estimated gravity-prior covariance) or '4dof' "
                           "(4-DOF step, roll/pitch from the IMU-only filter)")
    adaptive: Bool = setting(True, "estimate the gravity-prior covariance (false: spec 8's fixed-weight baseline, "
                                "Sigma = (sigma_a / g)^2 I at the accelerometer noise floor)")
    max_iter: Int = setting(2, "BCD iterations (spec 8.3: 1-2)", ge=1)
    lm_iters: Int = setting(2, "LM iterations per chi-step", ge=1)
    sigma_hi: Float = setting(0.2, "upper bound of the gravity-prior std (sqrt of the largest eigenvalue)", gt=0)
    max_window_frames: Int = setting(20, "at most this many frames in a BCD window: the oldest after the keyframe are "
                                     "folded into one gyro-chain link (the cost is cubic in it)", ge=3)
    kf_tilt_floor_deg: Float = setting(0.05, "lower bound of the keyframe roll/pitch prior std (deg)", gt=0)
    kf_tilt_gravity_gain: Float = setting(1.0, "with the BA: new keyframe tilt = BA tilt + gain x (BCD tilt - BA tilt); 1: "
                                           "the BCD tilt (gravity-anchored), 0: the BA tilt (visual) [PROPOSAL]", ge=0, le=1)
    sigma_memory_s: Float = setting(2.0, "[PROPOSAL, spec 8.3] conjugate prior of the gravity-prior covariance: the "
                                     "innovations of the last this many seconds (s); 0: window residuals only", ge=0)
    acc_window_s: Float = setting(0.4, "acceleration compensation [PROPOSAL]: remove the acceleration fitted to the "
                                   "tracked positions of the last this many seconds (s); 0: specific force only (the "
                                   "paper)", ge=0)
    gravity_window_s: Float = setting(2.0, "window gravity [PROPOSAL]: gravity from the tracked positions of the last this "
                                       "many seconds against the integrated IMU (s); 0: specific force minus "
                                       "acc_window_s's acceleration", ge=0)
    bias_window_s: Float = setting(20.0, "accelerometer bias in flight [PROPOSAL]: the horizontal bias re-estimated at "
                                     "each keyframe over the last this many seconds; 0: the initialisation's bias "
                                     "throughout", ge=0)
    bias_max_std: Float = setting(0.02, "that estimate is adopted when its posterior std (m/s^2, horizontal) is below this", gt=0)
    acc_order: Annotated[Literal[0, 2, 3], BeforeValidator(integer_choice)] = setting(0, "degree of that position fit: 2 or 3; 0 chooses per frame the one with the smaller "
                            "estimated mean squared error")


@dataclass(config=STRICT)
class RunConfig:
    """Run-level settings."""

    seed: Int = setting(0, "seed of GeVI's 3-point RANSAC: frame k draws from (seed, k), so a run is reproducible (CFO's "
                       "OpenCV 5-point RANSAC has its own fixed seed)", ge=0)
    align: Literal["se3", "sim3", "posyaw", "origin", "none"] = setting("se3", "alignment of the run's evaluation (se3 for stereo)")
    rpe_delta: Float = setting(1.0, "RPE delta in frames", gt=0)


@dataclass(config=STRICT)
class OdometryConfig:
    """The whole configuration of a `gevi run`."""

    frontend: FrontendConfig = stage(FrontendConfig)
    verify: VerifyConfig = stage(VerifyConfig)
    triangulation: TriangulationConfig = stage(TriangulationConfig)
    noise: NoiseConfig = stage(NoiseConfig)
    pnp: PnPConfig = stage(PnPConfig)
    keyframe: KeyframeConfig = stage(KeyframeConfig)
    ba: BAConfig = stage(BAConfig)
    imu: ImuConfig = stage(ImuConfig)
    init: InitConfig = stage(InitConfig)
    fusion: FusionConfig = stage(FusionConfig)
    run: RunConfig = stage(RunConfig)


#: Per-method defaults applied over the dataclass defaults (before gevi_cli/configs/<kind>.yaml): GeVI verifies
#: with its 3-point RANSAC only (spec 2: no l1 stage).  CFO's l1 stage after it (``--set verify.l1=irls``)
#: lowers pool-easy's ATE (60 s, 3 seeds: 1.63 -> 1.31 mm at 522e2ed, CFO 1.24) by when keyframes are taken,
#: not by the points it drops, raises pool-hard's (34.4 -> 37.6 mm), and costs 1.5-2.7 ms per frame: GeVI at
#: 1.3-1.4x CFO's time on euroc_micro (docs/method.md 9b).  It keeps the epipolar BA at keyframes,
#: as CFO (spec 2 lists none for GeVI; measured on pool-easy_s1, 30 s: ATE 0.91 mm with it, 2.0 mm without).
METHOD_DEFAULTS = {
    "cfo": {},
    "gevi": {"verify": {"ransac": "3pt", "l1": "none"}},
}
