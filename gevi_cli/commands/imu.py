"""`gevi imu SEQUENCE`: the IMU report (what to check before trusting a VIO run)."""
from __future__ import annotations

import click

from gevi_cli.commands.options import add_sequence_options


@click.command("imu")
@click.argument("sequence", type=click.Path())
@click.option("-o", "--out", default=None, type=click.Path(file_okay=False),
              help="Report folder (default results/imu/<sequence>/<timestamp>/).")
@click.option("--results-root", default="results", show_default=True, type=click.Path(file_okay=False))
@click.option("--imu-time-offset", type=float, default=None, metavar="SECONDS",
              help="Camera-IMU time shift t_imu = t_cam + shift (default: the calibration's).")
@click.option("--no-plots", is_flag=True, help="Skip the plots.")
@click.option("--imu-stride", type=click.IntRange(min=1), default=1, show_default=True, metavar="K",
              help="Use every K-th IMU sample (a K-times slower IMU, e.g. 200 Hz -> 50 Hz with 4).")
@click.option("--no-align", is_flag=True,
              help="Score on the ground truth as given: no clock offset or IMU-from-reference rotation estimated "
                   "from the angular rates (for references known to be aligned; BROAD's always are).")
@click.option("--align-rotation", is_flag=True,
              help="Also estimate the IMU-from-reference rotation where the dataset states its ground truth in the "
                   "IMU frame (EuRoC, renders): by default such a reference gets a clock offset only.")
@add_sequence_options
def command(sequence, out, results_root, imu_time_offset, no_plots, imu_stride, no_align, align_rotation, kind,
            groundtruth, calib, imu_calib, topics, cameras):
    """IMU report of SEQUENCE: rate and gaps, standstill intervals, the starting gyro bias and gravity
    direction, white noise measured at rest next to the stated densities, and roll/pitch over the
    whole stream (IMU-only velocity-aided filter; against ground truth when there is some, next to
    GeVI's gravity-prior filter, gyro-only integration, a fixed-gain complementary filter at the best
    time constant of a 1-2-5 grid, chosen on the ground truth (oracle), and VQF 6D online and offline).
    A motion-capture ground truth is first put on the IMU clock and into the IMU frame from the angular
    rates alone, read at the IMU's full rate (clock offset and rotation printed; --no-align to skip); a
    ground truth the dataset states in the IMU frame (EuRoC, renders) gets the clock offset only
    (--align-rotation to estimate a rotation too).  With no noise model stated,
    the filter uses the white noise measured at the longest standstill, and says so.  SEQUENCE may also
    be an IMU-only EuRoC folder (mav0/imu0 and ground truth, no cameras: `gevi simulate mav`) or a BROAD
    trial .mat (scored as the benchmark does: inclination over the movement samples).

    Writes imu_states.csv (the velocity-aided filter's states), attitude.tum (orientation of the body in a
    gravity-aligned frame, zero position: the standstill-compensated VQF online, causal), attitude_offline.tum,
    report.md and plots.

    \b
    Example:
      gevi imu ../shared/data/euroc_micro --gt ../shared/data/euroc_micro/groundtruth/V1_01_easy.csv
      gevi imu ../shared/data/euroc_micro --gt ../shared/data/euroc_micro/groundtruth/V1_01_easy.csv --imu-stride 4
    """
    from gevi_cli.run.imu import run_imu_report
    from gevi_cli.run.threads import one_thread

    with one_thread():
        run_imu_report(sequence, out=out, results_root=results_root, imu_time_offset=imu_time_offset,
                       plots=not no_plots, kind=kind, groundtruth=groundtruth, calib=calib, imu_calib=imu_calib,
                       topics=topics, cameras=cameras, imu_stride=imu_stride, align=not no_align,
                       align_rotation=align_rotation, echo=click.echo)
