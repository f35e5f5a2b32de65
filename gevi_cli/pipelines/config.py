"""Per-stage configuration of the odometry pipelines (defaults are the product; see gevi_cli.config).

Units: pixels (px) in the rectified images, metres (m), seconds (s).  ``gevi run --dump-config``
lists every key with its default; ``gevi_cli/configs/<kind>.yaml`` overrides them per dataset kind.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

from gevi_cli.config import opt
from gevi_cli.frontend.config import FrontendConfig

PNP_METHODS = ("be-w", "be", "ls", "epnp", "sqpnp")
RANSAC_METHODS = ("5pt", "3pt", "none")
METHODS = ("gevi", "cfo")
L1_METHODS = ("lp", "irls", "none")
NOISE_METHODS = ("symmetric", "onesided", "stereo")


@dataclass
class VerifyConfig:
    """Two-stage verification of keyframe<->current matches (spec 12.1 / 5.5)."""

    ransac: str = opt("5pt", "first stage: '5pt' (OpenCV 5-point essential-matrix RANSAC), '3pt' (GeVI: upright "
                             "3-point RANSAC with the IMU roll/pitch, spec 7) or 'none'")
    ransac_threshold_px: float = opt(1.0, "RANSAC inlier threshold (Sampson distance, px); 3pt: the larger of this "
                                          "and threshold_sigmas x the noise std")
    threshold_sigmas: float = opt(3.0, "3pt: inlier threshold in noise std (spec 7 [PROPOSAL] 3 sigma)")
    ransac_prob: float = opt(0.999, "RANSAC confidence")
    min_parallax_px: float = opt(0.5, "below this median KF->current displacement the essential matrix "
                                      "is undefined (no translation): the 5-point stage is skipped")
    l1: str = opt("irls", "second stage: l1-PnP drop of the worst fraction: 'irls' (exact l1 by IRLS + simplex polish, "
                          "same keep-mask as the LP), 'lp' (HiGHS), 'none'")
    l1_drop: float = opt(0.10, "fraction of largest l1-PnP reprojection errors dropped")
    use_export_flags: bool = opt(False, "track exports only: drop the exporter's own outlier flags first")


@dataclass
class TriangulationConfig:
    """Keyframe stereo triangulation with covariance (spec 4)."""

    min_depth_m: float = opt(0.5, "points nearer than this are not used (m)")
    max_depth_m: float = opt(100.0, "points farther than this are not used (m)")
    min_disparity_px: float = opt(0.0, "points with less stereo disparity than this are not used (px): a depth cap the "
                                       "same for every baseline")
    fill_points: int = opt(100, "a keyframe with fewer points inside the far gate (max_depth_m, min_disparity_px) "
                                "keeps the points beyond it too (0: never)")
    min_points: int = opt(20, "a keyframe with fewer triangulated points cannot be tracked against")
    self_calibrate: bool = opt(True, "estimate the stereo pair's disparity offset from the tracked frames' two-view "
                                     "geometry and add it to the keyframes' disparities")


@dataclass
class NoiseConfig:
    """Image-noise variance from the data (spec 3)."""

    method: str = opt("symmetric", "'symmetric' (GEP with both views noisy), 'onesided' (paper model), "
                                   "'stereo' (keyframe stereo epipolar residuals)")
    min_px: float = opt(0.05, "clamp of the estimated std (px): below, the estimate is degenerate")
    max_px: float = opt(5.0, "clamp of the estimated std (px)")
    default_px: float = opt(0.5, "std used until a first valid estimate exists (px)")


@dataclass
class PnPConfig:
    """Keyframe -> current pose (spec 5)."""

    method: str = opt("be-w", "'be-w' (Bias-Eli + weighted LM step), 'be' (Bias-Eli only), 'ls' (CPnP LS + "
                              "weighted step), 'epnp' / 'sqpnp' (OpenCV + LM)")
    refine_steps: int = opt(1, "weighted LM steps after the linear estimate, at least (the method: 1)")
    far_baselines: float = opt(0.0, "points farther than this many stereo baselines constrain the weighted step by "
                                    "bearing only (ORB-SLAM's close/far rule uses 35-40); 0: every point by its stereo "
                                    "depth")
    step_tol: float = opt(4.0, "[PROPOSAL] more steps while the last one exceeded this in the pose's own metric "
                               "(delta^T H delta); 0: exactly refine_steps steps")
    max_refine_steps: int = opt(10, "at most this many weighted steps")
    depth_weights: bool = opt(False, "linear-step row weights Z^-3/2 (the authors' code) instead of 1")
    current_noise: bool = opt(True, "add the current frame's noise sigma^2 I to the step's weights (spec 5.4 "
                                    "[PROPOSAL])")
    min_points: int = opt(12, "fewer verified matches than this is a tracking failure")
    fallback_sigmas: float = opt(4.0, "be-w/ls: redo the step from SQPnP (the better pose kept) when the median "
                                      "reprojection error exceeds this many noise std; 0: never")
    fallback_min_px: float = opt(0.5, "... but never below this error (px)")
    reverify: bool = opt(True, "[PROPOSAL] when the pose's median reprojection error exceeds that limit, drop the "
                               "outliers of a 3D-2D RANSAC (AP3P) and redo the pose; the better kept")
    reverify_sigmas: float = opt(3.0, "... its inlier threshold in noise std (at least 1 px)")
    chi2_gate: float = opt(13.8, "[PROPOSAL] be-w/ls: drop matches beyond this squared Mahalanobis residual "
                                 "(chi-square 2 dof; 13.8 = 99.9 %) and redo the steps, until the set is stable; 0: "
                                 "off")
    max_median_px: float = opt(10.0, "a pose whose median reprojection error exceeds this is a failure (px); "
                                           "loose, so ablations without the LM step (be) are not judged by it")


@dataclass
class KeyframeConfig:
    """When a new keyframe is inserted (spec 12.1)."""

    min_tracked_ratio: float = opt(0.5, "new keyframe when verified matches < ratio * keyframe points ...")
    min_tracked: int = opt(100, "... or < this count")
    max_mean_disp_px: float = opt(30.0, "... or the mean displacement since the keyframe exceeds this (px)")
    max_frames: int = opt(0, "... or this many frames since the keyframe (0: no limit)")


@dataclass
class BAConfig:
    """Epipolar local BA over the last two keyframes and the frames between (spec 10)."""

    enabled: bool = opt(True, "run the BA at each keyframe insertion")
    kernel: str = opt("truncated", "'truncated' (the authors' choice) or 'huber' (the same delta in both), 'none'")
    delta_sigmas: float = opt(3.0, "kernel threshold delta = this x the noise std sigma_hat")
    max_iter: int = opt(10, "LM iterations")
    tol: float = opt(1e-4, "stop when the relative step or the relative robust-cost decrease is below this")
    max_reproj_ratio: float = opt(1.5, "reject a BA whose new-keyframe pose reprojects the keyframe points with a "
                                       "median error above ratio x the tracking pose's + 0.05 px (0: never)")
    max_gap: int = opt(0, "frame-frame pairs F_j -> F_k only for j - k <= this (0: all j > k, the authors' pairs)")
    max_features: int = opt(0, "at most this many feature ids in a BA window (evenly thinned; 0: all)")
    max_step_ratio: float = opt(0.5, "reject a BA that moves the new keyframe by more than this fraction of "
                                     "the window's translation plus 5 cm")


@dataclass
class ImuConfig:
    """The IMU as GeVI uses it."""

    time_offset_s: Optional[float] = opt(None, "camera-IMU time shift, t_imu = t_cam + shift (s); empty: the "
                                               "calibration's (Kalibr timeshift_cam_imu), else 0")
    max_gap_factor: float = opt(5.0, "an IMU interval longer than this many sample periods is a gap: the frame "
                                     "is tracked visually (6-DOF) and status.json says so")


@dataclass
class InitConfig:
    """Stereo-IMU initialisation with known scale (spec 9 [PROPOSAL])."""

    still_min_s: float = opt(1.0, "a standstill start is initialised after this long at rest (s); gravity and gyro "
                                  "bias re-estimated over the standstill while it lasts")
    still_max_flow_px: float = opt(2.0, "at rest: image motion since a reference frame below this (px, 90th percentile "
                                        "over the features of a fitted similarity transform)")
    still_lag_s: float = opt(0.5, "the gyro bias of a standstill leaves out its last this many seconds (its end is "
                                   "detected late)")
    still_persist: int = opt(3, "... on this many consecutive frames before the images say 'moving'")
    still_max_gyro_std: float = opt(0.1, "at rest: gyro std per axis below this (rad/s; vibrating platforms reach "
                                         "0.06)")
    still_max_acc_std: float = opt(0.5, "at rest: std of |a| below this (m/s^2)")
    still_max_gravity_err: float = opt(0.5, "at rest: | mean |a| - 9.81 | below this (m/s^2)")
    window_s: float = opt(2.0, "moving start: seconds of stereo odometry used by the stereo-IMU initialisation")
    max_window_s: float = opt(6.0, "moving start: retry with a growing window up to this long (s)")
    stride: int = opt(2, "moving start: every this many frames is an initialisation pose")
    refine_acc_bias: bool = opt(True, "standstill start: estimate the accelerometer bias from the first window_s of "
                                      "motion after it (stereo-IMU initialisation, only b_a adopted)")
    ba_prior_sigma: float = opt(0.05, "zero-mean prior on the accelerometer bias (m/s^2, spec 9.6)")
    pose_sigma_m: float = opt(0.001, "position noise of the stereo-odometry poses in the initialisation's weights (m); "
                                     "0: the poses are taken as exact")


@dataclass
class FusionConfig:
    """GeVI per-frame attitude / pose refinement (spec 8)."""

    mode: str = opt("bcd", "'bcd' (6-DOF refinement with the jointly estimated gravity-prior covariance) or '4dof' "
                           "(4-DOF step, roll/pitch from the IMU-only filter)")
    adaptive: bool = opt(True, "estimate the gravity-prior covariance (false: spec 8's fixed-weight baseline, "
                                "Sigma = (sigma_a / g)^2 I at the accelerometer noise floor)")
    max_iter: int = opt(2, "BCD iterations (spec 8.3: 1-2)")
    lm_iters: int = opt(2, "LM iterations per chi-step")
    sigma_hi: float = opt(0.2, "upper bound of the gravity-prior std (sqrt of the largest eigenvalue)")
    max_window_frames: int = opt(20, "at most this many frames in a BCD window: the oldest after the keyframe are "
                                     "folded into one gyro-chain link (the cost is cubic in it)")
    kf_tilt_floor_deg: float = opt(0.05, "lower bound of the keyframe roll/pitch prior std (deg)")
    kf_tilt_gravity_gain: float = opt(1.0, "with the BA: new keyframe tilt = BA tilt + gain x (BCD tilt - BA tilt); 1: "
                                           "the BCD tilt (gravity-anchored), 0: the BA tilt (visual) [PROPOSAL]")
    sigma_memory_s: float = opt(2.0, "[PROPOSAL, spec 8.3] conjugate prior of the gravity-prior covariance: the "
                                     "innovations of the last this many seconds (s); 0: window residuals only")
    acc_window_s: float = opt(0.4, "acceleration compensation [PROPOSAL]: remove the acceleration fitted to the "
                                   "tracked positions of the last this many seconds (s); 0: specific force only (the "
                                   "paper)")
    gravity_window_s: float = opt(2.0, "window gravity [PROPOSAL]: gravity from the tracked positions of the last this "
                                       "many seconds against the integrated IMU (s); 0: specific force minus "
                                       "acc_window_s's acceleration")
    bias_window_s: float = opt(20.0, "accelerometer bias in flight [PROPOSAL]: the horizontal bias re-estimated at "
                                     "each keyframe over the last this many seconds; 0: the initialisation's bias "
                                     "throughout")
    bias_max_std: float = opt(0.02, "that estimate is adopted when its posterior std (m/s^2, horizontal) is below this")
    acc_order: int = opt(0, "degree of that position fit: 2 or 3; 0 chooses per frame the one with the smaller "
                            "estimated mean squared error")


@dataclass
class RunConfig:
    """Run-level settings."""

    seed: int = opt(0, "seed of GeVI's 3-point RANSAC: frame k draws from (seed, k), so a run is reproducible (CFO's "
                       "OpenCV 5-point RANSAC has its own fixed seed)")
    align: str = opt("se3", "alignment of the run's evaluation (se3 for stereo)")
    rpe_delta: float = opt(1.0, "RPE delta in frames")


@dataclass
class OdometryConfig:
    """The whole configuration of a `gevi run`."""

    frontend: FrontendConfig = field(default_factory=FrontendConfig)
    verify: VerifyConfig = field(default_factory=VerifyConfig)
    triangulation: TriangulationConfig = field(default_factory=TriangulationConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    pnp: PnPConfig = field(default_factory=PnPConfig)
    keyframe: KeyframeConfig = field(default_factory=KeyframeConfig)
    ba: BAConfig = field(default_factory=BAConfig)
    imu: ImuConfig = field(default_factory=ImuConfig)
    init: InitConfig = field(default_factory=InitConfig)
    fusion: FusionConfig = field(default_factory=FusionConfig)
    run: RunConfig = field(default_factory=RunConfig)

    def validate(self, where: str = "config") -> "OdometryConfig":
        from gevi_cli.config import check_choice
        from gevi_cli.errors import GeviError

        check_choice(self.pnp.method, PNP_METHODS, f"{where}: pnp.method")
        check_choice(self.verify.ransac, RANSAC_METHODS, f"{where}: verify.ransac")
        check_choice(self.verify.l1, L1_METHODS, f"{where}: verify.l1")
        check_choice(self.noise.method, NOISE_METHODS, f"{where}: noise.method")
        check_choice(self.ba.kernel, ("huber", "truncated", "none"), f"{where}: ba.kernel")
        check_choice(self.fusion.mode, ("bcd", "4dof"), f"{where}: fusion.mode")
        check_choice(self.fusion.acc_order, (0, 2, 3), f"{where}: fusion.acc_order")
        if not self.fusion.acc_window_s >= 0:
            raise GeviError(f"{where}: fusion.acc_window_s", f"must be >= 0 (s), got {self.fusion.acc_window_s}")
        if not self.fusion.gravity_window_s >= 0:
            raise GeviError(f"{where}: fusion.gravity_window_s", f"must be >= 0 (s), got {self.fusion.gravity_window_s}")
        if not self.fusion.bias_window_s >= 0:
            raise GeviError(f"{where}: fusion.bias_window_s", f"must be >= 0 (s), got {self.fusion.bias_window_s}")
        if not self.fusion.bias_max_std > 0:
            raise GeviError(f"{where}: fusion.bias_max_std", f"must be > 0 (m/s^2), got {self.fusion.bias_max_std}")
        if not self.pnp.far_baselines >= 0:
            raise GeviError(f"{where}: pnp.far_baselines", f"must be >= 0 (0: off), got {self.pnp.far_baselines}")
        if not self.pnp.step_tol >= 0:
            raise GeviError(f"{where}: pnp.step_tol", f"must be >= 0, got {self.pnp.step_tol}")
        if not self.pnp.max_refine_steps >= 1:
            raise GeviError(f"{where}: pnp.max_refine_steps", f"must be >= 1, got {self.pnp.max_refine_steps}")
        if not self.ba.delta_sigmas > 0:
            raise GeviError(f"{where}: ba.delta_sigmas", f"must be > 0, got {self.ba.delta_sigmas}")
        if not self.triangulation.min_disparity_px >= 0:
            raise GeviError(f"{where}: triangulation.min_disparity_px",
                            f"must be >= 0 (px), got {self.triangulation.min_disparity_px}")
        if not self.triangulation.fill_points >= 0:
            raise GeviError(f"{where}: triangulation.fill_points", f"must be >= 0, got {self.triangulation.fill_points}")
        if not self.pnp.reverify_sigmas > 0:
            raise GeviError(f"{where}: pnp.reverify_sigmas", f"must be > 0, got {self.pnp.reverify_sigmas}")
        return self


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
