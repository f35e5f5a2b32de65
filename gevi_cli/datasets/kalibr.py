"""Kalibr calibration YAML files: the camera chain (``camchain.yaml``) and the IMU noise (``imu.yaml``).

Camchain (one block per camera, ``cam0`` = left, ``cam1`` = right)::

    cam0:
      camera_model: pinhole
      intrinsics: [fu, fv, cu, cv]          # pixels
      distortion_model: radtan              # radtan | equidistant | none
      distortion_coeffs: [k1, k2, p1, p2]   # (k1, k2, k3, k4) for equidistant
      resolution: [width, height]
      T_cam_imu: 4x4 nested list            # IMU -> camera: X_C = T_cam_imu X_I
      rostopic: /cam0/image_raw             # optional
      timeshift_cam_imu: 0.0                # optional, t_imu = t_cam + shift (seconds)
    cam1:
      ...                                   # same keys, plus optionally
      T_cn_cnm1: 4x4 nested list            # cam0 -> cam1: X_C1 = T_cn_cnm1 X_C0

gevi's body frame is the IMU frame, so ``T_B_C = inv(T_cam_imu)``.  When ``cam1`` has no
``T_cam_imu`` it is derived from ``T_cn_cnm1``; when ``cam0`` has none (a camera-only calibration)
the body frame is taken to be cam0 and a warning says so.

IMU (``imu.yaml``; keys at the top level or under ``imu0``, the same names as EuRoC's
``imu0/sensor.yaml``)::

    accelerometer_noise_density: 2.0e-3   # m/s^2/sqrt(Hz)
    accelerometer_random_walk: 3.0e-3     # m/s^3/sqrt(Hz)
    gyroscope_noise_density: 1.6968e-4    # rad/s/sqrt(Hz)
    gyroscope_random_walk: 1.9393e-5      # rad/s^2/sqrt(Hz)
    rostopic: /imu0                       # optional
    update_rate: 200.0                    # optional, Hz
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.datasets.yamlio import load_yaml, matrix
from gevi_cli.errors import DataError
from gevi_cli.geometry import invert_pose

_DISTORTION = {"radtan": "radtan", "radial-tangential": "radtan", "plumb_bob": "radtan",
               "equidistant": "equidistant", "fisheye": "equidistant", "none": "none"}

#: Kalibr key -> :class:`~gevi_cli.datasets.sequence.ImuData` field.
IMU_NOISE_KEYS = {
    "gyroscope_noise_density": "gyro_noise_density",
    "gyroscope_random_walk": "gyro_random_walk",
    "accelerometer_noise_density": "acc_noise_density",
    "accelerometer_random_walk": "acc_random_walk",
}

#: Stereo extrinsics given both ways (T_cam_imu and T_cn_cnm1) may differ by this much before a warning.
_CONSISTENCY_M = 1e-3
_CONSISTENCY_RAD = math.radians(0.05)


@dataclass
class Camchain:
    """What a Kalibr camchain says: the rig, the image topics it was calibrated on, and remarks."""

    rig: StereoRig
    topics: dict[str, str] = field(default_factory=dict)  # "left"/"right" -> rostopic, when given
    warnings: list[str] = field(default_factory=list)
    time_shift_s: float = 0.0  # cam0.timeshift_cam_imu: t_imu = t_cam + shift (s)


def is_camchain(data: dict) -> bool:
    return isinstance(data.get("cam0"), dict) and isinstance(data.get("cam1"), dict)


def read_camchain(path: Path) -> Camchain:
    """Parse a Kalibr camchain YAML holding (at least) ``cam0`` and ``cam1``."""
    path = Path(path)
    data = load_yaml(path)
    if not is_camchain(data):
        raise DataError(path, "not a Kalibr camchain: expected 'cam0:' and 'cam1:' blocks "
                              "(camera_model, intrinsics, distortion_model, distortion_coeffs, resolution, T_cam_imu)")
    warnings: list[str] = []
    cams = {}
    T_cam_imu = {}
    shifts = {}
    for name in ("cam0", "cam1"):
        block = data[name]
        cams[name] = _intrinsics(block, path, name)
        T_cam_imu[name] = matrix(block["T_cam_imu"], path, f"{name}.T_cam_imu") if "T_cam_imu" in block else None
        shift = block.get("timeshift_cam_imu", 0.0)
        try:
            shift = yaml_real(shift)
        except (TypeError, ValueError):
            raise DataError(path, f"'{name}.timeshift_cam_imu' is not a number") from None
        if not math.isfinite(shift):
            raise DataError(path, f"'{name}.timeshift_cam_imu' is not finite")
        shifts[name] = shift
    T_C1_C0 = matrix(data["cam1"]["T_cn_cnm1"], path, "cam1.T_cn_cnm1") if "T_cn_cnm1" in data["cam1"] else None

    if T_cam_imu["cam0"] is not None:
        T_B_C0 = invert_pose(T_cam_imu["cam0"])
    else:
        T_B_C0 = np.eye(4)
        warnings.append(f"{path}: cam0 has no T_cam_imu (camera-only calibration); the body frame is taken "
                        "to be cam0, so IMU data cannot be related to the cameras")
    if T_cam_imu["cam1"] is not None and T_cam_imu["cam0"] is not None:
        T_B_C1 = invert_pose(T_cam_imu["cam1"])
        if T_C1_C0 is not None:
            diff = invert_pose(T_B_C1) @ T_B_C0 @ invert_pose(T_C1_C0)
            dt = float(np.linalg.norm(diff[:3, 3]))
            dr = float(np.arccos(np.clip((np.trace(diff[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))
            if dt > _CONSISTENCY_M or dr > _CONSISTENCY_RAD:
                warnings.append(f"{path}: cam1.T_cn_cnm1 disagrees with the two T_cam_imu by {dt * 1e3:.2f} mm, "
                                f"{math.degrees(dr):.3f} deg; using T_cam_imu")
    elif T_C1_C0 is not None:
        T_B_C1 = T_B_C0 @ invert_pose(T_C1_C0)
    else:
        raise DataError(path, "cam1 needs 'T_cam_imu' or 'T_cn_cnm1' (its pose relative to the IMU or to cam0)")

    rig = StereoRig(cams["cam0"], cams["cam1"], T_B_C0, T_B_C1)
    topics = {side: str(data[cam]["rostopic"]) for side, cam in (("left", "cam0"), ("right", "cam1"))
              if data[cam].get("rostopic")}
    if shifts["cam1"] != shifts["cam0"]:
        warnings.append(f"{path}: cam1.timeshift_cam_imu ({shifts['cam1']:g} s) differs from cam0's "
                        f"({shifts['cam0']:g} s); the stereo pair is taken as synchronous and cam0's is applied")
    return Camchain(rig, topics, warnings, shifts["cam0"])


def _intrinsics(block: dict, path: Path, name: str) -> Intrinsics:
    if not isinstance(block, dict):
        raise DataError(path, f"'{name}' is not a mapping")
    model = str(block.get("camera_model", "pinhole"))
    if model != "pinhole":
        raise DataError(path, f"{name}.camera_model '{model}' is not supported (only pinhole)")
    try:
        fu, fv, cu, cv = (yaml_real(v) for v in _require(block, "intrinsics", path, name))
        width, height = (yaml_whole(v) for v in _require(block, "resolution", path, name))
    except (TypeError, ValueError):
        raise DataError(path, f"{name}: 'intrinsics' must be [fu, fv, cu, cv] and 'resolution' [width, height]") from None
    if width <= 0 or height <= 0:
        raise DataError(path, f"{name}: 'resolution' must be positive, got [{width}, {height}]")
    dist_name = str(block.get("distortion_model", "none")).lower()
    if dist_name not in _DISTORTION:
        raise DataError(path, f"{name}.distortion_model '{dist_name}' is not supported (radtan, equidistant, none)")
    dist = _DISTORTION[dist_name]
    try:
        coeffs = tuple(yaml_real(c) for c in (block.get("distortion_coeffs") or []))
    except (TypeError, ValueError):
        raise DataError(path, f"{name}.distortion_coeffs must be a list of numbers") from None
    if dist == "none":
        if any(coeffs):
            raise DataError(path, f"{name}: distortion_model none with non-zero distortion_coeffs")
        coeffs = ()
    elif len(coeffs) != 4:
        raise DataError(path, f"{name}: {dist_name} distortion needs 4 distortion_coeffs, got {len(coeffs)}")
    if not all(math.isfinite(v) for v in (fu, fv, cu, cv, *coeffs)) or fu <= 0 or fv <= 0:
        raise DataError(path, f"{name}: intrinsics must be finite with fu, fv > 0")
    return Intrinsics(width, height, fu, fv, cu, cv, dist, coeffs)


def _require(block: dict, key: str, path: Path, name: str):
    """``block[key]``; a missing key is a DataError at the file (``where`` is the file alone)."""
    if key not in block:
        raise DataError(path, f"{name}: missing key '{key}'")
    return block[key]


def yaml_real(value) -> float:
    """A YAML number: int, float or a string of one (PyYAML reads ``1e-3``, without a dot, as a
    string); not a bool (``true`` is not 1.0), a list or a mapping."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise TypeError(f"not a number: {value!r}")
    return float(value)


