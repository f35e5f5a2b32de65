"""The `gevi eval` pipeline: inputs -> per-estimate evaluation -> tables, eval folder, plots."""
from __future__ import annotations

import sys
import time
from pathlib import Path

from gevi_cli.errors import DataError, GeviError
from gevi_cli.evaluation import inputs as inp
from gevi_cli.evaluation.evaluate import EvalSettings, evaluate_pair, failed


def _settings(align, n_align, max_diff, t_offset, rpe_delta, rpe_unit, min_coverage, est_frame, kitti,
              allow_jumps=False) -> EvalSettings:
    if min_coverage > 1.0:
        min_coverage = min_coverage / 100.0
    if not 0.0 <= min_coverage <= 1.0:
        raise GeviError("--min-coverage", f"must be a fraction 0..1 (or percent 0..100), got {min_coverage:g}")
    if max_diff <= 0:
        raise GeviError("--max-diff", f"must be positive (seconds), got {max_diff:g}")
    if n_align == 0 or n_align < -1:
        raise GeviError("--n-align", f"must be -1 (all poses) or a positive count, got {n_align}")
    if rpe_delta <= 0:
        raise GeviError("--rpe-delta", f"must be positive, got {rpe_delta:g}")
    return EvalSettings(align=align, n_align=n_align, max_diff_s=max_diff, t_offset_s=t_offset,
                        rpe_delta=rpe_delta, rpe_unit=rpe_unit, min_coverage=min_coverage, est_frame=est_frame,
                        kitti=kitti, allow_jumps=allow_jumps)


def collect_specs(gt_opts, estimates, results_root, gt_root, sequence_name):
    """(estimate specs, {sequence: GT path}) from the CLI arguments (see inputs module docstring)."""
    gt_plain, gt_map = [], {}
    for g in gt_opts:
        if "=" in g and not Path(g).exists():
            seq, path = inp.parse_named(g, "--gt")
            gt_map[seq] = Path(path)
        else:
            gt_plain.append(Path(g))
    if len(gt_plain) > 1:
        raise GeviError("--gt", "give one plain --gt PATH (the -e sequence); name others SEQ=PATH")
    specs: list[inp.EstimateSpec] = []
    seq_gt: dict[str, Path] = {}
    if estimates:
        if gt_plain:
            g = gt_plain[0]
            seq = sequence_name or (g.name if g.is_dir() else g.stem)
            seq_gt[seq] = g
        elif sequence_name and sequence_name in gt_map:
            seq = sequence_name
        elif len(gt_map) == 1:
            seq = next(iter(gt_map))
        else:
            raise GeviError("--gt", "-e estimates need the ground truth of their sequence: --gt PATH")
        for e in estimates:
            name, path = inp.parse_named(e, "-e")
            p = Path(path)
            if not p.exists():
                raise GeviError(f"-e {name}", f"{p}: no such file or folder")
            if p.is_dir():
                for trial, f in inp.trials_in(p):
                    if f is None:
                        raise GeviError(f"-e {name}", f"{p}: no trajectory file in the folder")
                    specs.append(inp.EstimateSpec(name, seq, trial, f, [f.parent, p]))
            else:
                specs.append(inp.EstimateSpec(name, seq, "", p, [p.parent]))
    local_gt: dict[str, Path] = {}
    if results_root:
        more, local_gt = inp.discover_results(Path(results_root))
        specs += more
    elif not estimates:
        raise GeviError("eval", "nothing to evaluate: give -e NAME=PATH estimates or --results ROOT")
    names = list(dict.fromkeys(sp.sequence for sp in specs))
    gr = Path(gt_root) if gt_root else None
    if gr is not None and not gr.is_dir():
        raise GeviError("--gt-root", f"{gr}: no such folder")
    for seq in names:
        if seq in seq_gt:
            continue
        p = inp.gt_for_sequence(seq, gt_map, gr, local_gt)
        if p is None:
            tried = ", ".join(filter(None, [f"--gt {seq}=PATH", f"{gr}/{seq}[.*]" if gr else "--gt-root",
                                             "a *groundtruth* file in the sequence folder"]))
            raise GeviError(f"sequence {seq}", f"no ground truth found (tried {tried})")
        seq_gt[seq] = p
    return specs, seq_gt


def _stamped_for_run(gt, gt_raw, est, est_path: Path, cache: dict, info: dict):
    """(ground truth, its raw KITTI poses) to evaluate ``est`` with.

    A KITTI ground truth has no stamps, a `gevi run` estimate has the sequence's: when the estimate is
    the primary trajectory of a run folder of that KITTI sequence, the ground truth is stamped with the
    sequence's ``times.txt`` (row i = frame i), the same stamps `gevi run` gives it without ``--gt``.
    Anything else is returned unchanged (the association then explains a stamped/unstamped mix).
    """
    if not gt.indexed or est.indexed:
        return gt, gt_raw
    times = inp.run_sequence_times(Path(est_path).parent)
    if times is None:
        return gt, gt_raw
    key = (id(gt), times)
    if key not in cache:
        cache[key] = inp.stamp_kitti_groundtruth(gt, times)
        info.setdefault("stamped_from", []).append(str(times))
    return cache[key], None


