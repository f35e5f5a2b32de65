"""The one run path (gevi_cli.run.pipeline.run_and_evaluate): without a run folder it evaluates the
primary trajectory as the folder would hold it, so api.run, gevi run and gevi batch read the same numbers."""
from __future__ import annotations

import json

from support import run_cli, shared_path


def test_in_memory_kitti_rows_are_evaluated_as_written(tmp_path, capsys):
    """On a track export with a KITTI ground truth (matched by frame index) the primary trajectory is the
    KITTI rows, which keep ~1e-6 of each matrix: evaluated in memory they give the run folder's ATE, RPE,
    scale and KITTI figures to the bit."""
    from gevi_cli.run.folder import RunStatus
    from gevi_cli.run.pipeline import primary_file, run_and_evaluate
    from gevi_cli.run.session import RunRequest, resolve
    from gevi_cli.run.threads import one_thread

    data = shared_path("cfo_kitti04")
    seq = data / "data/ov2slam_data/ov2slam_data_kitti_04_gray"
    gt = data / "data/gt_poses/kitti_gt_pose/04.txt"
    calib = data / "calib/gray_calib.txt"
    resolved = resolve(RunRequest(sequence=str(seq), method="cfo", max_frames=30, groundtruth=str(gt),
                                  calib=str(calib), quiet=True))
    with one_thread():
        result = run_and_evaluate(resolved, RunStatus(method="cfo", primary=primary_file(resolved)))
    code, _, err = run_cli(["run", seq, "--method", "cfo", "--max-frames", "30", "--gt", gt, "--calib", calib, "-q",
                            "-o", tmp_path / "run"], capsys)
    assert code == 0, err
    status = json.loads((tmp_path / "run" / "status.json").read_text())
    assert status["primary"] == result.status.primary == "traj_body_kitti.txt"
    ev = result.evaluation
    assert ev.association.by_index
    assert (ev.ate.trans_rmse, ev.rpe.trans_rmse, ev.scale.path_ratio) == (
        status["evaluation"]["ate_m"], status["evaluation"]["rpe_m"], status["evaluation"]["path_ratio"])
    written = json.loads((tmp_path / "run" / "eval" / "metrics.json").read_text())["results"][0]
    assert ev.ate.rot_rmse_deg == written["ate"]["rot_rmse_deg"]
    # the KITTI metric re-reads the rows as written (not their nearest rotations)
    assert (ev.kitti.rpe_trans_mean_m, ev.kitti.rpe_rot_mean_deg) == (written["kitti"]["rpe_trans_mean_m"],
                                                                      written["kitti"]["rpe_rot_mean_deg"])
