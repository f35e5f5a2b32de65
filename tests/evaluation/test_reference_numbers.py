"""Real reference data: evo's KITTI 00 number, kitti-odom-eval's published example_0 numbers, rpg runs."""
import json

import numpy as np
import pytest
from eval_support import run_cli

from gevi_cli.evaluation.align import align
from gevi_cli.evaluation.associate import associate
from gevi_cli.evaluation.ate import compute_ate
from gevi_cli.evaluation.evaluate import EvalSettings, evaluate_pair
from gevi_cli.evaluation.rpe import compute_rpe
from gevi_cli.trajectory import read_trajectory

RPG = "rpg_trajectory_evaluation/results/euroc_vislam_mono/laptop/vislam_rp"

# kitti-odom-eval README screenshots (SOURCE.md), example_0, --align 7dof
PUBLISHED = {
    "09": dict(t_err=2.884112, r_err=0.249056, ate=8.386619, rpe_t=0.343413, rpe_r=0.063389),
    "10": dict(t_err=3.297840, r_err=0.304590, ate=6.630158, rpe_t=0.047353, rpe_r=0.066264),
}


def test_kitti00_orb_se3_ate_equals_evo(traj_data):
    from gevi_cli.evaluation.evo_compat import APE, PoseRelation, file_interface, metrics

    gt_p, est_p = traj_data / "evo_test_data/KITTI_00_gt.txt", traj_data / "evo_test_data/KITTI_00_ORB.txt"
    ref = file_interface.read_kitti_poses_file(str(gt_p))
    est = file_interface.read_kitti_poses_file(str(est_p))
    est.align(ref)
    ape = APE(PoseRelation.translation_part)
    ape.process_data((ref, est))
    evo_rmse = ape.get_statistic(metrics.StatisticsType.rmse)
    assert evo_rmse == pytest.approx(1.30345, abs=1e-5)  # evo's 2018 result zip
    r = evaluate_pair(read_trajectory(gt_p), read_trajectory(est_p), EvalSettings(), "se3", method="orb", sequence="00")
    assert r.association.summary() == "matched 4541 of 4541 poses, coverage 100.0 % of the GT time span"
    assert abs(r.ate.trans_rmse - evo_rmse) < 1e-6
    assert r.ate.trans_mean == pytest.approx(1.15700, abs=1e-5)