def run_eval(*, gt_opts, estimates, results_root, gt_root, sequence_name, align, n_align, max_diff, t_offset,
             rpe_delta, rpe_unit, min_coverage, est_frame, gt_frame, t_b_c0, kitti, plots, out, overwrite,
             keep_going, quiet, only_methods=(), echo=print, allow_jumps=False):
    t_start = time.perf_counter()
    settings = _settings(align, n_align, max_diff, t_offset, rpe_delta, rpe_unit, min_coverage, est_frame, kitti,
                         allow_jumps)
    specs, seq_gt = collect_specs(gt_opts, estimates, results_root, gt_root, sequence_name)
    if only_methods:
        wanted = [m for item in only_methods for m in item.split(",") if m]
        unknown = [m for m in wanted if m not in {s.method for s in specs}]
        if unknown:
            raise GeviError("--method", f"no method {', '.join(unknown)}; found {', '.join(sorted({s.method for s in specs}))}")
        specs = [s for s in specs if s.method in wanted]
    from gevi_cli.evaluation.kitti_devkit import raw_poses
    from gevi_cli.evaluation.report import build_tables, choose_out_dir, default_name, write_report
    from gevi_cli.evaluation.tables import render_markdown
    from gevi_cli.trajectory import read_trajectory

    T_override = inp.load_T_B_C0(Path(t_b_c0)) if t_b_c0 else None
    methods = list(dict.fromkeys(s.method for s in specs))
    sequences = list(dict.fromkeys(s.sequence for s in specs))
    out_dir, notice = choose_out_dir(out, default_name(sequences, methods, results_root), overwrite)

    def warn(msg):
        echo(f"gevi: warning: {msg}", err=True) if echo is not print else print(f"gevi: warning: {msg}", file=sys.stderr)

    gts, seq_info = {}, {}
    for seq in sequences:
        gt, T = inp.load_groundtruth(seq_gt[seq], gt_frame, allow_jumps)
        T = T_override if T_override is not None else T
        gts[seq] = (gt, T, raw_poses(gt) if gt.indexed else None)
        seq_info[seq] = {"groundtruth": str(seq_gt[seq]), "poses": len(gt), "frame": gt.frame,
                         "indexed": gt.indexed, "span_s": gt.duration_s, "path_length_m": gt.path_length_m}
        for w in gt.meta.get("warnings", []):
            warn(w)

    results, stamped = [], {}
    for sp in specs:
        label = f"{sp.method}/{sp.sequence}" + (f"/{sp.trial}" if sp.trial else "")
        if sp.path is None:
            results.append(failed(sp.method, sp.sequence, sp.trial, None, "missing"))
            if not quiet:
                echo(f"{label}: failed (no trajectory file)")
            continue
        gt, T, gt_raw = gts[sp.sequence]
        if settings.align == "auto":
            method, why = inp.align_from_hint(sp.hint_dirs)
            why = why.replace(str(Path(why.split(":")[0]).parent) + "/", "") if ":" in why else why
        else:
            method, why = settings.align, "--align"
        try:
            est = read_trajectory(sp.path, name=sp.method, allow_jumps=allow_jumps)
            pair_gt, pair_raw = _stamped_for_run(gt, gt_raw, est, sp.path, stamped, seq_info[sp.sequence])
            r = evaluate_pair(pair_gt, est, settings, method, method=sp.method, sequence=sp.sequence, trial=sp.trial,
                              T_B_C0=T, gt_raw=pair_raw)
        except DataError as exc:
            if exc.message.startswith("contains no pose rows"):
                r = failed(sp.method, sp.sequence, sp.trial, sp.path, "no valid poses")
            elif keep_going:
                warn(exc.one_line())
                r = failed(sp.method, sp.sequence, sp.trial, sp.path, exc.one_line())
            else:
                raise
        results.append(r)
        for w in r.warnings:
            warn(w)
        if not quiet:
            if r.association is not None:
                line = f"{label}: {r.association.summary()}; align {r.align} ({why})"
            else:
                line = f"{label}:"
            if not r.ok:
                line += f"; FAILED: {r.reason}"
            echo(line)
    # combinations absent from a results tree
    have = {(r.method, r.sequence) for r in results}
    for m in methods:
        for s in sequences:
            if (m, s) not in have:
                results.append(failed(m, s, "", None, "missing"))
                if not quiet:
                    echo(f"{m}/{s}: failed (missing)")

    tables = build_tables(results, methods, sequences, settings)
    echo("")
    for t in tables:
        echo(render_markdown(t, console=True))
    if notice:
        echo(notice)
    inputs = {"gt": {s: str(p) for s, p in seq_gt.items()}, "results": results_root, "gt_root": gt_root,
              "estimates": {f"{s.method}/{s.sequence}" + (f"/{s.trial}" if s.trial else ""): str(s.path) if s.path else None
                            for s in specs},
              "T_B_C0": t_b_c0, "gt_frame": gt_frame, "command": " ".join(["gevi"] + sys.argv[1:])}
    write_report(out_dir, tables, results, seq_info, settings, inputs)
    if plots:
        from gevi_cli.evaluation.plots import plot_sequence, plot_summary

        pdir = out_dir / "plots"
        for s in sequences:
            plot_sequence(pdir, s, gts[s][0], [r for r in results if r.sequence == s])
        ate = next((t for t in tables if t.key == "ate_trans_rmse"), None)
        if ate is not None:
            plot_summary(pdir, ate)
    echo(f"wrote {out_dir} ({time.perf_counter() - t_start:.1f} s)")
    return results, tables, out_dir
