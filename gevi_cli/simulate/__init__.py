"""``gevi simulate``: a photometric stereo-IMU simulator with exact ground truth.

Scenes of textured planes are ray cast per pixel (2x2 supersampling, radtan distortion, sensor noise,
underwater attenuation) along smooth analytic trajectories; the IMU is synthesised from the closed-form
derivatives.  Output layouts: EuRoC ASL folders, KITTI odometry folders and ROS1 bags.

Public entry points: :func:`gevi_cli.simulate.generate.simulate` and :func:`sample_sequence`.
"""
from __future__ import annotations


def sample_sequence(progress: bool = True):
    """Path of the built-in pool-easy sample sequence (EuRoC layout), rendering it on first use."""
    from gevi_cli.simulate.sample import sample_sequence as _sample

    return _sample(progress=progress)


__all__ = ["sample_sequence"]
