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
    assert np.array_equal(written.positions, result.trajectory.positions)
    assert np.array_equal(written.quat_wxyz, result.trajectory.quat_wxyz)
    frames = (tmp_path / "run" / "frames.csv").read_text().splitlines()[1:]
    assert [r.split(",")[2] for r in frames] == result.frames.status.tolist()
    status = json.loads((tmp_path / "run" / "status.json").read_text())
    pair = evaluate(gt, tmp_path / "run" / "traj_body.tum", align="se3")
    assert pair.ate.trans_rmse == status["evaluation"]["ate_m"]
    assert abs(result.evaluation.ate.trans_rmse - status["evaluation"]["ate_m"]) < 1e-9


class _ThreadProbe:
    """A run sink that records, at every frame, OpenCV's thread count and each loaded BLAS/OpenMP library's."""

    def __init__(self):
        self.cv2, self.blas = [], []

    def frame(self, index, res, total_s):
        import cv2
        from threadpoolctl import threadpool_info

        self.cv2.append(cv2.getNumThreads())
        self.blas.append([lib["num_threads"] for lib in threadpool_info()])

    def final(self, t_ns, T_cam0, T_body):
        pass

    def online(self, t_ns, T_body):
        pass

    def status(self, status):
        pass

    def restart(self):
        self.cv2, self.blas = [], []

    def close(self, status):
        pass


def test_api_runs_on_one_thread_and_gives_the_caller_its_threads_back(pool_render):
    """While api.run computes, OpenCV and every loaded BLAS (numpy's, scipy's, OpenCV's own) use one thread, as
    in `gevi run`, whatever the caller had set; on return the caller's counts are back."""
    import cv2
    from threadpoolctl import threadpool_info, threadpool_limits

    from gevi_cli.api import run

    before_cv2 = cv2.getNumThreads()
    probe = _ThreadProbe()
    with threadpool_limits(limits=2):
        cv2.setNumThreads(2)
        callers = (cv2.getNumThreads(), [lib["num_threads"] for lib in threadpool_info()])
        try:
            result = run(pool_render, method="cfo", max_frames=25, sinks=[probe])
            after = (cv2.getNumThreads(), [lib["num_threads"] for lib in threadpool_info()])
        finally:
            cv2.setNumThreads(before_cv2)
    assert len(result.frames) == 25 == len(probe.cv2)
    assert set(probe.cv2) == {1}
    assert all(len(libs) >= 1 and set(libs) == {1} for libs in probe.blas)
    assert after == callers


def test_api_is_gevi_run_to_the_bit(pool_render, tmp_path, capsys):
    """GeVI on the small pool render: api.run's final, online and cam0 poses are the run folder's, bit for bit
    (one thread in both: the same arithmetic)."""
    from gevi_cli.api import run
    from gevi_cli.trajectory import read_trajectory

    result = run(pool_render, method="gevi", max_frames=40)
    code, _, err = run_cli(["run", pool_render, "--method", "gevi", "--max-frames", "40", "-q", "-o", tmp_path / "run"],
                           capsys)
    assert code == 0, err
    for name, frame, mine in [("traj_body.tum", "body", result.trajectory),
                              ("traj_cam0.tum", "cam0", result.trajectory_cam0),
                              ("traj_online_body.tum", "body", result.online)]:
        written = read_trajectory(tmp_path / "run" / name, frame=frame)
        assert len(written) == len(mine) > 0, name
        assert np.array_equal(written.t_ns, mine.t_ns), name
        assert np.array_equal(written.positions, mine.positions), name
        assert np.array_equal(written.quat_wxyz, mine.quat_wxyz), name


def _written(metrics_json) -> dict:
    """ATE and RPE (m, deg) of the one estimate of an eval folder's metrics.json."""
    r = json.loads(metrics_json.read_text())["results"][0]
    assert r["status"] == "ok", r["reason"]
    return {k: r[part][k] for part in ("ate", "rpe") for k in ("trans_rmse", "rot_rmse_deg")}


def _numbers(pair) -> dict:
    return {k: getattr(getattr(pair, part), k) for part in ("ate", "rpe") for k in ("trans_rmse", "rot_rmse_deg")}


def test_api_evaluate_is_what_gevi_eval_writes(tmp_path, capsys):
    """evaluate() of a run folder's trajectory reads, bit for bit, the ATE and RPE that `gevi run` wrote into
    RUN/eval (against the dataset's ground truth) and that `gevi eval` writes against the KITTI ground-truth
    file (stamped with the run's times.txt): one library call under the API and both commands."""
    from gevi_cli.api import evaluate

    seq = shared_path("kitti06_head", "dataset", "sequences", "06")
    poses = shared_path("kitti06_head", "dataset", "poses", "06.txt")
    run = tmp_path / "run"
    code, _, err = run_cli(["run", seq, "--method", "cfo", "--stride", "3", "-q", "-o", run], capsys)
    assert code == 0, err
    code, _, err = run_cli(["eval", "--gt", poses, "-e", f"cfo={run}", "--align", "se3", "--no-plots", "-q",
                            "-o", tmp_path / "eval"], capsys)
    assert code == 0, err
    traj = run / "traj_body.tum"
    assert _numbers(evaluate(seq, traj, align="se3")) == _written(run / "eval" / "metrics.json")
    assert _numbers(evaluate(poses, traj, align="se3")) == _written(tmp_path / "eval" / "metrics.json")
