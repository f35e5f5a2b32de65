"""The Python API (gevi_cli.api): a run and its evaluation in memory, the same numbers as `gevi run`."""
from __future__ import annotations

import json

import numpy as np

from support import run_cli, shared_path


def test_api_alone_runs_and_evaluates():
    """Only the API: every 3rd frame of the real KITTI 06 head, tracked at every frame, within ORB-SLAM3's
    ATE there (0.090 m), and evaluate() of the returned trajectory gives the run's own evaluation."""
    from gevi_cli.api import evaluate, run

    seq = shared_path("kitti06_head", "dataset", "sequences", "06")
    result = run(seq, method="cfo", stride=3)
    assert result.method == "cfo" and len(result.trajectory) == 17 == len(result.frames)
    assert (result.frames.status == "ok").all() and result.states is None
    assert set(result.timings.columns) >= {"frontend", "pose", "ba"}
    assert result.evaluation.ate.trans_rmse < 0.090
    again = evaluate(result.groundtruth, result.trajectory, align="se3")
    assert again.ate.trans_rmse == result.evaluation.ate.trans_rmse
    assert again.rpe.trans_rmse == result.evaluation.rpe.trans_rmse


def test_api_is_what_the_cli_writes(tmp_path, capsys):
    """GeVI on euroc_micro: the in-memory trajectory and frames are the run folder's, and evaluate() on the
    folder's file against the ground-truth file reads the ATE gevi run printed into status.json."""
    from gevi_cli.api import evaluate, run
    from gevi_cli.trajectory import read_trajectory

    seq = shared_path("euroc_micro")
    gt = seq / "groundtruth" / "V1_01_easy.csv"
    result = run(seq, groundtruth=gt)
    assert result.method == "gevi" and result.states is not None
    code, _, err = run_cli(["run", seq, "--gt", gt, "-q", "-o", tmp_path / "run"], capsys)
    assert code == 0, err
    written = read_trajectory(tmp_path / "run" / "traj_body.tum", frame="body")
    assert np.array_equal(written.t_ns, result.trajectory.t_ns)
    np.testing.assert_allclose(written.positions, result.trajectory.positions, rtol=0, atol=1e-9)
    frames = (tmp_path / "run" / "frames.csv").read_text().splitlines()[1:]
    assert [r.split(",")[2] for r in frames] == result.frames.status.tolist()
    status = json.loads((tmp_path / "run" / "status.json").read_text())
    pair = evaluate(gt, tmp_path / "run" / "traj_body.tum", align="se3")
    assert pair.ate.trans_rmse == status["evaluation"]["ate_m"]
    assert abs(result.evaluation.ate.trans_rmse - status["evaluation"]["ate_m"]) < 1e-9
