"""Helpers for the evaluation tests (fixtures are in conftest.py): the shared data folder, synthetic trajectories, the CLI."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from gevi_cli.trajectory import Trajectory
from support import SHARED_DATA

DATA = SHARED_DATA  # $GEVI_SHARED_DATA, else ../shared/data next to the repo (support.py)
TRAJ = DATA / "trajectories"


def synthetic(n=600, seed=0, dt_ns=50_000_000, t0_ns=1_403_638_000_000_000_000, frame="body", name="gt") -> Trajectory:
    """A smooth 3D trajectory (a few metres, ~30 s at 20 Hz) with varying orientation."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt_ns * 1e-9
    a = rng.uniform(0.5, 1.5, 3)
    pos = np.column_stack([4 * np.sin(0.2 * a[0] * t), 3 * np.cos(0.15 * a[1] * t), 1 + 0.5 * np.sin(0.3 * a[2] * t)])
    rot = Rotation.from_euler("zyx", np.column_stack([0.4 * t, 0.2 * np.sin(0.5 * t), 0.1 * np.cos(0.3 * t)]))
    q = rot.as_quat()
    return Trajectory(t0_ns + np.arange(n, dtype=np.int64) * dt_ns, pos, np.roll(q, 1, axis=1), frame=frame, name=name)


def transformed(traj: Trajectory, R: np.ndarray, t: np.ndarray, s: float = 1.0, name="est") -> Trajectory:
    T = traj.matrices
    out = T.copy()
    out[:, :3, :3] = R @ T[:, :3, :3]
    out[:, :3, 3] = s * T[:, :3, 3] @ R.T + t
    return Trajectory.from_matrices(traj.t_ns, out, frame=traj.frame, name=name)


def write_tum(traj: Trajectory, path: Path, scale_from_row: int | None = None, factor: float = 1.0) -> Path:
    lines = ["# timestamp tx ty tz qx qy qz qw"]
    for k, (t, p, q) in enumerate(zip(traj.t_ns, traj.positions, traj.quat_wxyz)):
        p = p.copy()
        if scale_from_row is not None and k >= scale_from_row:
            p[0] *= factor
        lines.append(f"{t // 10**9}.{t % 10**9:09d} {p[0]:.9g} {p[1]:.9f} {p[2]:.9f} {q[1]:.9f} {q[2]:.9f} {q[3]:.9f} {q[0]:.9f}")
    path.write_text("\n".join(lines) + "\n")
    return path


def run_cli(args, cwd: Path, home: Path | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["HOME"] = str(home or cwd)
    env["MPLBACKEND"] = "Agg"
    return subprocess.run([sys.executable, "-m", "gevi_cli.cli", "eval", *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)
