"""Scale of an estimate against the ground truth: the path-length ratio and the median step-length ratio.

Both figures compare the lengths of the position steps between consecutive *associated* poses, in time
order, of the estimate and of the ground truth:

* ``path_ratio = sum_k |dp_est_k| / sum_k |dp_gt_k|`` over every step ``k`` (``dp_k = p_{k+1} - p_k``);
* ``step_ratio_median = median_k |dp_est_k| / |dp_gt_k|`` over the steps with ``|dp_gt_k| >=``
  :data:`MIN_STEP_M` (1 cm): a step that short is dominated by the ground truth's own noise.

1 is the right scale; 1.08 means the estimate travels 8 % too far.  ``n/a`` (NaN, ``None`` in JSON):
the median with fewer than :data:`MIN_STEPS` steps of 1 cm (a sequence at rest); the path ratio when the
ground truth's path over the associated poses is shorter than :data:`MIN_PATH_M` (5 cm, the least
motion the median accepts).  A ground truth that jitters at rest can exceed 5 cm of path; then the path
ratio compares the two noises, and the median's n/a says so.

Frames: the estimate poses are those after the conversion into the ground truth's sensor frame
(``body`` or ``cam0``, with ``T_B_C0``: the lever arm changes a turning path's length), the frame ATE
compares, and *before* alignment.  Step lengths are invariant under any rigid (SE(3), posyaw, origin)
change of the estimate's world frame, so these figures are the same for every alignment; a Sim(3)
alignment would multiply the estimate's steps by its scale and hide the very error measured here, so
they are computed on the unscaled estimate.

Relation to evo's Sim(3) scale: evo's Umeyama ``s`` scales the *estimate* onto the ground truth
(``p_gt ~ s R p_est + t``), so for an estimate whose scale error is uniform, ``s = 1 / path_ratio``
(exactly, for ``p_est = c R p_gt + t``); a scale that drifts along the path makes the two differ
(Umeyama weights the poses far from the centroid most, the path ratio every metre of travel alike).
Units: metres; the ratios are unitless.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.trajectory import Trajectory

#: Ground-truth steps shorter than this (m) do not enter the median step ratio.
MIN_STEP_M = 0.01
#: The median step ratio needs at least this many steps of MIN_STEP_M or more.
MIN_STEPS = 5
#: The path ratio needs a ground-truth path at least this long (m): MIN_STEPS steps of MIN_STEP_M.
MIN_PATH_M = MIN_STEPS * MIN_STEP_M


@dataclass(frozen=True)
class ScaleResult:
    """Path-length and median step-length ratio, estimate over ground truth (unitless; NaN = n/a).

    ``path_length_est_m`` / ``path_length_gt_m``: the paths over the associated poses (m); ``n_steps``:
    consecutive associated steps; ``n_steps_used``: those of at least :data:`MIN_STEP_M` in the
    ground truth (the median's support); ``step_ratios``: their ratios, in time order.
    """

    path_ratio: float
    step_ratio_median: float
    path_length_est_m: float
    path_length_gt_m: float
    n_steps: int
    n_steps_used: int
    step_ratios: np.ndarray = field(repr=False, compare=False, default=None)

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("path_ratio", "step_ratio_median", "path_length_est_m",
                                              "path_length_gt_m", "n_steps", "n_steps_used")}


def step_lengths(traj: Trajectory) -> np.ndarray:
    """``|p_{k+1} - p_k|`` (m) of consecutive poses, in the order given (n - 1 values)."""
    return np.linalg.norm(np.diff(traj.positions, axis=0), axis=1)


def compute_scale(gt: Trajectory, est: Trajectory) -> ScaleResult:
    """Scale figures of associated trajectories of equal length (see module docstring): ``est`` in the
    ground truth's sensor frame, not aligned (or rigidly aligned), never Sim(3)-scaled."""
    if len(gt) != len(est):
        raise ValueError(f"associated trajectories differ in length: {len(gt)} and {len(est)}")
    d_gt, d_est = step_lengths(gt), step_lengths(est)
    len_gt, len_est = float(d_gt.sum()), float(d_est.sum())
    used = d_gt >= MIN_STEP_M
    ratios = d_est[used] / d_gt[used]
    return ScaleResult(
        path_ratio=len_est / len_gt if len_gt >= MIN_PATH_M else float("nan"),
        step_ratio_median=float(np.median(ratios)) if len(ratios) >= MIN_STEPS else float("nan"),
        path_length_est_m=len_est, path_length_gt_m=len_gt, n_steps=len(d_gt), n_steps_used=int(used.sum()),
        step_ratios=ratios)
