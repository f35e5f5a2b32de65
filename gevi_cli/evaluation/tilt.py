"""Roll/pitch (tilt) error of a gravity-aligned estimate: what a stereo-inertial odometry must keep.

Both trajectories must have a gravity-aligned world (z up) and describe the same sensor frame; no
alignment is applied (a rotation about z would not change the tilt, any other would hide the very
error measured).  The tilt error of a pose pair is the angle between the two gravity directions
seen from the sensor, ``angle(R_est^T e3, R_gt^T e3)``: yaw-free and free of the Euler singularity
of roll/pitch differences near pitch +-90 deg.  Degrees.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gevi_cli.trajectory import Trajectory

E3 = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class TiltErrors:
    """Per matched pose: stamps (ns) and tilt error (deg)."""

    t_ns: np.ndarray
    err_deg: np.ndarray
    roll_pitch_deg: np.ndarray  # (n, 2) wrapped roll and pitch differences (ZYX Euler, spec 1)

    @property
    def rmse_deg(self) -> float:
        return float(np.sqrt(np.mean(self.err_deg ** 2)))

    @property
    def roll_pitch_rmse_deg(self) -> float:
        """RMS over roll and pitch differences (amplified near pitch +-90 deg, where roll is ill-defined)."""
        return float(np.sqrt(np.mean(self.roll_pitch_deg ** 2)))

    def trend_deg_per_min(self, t0_ns: int, window_s: float = 5.0) -> float:
        """Slope (deg per minute) of the tilt error's RMSE over consecutive ``window_s`` windows from ``t0_ns``
        on, by least squares: whether roll/pitch drift over the run (> 0) or settle (< 0).  Every window
        counts, where a first-against-last comparison reads two windows of an error that fluctuates by
        about its own size.  The windows' errors are correlated in time (an accelerometer bias walks), so
        the spread of this slope over runs, not a per-run residual, is its uncertainty.  NaN with fewer
        than three windows."""
        step = int(round(window_s * 1e9))
        if step <= 0:
            raise ValueError("window_s must be > 0")
        m = self.t_ns >= t0_ns  # stamps are increasing: each window is one run of samples
        d_ns = self.t_ns[m] - t0_ns
        if len(d_ns) == 0:
            return float("nan")
        _, start, count = np.unique(d_ns // step, return_index=True, return_counts=True)
        dt = d_ns.astype(np.float64)
        span = dt[start + count - 1] - dt[start]
        t = np.add.reduceat(dt, start) / count / 60e9  # each window's mean time (a last window is short)
        rms = np.sqrt(np.add.reduceat(self.err_deg[m] ** 2, start) / count)
        full = span >= 0.5 * step  # a window cut short by the end of the run counts from half its length
        if full.sum() < 3:
            return float("nan")
        return float(np.polyfit(t[full], rms[full], 1)[0])


def gravity_angle_deg(R_est: np.ndarray, R_ref: np.ndarray) -> np.ndarray:
    """Angle (deg) between R_est^T e3 and R_ref^T e3 for (n, 3, 3) arrays."""
    a = np.einsum("nji,j->ni", R_est, E3)
    b = np.einsum("nji,j->ni", R_ref, E3)
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=1), -1.0, 1.0)))


def tilt_errors(est: Trajectory, gt: Trajectory, max_diff_s: float = 0.01) -> TiltErrors:
    """Tilt error of every estimated pose with a ground-truth pose within ``max_diff_s``."""
    from gevi_cli.evaluation.associate import associate
    from gevi_cli.geometry import tilt_angles, wrap_angle

    a = associate(gt, est, max_diff_s=max_diff_s)
    Re, Rg = a.est.rotations, a.gt.rotations
    d = np.stack([wrap_angle(x - y) for x, y in zip(tilt_angles(Re), tilt_angles(Rg))], axis=1)
    return TiltErrors(a.est.t_ns.copy(), gravity_angle_deg(Re, Rg), np.degrees(d))
