"""Self-calibration of the rectified stereo pair's disparity offset: one value per run, with its evidence.

A rectified pair whose two principal points (or rectifications) disagree by ``delta`` pixels along the
rows measures every disparity ``delta`` short: ``d = fx b / Z - delta``.  Near points barely notice,
far ones do (at 7 px of disparity, 0.8 px is 11 % of depth), and a stereo odometry that trusts far
points reads every step too long.

**One step.**  A frame tracked against its keyframe sees the offset through the keyframe's stereo points
reprojected into it: with the points at depth ``fx b / (d + delta)``, the pose ``T_ck`` and ``delta``
are fitted together (:func:`step_offset`, Gauss-Newton with Huber weights, each point weighted by its
reprojection covariance: image noise plus the disparity's, two pixels' worth, carried through its
depth).  The tracked pose only starts the fit: it was made with the uncorrected depths and leans towards
them (taken as it is, it recovers 78 % of a known shift on a render), the joint fit recovers all of it.
A step counts when its points reach far enough that zero disparity is not an extrapolation
(:data:`MAX_EXTRAPOLATION`) and the offset's standard error is below :data:`MAX_STEP_SE_PX` (a step of
pure rotation says nothing about depth and does not count).

**The estimate.**  Steps against the same keyframe share its disparities, so each keyframe gives one
value (the median of its steps); the estimate is the median over keyframes, its statistical standard
deviation ``1.2533 * 1.4826 MAD / sqrt(n)`` from their spread (:class:`OffsetEstimate`).  Its error on
real images also has a part that spread does not show (:data:`SYSTEMATIC_PX`).

**The decision.**  The offset is *found* once :data:`MIN_KEYFRAMES` keyframes gave steps and the estimate
lies :data:`EVIDENCE_SIGMAS` of its total uncertainty from zero.  It is then fixed: one value for the
rest of the run.  Found within the first :data:`RESTART_MAX_KEYFRAMES` keyframes, the run driver restarts
the run from its first frame with it (:attr:`DisparityOffset.calls_for_restart`), so every keyframe
carries it; found later, it applies from the next keyframe on.  Steps observed after that are kept as a
diagnostic (:attr:`DisparityOffset.diagnostic`) and never move the applied value.

Frames: keyframe-left and current-left normalized coordinates; disparities in pixels of the rectified
images; ``T_ck`` maps keyframe-left coordinates into the current left camera, metres.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MIN_POINTS = 20
"""A step's fit needs this many points."""

MAX_STEP_SE_PX = 0.25
"""A step counts when the standard error of its offset is below this (px)."""

MAX_EXTRAPOLATION = 1.0
"""A step counts only when its points reach within this many spans of zero disparity: the 10th
percentile of their disparities at most this times the 10-90 % spread.  The offset is where depth is
infinite; from a pool floor at 45-57 px it is an extrapolation of six spans."""

HUBER_K = 1.5
"""Huber threshold of a step's fit, in robust standard deviations of its whitened residuals."""

MIN_KEYFRAMES = 5
"""The estimate's spread needs the steps of at least this many keyframes."""

EVIDENCE_SIGMAS = 3.0
"""The offset is found when the estimate is this many total standard deviations from zero."""

SYSTEMATIC_PX = 0.075
"""The estimator's error on real images beyond its own spread (px): the standard deviation of the
estimates of one rig read at every frame, every 2nd and every 3rd (KITTI 06 head 0.18 / 0.10 / 0.04 px,
0.070; KITTI 01 head 1.02 / 0.96 / 0.87 px, 0.075), where each run's own spread says 0.04-0.09 px.
Renders with a known shift show no such error (docs/studies/far_scenes.md section 9).  Added in
quadrature to the spread for the decision."""

RESTART_MAX_KEYFRAMES = 20
"""An offset found within this many keyframes restarts the run from its first frame; later it applies
from the next keyframe on.  Every row that finds one (KITTI 01 head at strides 1-3, renders shifted by
0.3-1 px) finds it at the 5th keyframe, the earliest the evidence allows (:data:`MIN_KEYFRAMES`); 20 leaves
four times that for a slower scene and bounds a restart's repeated work to 20 keyframes (KITTI 01: 26
frames at stride 1), however long the sequence."""

def _exp_so3(w: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(w))
    if th < 1e-12:
        return np.eye(3)
    k = w / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * K @ K


