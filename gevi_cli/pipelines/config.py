"""Per-stage configuration of the odometry pipelines (defaults are the product; see gevi_cli.config).

Units: pixels (px) in the rectified images, metres (m), seconds (s).  ``gevi run --dump-config``
lists every key with its type, default and valid domain; ``gevi_cli/configs/<kind>.yaml`` overrides
them per dataset kind.  Each setting's type and domain are declared here, once (see :mod:`gevi_cli.config`):
ordered pairs in a stage's ``ORDERED``, what applies to one method or input only in ``APPLIES`` /
``applies=``.
"""
from __future__ import annotations

from typing import ClassVar, Literal, Optional, get_args

from pydantic import model_validator
from pydantic.dataclasses import dataclass

from gevi_cli.config import Applies, Bool, Float, Int, ordered, setting, stage
from gevi_cli.datasets.sequence import GAP_FACTOR
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
TRACKS_ONLY = Applies(inputs="tracks", why="the outlier flags of a track export")
#: the methods whose runs draw from run.seed (GeVI's 3-point RANSAC); the others are identical to the byte
SEEDED_METHODS = ("gevi",)
#: the local BA's own settings: read only when it runs
BA_ON = Applies(requires=("ba.enabled", (True,)), why="a setting of the local BA, which --no-ba turns off")


@dataclass(config=STRICT)
class VerifyConfig:
    """Two-stage verification of keyframe<->current matches (spec 12.1 / 5.5)."""

    ransac: RansacMethod = setting("5pt", "first stage: '5pt' (OpenCV 5-point essential-matrix RANSAC), '3pt' (GeVI: upright "
                             "3-point RANSAC with the IMU roll/pitch, spec 7) or 'none'", applies=RANSAC_APPLIES)
    ransac_threshold_px: Float = setting(1.0, "RANSAC inlier threshold (Sampson distance, px); 3pt: the larger of this "
                                          "and THRESHOLD_SIGMAS x the noise std", gt=0,
                                          applies=Applies(requires=("verify.ransac", ("5pt", "3pt")),
                                                          why="the RANSAC's threshold; ransac=none runs no RANSAC"))
    l1: L1Method = setting("irls", "second stage: l1-PnP drop of the worst fraction: 'irls' (exact l1 by IRLS + simplex polish, "
                          "same keep-mask as the LP), 'lp' (HiGHS), 'none'")
    use_export_flags: Bool = setting(False, "track exports only: drop the exporter's own outlier flags first", applies=TRACKS_ONLY)


# Fixed values of the verification (former settings, each at its former default; issue 46)
THRESHOLD_SIGMAS = 3.0  # 3pt: inlier threshold in noise std (3 sigma: a Gaussian inlier is kept 99.7 % of the time)
RANSAC_PROB = 0.999  # RANSAC confidence (both RANSACs' usual value)
MIN_PARALLAX_PX = 0.5  # below this median displacement the essential matrix is undefined (no translation): no 5pt
L1_DROP = 0.10  # fraction of the largest l1-PnP reprojection errors the l1 stage drops (CurrentFeature's 10 %)


@dataclass(config=STRICT)
class TriangulationConfig:
    """Keyframe stereo triangulation with covariance (spec 4)."""

    ORDERED: ClassVar[tuple] = (("min_depth_m", "max_depth_m", True),)

    min_depth_m: Float = setting(0.5, "points nearer than this are not used (m)", gt=0)
    max_depth_m: Float = setting(100.0, "points farther than this are not used (m)", gt=0, inf=True)
    min_disparity_px: Float = setting(0.0, "points with less stereo disparity than this are not used (px): a depth cap the "
                                       "same for every baseline", ge=0)
    self_calibrate: Bool = setting(True, "estimate the stereo pair's disparity offset from the tracked steps (pose and "
                                     "offset fitted jointly) and, once it is told from zero, add that one value to "
                                     "the keyframes' disparities (restarting the run if found early)")

    _order = model_validator(mode="after")(ordered)


# Fixed values of the triangulation (former settings; issue 46)
FILL_POINTS = 100  # fewer points inside the far gate than this: the keyframe keeps those beyond it (ORB-SLAM's rule)
MIN_KF_POINTS = 20  # a keyframe with fewer triangulated points cannot be tracked against


@dataclass(config=STRICT)
class NoiseConfig:
    """Image-noise variance from the data (spec 3)."""

    method: NoiseMethod = setting("symmetric", "'symmetric' (GEP with both views noisy), 'onesided' (paper model), "
                                   "'stereo' (keyframe stereo epipolar residuals)")


