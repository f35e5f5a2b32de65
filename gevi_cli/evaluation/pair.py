"""One estimate against one ground truth: the library call under `gevi eval`, `gevi run` and
:func:`gevi_cli.api.evaluate`.

The ground truth is read as `gevi eval --gt` reads it (a trajectory file or a dataset folder, with the
dataset's cam0->body ``T_B_C0``); a KITTI ground truth (no stamps) is stamped with the sequence's
``times.txt`` for an estimate that is the primary trajectory of a `gevi run` folder of that sequence;
then :func:`~gevi_cli.evaluation.evaluate.evaluate_pair` associates, aligns and computes ATE, RPE and
the KITTI metric.  Poses: metres; stamps: ns.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gevi_cli.errors import DataError
from gevi_cli.evaluation import inputs as inp
from gevi_cli.evaluation.evaluate import EvalSettings, PairResult, evaluate_pair, failed
from gevi_cli.evaluation.kitti_devkit import raw_poses
from gevi_cli.trajectory import Trajectory


@dataclass
class GroundTruth:
    """A sequence's ground truth: its trajectory, the cam0->body ``T_B_C0`` (4x4; None when unknown),
    the KITTI rows as written (indexed ground truth, else None), where it was read from (None: given in
    memory) and the ``times.txt`` files it was stamped with for `gevi run` estimates."""

    trajectory: Trajectory
    T_B_C0: np.ndarray | None = None
    raw: tuple | None = None
    path: Path | None = None
    stamped_from: list = field(default_factory=list)
    _stamped: dict = field(default_factory=dict, repr=False)

    def info(self) -> dict:
        """What the eval folder records of it (``metrics.json`` "sequences"); span in s, length in m."""
        gt = self.trajectory
        d = {"groundtruth": str(self.path), "poses": len(gt), "frame": gt.frame, "indexed": gt.indexed,
             "span_s": gt.duration_s, "path_length_m": gt.path_length_m}
        if self.stamped_from:
            d["stamped_from"] = list(self.stamped_from)
        return d


def groundtruth(trajectory: Trajectory, T_B_C0: np.ndarray | None = None) -> GroundTruth:
    """A ground truth given in memory."""
    return GroundTruth(trajectory, T_B_C0, raw_poses(trajectory) if trajectory.indexed else None)


def read_groundtruth(path, gt_frame: str = "body", allow_jumps: bool = False,
                     T_B_C0: np.ndarray | None = None) -> GroundTruth:
    """The ground truth of a trajectory file (its sensor frame ``gt_frame``) or a dataset folder;
    ``T_B_C0`` replaces the dataset's cam0->body transform (``--T-B-C0``)."""
    path = Path(path)
    gt, T = inp.load_groundtruth(path, gt_frame, allow_jumps)
    truth = groundtruth(gt, T_B_C0 if T_B_C0 is not None else T)
    truth.path = path
    return truth


def _for_estimate(gt: GroundTruth, est: Trajectory) -> tuple[Trajectory, tuple | None]:
    """(ground truth, its raw KITTI rows) to evaluate ``est`` with.

    A KITTI ground truth has no stamps, a `gevi run` estimate has the sequence's: when the estimate is
    the primary trajectory of a run folder of that KITTI sequence, the ground truth is stamped with the
    sequence's ``times.txt`` (row i = frame i), the same stamps `gevi run` gives it without ``--gt``.
    Anything else is returned unchanged (the association then explains a stamped/unstamped mix).
    """
    path = est.meta.get("path")
    if not gt.trajectory.indexed or est.indexed or not path:
        return gt.trajectory, gt.raw
    times = inp.run_sequence_times(Path(path).parent)
    if times is None:
        return gt.trajectory, gt.raw
    if times not in gt._stamped:
        gt._stamped[times] = inp.stamp_kitti_groundtruth(gt.trajectory, times)
        gt.stamped_from.append(str(times))
    return gt._stamped[times], None


def evaluate_estimate(gt: GroundTruth, est: Trajectory, settings: EvalSettings, align: str, *, method: str,
                      sequence: str, trial: str = "") -> PairResult:
    """ATE, RPE and KITTI metric of ``est`` against ``gt`` aligned by ``align`` (see module docstring);
    raises GeviError on unusable input."""
    pair_gt, pair_raw = _for_estimate(gt, est)
    return evaluate_pair(pair_gt, est, settings, align, method=method, sequence=sequence, trial=trial,
                         T_B_C0=gt.T_B_C0, gt_raw=pair_raw)


def evaluate_file(gt: GroundTruth, path: Path, settings: EvalSettings, align: str, *, method: str, sequence: str,
                  trial: str = "", keep_going: bool = False, warn=None) -> PairResult:
    """:func:`evaluate_estimate` of the trajectory file ``path``.  A file without pose rows is a failed
    result ("no valid poses"); with ``keep_going`` so is any other unreadable input (its one-line error,
    also handed to ``warn``), else that DataError is raised."""
    from gevi_cli.trajectory import read_trajectory

    try:
        est = read_trajectory(path, name=method, allow_jumps=settings.allow_jumps)
        return evaluate_estimate(gt, est, settings, align, method=method, sequence=sequence, trial=trial)
    except DataError as exc:
        if exc.message.startswith("contains no pose rows"):
            return failed(method, sequence, trial, path, "no valid poses")
        if not keep_going:
            raise
        if warn is not None:
            warn(exc.one_line())
        return failed(method, sequence, trial, path, exc.one_line())
