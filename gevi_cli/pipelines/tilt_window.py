"""GeVI's roll/pitch state and its 6-DOF refinement with the jointly estimated gravity-prior covariance
(spec 8): the frames since the keyframe, their tilts, the keyframe-tilt prior, Sigma and its prior.

Per GEVI-mode frame :meth:`TiltWindow.refine` runs the block coordinate descent over the window (visual
reprojection residuals of the current frame, one gravity residual per frame, the gyro chain between
frames and the keyframe-tilt prior) from the 4-DOF pose, behind CFO's chi-square gate.  At a keyframe
the current tilt becomes the keyframe tilt, its marginal covariance the next windows' prior.

Frames: ``R_ic`` = R_BC0; tilts are (roll, pitch) of R_WB in rad; ``Sigma`` is the 3x3 covariance of
the unit gravity direction in the body frame (dimensionless).
"""
from __future__ import annotations

import time

import numpy as np

from gevi_cli import estimators as est
from gevi_cli.inertial.imu_stream import ImuNoise
from gevi_cli.inertial.standstill import GRAVITY
from gevi_cli.pipelines.config import (
    BA_PRIOR_SIGMA,
    BCD_LM_ITERS,
    BCD_MAX_ITER,
    CHI2_GATE,
    KF_TILT_FLOOR_DEG,
    MAX_WINDOW_FRAMES,
    MIN_PNP_POINTS,
    SIGMA_HI,
    SIGMA_MEMORY_S,
    OdometryConfig,
)
from gevi_cli.pipelines.inertial_state import FrameSample
from gevi_cli.pipelines.verification import TrackingFailure

#: at most this many BCDs per frame for the chi-square gate (TiltWindow.refine)
GATE_BCDS = 3


