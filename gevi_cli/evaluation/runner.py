"""The `gevi eval` pipeline: inputs -> per-estimate evaluation (:mod:`gevi_cli.evaluation.pair`) -> tables,
eval folder, plots."""
from __future__ import annotations

import sys
import time
from pathlib import Path

from gevi_cli.errors import GeviError
from gevi_cli.evaluation import inputs as inp
from gevi_cli.evaluation.evaluate import EvalSettings, failed
from gevi_cli.evaluation.pair import GroundTruth, evaluate_file, read_groundtruth


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


def _only(specs, only_methods):
    """The specs of the ``--method`` names (comma-separated, repeatable); all of them without."""
    if not only_methods:
        return specs
    wanted = [m for item in only_methods for m in item.split(",") if m]
    unknown = [m for m in wanted if m not in {s.method for s in specs}]
    if unknown:
        raise GeviError("--method", f"no method {', '.join(unknown)}; found {', '.join(sorted({s.method for s in specs}))}")
    return [s for s in specs if s.method in wanted]


def _label(method: str, sequence: str, trial: str = "") -> str:
    return f"{method}/{sequence}" + (f"/{trial}" if trial else "")


def _evaluate_spec(sp: inp.EstimateSpec, gt: GroundTruth, settings: EvalSettings, keep_going: bool, warn):
    """(PairResult, why this alignment) of one estimate of the CLI (``--align auto``: from the run-folder hints)."""
    if sp.path is None:
        return failed(sp.method, sp.sequence, sp.trial, None, "missing"), ""
    if settings.align == "auto":
        align, why = inp.align_from_hint(sp.hint_dirs)
        why = why.replace(str(Path(why.split(":")[0]).parent) + "/", "") if ":" in why else why
    else:
        align, why = settings.align, "--align"
    r = evaluate_file(gt, sp.path, settings, align, method=sp.method, sequence=sp.sequence, trial=sp.trial,
                      keep_going=keep_going, warn=warn)
    return r, why


def eval_inputs(gt: dict, estimates: dict, results_root=None, gt_root=None, t_b_c0=None, gt_frame="body") -> dict:
    """The inputs ``settings.yaml`` records: ``gt`` {sequence: path}, ``estimates`` {label: path or None},
    the other `gevi eval` options and the command line."""
    return {"gt": {s: str(p) for s, p in gt.items()}, "results": results_root, "gt_root": gt_root,
            "estimates": {label: str(p) if p else None for label, p in estimates.items()},
            "T_B_C0": t_b_c0, "gt_frame": gt_frame, "command": " ".join(["gevi"] + sys.argv[1:])}


def write_eval_folder(out_dir: Path, tables, results, gts: dict, settings: EvalSettings, inputs: dict,
                      plots: bool) -> None:
    """The eval folder (see :mod:`gevi_cli.evaluation.report`) of ``results`` against ``gts``
    ({sequence: GroundTruth}), with the figures when ``plots``."""
    from gevi_cli.evaluation.report import write_report

    write_report(out_dir, tables, results, {s: g.info() for s, g in gts.items()}, settings, inputs)
    if plots:
        from gevi_cli.evaluation.plots import plot_sequence, plot_summary

        pdir = out_dir / "plots"
        for s, g in gts.items():
            plot_sequence(pdir, s, g.trajectory, [r for r in results if r.sequence == s])
        ate = next((t for t in tables if t.key == "ate_trans_rmse"), None)
        if ate is not None:
            plot_summary(pdir, ate)


def _departure(path: Path) -> str:
    """What the gevi run that wrote ``path`` did beyond the published method, from its status.json ("": nothing,
    or not a gevi run folder)."""
    import json

    try:
        rec = json.loads((path.parent / "status.json").read_text()).get("disparity_offset") or {}
    except (OSError, ValueError, AttributeError):
        return ""
    if not rec.get("applied_px"):
        return ""
    from gevi_cli.pipelines.disparity_offset import describe_record

    return f"beyond the published method: stereo disparity offset {describe_record(rec)} ({path.parent / 'status.json'})"


def run_eval(*, gt_opts, estimates, results_root, gt_root, sequence_name, align, n_align, max_diff, t_offset,
             rpe_delta, rpe_unit, min_coverage, est_frame, gt_frame, t_b_c0, kitti, plots, out, overwrite,
             keep_going, quiet, only_methods=(), echo=print, allow_jumps=False):
    """`gevi eval`: collect the estimates and ground truths of the options, evaluate each
    (:func:`evaluate_file`), print the tables and write the eval folder; (results, tables, folder)."""
    t_start = time.perf_counter()
    settings = EvalSettings(align=align, n_align=n_align, max_diff_s=max_diff, t_offset_s=t_offset,
                            rpe_delta=rpe_delta, rpe_unit=rpe_unit, min_coverage=min_coverage, est_frame=est_frame,
                            kitti=kitti, allow_jumps=allow_jumps).checked()
    specs, seq_gt = collect_specs(gt_opts, estimates, results_root, gt_root, sequence_name)
    specs = _only(specs, only_methods)
    from gevi_cli.evaluation.report import build_tables, choose_out_dir, default_name
    from gevi_cli.evaluation.tables import render_markdown

    T_override = inp.load_T_B_C0(Path(t_b_c0)) if t_b_c0 else None
    methods = list(dict.fromkeys(s.method for s in specs))
    sequences = list(dict.fromkeys(s.sequence for s in specs))
    out_dir, notice = choose_out_dir(out, default_name(sequences, methods, results_root), overwrite)

    def warn(msg):
        echo(f"gevi: warning: {msg}", err=True) if echo is not print else print(f"gevi: warning: {msg}", file=sys.stderr)

    gts = {}
    for seq in sequences:
        gts[seq] = read_groundtruth(seq_gt[seq], gt_frame, allow_jumps, T_override)
        for w in gts[seq].trajectory.meta.get("warnings", []):
            warn(w)

    results = []
    for sp in specs:
        r, why = _evaluate_spec(sp, gts[sp.sequence], settings, keep_going, warn)
        results.append(r)
        label = _label(sp.method, sp.sequence, sp.trial)
        if sp.path is None:
            if not quiet:
                echo(f"{label}: failed (no trajectory file)")
            continue
        for w in r.warnings:
            warn(w)
        if not quiet:
            line = f"{label}: {r.association.summary()}; align {r.align} ({why})" if r.association is not None \
                else f"{label}:"
            if not r.ok:
                line += f"; FAILED: {r.reason}"
            echo(line)
            departure = _departure(Path(sp.path))
            if departure:
                echo(f"{label}: {departure}")
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
    inputs = eval_inputs(seq_gt, {_label(s.method, s.sequence, s.trial): s.path for s in specs}, results_root,
                         gt_root, t_b_c0, gt_frame)
    write_eval_folder(out_dir, tables, results, gts, settings, inputs, plots)
    echo(f"wrote {out_dir} ({time.perf_counter() - t_start:.1f} s)")
    return results, tables, out_dir
