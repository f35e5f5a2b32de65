"""Click options shared by commands that open a sequence."""
from __future__ import annotations

import click

sequence_options = [
    click.option("--kind", default=None, help="Force the dataset kind (euroc, pool, kitti, rosbag); default: detect."),
    click.option("--gt", "--groundtruth", "groundtruth", type=click.Path(dir_okay=False), default=None,
                 help="Ground-truth trajectory file overriding the dataset's own (any format gevi reads)."),
    click.option("--calib", default=None, type=click.Path(),
                 help="Bags: Kalibr camchain YAML or EuRoC mav0 folder; track exports: KITTI calib.txt."),
    click.option("--imu-calib", "imu_calib", default=None, type=click.Path(dir_okay=False),
                 help="Bags: Kalibr imu.yaml with the IMU noise model."),
    click.option("--topics", default=None, help="Bags: left=/cam0/image_raw,right=/cam1/image_raw,imu=/imu0,gt=/pose "
                                                "(a split IMU: gyro=TOPIC,accel=TOPIC; none skips imu/gt)"),
    click.option("--cameras", type=click.Choice(["gray", "color"]), default=None, help="KITTI: which stereo pair."),
]


def add_sequence_options(func):
    for option in reversed(sequence_options):
        func = option(func)
    return func
