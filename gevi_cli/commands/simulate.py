"""``gevi simulate``: render a synthetic stereo-IMU sequence with exact ground truth."""
from __future__ import annotations

import re

import click

from gevi_cli.errors import GeviError
from gevi_cli.simulate.presets import PRESET_NAMES, parse_resolution

MAV_MIN_DURATION_S = 20.0
#: options that only concern images: refused with the IMU-only mav preset
IMAGE_OPTIONS = ("--rate", "--resolution", "--baseline", "--no-distortion", "--no-image-noise", "--supersample",
                 "--disparity-shift", "--workers", "--name")

EPILOG = """\b
Examples:
  gevi simulate pool-easy out/pool_easy --format euroc --duration 20 --rate 10 --resolution 640x360 --seed 1
  gevi simulate kitti-like out/kitti --format kitti --duration 30
  gevi simulate euroc-like out/bag --format bag --name euroc_like
  gevi simulate mav out/mav50 --imu-rate 50 --seed 1     # IMU only: gevi imu out/mav50
  gevi simulate pool-easy out/pool_imu --imu-only --duration 60
  gevi simulate --sample          # path of the cached built-in sample (rendered on first use)
"""


@click.command("simulate", epilog=EPILOG, context_settings={"help_option_names": ["-h", "--help"]})
@click.argument("preset", required=False, metavar="PRESET")
@click.argument("out_dir", required=False, type=click.Path(file_okay=False), metavar="OUT_DIR")
@click.option("--format", "fmt", type=click.Choice(["euroc", "kitti", "bag"]), default="euroc", show_default=True,
              help="Output layout: EuRoC ASL folder, KITTI odometry folder, or ROS1 bag + Kalibr yaml.")
@click.option("--duration", type=click.FloatRange(min=0.1, max=3600), help="Length in seconds [preset default].")
@click.option("--rate", type=click.FloatRange(min=0.1, max=1000), help="Camera rate in Hz [preset default].")
@click.option("--resolution", help="Image size WIDTHxHEIGHT; intrinsics scale to keep the field of view.")
@click.option("--baseline", type=click.FloatRange(min=0.001, max=10), help="Stereo baseline in metres.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seeds scene, trajectory and all noise.")
@click.option("--imu-rate", type=click.FloatRange(min=10, max=2000), default=200.0, show_default=True, help="IMU rate in Hz.")
@click.option("--gyro-noise", type=click.FloatRange(min=0), default=1.6968e-4, show_default=True,
              help="Gyro noise density [rad/s/sqrt(Hz)].")
@click.option("--gyro-walk", type=click.FloatRange(min=0), default=1.9393e-5, show_default=True,
              help="Gyro bias random walk [rad/s^2/sqrt(Hz)].")
@click.option("--acc-noise", type=click.FloatRange(min=0), default=2.0e-3, show_default=True,
              help="Accelerometer noise density [m/s^2/sqrt(Hz)].")
@click.option("--acc-walk", type=click.FloatRange(min=0), default=3.0e-3, show_default=True,
              help="Accelerometer bias random walk [m/s^3/sqrt(Hz)].")
@click.option("--no-imu-noise", is_flag=True, help="Perfect IMU: no white noise, no biases.")
@click.option("--no-distortion", is_flag=True, help="Ideal pinhole cameras (always so for --format kitti).")
@click.option("--no-image-noise", is_flag=True, help="No shot/read noise in the images.")
@click.option("--supersample", type=click.IntRange(1, 8), default=2, show_default=True,
              help="Sub-samples per pixel and axis (anti-aliasing).")
@click.option("--a-max", type=click.FloatRange(min=0.001), default=None,
              help="Peak acceleration of the hovering presets [m/s^2] (default: the preset's).")
@click.option("--imu-only", is_flag=True,
              help="Write only the IMU and the ground truth (an EuRoC folder with mav0/imu0, no images; for `gevi imu`).")
@click.option("--no-noise-model", is_flag=True,
              help="IMU-only output: leave the noise densities out of imu0/sensor.yaml (a recording that states none).")
@click.option("--moving-start", is_flag=True, help="Hovering presets: in motion from the first frame (no still start).")
@click.option("--disparity-shift", type=click.FloatRange(min=-20, max=20), default=0.0, show_default=True,
              help="Render the right image moved right by this many pixels, the calibration unchanged: a pair "
                   "whose disparities all read this much short (a known disparity offset).")
