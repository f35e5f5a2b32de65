"""A dataset folder as ground truth: its GT (body frame) and its T_B_C0 convert cam0 estimates."""
import json
import shutil

import pytest
from eval_support import DATA, run_cli


def test_dataset_as_ground_truth_converts_cam0_estimates(tmp_path):
    micro = DATA / "euroc_micro"
    if not (micro / "mav0").is_dir():
        pytest.skip(f"EuRoC micro dataset not found: {micro}")
    from gevi_cli.datasets import open_sequence
    from gevi_cli.trajectory import write_trajectory

    ds = tmp_path / "V1_01_easy"
    (ds / "mav0" / "state_groundtruth_estimate0").mkdir(parents=True)
    for x in ("cam0", "cam1", "imu0", "body.yaml"):
        if (micro / "mav0" / x).exists():
            (ds / "mav0" / x).symlink_to(micro / "mav0" / x)
    shutil.copy(micro / "groundtruth" / "V1_01_easy.csv", ds / "mav0/state_groundtruth_estimate0/data.csv")
    seq = open_sequence(ds)
    cam = seq.groundtruth.with_sensor_frame(seq.calibration.T_B_C0, "cam0")
    write_trajectory(cam, tmp_path / "cam.tum", "tum")
    p = run_cli(["--gt", ds, "-e", f"cam={tmp_path / 'cam.tum'}", "--est-frame", "cam0", "--no-plots",
                 "-o", tmp_path / "o"], tmp_path)
    assert p.returncode == 0, p.stderr
    r = json.loads((tmp_path / "o/metrics.json").read_text())["results"][0]
    assert r["sequence"] == "V1_01_easy" and r["ate"]["trans_rmse"] < 1e-6 and r["rpe"]["rot_rmse_deg"] < 1e-4
