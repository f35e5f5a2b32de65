"""The batch's evaluation of a row matched to the ground truth by frame index (KITTI 04 tracks: the ground
truth file has no stamps) equals an independent api.evaluate of the run's primary file, in the first
invocation (the run's own evaluation taken) and after a resume (evaluated from the folder)."""
import json
from pathlib import Path

import pytest

from gevi_cli.api import evaluate
from gevi_cli.batch.runner import run_batch
from support import shared_path

pytestmark = pytest.mark.slow


def test_by_index_row_equals_an_independent_evaluation_and_after_a_resume(tmp_path):
    root = shared_path("cfo_kitti04")
    gt = root / "data" / "gt_poses" / "kitti_gt_pose" / "04.txt"
    config = tmp_path / "tracks.yaml"
    config.write_text(f"""name: tracks
root: .
trials: 1
methods: [cfo]
sequences:
  - name: kitti04_tracks_gray
    path: {root / 'data' / 'ov2slam_data' / 'ov2slam_data_kitti_04_gray'}
    calib: {root / 'calib' / 'gray_calib.txt'}
    gt: {gt}
""")
    out = tmp_path / "out"
    assert run_batch(config, out, jobs=1, echo=lambda *a, **k: None, progress=False) == 0

    def row():
        (r,) = json.loads((out / "report" / "results.json").read_text())["runs"]
        return r

    first = row()
    run_dir = Path(first["run_dir"])
    status = json.loads((run_dir / "status.json").read_text())
    assert status["primary"] == "traj_body_kitti.txt"  # by frame index
    ev = evaluate(gt, run_dir / status["primary"])
    assert ev.association.by_index
    assert (first["ate_m"], first["rpe_m"]) == (ev.ate.trans_rmse, ev.rpe.trans_rmse)
    (out / "report").rename(tmp_path / "report_first")
    assert run_batch(config, out, jobs=1, echo=lambda *a, **k: None, progress=False) == 0
    again = row()
    for key in ("ate_m", "rpe_m", "path_ratio", "step_ratio_median"):
        assert again[key] == first[key], key
