"""`gevi run SEQUENCE`: odometry from images (or exported tracks) to a trajectory, evaluated."""
from __future__ import annotations

import click

from gevi_cli.commands.options import add_sequence_options
from gevi_cli.run.method_options import method_options


@click.command("run")
@click.argument("sequence", type=click.Path(), required=False)
@method_options
@click.option("--start", type=click.IntRange(min=0), default=0, help="First frame (index).")
@click.option("--max-frames", type=click.IntRange(min=1), default=None, help="Number of frames to run.")
@click.option("--stride", type=click.IntRange(min=1), default=1, show_default=True, metavar="K",
              help="Use every K-th frame (frame j = original frame K*j, its stamp kept; --start and --max-frames "
                   "count strided frames); the IMU and the ground truth stay whole. Not for track exports.")
@click.option("--seed", type=int, default=None, help="Seed of GeVI's 3-point RANSAC (= --set run.seed=...); GeVI only: OpenCV's 5-point RANSAC (CFO) has its own fixed seed.")
@click.option("-o", "--out", default=None, type=click.Path(file_okay=False),
              help="Run folder (default results/<method>/<sequence>/<timestamp>/).")
@click.option("--results-root", default="results", show_default=True, type=click.Path(file_okay=False),
              help="Root of the default run folders.")
@click.option("--plots", is_flag=True, help="Also write the evaluation plots.")
@click.option("--dump-config", is_flag=True, help="Print every --set key with its effective value and exit.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar; only the result lines.")
@add_sequence_options
def command(sequence, method, start, max_frames, stride, config_file, sets, pnp, no_ba, seed, ransac, no_adaptive, no_fusion,
            imu_time_offset, out, results_root, plots, dump_config, quiet, kind, groundtruth, calib, imu_calib, topics,
            cameras):
    """Run odometry on SEQUENCE and evaluate it against its ground truth.

    Without SEQUENCE: GeVI on the built-in pool-easy sample (rendered on first use).

    SEQUENCE is a dataset folder or bag (EuRoC, pool, KITTI, rosbag, `gevi simulate` output) or an
    OV2SLAM track export (with --calib calib.txt; the front end is then the export's).

    \b
    Examples:
      gevi run
      gevi run ../shared/data/kitti06_head/dataset/sequences/06
      gevi run ../shared/data/euroc_micro --gt ../shared/data/euroc_micro/groundtruth/V1_01_easy.csv
      gevi run EXPORT/ov2slam_data_kitti_04_gray --calib EXPORT/../calib/gray_calib.txt --gt 04.txt
      gevi run SEQ --pnp epnp --no-ba --set keyframe.max_mean_disp_px=20
      gevi run ../shared/data/kitti06_head/dataset/sequences/06 --stride 3   # every 3rd frame
    """
    from gevi_cli.run.session import RunRequest, execute

    req = RunRequest(sequence=sequence, method=method, start=start, max_frames=max_frames, stride=stride,
                     config_file=config_file,
                     sets=tuple(sets), pnp=pnp, no_ba=no_ba, seed=seed, out=out, results_root=results_root,
                     plots=plots, quiet=quiet, kind=kind, groundtruth=groundtruth, calib=calib, imu_calib=imu_calib,
                     topics=topics, cameras=cameras, ransac=ransac, no_adaptive=no_adaptive, no_fusion=no_fusion,
                     imu_time_offset=imu_time_offset)
    if dump_config:
        from gevi_cli.run.session import dump_config as dump

        click.echo(dump(req))
        return
    code = execute(req, echo=click.echo)
    if code:
        raise click.exceptions.Exit(code)
