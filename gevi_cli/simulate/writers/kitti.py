"""KITTI odometry layout (rectified, undistorted, no IMU).

::

    OUT/simulation.yaml
    OUT/sequences/00/image_0/000000.png ...   left (cam0), 8-bit grey
    OUT/sequences/00/image_1/000000.png ...   right (cam1)
    OUT/sequences/00/calib.txt                P0..P3 (3x4, rectified), Tr (body/IMU -> cam0, 3x4)
    OUT/sequences/00/times.txt                seconds from the first frame, "%.6e"
    OUT/poses/00.txt                          cam0 poses relative to the first cam0 pose, 3x4 row-major

P0 = K [I | 0]; P1 = K [I | (-b, 0, 0)] so P1[0, 3] = -fx b; P2/P3 repeat P0/P1 (KITTI's colour
cameras do not exist here).  ``Tr`` (velodyne -> cam0 in real KITTI) is the IMU-body -> cam0 transform.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from gevi_cli.geometry import invert_pose, snap
from gevi_cli.simulate.writers import write_png, write_simulation_yaml


def _row(values, f="%.12e") -> str:
    return " ".join(f % v for v in np.asarray(values, float).ravel())


def calib_text(rig) -> str:
    cam = rig.cam0
    if cam.has_distortion or rig.cam1.has_distortion:
        raise ValueError("KITTI output must be rendered without lens distortion")
    K = cam.K
    T_C1_C0 = snap(rig.T_C1_C0)
    if not np.allclose(T_C1_C0[:3, :3], np.eye(3), atol=1e-12) or not np.allclose(T_C1_C0[1:3, 3], 0, atol=1e-12):
        raise ValueError("KITTI output needs a rectified rig (cam1 = cam0 shifted along x)")
    P0 = K @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P1 = snap(K @ np.hstack([np.eye(3), T_C1_C0[:3, 3:4]]))
    Tr = invert_pose(rig.T_B_C0)[:3, :]
    lines = [f"P0: {_row(P0)}", f"P1: {_row(P1)}", f"P2: {_row(P0)}", f"P3: {_row(P1)}", f"Tr: {_row(Tr)}"]
    return "\n".join(lines) + "\n"


def write_kitti(seq, out: Path, progress: bool = True, workers: int | None = None) -> Path:
    """Write ``seq`` as KITTI sequence 00 below ``out``; returns ``out``."""
    out = Path(out)
    sdir = out / "sequences" / "00"
    for d in ("image_0", "image_1"):
        (sdir / d).mkdir(parents=True, exist_ok=True)
    (out / "poses").mkdir(parents=True, exist_ok=True)
    write_simulation_yaml(out / "simulation.yaml", seq.description("kitti"))
    (sdir / "calib.txt").write_text(calib_text(seq.rig))
    t = seq.frame_t_ns
    (sdir / "times.txt").write_text("".join("%.6e\n" % ((x - t[0]) * 1e-9) for x in t.tolist()))
    T = seq.camera_poses(t, 0)
    rel = snap(invert_pose(T[0]) @ T, 1e-15)
    (out / "poses" / "00.txt").write_text("".join(_row(P[:3, :], "%.9e") + "\n" for P in rel))
    for k, _, left, right in seq.frames(progress=progress, workers=workers):
        write_png(sdir / "image_0" / f"{k:06d}.png", left)
        write_png(sdir / "image_1" / f"{k:06d}.png", right)
    return out
