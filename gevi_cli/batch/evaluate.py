"""The evaluator over a batch's results tree, with `gevi eval`'s code (evaluate_pair, build_tables).

Every comparison across methods is SE(3) in the body frame with RPE over consecutive frames; the
stereo-inertial methods (GeVI and its ablations) are also aligned in posyaw (4-DOF: gravity is
known), in tables of their own.  A crashed run is a ``failed`` cell with its message; a (sequence,
method) never run has no result at all and reads ``n/a``.  Units: metres, degrees, seconds.

Each run is evaluated once: the batch takes the evaluation its run path made
(:func:`gevi_cli.run.pipeline.run_and_evaluate`) and only trims the ground truth to the run's frames
for the coverage figure and gate; a run without one (finished by an earlier invocation) is evaluated here.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gevi_cli.batch.worker import read_marker
from gevi_cli.errors import GeviError


@dataclass
class BatchResults:
    """PairResults per alignment, per-run facts (state, frames, timing) and sequence ground truths."""

    se3: list = field(default_factory=list)
    posyaw: list = field(default_factory=list)
    online: list = field(default_factory=list)  # SE(3) results of the online trajectories (eval: online)
    runs: list = field(default_factory=list)  # dicts: run_id, method, sequence, trial, state, message, ...
    gts: dict = field(default_factory=dict)  # sequence -> ground truth Trajectory (trial 1)
    problems: list = field(default_factory=list)  # "<sequence>: why it could not be evaluated"


def _gt_loader():
    """load(path) -> (ground truth, its cam0->body T_B_C0 or None, its raw KITTI rows or None), read once
    per path as `gevi eval --gt` reads it."""
    from gevi_cli.evaluation.pair import read_groundtruth

    cache = {}

    def load(path: str):
        if path not in cache:
            truth = read_groundtruth(path)
            cache[path] = (truth.trajectory, truth.T_B_C0, truth.raw)
        return cache[path]

    return load


def _clip_to_run(gt, run_dir: Path, margin_s: float):
    """The ground truth over the frames the run was given (frames.csv span): a dataset whose ground
    truth outlasts its images (euroc_micro: 4.7 s of frames, 145 s of ground truth), or a run limited by
    ``max_frames``, is judged on the coverage of its own frames.  Indexed (KITTI) ground truth is kept."""
    if gt.indexed:
        return gt
    try:
        import pandas as pd

        t = pd.read_csv(run_dir / "frames.csv", usecols=["t_ns"])["t_ns"].to_numpy()
    except (OSError, ValueError, KeyError):
        return gt
    if len(t) == 0:
        return gt
    m = int(margin_s * 1e9)
    keep = (gt.t_ns >= t.min() - m) & (gt.t_ns <= t.max() + m)
    return gt.select(np.flatnonzero(keep)) if keep.sum() >= 3 else gt


def _or_none(v: float) -> float | None:
    """``v``, or None for NaN (JSON has no NaN)."""
    return None if np.isnan(v) else float(v)


def _T(spec_T, T_seq):
    if isinstance(spec_T, (tuple, list)):
        return np.asarray(spec_T, dtype=float).reshape(4, 4)
    if spec_T == "identity":
        return np.eye(4)
    if spec_T == "sequence":
        return T_seq
    from gevi_cli.evaluation.inputs import load_T_B_C0

    return load_T_B_C0(Path(spec_T))


def _same_evaluation(run_settings, settings) -> bool:
    """Whether a run's own evaluation is the batch's but for the alignment's name and the coverage gate."""
    return dataclasses.replace(run_settings, align=settings.align, min_coverage=settings.min_coverage) == settings


def _taken(ev, gt, settings, spec, trial: str, primary: Path):
    """The batch's result from a run's own evaluation ``ev`` (:class:`gevi_cli.run.pipeline.Evaluation`):
    labelled with the batch's method, sequence and trial, its coverage read against ``gt`` (the ground
    truth over the run's frames: the same matched pairs, so ATE, RPE, scale and KITTI figures are
    unchanged) and the batch's coverage gate applied."""
    from gevi_cli.evaluation.evaluate import failed, gate_coverage

    if ev.error is not None:
        return failed(spec.method, spec.sequence, trial, primary, ev.error)
    r = dataclasses.replace(ev.result, method=spec.method, sequence=spec.sequence, trial=trial)
    if r.association is not None and not r.association.by_index:
        r.association = r.association.over(gt)
    return gate_coverage(r, settings.min_coverage)