def test_rotation_errors_equal_evo_pose_by_pose(traj_data):
    """gevi vectorizes evo's rotation_angle_deg relation; check it is the same number."""
    from gevi_cli.evaluation.evo_compat import APE, RPE, PoseRelation, Unit, to_evo

    gt = read_trajectory(traj_data / "evo_test_data/KITTI_00_gt.txt").select(slice(0, 800))
    est = read_trajectory(traj_data / "evo_test_data/KITTI_00_ORB.txt").select(slice(0, 800))
    aligned, _ = align(gt, est, "se3")
    ape = APE(PoseRelation.rotation_angle_deg)
    ape.process_data((to_evo(gt), to_evo(aligned)))
    np.testing.assert_allclose(compute_ate(gt, aligned).rot_errors_deg, ape.error, rtol=1e-9, atol=1e-9)
    rpe = RPE(PoseRelation.rotation_angle_deg, 1, Unit.frames, pairs_from_reference=True)
    rpe.process_data((to_evo(gt), to_evo(aligned)))
    np.testing.assert_allclose(compute_rpe(gt, aligned).rot_errors_deg, rpe.error, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("seq", ["09", "10"])
def test_kitti_odom_eval_example0_published_numbers(traj_data, seq):
    kd = traj_data / "kitti_odom_eval"
    gt = read_trajectory(kd / f"dataset/kitti_odom/gt_poses/{seq}.txt")
    est = read_trajectory(kd / f"result/example_0/{seq}.txt")
    assert est.indexed and est.t_ns[0] >= 200_000_000  # starts at frame 2 (09) or 4 (10)
    r = evaluate_pair(gt, est, EvalSettings(), "sim3", method="example_0", sequence=seq)
    want = PUBLISHED[seq]
    got = dict(t_err=r.kitti.t_err_pct, r_err=r.kitti.r_err_deg_per_100m, ate=r.ate.trans_rmse,
               rpe_t=r.kitti.rpe_trans_mean_m, rpe_r=r.kitti.rpe_rot_mean_deg)
    for k, v in want.items():
        assert got[k] == pytest.approx(v, rel=1e-4), k
    # evo's RPE (delta 1 frame, mean) equals the toolbox's translational RPE as well
    assert r.rpe.trans_mean == pytest.approx(want["rpe_t"], rel=1e-4)


def test_kitti_odom_eval_tree_through_cli(traj_data, tmp_path):
    kd = traj_data / "kitti_odom_eval"
    p = run_cli(["--results", kd / "result", "--gt-root", kd / "dataset/kitti_odom/gt_poses", "--align", "sim3",
                 "--no-plots", "-o", tmp_path / "ev"], cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "matched 1589 of 1589 poses, coverage 99.9 % of the GT time span" in p.stdout
    assert "alignment: sim3" in p.stdout
    m = json.loads((tmp_path / "ev/metrics.json").read_text())
    cells = m["tables"]["kitti_t_err"]["cells"]
    assert cells["09"]["example_0"]["mean"] == pytest.approx(PUBLISHED["09"]["t_err"], rel=1e-4)
    assert cells["10"]["example_0"]["mean"] == pytest.approx(PUBLISHED["10"]["t_err"], rel=1e-4)
    for name in ("summary.md", "runs.csv", "settings.yaml", "tables/ate_trans_rmse.tex", "tables/kitti_r_err.csv"):
        assert (tmp_path / "ev" / name).is_file(), name


@pytest.mark.parametrize("seq", ["MH_04", "V1_02"])
def test_rpg_runs_posyaw_ge_se3_ge_sim3(traj_data, seq):
    folder = traj_data / RPG / f"laptop_vislam_rp_{seq}"
    gt = read_trajectory(folder / "stamped_groundtruth.txt")
    for k in range(10):
        est = read_trajectory(folder / f"stamped_traj_estimate{k}.txt")
        a = associate(gt, est)
        assert a.n_matched == a.n_est
        e = [compute_ate(a.gt, align(a.gt, a.est, m)[0]).trans_rmse for m in ("posyaw", "se3", "sim3")]
        assert e[0] >= e[1] >= e[2], (k, e)


@pytest.mark.slow
def test_rpg_trials_table_through_cli(traj_data, tmp_path):
    root = traj_data / RPG.rsplit("/", 1)[0]
    p = run_cli(["--results", root, "--method", "vislam_rp", "--align", "auto", "--min-coverage", "0.5",
                 "-o", tmp_path / "ev"], cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    out = p.stdout
    assert "align posyaw (eval_cfg.yaml: align_type)" in out
    assert "ATE translation RMSE [m] — alignment: posyaw (all poses)" in out
    assert "| MH_04 median (min, max) |" in out and " ± " in out
    m = json.loads((tmp_path / "ev/metrics.json").read_text())
    cell = m["tables"]["ate_trans_rmse"]["cells"]["MH_04"]["vislam_rp"]
    assert cell["n_trials"] == 10 and cell["n_ok"] == 10
    vals = np.array(cell["values"])
    assert cell["mean"] == pytest.approx(vals.mean()) and cell["std"] == pytest.approx(vals.std(ddof=1))
    assert cell["median"] == pytest.approx(np.median(vals)) and cell["max"] == pytest.approx(vals.max())
    for f in ("traj_MH_04", "ate_V1_02", "rpe_MH_04", "summary_ate"):
        assert (tmp_path / "ev/plots" / f"{f}.png").is_file() and (tmp_path / "ev/plots" / f"{f}.pdf").is_file()
    # with the default 90 % coverage rule these runs (they start after take-off) are failed cells
    p = run_cli(["--results", root, "--method", "vislam_rp", "--no-plots", "-o", tmp_path / "ev90"], cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert "FAILED: coverage 68.1 % of the GT time span < 90 % (--min-coverage)" in p.stdout
    assert "| MH_04                   | failed" in p.stdout or "| MH_04 | failed" in p.stdout
