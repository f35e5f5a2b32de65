"""`gevi info PATH`: what a sequence holds, and every warning about it."""
from __future__ import annotations

import click

from gevi_cli.commands.options import add_sequence_options
from gevi_cli.datasets.registry import sequence_kwargs


@click.command("info")
@click.argument("path", type=click.Path())
@add_sequence_options
def command(path, kind, groundtruth, calib, imu_calib, topics, cameras):
    """Describe the sequence at PATH: kind, sensors, rates, counts, duration, calibration, GT coverage.

    A ROS bag is described whatever it holds (topics, types, counts, image sizes and encodings, IMU
    rate and gaps, pose topics), with the gevi commands that can use it.
    """
    from gevi_cli.datasets import open_sequence
    from gevi_cli.datasets.bagfile import is_bag
    from gevi_cli.datasets.registry import detect_kind

    options = sequence_kwargs(groundtruth, calib, topics, cameras, imu_calib)
    echo = click.echo
    from gevi_cli.datasets.broad import is_broad_mat

    if kind is None and is_broad_mat(path):
        _describe_broad(path, echo)
        return
    if (kind or detect_kind(path)) == "rosbag" and is_bag(path):
        _describe_bag(path, options, echo)
        return
    _describe_sequence(open_sequence(path, kind=kind, **options), path, echo)


def _describe_bag(path, options, echo) -> None:
    """Any bag: its inventory, then the stereo sequence when it is one, or why `gevi run` cannot use it."""
    from gevi_cli.datasets import open_sequence
    from gevi_cli.datasets.bag_inventory import describe, inventory, usable_by
    from gevi_cli.errors import GeviError

    inv = inventory(path)
    try:
        seq = open_sequence(path, kind="rosbag", **options)
        problem = None
    except GeviError as err:
        if (err.where or "").startswith("--") or err.message.startswith("--"):
            raise  # the user's own option is wrong: that is the error, not a property of the bag
        seq, problem = None, err.message if err.where in (None, str(inv.path), str(path)) else err.one_line()
    if seq is not None:
        _describe_sequence(seq, path, echo)
    else:
        echo(f"sequence      {inv.path.stem if inv.path.is_file() else inv.path.name}  (rosbag)")
        echo(f"path          {path}")
    for line in describe(inv) + usable_by(inv, problem):
        echo(line)


def _describe_broad(path, echo) -> None:
    """A BROAD trial (.mat): IMU, the optical reference and the movement phases the benchmark scores."""
    from gevi_cli.datasets.broad import BroadTrial

    trial = BroadTrial(path)
    imu, n = trial.imu, len(trial.t_ns)
    echo(f"sequence      {trial.name}  (broad: BROAD benchmark trial, Laidig et al. 2021)")
    echo(f"path          {path}")
    echo(f"imu           {n} samples at {trial.rate_hz:.3f} Hz over {imu.duration_s:.1f} s (gyro rad/s, acc m/s^2; "
         "no noise model stated)")
    echo(f"groundtruth   optical motion capture (opt_quat, ENU, aligned to the IMU by the dataset): "
         f"{int(trial.valid.sum())} of {n} samples valid ({n - int(trial.valid.sum())} occluded)")
    echo(f"scored        {int(trial.movement.sum())} movement samples ({trial.movement.sum() / trial.rate_hz:.1f} s), "
         f"{len(trial.scored_t_ns)} of them with a valid reference: BROAD's inclination RMSE is over these")
    echo("usable by     gevi imu (roll/pitch against the reference; heading needs the magnetometer, not used)")
    if trial.info:
        echo("info          " + trial.info.splitlines()[0] + (" / " + trial.info.splitlines()[2]
                                                              if len(trial.info.splitlines()) > 2 else ""))


def _describe_sequence(seq, path, echo) -> None:
    import numpy as np

    from gevi_cli.datasets.coverage import frame_coverage

    rig = seq.calibration
    echo(f"sequence      {seq.name}  ({seq.kind})")
    echo(f"path          {path}")
    echo(f"stereo        {len(seq)} stereo pairs at {seq.frame_rate_hz:.1f} Hz over {seq.duration_s:.2f} s")
    for label, cam in (("cam0 (left)", rig.cam0), ("cam1 (right)", rig.cam1)):
        echo(f"{label:13s} {cam.width}x{cam.height}, fx {cam.fx:.3f} fy {cam.fy:.3f} cx {cam.cx:.3f} cy {cam.cy:.3f}, "
             f"distortion {cam.distortion_model}{' ' + str(list(cam.distortion)) if cam.distortion else ''}")
    echo(f"baseline      {rig.baseline:.3f} m (rectified focal {rig.rectification.K[0, 0]:.1f} px)")
    imu = seq.imu
    if imu is None:
        echo("imu           none")
    else:
        span = (imu.t_ns[0] <= seq.stamps_ns[0]) and (imu.t_ns[-1] >= seq.stamps_ns[-1])
        echo(f"imu           {len(imu)} samples, IMU {imu.rate_hz:.0f} Hz over {imu.duration_s:.1f} s"
             f"{'' if span else ' (does NOT span all frames)'}")
        if imu.gyro_noise_density is not None:
            echo(f"imu noise     gyro {imu.gyro_noise_density:.4g} rad/s/sqrt(Hz) (walk {imu.gyro_random_walk:.4g}), "
                 f"acc {imu.acc_noise_density:.4g} m/s^2/sqrt(Hz) (walk {imu.acc_random_walk:.4g})")
    gt = seq.groundtruth
    if gt is None:
        echo("groundtruth   none")
    else:
        cov = frame_coverage(seq.stamps_ns, gt)
        gt_rate = 1e9 / float(np.median(np.diff(gt.t_ns))) if len(gt) > 1 else 0.0
        src = f" from {seq.groundtruth_source}" if seq.groundtruth_source is not None else ""
        echo(f"groundtruth   {len(gt)} poses ({gt.frame} frame) at {gt_rate:.0f} Hz, "
             f"{gt.duration_s:.1f} s, path {gt.path_length_m:.1f} m{src}")
        echo(f"GT coverage   {cov.describe()}")
    for warning in seq.warnings:
        echo(f"warning: {warning}", err=True)