def step_offset(z: np.ndarray, q: np.ndarray, disparity_px: np.ndarray, T_ck: np.ndarray, fx: float,
                baseline_m: float, iterations: int = 4) -> tuple[float, float]:
    """``(delta px, its standard error px)`` of one tracked step: the keyframe's stereo points (left
    normalized ``z``, raw disparities ``disparity_px``) at depth ``fx b / (d + delta)``, reprojected by the
    pose ``T_ck`` onto the current frame's normalized ``q``; pose and ``delta`` fitted jointly from
    ``T_ck`` and 0.  Each point's residual (px) is whitened by ``S = I + 2 j j^T`` (image noise plus a
    disparity's two pixels, ``j`` the residual's derivative by the disparity; ``S^-1 = I - c j j^T`` with
    ``c = 2 / (1 + 2 |j|^2)``) and Huber-weighted.  ``(nan, inf)`` when the fit is degenerate."""
    fb = fx * baseline_m
    zh = np.column_stack([z, np.ones(len(z))])
    R, t, delta = T_ck[:3, :3].copy(), T_ck[:3, 3].copy(), 0.0
    zk, qk, dk = zh, q, disparity_px
    for _ in range(iterations):
        dd = dk + delta
        if np.any(dd <= 0.05):  # points the offset puts at or beyond infinity leave the fit
            keep = dd > 0.05
            if np.count_nonzero(keep) < MIN_POINTS:
                return float("nan"), float("inf")
            zk, qk, dk, dd = zk[keep], qk[keep], dk[keep], dd[keep]
        e0, e1 = np.zeros((len(zk), 3)), np.zeros((len(zk), 3))
        e0[:, 0] = e1[:, 1] = 1.0
        X = (zk * (fb / dd)[:, None]) @ R.T  # keyframe points rotated into the current frame
        P = X + t
        if np.any(P[:, 2] <= 1e-9):
            return float("nan"), float("inf")
        x, y, s = P[:, 0] / P[:, 2], P[:, 1] / P[:, 2], fx / P[:, 2]
        e0[:, 2], e1[:, 2] = -x, -y  # rows of the projection's Jacobian, over s
        r = np.column_stack([qk[:, 0] - x, qk[:, 1] - y]) * fx
        dX = -X / dd[:, None]  # d(point) / d(delta)
        A = np.empty((len(P), 2, 7))
        for i, e in enumerate((e0, e1)):
            A[:, i, :3] = np.cross(X, e) * s[:, None]
            A[:, i, 3:6] = e * s[:, None]
            A[:, i, 6] = np.einsum("ij,ij->i", e, dX) * s
        j = A[:, :, 6]
        c = 2.0 / (1.0 + 2.0 * np.einsum("ij,ij->i", j, j))
        jr = np.einsum("ij,ij->i", j, r)
        m2 = np.einsum("ij,ij->i", r, r) - c * jr**2
        m = np.sqrt(np.maximum(m2, 0.0))
        scale = 1.4826 * np.median(m) + 1e-12
        hw = np.minimum(1.0, HUBER_K * scale / np.maximum(m, 1e-12))
        Aj = np.einsum("nik,ni->nk", A, j)
        A2 = A.reshape(-1, 7)
        hw2 = np.repeat(hw, 2)
        H = (A2 * hw2[:, None]).T @ A2 - (Aj * (hw * c)[:, None]).T @ Aj
        g = (A2 * hw2[:, None]).T @ r.ravel() - Aj.T @ (hw * c * jr)
        if np.linalg.cond(H) > 1e14:
            return float("nan"), float("inf")
        dx = np.linalg.solve(H, g)
        R = _exp_so3(dx[:3]) @ R
        t = t + dx[3:6]
        delta += float(dx[6])
        if not np.isfinite(delta):
            return float("nan"), float("inf")
        if abs(dx[6]) < 1e-5:
            break
    s2 = float(np.sum(hw * m2) / max(np.sum(hw) - 7.0, 1.0))
    return delta, float(np.sqrt(s2 * np.linalg.inv(H)[6, 6]))


@dataclass(frozen=True)
class Step:
    """One counted step: frame ``index`` against keyframe ``keyframe`` (frame indices), the offset read."""

    index: int
    keyframe: int
    delta_px: float
    se_px: float


@dataclass(frozen=True)
class OffsetEstimate:
    """The offset from ``steps``: ``value_px`` the median over keyframes of each keyframe's median step,
    ``sigma_px`` its statistical standard deviation from their spread, ``keyframes`` and ``steps`` the
    counts it rests on."""

    value_px: float
    sigma_px: float
    keyframes: int
    steps: int

    @classmethod
    def of(cls, steps: list[Step]) -> OffsetEstimate:
        if not steps:
            return cls(float("nan"), float("inf"), 0, 0)
        by_kf: dict[int, list[float]] = {}
        for s in steps:
            by_kf.setdefault(s.keyframe, []).append(s.delta_px)
        v = np.array([np.median(d) for d in by_kf.values()])
        med = float(np.median(v))
        spread = 1.4826 * float(np.median(np.abs(v - med))) if len(v) > 1 else float("inf")
        return cls(med, 1.2533 * spread / np.sqrt(len(v)), len(v), len(steps))

    @property
    def total_sigma_px(self) -> float:
        """The statistical and the systematic part (:data:`SYSTEMATIC_PX`) together."""
        return float(np.hypot(self.sigma_px, SYSTEMATIC_PX))

    @property
    def evident(self) -> bool:
        """Distinguishable from zero: enough keyframes, :data:`EVIDENCE_SIGMAS` total sigmas away."""
        return (self.keyframes >= MIN_KEYFRAMES and np.isfinite(self.value_px)
                and abs(self.value_px) >= EVIDENCE_SIGMAS * self.total_sigma_px)

    def as_dict(self) -> dict:
        return {"estimate_px": _num(self.value_px), "sigma_px": _num(self.sigma_px),
                "systematic_px": SYSTEMATIC_PX, "keyframes": self.keyframes, "steps": self.steps}


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


