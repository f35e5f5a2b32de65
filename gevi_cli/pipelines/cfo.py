"""CurrentFeature Odometry (stereo only; "Bias-Eliminated PnP for Stereo Visual Odometry").

Per frame (spec 2): LK tracks -> 5-point RANSAC -> l1-PnP drop of the worst 10 % -> noise variance
-> Bias-Eli-W PnP (bias-eliminated linear step + the weighted LM step(s) of pose6) against the points of the
current keyframe only; at each new keyframe the epipolar local BA.  Everything but the two pipeline
choices (verification, pose) lives in :class:`~gevi_cli.pipelines.odometry.KeyframeOdometry`.
"""
from __future__ import annotations

import numpy as np

from gevi_cli.frontend import FrontEnd
from gevi_cli.geometry import make_T
from gevi_cli.pipelines.config import OdometryConfig
from gevi_cli.pipelines.odometry import KeyframeOdometry, Matches
from gevi_cli.pipelines.pose6 import tracked_pose6
from gevi_cli.pipelines.verification import FivePointL1Verification


class CurrentFeatureOdometry(KeyframeOdometry):
    name = "cfo"

    def __init__(self, frontend: FrontEnd, cfg: OdometryConfig):
        super().__init__(frontend, cfg)
        self.verification = FivePointL1Verification(cfg.verify, self.camera)

    def estimate_T_ck(self, m: Matches, frame) -> np.ndarray:
        R, t, fallback = tracked_pose6(m.p, m.cov_unit * self.sigma2, m.q, self.cfg.pnp, self.sigma2, self.camera.f)
        self.fallbacks += int(fallback)
        return make_T(R, t)