def evaluate_batch(specs, baselines, settings, inertial_methods: set, online: bool = False,
                   evaluated: dict | None = None) -> BatchResults:
    """Evaluate every finished run of ``specs`` and every baseline (see module docstring).

    ``evaluated``: the runs' own evaluations by run id (:class:`gevi_cli.batch.worker.Finished`), taken
    where their settings are the batch's (:func:`_taken`); a run finished by an earlier invocation
    (resumed batch) or evaluated otherwise (another ``rpe_delta``, ``max_diff``, alignment) is evaluated
    here from its folder."""
    from gevi_cli.evaluation.evaluate import evaluate_pair, failed
    from gevi_cli.evaluation.inputs import run_primary
    from gevi_cli.run.folder import read_status
    from gevi_cli.trajectory import Trajectory, read_trajectory

    load = _gt_loader()
    out = BatchResults()
    seq_gt_path = {}
    seq_run_dir = {}  # a run of each sequence: the frames a baseline is judged over, as the runs are
    for spec in specs:
        marker = read_marker(spec.run_dir)
        if marker is None:
            continue  # never finished: n/a
        st = read_status(spec.run_dir) or {}
        trial = f"trial{spec.trial}"
        gt_path = spec.inputs.gt or spec.source
        seq_gt_path.setdefault(spec.sequence, gt_path)
        seq_run_dir.setdefault(spec.sequence, Path(spec.run_dir))
        run = {"run_id": spec.run_id, "method": spec.method, "sequence": spec.sequence, "trial": spec.trial,
               "seed": spec.seed, "state": marker["state"], "message": marker.get("message", ""),
               "frames_total": st.get("frames_total", 0), "frames_done": st.get("frames_done", 0),
               "frames_tracked": st.get("frames_tracked", 0), "elapsed_s": st.get("elapsed_s", 0.0),
               "lost_intervals": st.get("lost_intervals", []), "wall_s": marker.get("wall_s", 0.0),
               "run_dir": spec.run_dir,
               # what ran beyond the published method: the disparity offset applied (px), the restart with it
               "disparity_offset_px": float((st.get("disparity_offset") or {}).get("applied_px", 0.0)),
               "disparity_offset_from_frame": (st.get("disparity_offset") or {}).get("applied_from_frame"),
               "online_causal": bool(st.get("online_causal", True))}
        # a stereo-inertial run's roll/pitch error, as gevi run evaluated it (the report's tilt tables)
        run.update({k: v for k, v in (st.get("evaluation") or {}).items() if k.startswith("tilt_")})
        out.runs.append(run)
        primary = run_primary(Path(spec.run_dir)) if marker["state"] != "crashed" else None
        aligns = ["se3"] + (["posyaw"] if spec.method in inertial_methods else [])
        own = {ev.align: ev for ev in (evaluated or {}).get(spec.run_id, [])
               if _same_evaluation(ev.settings, settings)}
        for align in aligns:
            bucket = out.se3 if align == "se3" else out.posyaw
            if primary is None:
                bucket.append(failed(spec.method, spec.sequence, trial, None,
                                     marker.get("message") or "crashed: no trajectory"))
                continue
            try:
                gt, T, raw = load(gt_path)
                gt = _clip_to_run(gt, Path(spec.run_dir), settings.max_diff_s)
                if align in own:
                    r = _taken(own[align], gt, settings, spec, trial, primary)
                else:
                    est = read_trajectory(primary, name=spec.method)
                    r = evaluate_pair(gt, est, settings, align, method=spec.method, sequence=spec.sequence,
                                      trial=trial, T_B_C0=T, gt_raw=raw)
            except GeviError as exc:
                r = failed(spec.method, spec.sequence, trial, primary, exc.one_line())
            r.lost = marker["state"] == "lost-tracking"
            bucket.append(r)
            if align == "se3" and spec.trial == 1 and spec.sequence not in out.gts:
                try:
                    out.gts[spec.sequence] = load(gt_path)[0]
                except GeviError as exc:
                    out.problems.append(f"{spec.sequence}: {exc.one_line()}")
        if online and primary is not None:
            # the poses as tracked, before any BA of their window (gevi run's traj_online_body.tum)
            path = Path(spec.run_dir) / "traj_online_body.tum"
            try:
                gt, T, raw = load(gt_path)
                gt = _clip_to_run(gt, Path(spec.run_dir), settings.max_diff_s)
                r = evaluate_pair(gt, read_trajectory(path, name=spec.method), settings, "se3", method=spec.method,
                                  sequence=spec.sequence, trial=trial, T_B_C0=T, gt_raw=raw)
            except GeviError as exc:
                r = failed(spec.method, spec.sequence, trial, path, exc.one_line())
            r.lost = marker["state"] == "lost-tracking"
            out.online.append(r)
        if out.se3 and out.se3[-1].ok:
            run["ate_m"] = out.se3[-1].ate.trans_rmse
            run["rpe_m"] = out.se3[-1].rpe.trans_rmse if out.se3[-1].rpe is not None else None
            scale = out.se3[-1].scale  # before alignment (gevi_cli.evaluation.scale); None in JSON = n/a
            run["path_ratio"] = _or_none(scale.path_ratio)
            run["step_ratio_median"] = _or_none(scale.step_ratio_median)
    for b in baselines:
        if b.state == "n/a":
            continue  # no result: the cell reads n/a
        if b.state == "failed" or b.sequence not in seq_gt_path:
            if b.state == "failed":
                out.se3.append(failed(b.name, b.sequence, b.trial, None, b.reason))
            continue
        try:
            gt, T_seq, raw = load(seq_gt_path[b.sequence])
            gt = _clip_to_run(gt, seq_run_dir[b.sequence], settings.max_diff_s)
            T = _T(b.T_B_C0, T_seq)
            est = read_trajectory(b.path, name=b.name, frame=b.frame)
            if b.stamps_ns is not None:  # KITTI rows, one per frame the runs were given: their times
                est = Trajectory(np.asarray(b.stamps_ns, dtype=np.int64), est.positions, est.quat_wxyz,
                                 frame=b.frame, name=b.name, meta=est.meta)
            r = evaluate_pair(gt, est, dataclasses.replace(settings, est_frame=b.frame), "se3", method=b.name,
                              sequence=b.sequence, trial=b.trial, T_B_C0=T, gt_raw=raw)
        except GeviError as exc:
            r = failed(b.name, b.sequence, b.trial, b.path, exc.one_line())
        out.se3.append(r)
    return out