def yaml_whole(value) -> int:
    """A YAML whole number (752 or 752.0; 752.5 is refused, not truncated)."""
    value = yaml_real(value)
    if not math.isfinite(value) or value != int(value):
        raise ValueError(f"not a whole number: {value!r}")
    return int(value)


def read_imu_noise(path: Path) -> dict[str, float]:
    """The IMU noise parameters of a Kalibr ``imu.yaml`` (or an EuRoC ``imu0/sensor.yaml``) as ImuData fields."""
    path = Path(path)
    data = load_yaml(path)
    if isinstance(data.get("imu0"), dict) and not any(k in data for k in IMU_NOISE_KEYS):
        data = data["imu0"]
    noise = {}
    for key, name in IMU_NOISE_KEYS.items():
        if key in data:
            try:
                value = yaml_real(data[key])
            except (TypeError, ValueError):
                raise DataError(path, f"'{key}' is not a number") from None
            if not math.isfinite(value) or value < 0:
                raise DataError(path, f"'{key}' must be a finite non-negative number")
            noise[name] = value
    if not noise:
        raise DataError(path, "holds none of " + ", ".join(IMU_NOISE_KEYS) + " (not a Kalibr imu.yaml)")
    return noise


# ------------------------------------------------------------------------------------------ writing
def camchain_dict(rig: StereoRig, topics: dict[str, str] | None = None) -> dict:
    """The Kalibr camchain mapping of ``rig`` (``T_cam_imu = inv(T_B_C)``, plus ``T_cn_cnm1`` for cam1)."""
    topics = topics or {}
    out = {}
    for name, side, cam, T_B_C in (("cam0", "left", rig.cam0, rig.T_B_C0), ("cam1", "right", rig.cam1, rig.T_B_C1)):
        block = {
            "T_cam_imu": invert_pose(T_B_C).tolist(),
            "camera_model": "pinhole",
            "distortion_coeffs": [float(c) for c in cam.distortion],
            "distortion_model": cam.distortion_model,
            "intrinsics": [float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy)],
            "resolution": [int(cam.width), int(cam.height)],
        }
        if name == "cam1":
            block["T_cn_cnm1"] = rig.T_C1_C0.tolist()
            block["cam_overlaps"] = [0]
        else:
            block["cam_overlaps"] = [1]
        if side in topics:
            block["rostopic"] = topics[side]
        block["timeshift_cam_imu"] = 0.0
        out[name] = block
    return out


def write_camchain(path: Path, rig: StereoRig, topics: dict[str, str] | None = None) -> None:
    """Write ``rig`` as a Kalibr camchain YAML (floats keep full precision: YAML repr round-trips)."""
    Path(path).write_text(yaml.safe_dump(camchain_dict(rig, topics), sort_keys=False, default_flow_style=None))


def write_imu_yaml(path: Path, *, gyro_noise_density: float, gyro_random_walk: float, acc_noise_density: float,
                   acc_random_walk: float, rostopic: str = "/imu0", update_rate: float | None = None) -> None:
    """Write the IMU noise model as a Kalibr ``imu.yaml``."""
    data = {
        "accelerometer_noise_density": float(acc_noise_density),
        "accelerometer_random_walk": float(acc_random_walk),
        "gyroscope_noise_density": float(gyro_noise_density),
        "gyroscope_random_walk": float(gyro_random_walk),
        "rostopic": rostopic,
    }
    if update_rate is not None:
        data["update_rate"] = float(update_rate)
    Path(path).write_text(yaml.safe_dump(data, sort_keys=False))