@dataclass
class DisparityOffset:
    """The self-calibration of one run.  ``steps``: the steps observed while no offset was applied (the
    estimate's data); ``applied_px``: the one value the keyframes made from then on carry (0 until the
    offset is found); ``found`` the estimate when it was fixed and ``found_at_frame`` its frame;
    ``applied_from_frame`` the first keyframe that carries it; ``restarted`` the run began again with it;
    ``diagnostic``: the steps observed after it was fixed (kept, never used)."""

    steps: list[Step] = field(default_factory=list)
    diagnostic: list[Step] = field(default_factory=list)
    applied_px: float = 0.0
    found: OffsetEstimate | None = None
    found_at_frame: int | None = None
    applied_from_frame: int | None = None
    restarted: bool = False
    keyframes_made: int = 0
    _restart_due: bool = False

    def observe(self, index: int, keyframe: int, z: np.ndarray, q: np.ndarray, raw_disparity_px: np.ndarray,
                T_ck: np.ndarray, fx: float, baseline_m: float) -> None:
        """One tracked step of frame ``index`` against keyframe ``keyframe``: keyframe-left ``z`` and
        current-left ``q`` (normalized), the keyframe's raw (uncorrected) disparities of those points (px),
        the tracked pose ``T_ck`` (the fit's start), the rectified focal (px) and baseline (m)."""
        ok = np.isfinite(raw_disparity_px) & (raw_disparity_px > 0)
        if ok.sum() < MIN_POINTS:
            return
        d10, d90 = np.percentile(raw_disparity_px[ok], [10, 90])
        if d10 > MAX_EXTRAPOLATION * (d90 - d10):
            return
        delta, se = step_offset(z[ok], q[ok], raw_disparity_px[ok], T_ck, fx, baseline_m)
        if not (np.isfinite(delta) and se < MAX_STEP_SE_PX):
            return
        self.add(Step(int(index), int(keyframe), float(delta), float(se)))

    def add(self, step: Step) -> None:
        """A counted step: to the estimate while none is applied (deciding whether the offset is found), to
        the diagnostic after."""
        if self.found is not None:
            self.diagnostic.append(step)
            return
        self.steps.append(step)
        est = OffsetEstimate.of(self.steps)
        if est.evident:
            self.found, self.found_at_frame, self.applied_px = est, step.index, est.value_px
            self._restart_due = self.keyframes_made <= RESTART_MAX_KEYFRAMES

    def keyframe_made(self, index: int, offset_px: float) -> None:
        """A keyframe at frame ``index`` was made carrying ``offset_px``."""
        self.keyframes_made += 1
        if offset_px and self.applied_from_frame is None:
            self.applied_from_frame = int(index)

    @property
    def value(self) -> float:
        """The offset (px) the next keyframe's disparities are raised by: the applied one, 0 before."""
        return self.applied_px

    @property
    def calls_for_restart(self) -> bool:
        """The offset was just found within :data:`RESTART_MAX_KEYFRAMES` keyframes in the run's first
        pass: the run is better begun again with it."""
        return self._restart_due and not self.restarted

    def carried(self) -> DisparityOffset:
        """The self-calibration for the restarted run: the same steps and fixed value, nothing applied yet."""
        return DisparityOffset(steps=list(self.steps), applied_px=self.applied_px, found=self.found,
                               found_at_frame=self.found_at_frame, restarted=True)

    def record(self) -> dict:
        """What ran, for ``status.json``: the estimate (at the decision when found, else over the run), the
        applied value, from which frame and how, and the diagnostic steps after it."""
        est = self.found if self.found is not None else OffsetEstimate.of(self.steps)
        diag = OffsetEstimate.of(self.diagnostic)
        return {**est.as_dict(), "applied_px": float(self.applied_px), "found_at_frame": self.found_at_frame,
                "applied_from_frame": self.applied_from_frame, "restarted": self.restarted,
                "diagnostic_px": _num(diag.value_px), "diagnostic_steps": diag.steps}


def describe_record(rec: dict) -> str:
    """One line on a run's self-calibration from its record (:meth:`DisparityOffset.record`, status.json's
    ``disparity_offset``): the estimate with its uncertainty, and what was applied from where."""
    if rec.get("estimate_px") is None:
        return f"no estimate ({rec.get('steps', 0)} steps counted); none applied"
    spread = "no spread yet" if rec.get("sigma_px") is None else f"+- {rec['sigma_px']:.3f} (spread)"
    est = (f"estimate {rec['estimate_px']:+.3f} px {spread} +- {rec['systematic_px']:.3f} (systematic) over "
           f"{rec['keyframes']} keyframe(s)")
    if not rec.get("applied_px"):
        return est + "; not distinguishable from 0, none applied"
    how = "the run restarted with it" if rec.get("restarted") else f"applied from frame {rec['applied_from_frame']}"
    return f"{est}; {rec['applied_px']:+.3f} px applied, found at frame {rec['found_at_frame']}, {how}"
