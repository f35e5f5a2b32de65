"""Evaluate one estimate against one ground truth: associate, convert frames, align, ATE/RPE/KITTI, scale.

Frames: the estimate is brought into the sensor frame of the ground truth (``body`` = IMU, ``cam0``)
with ``T_B_C0`` (cam0 -> body) *before* alignment, so ATE, RPE, the KITTI metric and the scale figures
(:mod:`gevi_cli.evaluation.scale`, on the associated poses before alignment) all compare the same frame.
Units: metres, degrees, seconds.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.evaluation.align import Alignment, align, collinearity_warning
from gevi_cli.evaluation.associate import Association, associate
from gevi_cli.evaluation.ate import AteResult, compute_ate
from gevi_cli.evaluation.kitti_devkit import KittiResult, kitti_errors, raw_poses
from gevi_cli.evaluation.rpe import RpeResult, compute_rpe
from gevi_cli.evaluation.scale import ScaleResult, compute_scale
from gevi_cli.trajectory import Trajectory

#: Translational RPE above this multiple of what the aligned position errors imply flags a frame mix-up.
FRAME_MIXUP_RATIO = 3.0
#: An ATE RMSE above this multiple of (the matched ground truth's extent + 1 m) is not an error of a
#: real estimate in the ground truth's world: the estimate is corrupt (or diverged beyond meaning).
ABSURD_ATE_RATIO = 1000.0


@dataclass(frozen=True)
class EvalSettings:
    """Options shared by every evaluation (see docs/eval.md for the CLI names)."""

    align: str = "auto"
    n_align: int = -1
    max_diff_s: float = 0.01
    t_offset_s: float = 0.0
    rpe_delta: float = 1.0
    rpe_unit: str = "frames"
    min_coverage: float = 0.9
    est_frame: str = "same"  # "same" (as the GT), "body" or "cam0"
    kitti: bool = True
    allow_jumps: bool = False  # trajectories with position jumps were read as written (--allow-jumps)

    def as_dict(self) -> dict:
        return dict(self.__dict__)

    def checked(self) -> EvalSettings:
        """These settings with ``min_coverage`` as a fraction (a value above 1 is percent); a one-line
        GeviError naming the `gevi eval` option for a value out of range."""
        min_coverage = self.min_coverage / 100.0 if self.min_coverage > 1.0 else self.min_coverage
        if not 0.0 <= min_coverage <= 1.0:
            raise GeviError("--min-coverage", f"must be a fraction 0..1 (or percent 0..100), got {min_coverage:g}")
        if self.max_diff_s <= 0:
            raise GeviError("--max-diff", f"must be positive (seconds), got {self.max_diff_s:g}")
        if self.n_align == 0 or self.n_align < -1:
            raise GeviError("--n-align", f"must be -1 (all poses) or a positive count, got {self.n_align}")
        if self.rpe_delta <= 0:
            raise GeviError("--rpe-delta", f"must be positive, got {self.rpe_delta:g}")
        return dataclasses.replace(self, min_coverage=min_coverage)


@dataclass
class PairResult:
    """The result of one estimate (one trial of one method on one sequence).

    ``status`` is "ok" or "failed"; ``reason`` says why it failed (missing, no valid poses, coverage).
    """

    method: str
    sequence: str
    trial: str
    path: str | None
    status: str = "ok"
    reason: str = ""
    align: str = ""
    association: Association | None = None
    alignment: Alignment | None = None
    ate: AteResult | None = None
    rpe: RpeResult | None = None
    kitti: KittiResult | None = None
    scale: ScaleResult | None = None  # path and step-length ratios, before alignment
    warnings: list = field(default_factory=list)
    aligned: Trajectory | None = None  # aligned, matched estimate (for plots)
    lost: bool = False  # the run lost tracking: some of its poses were bridged, not estimated (batch)
    jumps: list = field(default_factory=list)  # position jumps read as written (--allow-jumps), "file:line: ..."

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def as_dict(self) -> dict:
        d = {"method": self.method, "sequence": self.sequence, "trial": self.trial, "path": self.path,
             "status": self.status, "reason": self.reason, "align": self.align, "warnings": list(self.warnings),
             "allowed_jumps": list(self.jumps)}
        if self.association is not None:
            a = self.association
            d["association"] = {"matched": a.n_matched, "est_poses": a.n_est, "gt_poses": a.n_gt,
                                "coverage": a.coverage, "by_index": a.by_index, "summary": a.summary()}
        if self.alignment is not None:
            d["alignment"] = self.alignment.as_dict()
        for key in ("ate", "rpe", "kitti", "scale"):
            val = getattr(self, key)
            d[key] = val.as_dict() if val is not None else None
        return d


def failed(method: str, sequence: str, trial: str, path, reason: str) -> PairResult:
    return PairResult(method, sequence, trial, str(path) if path else None, status="failed", reason=reason)


def to_gt_frame(est: Trajectory, est_frame: str, gt_frame: str, T_B_C0: np.ndarray | None, where: str) -> Trajectory:
    """Express estimate poses in the GT sensor frame (cam0 <-> body with ``T_B_C0``)."""
    if est_frame in ("same", "unknown") or gt_frame in ("unknown", est_frame):
        return est
    if T_B_C0 is None:
        raise GeviError("--est-frame", f"{where}: estimate poses are {est_frame} poses but the ground truth is "
                                       f"{gt_frame}; pass a dataset as ground truth or --T-B-C0 FILE")
    if est_frame == "cam0" and gt_frame == "body":
        return est.with_sensor_frame(np.linalg.inv(T_B_C0), "body")
    if est_frame == "body" and gt_frame == "cam0":
        return est.with_sensor_frame(T_B_C0, "cam0")
    raise GeviError("--est-frame", f"cannot convert {est_frame} poses to {gt_frame}")


def frame_mixup_warning(assoc: Association, est_aligned: Trajectory, rpe: RpeResult) -> str | None:
    """A warning when the translational RPE is far above what the aligned position errors imply.

    For a pair (i, j) of consistent frames, ``|t(E)| <= |e_j - e_i| + angle_i * |q_j - q_i|``; for a
    working estimate the rotation term is small, so an RPE several times the position-error term that
    is also a large fraction (>25 %) of the motion itself means the two trajectories describe different
    sensor frames (cam0 vs body).
    """
    if rpe is None or rpe.pairs is None or rpe.unit == "s" or len(rpe.trans_errors) == 0:
        return None
    e = est_aligned.positions - assoc.gt.positions
    j = np.asarray(rpe.pairs, dtype=np.int64)
    if rpe.unit != "frames":
        return None
    i = j - int(rpe.delta)
    ok = i >= 0
    i, j = i[ok], j[ok]
    if len(i) == 0:
        return None
    implied = float(np.mean(np.linalg.norm(e[j] - e[i], axis=1)))
    motion = float(np.mean(np.linalg.norm(assoc.gt.positions[j] - assoc.gt.positions[i], axis=1)))
    if rpe.trans_mean > FRAME_MIXUP_RATIO * implied + 1e-3 and rpe.trans_mean > 0.25 * motion:
        return (f"translational RPE {rpe.trans_mean:.4g} m is {rpe.trans_mean / max(implied, 1e-12):.1f}x what the "
                f"aligned position errors imply ({implied:.3g} m) and {100 * rpe.trans_mean / max(motion, 1e-12):.0f} % "
                "of the motion: estimate and ground truth probably describe different sensor frames "
                "(cam0 vs body); check --est-frame and T_B_C0")
    return None


def absurd_ate_reason(gt: Trajectory, ate: AteResult) -> str | None:
    """Why an ATE (m) cannot be a real estimate's error against ``gt`` (the matched ground truth), or None.

    After any alignment a real estimate's poses stay in the ground truth's world: its RMSE is at most
    a few times the ground truth's extent (bounding-box diagonal, m), even for a run that drifted badly.
    :data:`ABSURD_ATE_RATIO` times that extent (+1 m, for a ground truth standing still) is beyond any
    such estimate; a corrupt file (a column scaled, a frame offset added) reaches it easily.
    """
    extent = float(np.linalg.norm(np.ptp(gt.positions, axis=0)))
    if ate.trans_rmse <= ABSURD_ATE_RATIO * (extent + 1.0):  # a nan ATE is not physical either
        return None
    return (f"ATE {ate.trans_rmse:.3g} m is not physical: {ate.trans_rmse / (extent + 1.0):.3g} x the ground truth's "
            f"extent ({extent:.3g} m + 1 m); the estimate is corrupt (or diverged)")


def evaluate_pair(gt: Trajectory, est: Trajectory, settings: EvalSettings, align_method: str, *, method: str,
                  sequence: str, trial: str = "", T_B_C0: np.ndarray | None = None,
                  gt_raw: tuple | None = None) -> PairResult:
    """Evaluate one estimate (see module docstring); raises GeviError on unusable input."""
    path = est.meta.get("path")
    where = path or est.name
    res = PairResult(method, sequence, trial, path, align=align_method)
    res.warnings.extend(est.meta.get("warnings", []))
    res.jumps = list(gt.meta.get("allowed_jumps", [])) + list(est.meta.get("allowed_jumps", []))
    if len(est) == 0:
        return failed(method, sequence, trial, path, "no valid poses")
    est_f = to_gt_frame(est, settings.est_frame, gt.frame, T_B_C0, where)
    assoc = associate(gt, est_f, settings.max_diff_s, settings.t_offset_s)
    res.association = assoc
    if assoc.n_matched < 3:
        res.status, res.reason = "failed", f"only {assoc.n_matched} matched poses"
        return res
    res.scale = compute_scale(assoc.gt, assoc.est)  # unaligned: a Sim(3) scale would hide the error
    aligned, alignment = align(assoc.gt, assoc.est, align_method, settings.n_align)
    w = collinearity_warning(assoc.gt, align_method, settings.n_align)
    if w:
        res.warnings.append(f"{where}: {w}")
    res.alignment = alignment
    res.aligned = aligned
    res.ate = compute_ate(assoc.gt, aligned)
    absurd = absurd_ate_reason(assoc.gt, res.ate)
    if absurd:
        res.status, res.reason = "failed", absurd
        return res
    try:
        res.rpe = compute_rpe(assoc.gt, aligned, settings.rpe_delta, settings.rpe_unit)
    except GeviError as exc:
        res.warnings.append(f"{where}: RPE: {exc.message}")
    if settings.kitti:
        res.kitti = _kitti(gt, est_f, assoc, alignment, gt_raw, use_raw=est_f is est)
    w = frame_mixup_warning(assoc, aligned, res.rpe)
    if w:
        res.warnings.append(f"{where}: {w}")
    return gate_coverage(res, settings.min_coverage)


def gate_coverage(res: PairResult, min_coverage: float) -> PairResult:
    """``res``, failed when it matches less than ``min_coverage`` of the ground truth's time span."""
    if res.ok and res.association is not None and res.association.coverage < min_coverage:
        res.status = "failed"
        res.reason = (f"coverage {100 * res.association.coverage:.1f} % of the GT time span < "
                      f"{100 * min_coverage:g} % (--min-coverage)")
    return res


def _kitti(gt: Trajectory, est: Trajectory, assoc: Association, alignment: Alignment, gt_raw,
           use_raw: bool) -> KittiResult:
    """KITTI metric on GT frames (indexed data) or on the matched pairs (stamped data).

    ``use_raw``: the estimate is unchanged from its file, so KITTI files may be re-read as written.
    """
    if assoc.by_index:
        gf, gT = gt_raw if gt_raw is not None else raw_poses(gt)
        if use_raw:
            ef, eT = raw_poses(est)
        else:
            ef, eT = est.t_ns // 100_000_000, est.matrices
        # the same frame shift the association applied (--t-offset on indexed data)
        ef = ef + int(gf[assoc.gt_index[0]] - assoc.est.t_ns[0] // 100_000_000)
        return kitti_errors(gf, gT, ef, eT, scale=alignment.scale)
    n = assoc.n_matched
    frames = np.arange(n)
    return kitti_errors(frames, assoc.gt.matrices, frames, assoc.est.matrices, scale=alignment.scale)
