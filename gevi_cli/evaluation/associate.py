"""Pair estimate poses with ground-truth poses.

* Stamped trajectories: nearest stamp within ``max_diff_s`` (default 10 ms) after adding
  ``t_offset_s`` to the estimate stamps (``t_gt = t_est + t_offset``), using evo's
  ``matching_time_indices`` (starting from the sparser trajectory, so no pose is used twice).
* Indexed trajectories (KITTI files, no stamps): by frame index (``t_ns / 0.1 s``).

The result carries the counts and the coverage used by the failed rule:
``coverage = (last matched GT stamp - first matched GT stamp) / (GT time span)``.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from gevi_cli.errors import DataError, GeviError
from gevi_cli.trajectory import Trajectory
from gevi_cli.trajectory.trajectory import KITTI_NOMINAL_PERIOD_NS


@dataclass(frozen=True)
class Association:
    """Matched pose pairs: ``gt.select(i)`` and ``est.select(i)`` describe the same instant.

    Attributes:
        gt, est: the matched sub-trajectories (same length, GT frame/units unchanged).
        gt_index, est_index: indices into the original trajectories.
        n_est, n_gt: pose counts of the original estimate and ground truth.
        coverage: matched fraction of the GT time span, 0..1.
        by_index: True when matched by KITTI frame index.
    """

    gt: Trajectory
    est: Trajectory
    gt_index: np.ndarray
    est_index: np.ndarray
    n_est: int
    n_gt: int
    coverage: float
    by_index: bool

    def over(self, gt: Trajectory) -> Association:
        """The same matched pairs counted against ``gt``, a part of the ground truth that holds every matched
        pose (a ground truth trimmed to the frames a run was given): its pose count, indices and coverage."""
        return dataclasses.replace(self, gt_index=np.searchsorted(gt.t_ns, self.gt.t_ns), n_gt=len(gt),
                                   coverage=_coverage(gt.t_ns, self.gt.t_ns))

    @property
    def n_matched(self) -> int:
        return len(self.gt_index)

    def summary(self) -> str:
        return (f"matched {self.n_matched} of {self.n_est} poses, "
                f"coverage {100.0 * self.coverage:.1f} % of the GT time span")


def _span_text(t_ns: np.ndarray, indexed: bool) -> str:
    if indexed:
        a, b = t_ns[0] // KITTI_NOMINAL_PERIOD_NS, t_ns[-1] // KITTI_NOMINAL_PERIOD_NS
        return f"frames {a}..{b}"
    return f"{t_ns[0] * 1e-9:.3f}..{t_ns[-1] * 1e-9:.3f} s"


def associate(gt: Trajectory, est: Trajectory, max_diff_s: float = 0.01, t_offset_s: float = 0.0) -> Association:
    """Associate ``est`` with ``gt`` (see module docstring).

    Raises:
        GeviError: stamped vs indexed mix, or no pose pair at all (the message gives both time ranges).
    """
    where = est.meta.get("path") or est.name or "estimate"
    if gt.indexed != est.indexed:
        which = "ground truth" if gt.indexed else "estimate"
        raise GeviError(where, f"the {which} is a KITTI file without timestamps and the other one is stamped; "
                               "convert both to the same kind (KITTI by frame, or TUM/EuRoC with stamps)")
    if gt.indexed:
        gi = gt.t_ns // KITTI_NOMINAL_PERIOD_NS
        ei = est.t_ns // KITTI_NOMINAL_PERIOD_NS + int(round(t_offset_s / 0.1))
        common, g_idx, e_idx = np.intersect1d(gi, ei, assume_unique=True, return_indices=True)
        by_index = True
    else:
        from gevi_cli.evaluation.evo_compat import sync

        t0 = int(gt.t_ns[0])
        ts_gt = (gt.t_ns - t0).astype(np.float64) * 1e-9
        ts_est = (est.t_ns - t0).astype(np.float64) * 1e-9 + float(t_offset_s)
        if len(est) <= len(gt):
            e_idx, g_idx = sync.matching_time_indices(ts_est, ts_gt, max_diff_s, 0.0)
        else:
            g_idx, e_idx = sync.matching_time_indices(ts_gt, ts_est, max_diff_s, 0.0)
        g_idx, e_idx = np.asarray(g_idx, dtype=np.int64), np.asarray(e_idx, dtype=np.int64)
        by_index = False
    if len(g_idx) == 0:
        off = f" with --t-offset {t_offset_s:g} s" if t_offset_s else ""
        tol = "" if gt.indexed else f" within {max_diff_s * 1e3:g} ms"
        raise DataError(where, f"no pose matches the ground truth{tol}{off}: estimate spans "
                               f"{_span_text(est.t_ns, est.indexed)}, ground truth spans "
                               f"{_span_text(gt.t_ns, gt.indexed)}; check the stamp units or pass --t-offset")
    return Association(gt=gt.select(g_idx), est=est.select(e_idx), gt_index=g_idx, est_index=e_idx,
                       n_est=len(est), n_gt=len(gt), coverage=_coverage(gt.t_ns, gt.t_ns[g_idx]), by_index=by_index)


def _coverage(gt_t_ns: np.ndarray, matched_t_ns: np.ndarray) -> float:
    """The matched fraction of the ground truth's time span (1 for a ground truth of one instant)."""
    span = float(gt_t_ns[-1] - gt_t_ns[0])
    matched_span = float(matched_t_ns[-1] - matched_t_ns[0])
    return matched_span / span if span > 0 else 1.0
