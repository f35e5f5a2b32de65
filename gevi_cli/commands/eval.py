"""`gevi eval`: ATE / RPE / KITTI-devkit tables and plots of estimates against ground truth.

Heavy imports (numpy, evo, matplotlib) happen inside the command so `gevi --help` stays fast.
Documentation of every option and of the eval folder: docs/eval.md.
"""
from __future__ import annotations

import click

ALIGN_CHOICES = ("auto", "none", "origin", "se3", "sim3", "posyaw")

EPILOG = """\b
Examples:
  gevi eval --gt datasets/euroc/MH_04_difficult -e ours=runs/mh04.tum -e orbslam3=f_MH04.txt --est-frame body
  gevi eval --gt gt/00.txt -e orb=KITTI_00_ORB.txt --align se3
  gevi eval --results results/ --gt-root kitti/gt_poses --align sim3
  gevi eval --results rpg/laptop --align auto --min-coverage 0.5 -o eval/rpg
\b
Results tree: <root>/<method>/<sequence>/ holding one trajectory file, run*/ trial folders, or
<stem><k>.txt trial files; or <root>/<method>/<sequence>.txt. See docs/eval.md.
"""


@click.command("eval", epilog=EPILOG, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--gt", "gt_opts", multiple=True, metavar="PATH|SEQ=PATH",
              help="Ground truth: a trajectory file or a dataset folder; SEQ=PATH names it for one sequence "
                   "of --results (repeatable).")
@click.option("-e", "--estimate", "estimates", multiple=True, metavar="NAME=PATH",
              help="An estimate of method NAME for the --gt sequence (repeatable). PATH may be a folder of trials.")
@click.option("--results", "results_root", metavar="ROOT", help="A results tree <root>/<method>/<sequence>/.")
@click.option("--method", "only_methods", multiple=True, metavar="NAME[,NAME]",
              help="Evaluate only these methods of --results (repeatable).")
@click.option("--gt-root", metavar="DIR", help="Ground truth of sequence S: DIR/S (dataset or folder) or DIR/S.<ext>.")
@click.option("--sequence", "sequence_name", metavar="NAME", help="Sequence name of the -e estimates (default: from --gt).")
@click.option("--align", "align", type=click.Choice(ALIGN_CHOICES), default="auto", show_default=True,
              help="Alignment before ATE. auto: from a run-folder hint (config.yaml/meta/eval_cfg.yaml), else se3.")
@click.option("--n-align", type=int, default=-1, show_default=True, help="Align on the first N matched poses (-1 = all).")
@click.option("--max-diff", type=float, default=0.01, show_default=True, help="Association tolerance [s].")
@click.option("--t-offset", type=float, default=0.0, show_default=True, help="Added to estimate stamps [s] (t_gt = t_est + offset).")
@click.option("--rpe-delta", type=float, default=1.0, show_default=True, help="RPE pair distance.")
@click.option("--rpe-unit", type=click.Choice(("frames", "m", "s")), default="frames", show_default=True)
@click.option("--min-coverage", type=float, default=0.9, show_default=True,
              help="Fail an estimate covering less of the GT time span (fraction, or percent if > 1).")
@click.option("--est-frame", type=click.Choice(("same", "body", "cam0")), default="same", show_default=True,
              help="Sensor frame of the estimate poses; converted to the GT frame with T_B_C0.")
@click.option("--gt-frame", type=click.Choice(("body", "cam0")), default="body", show_default=True,
              help="Sensor frame of a GT *file* (datasets say it themselves).")
@click.option("--T-B-C0", "t_b_c0", metavar="FILE", help="cam0->body 4x4 (text or YAML T_B_C0/T_BS); default: the dataset's.")
@click.option("--no-kitti", is_flag=True, help="Skip the KITTI devkit metric.")
@click.option("--no-plots", is_flag=True, help="Skip the figures.")
@click.option("-o", "--out", metavar="DIR", help="Eval folder (default eval/<name from inputs>; never overwritten).")
@click.option("--overwrite", is_flag=True, help="Allow writing into an existing, non-empty --out folder.")
@click.option("--keep-going", is_flag=True, help="Turn an unreadable estimate into a failed cell instead of stopping.")
@click.option("--allow-jumps", is_flag=True,
              help="Read trajectories whose position jumps (refused by default as corrupt rows) as written; "
                   "the tables say so.")
@click.option("-q", "--quiet", is_flag=True, help="Print only the tables and the eval folder.")
def command(gt_opts, estimates, results_root, only_methods, gt_root, sequence_name, align, n_align, max_diff, t_offset, rpe_delta,
            rpe_unit, min_coverage, est_frame, gt_frame, t_b_c0, no_kitti, no_plots, out, overwrite, keep_going, allow_jumps,
            quiet):
    """Evaluate estimates against ground truth: ATE, RPE, KITTI t_err/r_err; tables and plots."""
    from gevi_cli.evaluation.runner import run_eval

    run_eval(
        gt_opts=gt_opts, estimates=estimates, results_root=results_root, gt_root=gt_root,
        sequence_name=sequence_name, align=align, n_align=n_align, max_diff=max_diff, t_offset=t_offset,
        rpe_delta=rpe_delta, rpe_unit=rpe_unit, min_coverage=min_coverage, est_frame=est_frame, gt_frame=gt_frame,
        t_b_c0=t_b_c0, kitti=not no_kitti, plots=not no_plots, out=out, overwrite=overwrite,
        keep_going=keep_going, quiet=quiet, only_methods=only_methods, echo=click.echo, allow_jumps=allow_jumps,
    )