@click.option("--workers", type=click.IntRange(1, 64), help="Render processes [min(2, CPUs)].")
@click.option("--name", help="Bag base name for --format bag [preset name].")
@click.option("--overwrite", is_flag=True, help="Replace OUT_DIR if it is a previous gevi simulate output.")
@click.option("--sample", is_flag=True, help="Print the path of the built-in pool-easy sample, rendering it if missing.")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar.")
def command(preset, out_dir, fmt, duration, rate, resolution, baseline, seed, imu_rate, gyro_noise, gyro_walk,
            acc_noise, acc_walk, no_imu_noise, no_distortion, no_image_noise, supersample, a_max, imu_only, no_noise_model,
            moving_start, disparity_shift, workers, name, overwrite, sample, quiet):
    """Render a synthetic stereo-IMU sequence with exact ground truth.

    PRESET is one of pool-easy, pool-hard, euroc-like, kitti-like, kitti-highway, mav; OUT_DIR is created (it must
    not exist or be empty unless --overwrite).  Same seed and options give byte-identical files.

    mav is IMU only (no images; written as an EuRoC folder with mav0/imu0 and the ground truth, which
    `gevi imu OUT_DIR` reads): 60 s of aggressive multirotor flight (8 s still start, 5 s still end),
    the body tilted with the thrust plus roll/pitch excursions (tilts past 60 deg, --a-max default 6
    m/s^2), rotor vibration as 70-180 Hz band-limited noise (0.05 rad/s, 0.6 m/s^2 per axis RMS in flight,
    a quarter at rest) on top of the white noise, 1 % gyro scale-factor errors and a gyro-bias shift at
    take-off; --duration at least 20 s.  imu0/sensor.yaml states the white noise only (as a
    datasheet would); --no-noise-model leaves it out.  The same seed is the same flight at any --imu-rate.
    --imu-only writes any preset that way (its motion and IMU exactly as in the full render, no images).
    """
    if sample:
        if preset or out_dir:
            raise GeviError("--sample", "takes no PRESET or OUT_DIR; it prints the cached sample's path")
        from gevi_cli.simulate.sample import sample_sequence

        click.echo(str(sample_sequence(progress=not quiet)))
        return
    if not preset:
        raise GeviError("PRESET", f"missing; choose one of {', '.join(PRESET_NAMES)} (or use --sample)")
    if preset not in PRESET_NAMES:
        raise GeviError("PRESET", f"unknown preset {preset!r}; choose one of {', '.join(PRESET_NAMES)}")
    if not out_dir:
        raise GeviError("OUT_DIR", "missing; give the folder to write the sequence into")
    if preset == "mav" or no_noise_model or imu_only:
        _check_imu_only_options(preset, fmt, no_noise_model, imu_only)
        from functools import partial

        from gevi_cli.simulate.imu import ImuParams
        from gevi_cli.simulate.mav import MavParams, simulate_imu_only, write_mav, write_preset_imu

        imu = ImuParams(rate_hz=imu_rate, gyro_noise_density=gyro_noise, gyro_random_walk=gyro_walk,
                        acc_noise_density=acc_noise, acc_random_walk=acc_walk)
        if preset == "mav":
            params = MavParams(**{k: v for k, v in (("duration_s", duration), ("a_max", a_max)) if v is not None})
            if params.duration_s < MAV_MIN_DURATION_S:
                raise GeviError("--duration", f"mav needs at least {MAV_MIN_DURATION_S:g} s (8 s still start, 5 s "
                                              f"still end, 2 s ramps each way), got {params.duration_s:g}")
            if not params.a_max < 9.0:
                raise GeviError("--a-max", f"mav's thrust must point up: below 9 m/s^2, got {params.a_max:g}")
            if no_imu_noise:  # a perfect IMU: no white noise, no biases, no vibration, no scale error
                imu = imu.noise_free()
                params = MavParams(**{**params.__dict__, "vib_gyro": 0.0, "vib_acc": 0.0, "gyro_scale": 0.0,
                                      "gyro_bias_flight": 0.0})
            write = partial(write_mav, params=params, imu=imu, seed=seed, noise_model=not no_noise_model)
        else:
            from gevi_cli.simulate.generate import SimulationConfig

            config = SimulationConfig(preset, seed=seed, duration_s=duration, imu=imu.noise_free() if no_imu_noise else imu,
                                      a_max=a_max, moving_start=moving_start)
            write = partial(write_preset_imu, config=config, noise_model=not no_noise_model)
        click.echo(str(simulate_imu_only(out_dir, write, overwrite=overwrite)))
        return
    if name is not None and (not re.fullmatch(r"[A-Za-z0-9_.+-]+", name) or fmt != "bag"):
        raise GeviError("--name", "is only for --format bag and must be a plain file name (letters, digits, _ . + -)")
    res = parse_resolution(resolution)

    from gevi_cli.simulate.generate import SimulationConfig, simulate
    from gevi_cli.simulate.imu import ImuParams

    imu = ImuParams(rate_hz=imu_rate, gyro_noise_density=gyro_noise, gyro_random_walk=gyro_walk,
                    acc_noise_density=acc_noise, acc_random_walk=acc_walk)
    if no_imu_noise:
        imu = imu.noise_free()
    config = SimulationConfig(preset, seed=seed, duration_s=duration, rate_hz=rate, resolution=res,
                              baseline_m=baseline, distortion=not no_distortion, image_noise=not no_image_noise,
                              imu=imu, supersample=supersample, a_max=a_max, moving_start=moving_start,
                              disparity_shift_px=disparity_shift)
    result = simulate(config, out_dir, fmt, overwrite=overwrite, name=name, progress=not quiet, workers=workers)
    click.echo(str(result))


def _check_imu_only_options(preset, fmt, no_noise_model, imu_only) -> None:
    """mav and --imu-only write an IMU-only EuRoC folder: image options and other layouts are refused."""
    if no_noise_model and not (preset == "mav" or imu_only):
        raise GeviError("--no-noise-model", "is for IMU-only output (the mav preset or --imu-only)")
    if fmt != "euroc":
        raise GeviError("--format", "IMU-only output is an EuRoC folder (mav0/imu0); use --format euroc")
    ctx = click.get_current_context()
    for opt in ctx.command.params:
        flag = opt.opts[0] if opt.opts else ""
        if flag in IMAGE_OPTIONS and ctx.get_parameter_source(opt.name) == click.core.ParameterSource.COMMANDLINE:
            raise GeviError(flag, "concerns images; the output is IMU only")
