"""End to end on real data: the CurrentFeature back end on the authors' KITTI 04 tracks.

`scripts/cfo_kitti04.py --ba` chains the library's estimators (triangulation with covariance, l1
pre-filter, sigma2_symmetric, Bias-Eli-W PnP + refinement, epipolar local BA) over OV2SLAM's
exported front-end data.  The paper's claim for this back end is that it beats the front end it is
fed: OV2SLAM's own trajectory on 04 gray has ATE 1.306 m and RPE 0.0239 m (gevi eval reproduces
those numbers, tests/evaluation/test_cfo_kitti04.py).  Assert that claim, on every frame.
"""
import subprocess
import sys
from pathlib import Path

from support import REPO, shared_path

from gevi_cli.evaluation.evaluate import EvalSettings, evaluate_pair
from gevi_cli.trajectory import read_trajectory

OV2SLAM_GRAY = (1.306, 0.0239)  # ATE, RPE RMSE (m), SOURCE.md


def test_backend_beats_the_front_end_it_is_fed(tmp_path):
    gt_path = shared_path("cfo_kitti04", "data", "gt_poses", "kitti_gt_pose", "04.txt")
    proc = subprocess.run([sys.executable, str(REPO / "scripts" / "cfo_kitti04.py"), "--ba", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "estimator failures: 0" in proc.stdout
    est = read_trajectory(Path(tmp_path) / "04_gray.txt", frame="cam0")
    r = evaluate_pair(read_trajectory(gt_path, frame="cam0"), est, EvalSettings(), "se3", method="cfo", sequence="04")
    assert r.association.n_matched == 271
    assert r.ate.trans_rmse < OV2SLAM_GRAY[0]
    assert r.rpe.trans_rmse < OV2SLAM_GRAY[1]