class TiltWindow:
    """The BCD window of frames since the keyframe (``samples[0]`` is the keyframe's) and the tilt state.

    ``tilt`` / ``tilt_cov``: the current frame's roll/pitch (rad) and covariance (rad^2; NaN where no
    refinement gave one); ``kf_tilt`` / ``kf_tilt_cov``: the keyframe's, the prior of the window;
    ``Sigma``: the last refinement's gravity-prior covariance; ``bcd_ms``: its run time."""

    def __init__(self, cfg: OdometryConfig, noise: ImuNoise, frame_period_s: float, R_ic: np.ndarray):
        self.cfg = cfg
        self.noise = noise
        self.frame_period = float(frame_period_s)
        self.R_ic = R_ic
        self.samples: list[FrameSample] = []
        self.tilt = np.zeros(2)
        self.tilt_cov = np.eye(2)
        self.kf_tilt, self.kf_tilt_cov = np.zeros(2), np.eye(2)
        self.Sigma = np.full((3, 3), np.nan)
        self.bcd_ms = 0.0
        self._innovations: list[tuple[int, np.ndarray]] = []  # (t_ns, a_dir - R_tilt(pred)^T e3), Sigma's prior
        self._fold = None  # (keyframe index, frames folded, their composed gyro rotation, their seconds)

    # -------------------------------------------------------------------------------- the window
    def append(self, sample: FrameSample) -> None:
        """A frame that is not a keyframe joins the window with its tilt."""
        self.samples.append(sample)

    def restart(self, sample: FrameSample) -> int | None:
        """The keyframe's ``sample`` starts the next window; the index of the previous one (None: none)."""
        i_prev = self.samples[0].index if self.samples else None
        self.samples = [sample]
        return i_prev

    def take_keyframe_tilt(self) -> None:
        """The current tilt becomes the keyframe tilt, its covariance (floored at
        ``KF_TILT_FLOOR_DEG`` per eigen-direction) the prior of the next windows."""
        floor = np.radians(KF_TILT_FLOOR_DEG) ** 2
        cov = self.tilt_cov if np.all(np.isfinite(self.tilt_cov)) else np.eye(2) * floor
        w, V = np.linalg.eigh(0.5 * (cov + cov.T))
        self.kf_tilt, self.kf_tilt_cov = self.tilt.copy(), (V * np.maximum(w, floor)) @ V.T

    def reset_tilts(self, tilt: np.ndarray, kf_tilt: np.ndarray | None, cov0: float) -> None:
        """At the start (W just known): the current and, given, the keyframe tilt with variance ``cov0``."""
        self.tilt, self.tilt_cov = tilt, np.eye(2) * cov0
        if kf_tilt is not None:
            self.kf_tilt, self.kf_tilt_cov = kf_tilt, np.eye(2) * cov0

    def saved(self):
        """What a refinement changes besides its result: the tilts (current and window frames), Sigma."""
        return (self.tilt.copy(), np.array(self.tilt_cov, copy=True), np.array(self.Sigma, copy=True),
                [np.array(s.tilt, copy=True) for s in self.samples])

    def restore(self, saved) -> None:
        """Put back what :meth:`saved` returned."""
        self.tilt, self.tilt_cov, self.Sigma, tilts = saved
        for s, tl in zip(self.samples, tilts):
            s.tilt = tl

    def note_innovation(self, cur: FrameSample, tilt_pred: np.ndarray) -> None:
        """The current frame's innovation (its gravity direction against the gyro-predicted tilt) into the
        last ``SIGMA_MEMORY_S`` seconds' list, Sigma's conjugate prior.  The window residuals are
        taken at the estimate, which an acceleration already pulled toward the specific force (they
        understate it); the innovations do not."""
        inn = cur.acc_dir - est.rtilt(*tilt_pred).T @ np.array([0.0, 0.0, 1.0])
        mem = int(SIGMA_MEMORY_S * 1e9)
        self._innovations = [x for x in self._innovations if cur.t_ns - x[0] < mem] + [(cur.t_ns, inn)]

    # ------------------------------------------------------------------------------ the refinement
    def refine(self, m, cov, psi, t, L_k, L_c, sigma2: float, cur: FrameSample, tilt_pred: np.ndarray):
        """The BCD on the matches ``m`` (keyframe points with covariances ``cov``) whose reprojection
        residual its visual weights can explain, from the 4-DOF pose ``(psi, t)`` of the levelling
        rotations ``L_k``, ``L_c``; returns ``(R_ck, t_ck)``.

        CFO's chi-square gate (``CHI2_GATE``, as in ``pose6._chi2_refit``): ``r^T Sigma_bar^-1 r`` is
        chi-square with 2 dof, and a match far beyond the gate is a wrong stereo depth, which the 2D-2D
        verification cannot see and the BCD's quadratic visual cost would follow [PROPOSAL].  Every match
        is tested at the BCD's pose and the BCD redone on those within the gate until the kept set stops
        changing, at most ``GATE_BCDS`` BCDs in all; where every match passes at the first pose it costs
        one test."""
        gate = CHI2_GATE
        s2q = sigma2
        keep = np.ones(len(m.p), dtype=bool)
        sub, cov_sub = m, cov
        for k in range(GATE_BCDS):
            R, t = self._bcd(sub, cov_sub, psi, t, L_k, L_c, sigma2, cur, tilt_pred)
            if gate <= 0 or k + 1 == GATE_BCDS:
                break
            new = est.pnp6_whitened_sq(R, t, m.p, cov, m.q, s2q) <= gate
            if np.array_equal(new, keep) or new.sum() < MIN_PNP_POINTS:
                break
            keep = new
            sub = m.subset(keep)
            cov_sub = cov[keep]
        return R, t

    def _bcd(self, m, cov, psi, t, L_k, L_c, sigma2: float, cur: FrameSample, tilt_pred: np.ndarray):
        """One BCD (spec 8) from the 4-DOF pose ``(psi, t)`` of the levelling rotations ``L_k``, ``L_c``."""
        samples = self.samples + [cur]
        links = [s.dt for s in samples[1:]]  # seconds of gyro integration per chain link
        cap = MAX_WINDOW_FRAMES
        if len(samples) > cap:
            # a long window (slow motion, a standstill: one keyframe for seconds) costs O(K^3) per LM
            # step; the oldest frames after the keyframe are folded into one chain link (the gyro
            # rotations composed, the variance summed) and their gravity residuals dropped
            drop = samples[1:len(samples) - cap + 2]
            first = samples[len(samples) - cap + 2]
            # the folded prefix only grows within a window: its product is kept, not recomposed per frame
            # (the same products in the same order as composing them all again)
            key = samples[0].index
            if self._fold is None or self._fold[0] != key or self._fold[1] > len(drop):
                self._fold = (key, 0, np.eye(3), 0.0)
            _, k, R, dt = self._fold
            for s in drop[k:]:
                R = R @ est.exp_so3(s.rotvec)
                dt += s.dt
            self._fold = (key, len(drop), R, dt)
            R = R @ est.exp_so3(first.rotvec)
            merged = FrameSample(first.index, first.t_ns, samples[0].t_ns, first.acc_dir, est.log_so3(R),
                                 dt + first.dt, first.tilt)
            tail = samples[len(samples) - cap + 3:]
            samples = [samples[0], merged] + tail
            links = [merged.dt] + [s.dt for s in tail]
        depth = (m.p @ est.rot4(psi, L_k, L_c).T + t)[:, 2]
        front = depth > 0.5 * self.cfg.triangulation.min_depth_m
        if front.sum() < MIN_PNP_POINTS:
            raise TrackingFailure(f"only {int(front.sum())} points in front of the camera after the 4-DOF step")
        m = m.subset(front)
        cov = cov[front]
        acc = np.array([s.acc_dir for s in samples])
        rot = np.array([s.rotvec for s in samples[1:]])
        noise = self.noise
        fc = self.cfg.fusion
        # noise floor of Sigma_imu: the frame-mean white noise and the accelerometer-bias uncertainty (the
        # bias prior of spec 9.6: a standstill cannot observe b_a), so an unmodelled bias or a small
        # acceleration does not get the weight of pure white noise.  ``--no-adaptive`` is spec 8's
        # fixed-weight baseline, Sigma_imu = lambda_lo I at the accelerometer noise floor (sigma_a / g)^2
        lo = noise.acc_noise_density ** 2 / self.frame_period / GRAVITY ** 2
        if fc.adaptive:
            lo += (BA_PRIOR_SIGMA / GRAVITY) ** 2
        tilts0 = np.array([self.kf_tilt] + [s.tilt for s in samples[1:-1]] + [tilt_pred])
        # Sigma's conjugate prior: the innovations of the last SIGMA_MEMORY_S (note_innovation)
        prior, dof = None, 0.0
        if int(SIGMA_MEMORY_S * 1e9) > 0:
            E = np.array([x[1] for x in self._innovations])
            prior, dof = E.T @ E / len(E) + lo * np.eye(3), float(len(E))
        window = est.FusionWindow(p=m.p, cov=cov, q=m.q, sigma2=sigma2, R_ic=self.R_ic, acc_dir=acc,
                                  gyro_inc=rot, gyro_var=noise.gyro_noise_density ** 2 * np.array(links),
                                  prior_mean=self.kf_tilt,
                                  prior_cov=self.kf_tilt_cov, psi0=psi, t0=t, lo=lo, hi=SIGMA_HI ** 2,
                                  tilts0=tilts0, sigma_prior=prior, sigma_prior_dof=dof)
        t0 = time.perf_counter()
        try:
            state, Sigma, _ = est.bcd_refine(window, adaptive=fc.adaptive, max_iter=BCD_MAX_ITER, lm_iters=BCD_LM_ITERS)
        except est.EstimatorError as err:
            raise TrackingFailure(f"BCD refinement: {err}") from None
        self.bcd_ms = (time.perf_counter() - t0) * 1e3
        self.tilt, self.tilt_cov, self.Sigma = state.tilts[-1].copy(), state.cov_last_tilt, Sigma
        for s, tl in zip(samples[1:-1], state.tilts[1:-1]):
            s.tilt = tl.copy()  # (a merged link's sample is a copy: the folded frames keep their tilts)
        return state.R_ck(self.R_ic), state.t
