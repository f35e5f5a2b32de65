"""`gevi info PATH`: what a sequence holds, and every warning about it."""
from __future__ import annotations

import click

from gevi_cli.commands.options import add_sequence_options, sequence_kwargs


@click.command("info")
@click.argument("path", type=click.Path())
@add_sequence_options
def command(path, kind, groundtruth, calib, imu_calib, topics, cameras):
    """Describe the sequence at PATH: kind, sensors, rates, counts, duration, calibration, GT coverage."""
    import numpy as np

    from gevi_cli.datasets import open_sequence
    from gevi_cli.datasets.coverage import frame_coverage

    seq = open_sequence(path, kind=kind, **sequence_kwargs(groundtruth, calib, topics, cameras, imu_calib))
    rig = seq.calibration
    echo = click.echo
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
        echo(f"groundtruth   {len(gt)} poses ({gt.frame} frame) at {gt_rate:.0f} Hz, "
             f"{gt.duration_s:.1f} s, path {gt.path_length_m:.1f} m")
        echo(f"GT coverage   {cov.describe()}")
    for warning in seq.warnings:
        echo(f"warning: {warning}", err=True)