# Fixed values of the noise estimate (former settings; issue 46)
NOISE_MIN_PX = 0.05  # clamp of the estimated std (px): below it the estimate is degenerate
NOISE_MAX_PX = 5.0  # clamp of the estimated std (px): above it the estimate is a tracking failure's, not noise
NOISE_DEFAULT_PX = 0.5  # std used until a first valid estimate exists (px)


@dataclass(config=STRICT)
class PnPConfig:
    """Keyframe -> current pose (spec 5)."""

    method: PnPMethod = setting("be-w", "'be-w' (Bias-Eli + weighted LM step), 'be' (Bias-Eli only), 'ls' (CPnP LS + "
                              "weighted step), 'epnp' / 'sqpnp' (OpenCV + LM)")
    depth_weights: Bool = setting(False, "linear-step row weights Z^-3/2 (the authors' code) instead of 1")


# Fixed values of the pose step (former settings, each at its former default; issue 46)
REFINE_STEPS = 1  # weighted LM steps after the linear estimate, at least (the method's one step)
MAX_REFINE_STEPS = 10  # at most this many weighted steps
STEP_TOL = 4.0  # more steps while the last exceeded this in the pose's metric (delta^T H delta); 0: REFINE_STEPS
MIN_PNP_POINTS = 12  # fewer verified matches than this is a tracking failure
FALLBACK_SIGMAS = 4.0  # be-w/ls: redo the step from SQPnP above this median reprojection error (noise std; 0: never)
FALLBACK_MIN_PX = 0.5  # ... but never below this error (px)
REVERIFY_SIGMAS = 3.0  # above that limit: inlier threshold (noise std, at least 1 px) of the AP3P re-verification
CHI2_GATE = 13.8  # drop matches beyond this squared Mahalanobis residual (chi-square 2 dof: 99.9 %) and redo; 0: off
MAX_MEDIAN_PX = 10.0  # a pose with a larger median reprojection error (px) is a failure; loose, for the be ablation


@dataclass(config=STRICT)
class KeyframeConfig:
    """When a new keyframe is inserted (spec 12.1)."""

    APPLIES: ClassVar[Applies] = Applies(inputs="images", why="a track export's keyframes are the exporter's")

    min_tracked_ratio: Float = setting(0.5, "new keyframe when verified matches < ratio * keyframe points ...", ge=0, le=1)
    min_tracked: Int = setting(100, "... or < this count", ge=0)
    max_mean_disp_px: Float = setting(30.0, "... or the mean displacement since the keyframe exceeds this (px)", gt=0)


@dataclass(config=STRICT)
class BAConfig:
    """Epipolar local BA over the last two keyframes and the frames between (spec 10)."""

    enabled: Bool = setting(True, "run the BA at each keyframe insertion")
    kernel: Literal["truncated", "huber", "none"] = setting("truncated", "'truncated' (the authors' choice) or 'huber' (the same delta in both), 'none'",
                                                            applies=BA_ON)
    delta_sigmas: Float = setting(3.0, "kernel threshold delta = this x the noise std sigma_hat", gt=0, applies=BA_ON)


# Fixed values of the local BA (former settings, each at its former default; issue 46)
BA_MAX_ITER = 10  # LM iterations
BA_TOL = 1e-4  # stop when the relative step or the relative robust-cost decrease is below this
BA_MAX_REPROJ_RATIO = 1.5  # reject a BA whose new keyframe reprojects its points > ratio x the tracked pose's + 0.05 px
BA_MAX_STEP_RATIO = 0.5  # reject a BA that moves the new keyframe by more than this fraction of the window's path + 5 cm


@dataclass(config=STRICT)
class ImuConfig:
    """The IMU as GeVI uses it."""

    APPLIES: ClassVar[Applies] = Applies(methods=("gevi",), why=GEVI_ONLY.format("the IMU settings"))

    time_offset_s: Optional[Float] = setting(None, "camera-IMU time shift, t_imu = t_cam + shift (s); empty: the "
                                               "calibration's (Kalibr timeshift_cam_imu), else 0")
    max_gap_factor: Float = setting(GAP_FACTOR, "an IMU interval longer than this many sample periods is a gap: the frame "
                                     "is tracked visually (6-DOF) and status.json says so", gt=1)


STILL_LAG_S = 0.5  # the standstill's gyro bias leaves out its last this many seconds (its end is detected late)
MAX_WINDOW_S = 6.0  # moving start: retry with a growing window up to this long (s)


