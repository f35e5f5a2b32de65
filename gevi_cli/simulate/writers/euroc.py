"""EuRoC ASL layout (``mav0/``), byte-compatible with the real V1_01_easy files.

::

    OUT/simulation.yaml
    OUT/mav0/body.yaml
    OUT/mav0/cam0/{data.csv, sensor.yaml, data/<t_ns>.png}      (cam1 the same)
    OUT/mav0/imu0/{data.csv, sensor.yaml}                       200 Hz, body = IMU frame
    OUT/mav0/state_groundtruth_estimate0/{data.csv, sensor.yaml}  body poses at the IMU stamps
    OUT/mav0/mocap0/{data.csv, sensor.yaml}                     pool presets: marker poses, T_BS = T_B_M
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gevi_cli.geometry import matrix_to_quat_wxyz
from gevi_cli.simulate.constants import MOCAP_RATE_HZ
from gevi_cli.simulate.writers import fmt, write_png, write_simulation_yaml

IMU_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
              "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
GT_HEADER = ("#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], "
             "v_RS_R_x [m s^-1], v_RS_R_y [m s^-1], v_RS_R_z [m s^-1], b_w_RS_S_x [rad s^-1], "
             "b_w_RS_S_y [rad s^-1], b_w_RS_S_z [rad s^-1], b_a_RS_S_x [m s^-2], b_a_RS_S_y [m s^-2], "
             "b_a_RS_S_z [m s^-2]")
MOCAP_HEADER = "#timestamp [ns], p_x, p_y, p_z, q_w, q_x, q_y, q_z"
CAM_HEADER = "#timestamp [ns],filename"


def _T_BS_block(T: np.ndarray) -> str:
    rows = [", ".join(fmt(x) for x in T[i]) for i in range(4)]
    return ("T_BS:\n  cols: 4\n  rows: 4\n  data: [" + rows[0] + ",\n         " + rows[1] + ",\n         "
            + rows[2] + ",\n         " + rows[3] + "]\n")


def _rate(r: float) -> str:
    return str(int(r)) if float(r).is_integer() else fmt(r)


def camera_yaml(name: str, cam, T_B_C: np.ndarray, rate_hz: float, comment: str) -> str:
    return (
        "%YAML:1.0\n"
        "# General sensor definitions.\n"
        "sensor_type: camera\n"
        f"comment: {comment}\n"
        "\n"
        "# Sensor extrinsics wrt. the body-frame.\n"
        + _T_BS_block(T_B_C)
        + "\n"
        "# Camera specific definitions.\n"
        f"rate_hz: {_rate(rate_hz)}\n"
        f"resolution: [{cam.width}, {cam.height}]\n"
        "camera_model: pinhole\n"
        f"intrinsics: [{fmt(cam.fx)}, {fmt(cam.fy)}, {fmt(cam.cx)}, {fmt(cam.cy)}] #fu, fv, cu, cv\n"
        "distortion_model: radial-tangential\n"
        f"distortion_coefficients: [{', '.join(fmt(d) for d in cam.distortion)}]\n"
    )


def imu_yaml(imu, comment: str) -> str:
    return (
        "%YAML:1.0\n"
        "#Default imu sensor yaml file\n"
        "sensor_type: imu\n"
        f"comment: {comment}\n"
        "\n"
        "# Sensor extrinsics wrt. the body-frame.\n"
        + _T_BS_block(np.eye(4))
        + f"rate_hz: {_rate(imu.rate_hz)}\n"
        "\n"
        "# inertial sensor noise model parameters (static)\n"
        f"gyroscope_noise_density: {fmt(imu.gyro_noise_density)}     # [ rad / s / sqrt(Hz) ]   ( gyro \"white noise\" )\n"
        f"gyroscope_random_walk: {fmt(imu.gyro_random_walk)}       # [ rad / s^2 / sqrt(Hz) ] ( gyro bias diffusion )\n"
        f"accelerometer_noise_density: {fmt(imu.acc_noise_density)}  # [ m / s^2 / sqrt(Hz) ]   ( accel \"white noise\" )\n"
        f"accelerometer_random_walk: {fmt(imu.acc_random_walk)}    # [ m / s^3 / sqrt(Hz) ].  ( accel bias diffusion )\n"
    )


def gt_yaml() -> str:
    return (
        "%YAML:1.0\n"
        "# General sensor definitions.\n"
        "sensor_type: visual-inertial\n"
        "comment: Exact simulated body (IMU) state, poses in the world frame (z up).\n"
        "\n"
        "# Sensor extrinsics wrt. the body-frame. This is the transformation of the\n"
        "# tracking prima to the body frame.\n"
        + _T_BS_block(np.eye(4))
    )


def mocap_yaml(T_B_M: np.ndarray, rate_hz: float) -> str:
    return (
        "%YAML:1.0\n"
        "# General sensor definitions.\n"
        "sensor_type: pose\n"
        "comment: Simulated motion capture of a marker body (pose noise 0.5 mm, 0.1 deg).\n"
        "\n"
        "# Sensor extrinsics wrt. the body-frame: marker body -> IMU body.\n"
        + _T_BS_block(T_B_M)
        + f"rate_hz: {_rate(rate_hz)}\n"
    )


def _write_rows(path: Path, header: str, t_ns: np.ndarray, cols: np.ndarray) -> None:
    lines = [header]
    for t, row in zip(t_ns.tolist(), cols.tolist()):
        lines.append(str(t) + "," + ",".join(fmt(x) for x in row))
    path.write_text("\n".join(lines) + "\n")


def write_groundtruth_csv(seq, path: Path) -> None:
    """``state_groundtruth_estimate0/data.csv``: body poses, velocities and IMU biases at the IMU stamps."""
    imu, gt = seq.imu, seq.groundtruth
    _write_rows(path, GT_HEADER, imu.t_ns,
                np.hstack([gt.p_W, matrix_to_quat_wxyz(gt.R_WB), gt.v_W, imu.bias_gyro, imu.bias_acc]))


def write_euroc(seq, out: Path, progress: bool = True, workers: int | None = None) -> Path:
    """Write ``seq`` (a :class:`~gevi_cli.simulate.generate.SimulatedSequence`) below ``out``; returns ``out``."""
    out = Path(out)
    mav = out / "mav0"
    c = seq.config
    tag = f"gevi simulate {c.preset} (seed {c.seed})"
    for d in ("cam0/data", "cam1/data", "imu0", "state_groundtruth_estimate0"):
        (mav / d).mkdir(parents=True, exist_ok=True)
    write_simulation_yaml(out / "simulation.yaml", seq.description("euroc"))
    (mav / "body.yaml").write_text(f"%YAML:1.0\ncomment: {tag}, body = IMU frame\n")
    for i, (cam, T) in enumerate(((seq.rig.cam0, seq.rig.T_B_C0), (seq.rig.cam1, seq.rig.T_B_C1))):
        (mav / f"cam{i}" / "sensor.yaml").write_text(camera_yaml(f"cam{i}", cam, T, c.rate_hz, f"{tag} cam{i}"))
        csv = [CAM_HEADER] + [f"{t},{t}.png" for t in seq.frame_t_ns.tolist()]
        (mav / f"cam{i}" / "data.csv").write_text("\n".join(csv) + "\n")
    (mav / "imu0" / "sensor.yaml").write_text(imu_yaml(c.imu, f"{tag} IMU"))
    imu = seq.imu
    _write_rows(mav / "imu0" / "data.csv", IMU_HEADER, imu.t_ns, np.hstack([imu.gyro, imu.acc]))
    (mav / "state_groundtruth_estimate0" / "sensor.yaml").write_text(gt_yaml())
    write_groundtruth_csv(seq, mav / "state_groundtruth_estimate0" / "data.csv")
    if seq.spec.mocap:
        (mav / "mocap0").mkdir(exist_ok=True)
        t_m, T_m = seq.mocap
        (mav / "mocap0" / "sensor.yaml").write_text(mocap_yaml(seq.T_B_M, MOCAP_RATE_HZ))
        _write_rows(mav / "mocap0" / "data.csv", MOCAP_HEADER, t_m,
                    np.hstack([T_m[:, :3, 3], matrix_to_quat_wxyz(T_m[:, :3, :3])]))
    for k, t, left, right in seq.frames(progress=progress, workers=workers):
        write_png(mav / "cam0" / "data" / f"{t}.png", left)
        write_png(mav / "cam1" / "data" / f"{t}.png", right)
    return out
