"""Relative pose error (RPE) via evo's ``RPE``.

For pairs ``(i, j)`` of matched poses, ``E = inv(inv(Q_i) Q_j) @ inv(P_i) P_j`` (Q ground truth, P
estimate, TUM RGB-D definition as evo implements it); the translation error is ``|t(E)|`` in metres and
the rotation error the angle of ``R(E)`` in degrees.  Pairs are consecutive (not all pairs) and chosen
by the delta:

* ``frames``: ``j = i + delta`` among the matched poses (evo ``Unit.frames``);
* ``m``: GT path length between i and j equal to delta within 10 % (evo ``Unit.meters``, pairs from the
  reference);
* ``s``: ``t_j - t_i`` equal to delta within 10 % (evo has no time delta: pairs chosen here, the error
  of each pair computed with evo's ``RPE.rpe_base``).

RPE is invariant to a rigid alignment; it is computed on the aligned estimate anyway, so that with
``sim3`` the scale is corrected (as kitti-odom-eval does).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gevi_cli.errors import GeviError
from gevi_cli.trajectory import Trajectory

RPE_UNITS = ("frames", "m", "s")


@dataclass(frozen=True)
class RpeResult:
    """RPE statistics: translation in metres, rotation in degrees, over ``n_pairs`` pose pairs."""

    delta: float
    unit: str
    trans_mean: float
    trans_rmse: float
    trans_median: float
    trans_max: float
    rot_mean_deg: float
    rot_rmse_deg: float
    n_pairs: int
    trans_errors: np.ndarray = field(repr=False, compare=False, default=None)
    rot_errors_deg: np.ndarray = field(repr=False, compare=False, default=None)
    pairs: np.ndarray = field(repr=False, compare=False, default=None)

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("delta", "unit", "trans_mean", "trans_rmse", "trans_median",
                                              "trans_max", "rot_mean_deg", "rot_rmse_deg", "n_pairs")}


def _pairs_by_time(t_ns: np.ndarray, delta_s: float, rel_tol: float = 0.1) -> list[tuple[int, int]]:
    """Consecutive pairs (i, j): j is the pose closest to ``t_i + delta_s`` if within ``rel_tol * delta_s``;
    the next pair starts at j (like evo's consecutive path-length pairs)."""
    t = (t_ns - t_ns[0]).astype(np.float64) * 1e-9
    pairs, i = [], 0
    n = len(t)
    while i < n - 1:
        target = t[i] + delta_s
        k = int(np.searchsorted(t, target))
        cands = [c for c in (k - 1, k) if i < c < n]
        if not cands:
            break
        j = min(cands, key=lambda c: abs(t[c] - target))
        if abs(t[j] - target) <= delta_s * rel_tol:
            pairs.append((i, j))
            i = j
        else:
            i += 1
    return pairs


def _angles_deg(R: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return np.degrees(Rotation.from_matrix(R).magnitude())


def compute_rpe(gt: Trajectory, est: Trajectory, delta: float = 1.0, unit: str = "frames",
                where: str = "--rpe-delta") -> RpeResult:
    """RPE of matched trajectories of equal length (see module docstring)."""
    from gevi_cli.evaluation.evo_compat import RPE, PoseRelation, Unit, filters, to_evo

    if unit not in RPE_UNITS:
        raise GeviError("--rpe-unit", f"unknown unit {unit!r}; choose one of {', '.join(RPE_UNITS)}")
    if delta <= 0 or (unit == "frames" and float(delta) != int(delta)):
        raise GeviError("--rpe-delta", f"must be a positive {'integer ' if unit == 'frames' else ''}number, got {delta:g}")
    ref, es = to_evo(gt), to_evo(est)
    if unit == "s":
        pairs = _pairs_by_time(gt.t_ns, float(delta))
        if not pairs:
            raise GeviError(where, f"no pose pair is {delta:g} s apart (trajectory spans {gt.duration_s:.3g} s)")
        Tq, Tp = ref.poses_se3, es.poses_se3
        E = [RPE.rpe_base(Tq[i], Tq[j], Tp[i], Tp[j]) for i, j in pairs]
        te = np.array([np.linalg.norm(e[:3, 3]) for e in E])
        re = _angles_deg(np.asarray(E)[:, :3, :3])
    else:
        evo_unit = Unit.frames if unit == "frames" else Unit.meters
        d = int(delta) if unit == "frames" else float(delta)
        try:
            mt = RPE(PoseRelation.translation_part, d, evo_unit, all_pairs=False, pairs_from_reference=True)
            mt.process_data((ref, es))
        except filters.FilterException:
            span = f"{len(gt)} matched poses" if unit == "frames" else f"a {gt.path_length_m:.3g} m GT path"
            raise GeviError(where, f"no pose pair is {delta:g} {unit} apart ({span})") from None
        te = np.asarray(mt.error, dtype=np.float64)
        # rotation: the angle of the same evo error poses E, in one batch (evo's rotation_angle_deg
        # relation computes |log(R(E))| pose by pose, ~0.3 ms each); tested equal to evo's numbers.
        re = _angles_deg(np.asarray(mt.E)[:, :3, :3])
        pairs = np.asarray(mt.delta_ids, dtype=np.int64)  # evo keeps the second index of each pair
    return RpeResult(
        delta=float(delta), unit=unit,
        trans_mean=float(np.mean(te)), trans_rmse=float(np.sqrt(np.mean(te ** 2))),
        trans_median=float(np.median(te)), trans_max=float(np.max(te)),
        rot_mean_deg=float(np.mean(re)), rot_rmse_deg=float(np.sqrt(np.mean(re ** 2))), n_pairs=len(te),
        trans_errors=te, rot_errors_deg=re, pairs=np.asarray(pairs),
    )