@dataclass(config=STRICT)
class InitConfig:
    """Stereo-IMU initialisation with known scale (spec 9 [PROPOSAL])."""

    APPLIES: ClassVar[Applies] = Applies(methods=("gevi",), why=GEVI_ONLY.format("the initialisation"))
    still_min_s: Float = setting(1.0, "a standstill start is initialised after this long at rest (s); gravity and gyro "
                                  "bias re-estimated over the standstill while it lasts", gt=STILL_LAG_S)
    window_s: Float = setting(2.0, "moving start: seconds of stereo odometry used by the stereo-IMU initialisation",
                              gt=0, le=MAX_WINDOW_S)


# Fixed values of the initialisation (former settings, each at its former default; issue 46); STILL_LAG_S and
# MAX_WINDOW_S above (the domains of still_min_s and window_s), the IMU rest limits in inertial.standstill.
STILL_MAX_FLOW_PX = 2.0  # at rest: image motion below this (px, 90th percentile of a fitted similarity's residual)
STILL_PERSIST = 3  # ... moving on this many consecutive frames before the images say 'moving'
INIT_STRIDE = 2  # moving start: every this many frames is an initialisation pose
BA_PRIOR_SIGMA = 0.05  # zero-mean prior on the accelerometer bias (m/s^2, spec 9.6)
POSE_SIGMA_M = 0.001  # position noise of the stereo-odometry poses in the initialisation's weights (m)


@dataclass(config=STRICT)
class FusionConfig:
    """GeVI per-frame attitude / pose refinement (spec 8)."""

    APPLIES: ClassVar[Applies] = Applies(methods=("gevi",), why=GEVI_ONLY.format("the gravity fusion"))

    mode: Literal["bcd", "4dof"] = setting("bcd", "'bcd' (6-DOF refinement with the jointly estimated gravity-prior covariance) or '4dof' "
                           "(4-DOF step, roll/pitch from the IMU-only filter)")
    adaptive: Bool = setting(True, "estimate the gravity-prior covariance (false: spec 8's fixed-weight baseline, "
                                "Sigma = (sigma_a / g)^2 I at the accelerometer noise floor)",
                             applies=Applies(requires=("fusion.mode", ("bcd",)),
                                             why="the BCD refinement's gravity prior; fusion.mode=4dof "
                                                 "(--no-fusion) takes roll/pitch from the IMU alone"))
    acc_window_s: Float = setting(0.4, "acceleration compensation: remove the acceleration fitted to the tracked "
                                   "positions of the last this many seconds (s); 0: specific force only (the paper)",
                                  ge=0)
    gravity_window_s: Float = setting(2.0, "window gravity: gravity from the tracked positions of the last this many "
                                       "seconds against the integrated IMU (s); 0: specific force minus "
                                       "acc_window_s's acceleration", ge=0)
    bias_window_s: Float = setting(20.0, "accelerometer bias in flight: the horizontal bias re-estimated at each "
                                     "keyframe over the last this many seconds; 0: the initialisation's bias "
                                     "throughout (the paper)", ge=0)


# Fixed values of the gravity fusion (former settings, each at its former default; issue 46)
BCD_MAX_ITER = 2  # BCD iterations (spec 8.3: 1-2)
BCD_LM_ITERS = 2  # LM iterations per chi-step
SIGMA_HI = 0.2  # upper bound of the gravity-prior std (sqrt of the largest eigenvalue)
MAX_WINDOW_FRAMES = 20  # at most this many frames in a BCD window (the cost is cubic in it): the oldest are folded
KF_TILT_FLOOR_DEG = 0.05  # lower bound of the keyframe roll/pitch prior std (deg)
SIGMA_MEMORY_S = 2.0  # conjugate prior of the gravity-prior covariance: the innovations of the last this many seconds
BIAS_MAX_STD = 0.02  # the in-flight bias is adopted when its posterior std (m/s^2, horizontal) is below this
ACC_ORDER = 0  # degree of the acceleration's position fit: 0 chooses 2 or 3 per frame by the smaller estimated MSE


@dataclass(config=STRICT)
class RunConfig:
    """Run-level settings."""

    seed: Int = setting(0, "seed of GeVI's 3-point RANSAC: frame k draws from (seed, k), so a run is reproducible",
                        ge=0, applies=Applies(methods=SEEDED_METHODS, why="CFO's OpenCV 5-point RANSAC keeps its own "
                                                                     "fixed seed: its runs are identical to the byte"))
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
