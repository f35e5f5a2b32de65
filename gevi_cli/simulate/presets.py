"""The five simulator presets and the builders that turn a preset + seed into a rig and a trajectory.

Frames: world W (z up), body B = IMU frame (x forward, y left, z up when level), camera C (x right,
y down, z forward).  ``T_B_C0`` is camera -> body; the right camera sits at ``+baseline`` along the
left camera's x axis with the same orientation (``R_C1C0 = I``), so undistorted images are rectified.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.geometry import make_T, small_rotation
from gevi_cli.simulate.imu import ImuParams
from gevi_cli.simulate.motion import (
    CarMotion,
    HoverMotion,
    Sines,
    Smoothstep,
    TimeWarp,
    max_acceleration,
)
from gevi_cli.simulate.render import SensorModel
from gevi_cli.simulate.scene import Water

#: camera axes expressed in the body frame (columns of R_BC) before the small mounting rotation
R_BC_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # x_c=-y_b, y_c=-x_b, z_c=-z_b
R_BC_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # x_c=-y_b, y_c=-z_b, z_c=x_b


@dataclass(frozen=True)
class HoverParams:
    """Random hovering motion inside a box (pool / room).

    Attributes:
        box_xy: (xmin, xmax, ymin, ymax) the body must stay in [m]; z0: mean height [m].
        travel: total amplitude (x, y, z) [m] of slow sinusoids with periods in ``travel_periods`` [s].
        busy: relative amplitude (x, y, z) of faster sinusoids (periods ``busy_periods``) that make
            the accelerations; the whole position signal is then scaled so that max |a| = a_max.
        yaw0_deg, angles_deg: start yaw and (yaw, pitch, roll) amplitudes; ``angle_periods`` [s].
        warp_ratio, warp_period: rate modulation r1/r0 and its period (quiet/busy periods).
        still_s, ramp_s: still start and the duration of the ramp into motion.
        a_max: target peak acceleration [m/s^2].
    """

    box_xy: tuple[float, float, float, float]
    z0: float
    travel: tuple[float, float, float]
    travel_periods: tuple[float, float]
    busy: tuple[float, float, float]
    busy_periods: tuple[float, float]
    yaw0_deg: float
    angles_deg: tuple[float, float, float]
    angle_periods: tuple[float, float]
    warp_ratio: float
    warp_period: float
    still_s: float
    ramp_s: float
    a_max: float


@dataclass(frozen=True)
class CarParams:
    """Car on a curved street: speed [m/s], road sway amplitude [m] and wavelengths [m]."""

    speed: float = 10.0
    height: float = 0.9
    road_amp: float = 25.0
    road_wavelengths: tuple[float, float] = (350.0, 600.0)
    lane_amp: float = 0.6
    surge_amp: float = 2.0


@dataclass(frozen=True)
class PresetSpec:
    """Everything a preset fixes by default (every camera/IMU number can be overridden)."""

    name: str
    description: str
    camera: Intrinsics           # reference intrinsics (radtan lens) at the default resolution
    rate_hz: float
    baseline_m: float
    duration_s: float
    facing: str                  # "down" or "forward"
    lever_arm_m: tuple[float, float, float]   # cam0 centre in the body frame
    mount_deg: tuple[float, float, float]     # small extra rotation of the camera mount
    motion: HoverParams | CarParams
    scene: str
    water: Water | None = None
    mocap: bool = False
    imu: ImuParams = field(default_factory=ImuParams)
    sensor: SensorModel = field(default_factory=SensorModel)


def _radtan(width, height, fx, fy, cx, cy, distortion=(0.0, 0.0, 0.0, 0.0)) -> Intrinsics:
    return Intrinsics(width, height, fx, fy, cx, cy, "radtan", distortion)


def _pinhole(width, height, hfov_deg, distortion, dc=(0.0, 0.0)) -> Intrinsics:
    f = (width / 2.0) / np.tan(np.radians(hfov_deg) / 2.0)
    return _radtan(width, height, f, f * 0.998, width / 2.0 - 0.5 + dc[0], height / 2.0 - 0.5 + dc[1], distortion)


_POOL_MOTION = HoverParams(
    box_xy=(1.3, 8.7, 1.3, 3.7), z0=1.0, travel=(2.6, 0.9, 0.12), travel_periods=(45.0, 90.0),
    busy=(0.35, 0.3, 0.05), busy_periods=(7.0, 14.0), yaw0_deg=10.0, angles_deg=(35.0, 5.0, 5.0),
    angle_periods=(9.0, 25.0), warp_ratio=0.6, warp_period=24.0, still_s=1.5, ramp_s=2.0, a_max=0.5)

PRESETS: dict[str, PresetSpec] = {
    "pool-easy": PresetSpec(
        name="pool-easy",
        description="10 m x 5 m x 2 m pool, downward stereo ~1 m above a floor of repetitive tiles and gravel",
        camera=_pinhole(752, 480, 80.0, (-0.18, 0.035, 2.0e-4, -1.5e-4), (3.1, -2.4)),
        rate_hz=20.0, baseline_m=0.12, duration_s=30.0, facing="down",
        lever_arm_m=(0.08, -0.03, -0.12), mount_deg=(1.5, -2.0, 3.0),
        motion=_POOL_MOTION, scene="pool-easy",
        water=Water(attenuation=0.10, veil=0.38, blur_sigma_px=1.0, blur_max=0.6, blur_range=3.0, lamp_power=1.5),
        mocap=True, sensor=SensorModel(exposure=1.05, vignetting=1.0),
    ),
    "pool-hard": PresetSpec(
        name="pool-hard",
        description="the same pool with a feature-sparse, largely planar floor, a few markers and one "
                    "calibration board; stronger accelerations",
        camera=_pinhole(752, 480, 80.0, (-0.18, 0.035, 2.0e-4, -1.5e-4), (3.1, -2.4)),
        rate_hz=20.0, baseline_m=0.12, duration_s=30.0, facing="down",
        lever_arm_m=(0.08, -0.03, -0.12), mount_deg=(1.5, -2.0, 3.0),
        motion=replace(_POOL_MOTION, busy=(0.5, 0.45, 0.08), busy_periods=(5.0, 10.0), angles_deg=(60.0, 8.0, 8.0),
                       angle_periods=(6.0, 16.0), warp_ratio=0.7, warp_period=18.0, a_max=0.95),
        scene="pool-hard",
        water=Water(attenuation=0.14, veil=0.40, blur_sigma_px=1.3, blur_max=0.75, blur_range=2.5, lamp_power=2.5),
        mocap=True, sensor=SensorModel(exposure=1.0, vignetting=1.0, read_noise_dn=1.5),
    ),
    "euroc-like": PresetSpec(
        name="euroc-like",
        description="8 m x 6 m x 3 m textured room, forward-looking 752x480 stereo at 20 Hz, 0.11 m baseline",
        camera=_radtan(752, 480, 458.654, 457.296, 367.215, 248.375, (-0.25, 0.06, 1.9e-4, 1.8e-5)),
        rate_hz=20.0, baseline_m=0.11, duration_s=30.0, facing="forward",
        lever_arm_m=(0.065, -0.02, 0.01), mount_deg=(0.8, 1.4, -1.5),
        motion=HoverParams(
            box_xy=(-2.6, 2.6, -1.8, 1.8), z0=1.3, travel=(1.8, 1.3, 0.35), travel_periods=(20.0, 45.0),
            busy=(0.3, 0.3, 0.1), busy_periods=(3.0, 8.0), yaw0_deg=0.0, angles_deg=(70.0, 8.0, 8.0),
            angle_periods=(6.0, 20.0), warp_ratio=0.5, warp_period=20.0, still_s=1.0, ramp_s=1.5, a_max=2.0),
        scene="euroc-like", sensor=SensorModel(exposure=1.0, vignetting=2.0),
    ),
    "kitti-like": PresetSpec(
        name="kitti-like",
        description="street with a ground plane and building facades, forward camera 1241x376 at 10 Hz, "
                    "0.54 m baseline, car at ~10 m/s with turns",
        camera=_radtan(1241, 376, 718.856, 718.856, 607.1928, 185.2157),
        rate_hz=10.0, baseline_m=0.54, duration_s=60.0, facing="forward",
        lever_arm_m=(0.8, 0.32, 0.75), mount_deg=(0.3, -0.5, 0.2),
        motion=CarParams(), scene="kitti-like", sensor=SensorModel(exposure=1.0, vignetting=1.5),
    ),
    "kitti-highway": PresetSpec(
        name="kitti-highway",
        description="highway: the kitti-like rig at ~27 m/s (2.7 m per frame) on gentle curves (radius > 1 km), "
                    "a road plane and only far structures (35-90 m away)",
        camera=_radtan(1241, 376, 718.856, 718.856, 607.1928, 185.2157),
        rate_hz=10.0, baseline_m=0.54, duration_s=30.0, facing="forward",
        lever_arm_m=(0.8, 0.32, 0.75), mount_deg=(0.3, -0.5, 0.2),
        motion=CarParams(speed=27.0, road_amp=40.0, road_wavelengths=(1800.0, 3000.0), surge_amp=1.5),
        scene="kitti-highway", sensor=SensorModel(exposure=1.0, vignetting=1.5),
    ),
}


# ------------------------------------------------------------------------------------- rigs
def build_rig(spec: PresetSpec, camera: Intrinsics, baseline_m: float) -> StereoRig:
    """Left/right cameras on the body: cam0 at ``spec.lever_arm_m``, cam1 at +baseline along x_c0."""
    base = R_BC_DOWN if spec.facing == "down" else R_BC_FORWARD
    R_BC0 = small_rotation(*spec.mount_deg) @ base
    T_B_C0 = make_T(R_BC0, spec.lever_arm_m)
    T_C0_C1 = make_T(np.eye(3), [baseline_m, 0.0, 0.0])
    return StereoRig(camera, camera, T_B_C0, T_B_C0 @ T_C0_C1)


def mocap_marker_extrinsic() -> np.ndarray:
    """``T_B_M``: marker-body -> IMU body transform of the pool presets (non-identity)."""
    return make_T(small_rotation(4.0, -3.0, 25.0), [0.02, 0.05, 0.18])


# ----------------------------------------------------------------------------------- motion
def _motion_horizon(duration: float) -> float:
    return max(float(duration), 120.0)


def build_motion(spec: PresetSpec, seed: int, duration: float, a_max: float | None = None, moving_start: bool = False):
    """The body trajectory of ``spec`` for ``seed``; independent of ``duration`` up to 120 s.

    ``a_max`` overrides the hovering presets' peak acceleration [m/s^2]; ``moving_start`` drops their
    still start and ramp (in motion from t = 0).  Both leave the random draws unchanged.
    """
    rng = np.random.default_rng([int(seed), 1001])
    mp = spec.motion
    if isinstance(mp, CarParams):
        return _car_motion(mp, rng)
    pos = []
    for i in range(3):
        slow = Sines.random(rng, mp.travel[i], mp.travel_periods, 2)
        fast = Sines.random(rng, mp.busy[i], mp.busy_periods, 3)
        pos.append(Sines(slow.amp + fast.amp, slow.freq + fast.freq, slow.phase + fast.phase))
    ang = [Sines.random(rng, np.radians(a), mp.angle_periods, 3) for a in mp.angles_deg]
    warp = TimeWarp(1.0, mp.warp_ratio, mp.warp_period, float(rng.uniform(0, 2 * np.pi)))
    step = Smoothstep(-2.0, -1.0) if moving_start else Smoothstep(mp.still_s, mp.still_s + mp.ramp_s)
    euler0 = (np.radians(mp.yaw0_deg), float(rng.uniform(-0.03, 0.03)), float(rng.uniform(-0.03, 0.03)))
    motion = HoverMotion((0.0, 0.0, mp.z0), euler0, tuple(pos), tuple(ang), warp, step)
    horizon = _motion_horizon(duration)
    # scale the position signal to the target peak acceleration
    k = (mp.a_max if a_max is None else float(a_max)) / max_acceleration(motion, horizon)
    motion = motion.with_position_scale(k)
    # keep the path inside the box: centre it, shrink if too wide
    t = np.arange(0.0, horizon, 0.05)
    p = motion(t).p_W
    xmin, xmax, ymin, ymax = mp.box_xy
    lo, hi = p[:, :2].min(0), p[:, :2].max(0)
    shrink = min(1.0, (xmax - xmin) / max(hi[0] - lo[0], 1e-9), (ymax - ymin) / max(hi[1] - lo[1], 1e-9))
    if shrink < 1.0:
        motion = motion.with_position_scale(shrink * 0.999)
        p = motion(t).p_W
        lo, hi = p[:, :2].min(0), p[:, :2].max(0)
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2])
    start_xy = centre - (lo + hi) / 2
    return motion.with_position_scale(1.0, p0=(float(start_xy[0]), float(start_xy[1]), mp.z0))


def _car_motion(mp: CarParams, rng: np.random.Generator) -> CarMotion:
    wl = rng.uniform(*mp.road_wavelengths, 2)
    w = rng.uniform(0.4, 1.0, 2)
    road = Sines(tuple((mp.road_amp * w / w.sum()).tolist()), tuple((1.0 / wl).tolist()),
                 tuple(rng.uniform(0, 2 * np.pi, 2).tolist()))
    surge = Sines.random(rng, mp.surge_amp, (15.0, 30.0), 2)
    lane = Sines.random(rng, mp.lane_amp, (8.0, 20.0), 2)
    bump = Sines.random(rng, 0.015, (0.7, 2.0), 3)
    pitch = Sines.random(rng, np.radians(0.6), (1.0, 4.0), 3)
    roll = Sines.random(rng, np.radians(0.6), (1.5, 5.0), 3)
    return CarMotion(0.0, mp.speed, mp.height, surge, road, lane, bump, pitch, roll)

#: what `gevi simulate` and batch configs accept: the image presets, and the IMU-only multirotor flight
PRESET_NAMES = tuple(PRESETS) + ("mav",)


def parse_resolution(value: str | None) -> tuple[int, int] | None:
    """``"WIDTHxHEIGHT"`` -> (width, height) px (16..8192 each), None for None; else a one-line GeviError."""
    import re

    from gevi_cli.errors import GeviError

    if value is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", value)
    if not m:
        raise GeviError("--resolution", f"{value!r} is not WIDTHxHEIGHT, e.g. 640x360")
    w, h = int(m.group(1)), int(m.group(2))
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise GeviError("--resolution", f"{w}x{h} is out of range (16..8192 pixels per side)")
    return w, h
