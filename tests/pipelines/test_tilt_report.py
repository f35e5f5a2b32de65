"""The run's roll/pitch report (the run path's evaluation for GeVI, RunResult.tilt, printed by gevi run): RMSE,
max and the trend after the initialisation."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli.evaluation.pair import read_groundtruth
from gevi_cli.geometry import exp_so3
from gevi_cli.run.folder import RunStatus
from gevi_cli.run.pipeline import RunResult, _tilt
from gevi_cli.run.session import _print_tilt
from gevi_cli.trajectory import Trajectory
from gevi_cli.trajectory.formats import write_trajectory


def _run(tmp_path, drift_deg_per_min, duration_s=60.0, init_s=2.0):
    """A gravity-aligned estimate whose tilt error is 0.1 deg until the initialisation, then 0.1 deg plus
    the drift (a roll about x), against a ground truth that turns in yaw only."""
    t = np.arange(0.0, duration_s, 0.05)
    yaw = 0.3 * np.sin(t / 7.0)
    R_gt = np.stack([exp_so3(np.array([0.0, 0.0, a])) for a in yaw])
    err = np.radians(0.1 + drift_deg_per_min * np.clip(t - init_s, 0.0, None) / 60.0)
    R_est = np.stack([R @ exp_so3(np.array([e, 0.0, 0.0])) for R, e in zip(R_gt, err)])
    t_ns = (1_000_000_000 + np.round(t * 1e9)).astype(np.int64)
    pos = np.zeros((len(t), 3))
    write_trajectory(Trajectory.from_rotations(t_ns, R_gt, pos, frame="body"), tmp_path / "gt.tum", "tum")
    write_trajectory(Trajectory.from_rotations(t_ns, R_est, pos, frame="body"), tmp_path / "traj_body.tum", "tum")
    st = RunStatus(primary="traj_body.tum", imu={"initialised": True, "initialisation": {"at_s": init_s}})
    result = RunResult("gevi", "s", None, None, None, None, None, None, None, st, None, None,
                       truth=read_groundtruth(tmp_path / "gt.tum"))
    result.tilt, result.tilt_problem = _tilt(result, tmp_path / "traj_body.tum")
    lines = []
    _print_tilt(result, st, lambda *a, **k: lines.append(" ".join(map(str, a))))
    assert st.evaluation == result.tilt  # the command only prints and records what the run path computed
    return st.evaluation, lines


@pytest.mark.parametrize("drift", [0.0, 0.2])
def test_trend_after_the_initialisation_is_reported(tmp_path, drift):
    ev, lines = _run(tmp_path, drift)
    # the error grows linearly after init: every 5 s window's RMSE is its mean to ~1e-5 deg
    assert ev["tilt_trend_deg_per_min"] == pytest.approx(drift, abs=1e-3)
    assert ev["tilt_max_deg"] == pytest.approx(0.1 + drift * 58 / 60, abs=2e-3)
    assert len(lines) == 1 and "trend" in lines[0] and "deg/min" in lines[0]


def test_short_run_has_no_trend(tmp_path):
    ev, lines = _run(tmp_path, 0.2, duration_s=12.0)
    assert ev["tilt_trend_deg_per_min"] is None and "trend" not in lines[0]
    assert ev["tilt_rmse_deg"] > 0.1
