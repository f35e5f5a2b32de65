"""Scale figures (path-length ratio, median step-length ratio): a known scale error read exactly under every
alignment, in the ground truth's sensor frame; n/a at rest; evo's Sim(3) scale is its inverse; the tables
rank by closeness to 1 and say n/a; `gevi eval` writes them into metrics.json, runs.csv and the tables."""
import json

import numpy as np
import pytest
from eval_support import run_cli, synthetic, transformed, write_tum
from scipy.spatial.transform import Rotation

from gevi_cli.evaluation.evaluate import EvalSettings, evaluate_pair
from gevi_cli.evaluation.report import build_tables
from gevi_cli.evaluation.scale import MIN_PATH_M, MIN_STEP_M, MIN_STEPS, compute_scale, step_lengths
from gevi_cli.evaluation.tables import Cell, Table, render_markdown
from gevi_cli.trajectory import Trajectory

SCALE = 1.08
#: the estimate's world: rotated and moved against the ground truth's (a rigid change: no step changes length)
R_W = Rotation.from_euler("zyx", [0.9, -0.2, 0.3]).as_matrix()
T_W = np.array([12.0, -3.5, 0.7])
#: float64 ratios of sums of ~600 step lengths of ~0.05 m: rounding is ~1e-13, far inside this
EXACT = 1e-9


def scaled_about_start(gt: Trajectory, s: float = SCALE) -> Trajectory:
    """The ground truth's positions scaled by ``s`` about its first position (orientations kept), then
    expressed in the world ``R_W, T_W``."""
    p0 = gt.positions[0]
    scaled = Trajectory(gt.t_ns, p0 + s * (gt.positions - p0), gt.quat_wxyz, frame=gt.frame, name="scaled")
    return transformed(scaled, R_W, T_W)


def at_rest(n=200, jitter_m=2e-5, seed=1) -> Trajectory:
    """A ground truth standing still with sub-millimetre position noise (every step far below 1 cm)."""
    gt = synthetic(n)
    rng = np.random.default_rng(seed)
    pos = np.array([1.0, 2.0, 0.5]) + rng.normal(0.0, jitter_m, (n, 3))
    return Trajectory(gt.t_ns, pos, np.tile([1.0, 0, 0, 0], (n, 1)), frame="body", name="gt")


def test_known_scale_error_reads_exactly():
    gt = synthetic()
    sc = compute_scale(gt, scaled_about_start(gt))
    assert sc.path_ratio == pytest.approx(SCALE, abs=EXACT)
    assert sc.step_ratio_median == pytest.approx(SCALE, abs=EXACT)
    assert sc.n_steps == len(gt) - 1 and sc.n_steps_used == int((step_lengths(gt) >= MIN_STEP_M).sum())
    assert sc.path_length_gt_m == pytest.approx(gt.path_length_m, rel=1e-12)
    assert sc.path_length_est_m == pytest.approx(SCALE * gt.path_length_m, rel=1e-12)


@pytest.mark.parametrize("align", ["none", "origin", "se3", "sim3", "posyaw"])
def test_scale_is_read_before_alignment_and_sim3_s_is_its_inverse(align):
    """Every alignment reads the same figures (the estimate unaligned, never Sim(3)-scaled); evo's Umeyama
    scale maps the estimate onto the ground truth, so for a uniform scale error s = 1 / path ratio exactly."""
    gt = synthetic()
    r = evaluate_pair(gt, scaled_about_start(gt), EvalSettings(kitti=False), align, method="m", sequence="s")
    assert r.ok
    assert r.scale.path_ratio == pytest.approx(SCALE, abs=EXACT)
    assert r.scale.step_ratio_median == pytest.approx(SCALE, abs=EXACT)
    if align == "sim3":
        assert r.alignment.scale * r.scale.path_ratio == pytest.approx(1.0, abs=EXACT)
        assert r.ate.trans_rmse < 1e-9  # the Sim(3) alignment removes the scale error from ATE, not from the ratio


def test_scale_is_read_in_the_ground_truths_sensor_frame():
    """cam0 poses of a body ground truth, converted with T_B_C0 before the figures are read: exactly 1. On
    the cam0 positions as written, the 0.5 m lever arm of this turning path changes the path's length."""
    gt = synthetic()
    T_B_C0 = np.eye(4)
    T_B_C0[:3, :3] = Rotation.from_euler("x", -90, degrees=True).as_matrix()
    T_B_C0[:3, 3] = [0.5, 0.1, -0.2]
    est_cam0 = transformed(gt.with_sensor_frame(T_B_C0, "cam0"), R_W, T_W)
    r = evaluate_pair(gt, est_cam0, EvalSettings(est_frame="cam0", kitti=False), "se3", method="m", sequence="s",
                      T_B_C0=T_B_C0)
    assert r.scale.path_ratio == pytest.approx(1.0, abs=EXACT)
    assert r.scale.step_ratio_median == pytest.approx(1.0, abs=EXACT)
    assert abs(compute_scale(gt, est_cam0).path_ratio - 1.0) > 1e-3


def test_at_rest_both_figures_are_na():
    """All ground-truth steps < 1 cm and a path below MIN_PATH_M (199 steps of ~0.05 mm): n/a, both."""
    gt = at_rest()
    assert step_lengths(gt).max() < MIN_STEP_M and gt.path_length_m < MIN_PATH_M
    sc = compute_scale(gt, scaled_about_start(gt))
    assert np.isnan(sc.step_ratio_median) and sc.n_steps_used == 0
    assert np.isnan(sc.path_ratio)
    assert sc.as_dict()["path_ratio"] != sc.as_dict()["path_ratio"]  # NaN: None once written to JSON
    standing = Trajectory(gt.t_ns, np.zeros((len(gt), 3)), gt.quat_wxyz, frame="body")  # no motion at all
    assert np.isnan(compute_scale(standing, standing).path_ratio)


def test_slow_motion_has_a_path_ratio_but_no_median():
    """Steps of 5 mm (below 1 cm) over a 0.5 m path: the median is n/a, the path ratio is read exactly."""
    gt = synthetic(101)
    pos = np.column_stack([0.005 * np.arange(101), np.zeros(101), np.zeros(101)])
    gt = Trajectory(gt.t_ns, pos, gt.quat_wxyz, frame="body", name="gt")
    sc = compute_scale(gt, scaled_about_start(gt))
    assert np.isnan(sc.step_ratio_median)
    assert sc.path_ratio == pytest.approx(SCALE, abs=EXACT)


def test_median_needs_min_steps_of_one_cm():
    """MIN_STEPS - 1 steps of 2 cm among 1 mm ones: n/a; one more: the median of the long steps only."""
    for n_long, defined in ((MIN_STEPS - 1, False), (MIN_STEPS, True)):
        steps = np.full(40, 0.001)
        steps[::5][:n_long] = 0.02
        pos = np.column_stack([np.concatenate([[0.0], np.cumsum(steps)]), np.zeros(41), np.zeros(41)])
        gt = Trajectory(synthetic(41).t_ns, pos, np.tile([1.0, 0, 0, 0], (41, 1)), frame="body")
        est_pos = pos.copy()
        est_pos[1:, 0] = np.cumsum(np.where(steps >= MIN_STEP_M, 1.1, 3.0) * steps)  # short steps 3x: left out
        sc = compute_scale(gt, Trajectory(gt.t_ns, est_pos, gt.quat_wxyz, frame="body"))
        assert sc.n_steps_used == n_long
        assert np.isnan(sc.step_ratio_median) != defined
        if defined:
            assert sc.step_ratio_median == pytest.approx(1.1, abs=EXACT)


def _row(md, label):
    return [c.strip() for c in next(ln for ln in md.splitlines() if ln.startswith(f"| {label} ")).strip("|").split("|")]


def test_scale_tables_rank_by_closeness_to_one_and_say_na():
    t = Table("scale_path_ratio", "ratio", ["a", "b", "c"], ["s"], target=1.0,
              cells={("s", "a"): Cell([1.2], 1), ("s", "b"): Cell([0.95], 1), ("s", "c"): Cell([1.08], 1)})
    assert _row(render_markdown(t), "s") == ["s", "1.200", "**0.9500**", "_1.080_"]
    # an estimate of a sequence at rest: evaluated (not failed), its scale n/a; ATE still a number
    gt = at_rest()
    moving = synthetic()
    settings = EvalSettings(kitti=False)
    results = [evaluate_pair(gt, scaled_about_start(gt), settings, "origin", method="m", sequence="rest"),
               evaluate_pair(moving, scaled_about_start(moving), settings, "se3", method="m", sequence="moving")]
    assert all(r.ok for r in results)
    tables = {t.key: t for t in build_tables(results, ["m"], ["rest", "moving"], settings)}
    for key in ("scale_path_ratio", "scale_step_ratio_median"):
        md = render_markdown(tables[key])
        assert _row(md, "rest") == ["rest", "n/a"] and _row(md, "moving") == ["moving", "1.080"]
    assert _row(render_markdown(tables["ate_trans_rmse"]), "rest")[1] != "n/a"


def test_gevi_eval_writes_the_scale_columns(tmp_path):
    gt = synthetic()
    est = scaled_about_start(gt)
    write_tum(gt, tmp_path / "gt.txt")
    write_tum(est, tmp_path / "est.txt")
    out = tmp_path / "eval"
    p = run_cli(["--gt", tmp_path / "gt.txt", "-e", f"scaled={tmp_path / 'est.txt'}", "--align", "sim3",
                 "--no-plots", "-o", out], cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    # write_tum keeps x to 9 significant digits (<= 5e-9 m here, |x| < 10 m) and y, z to 1e-9 m: each step
    # length is then off by <= 2 * |(5e-9, 5e-10, 5e-10)| and its ratio by that over the shortest step used
    quant = 2 * np.linalg.norm([5e-9, 5e-10, 5e-10])
    tol = (1 + SCALE) * quant / step_lengths(gt)[step_lengths(gt) >= MIN_STEP_M].min()
    res = json.loads((out / "metrics.json").read_text())
    sc = res["results"][0]["scale"]
    assert sc["path_ratio"] == pytest.approx(SCALE, abs=tol)
    assert sc["step_ratio_median"] == pytest.approx(SCALE, abs=tol)
    assert res["results"][0]["alignment"]["scale"] * sc["path_ratio"] == pytest.approx(1.0, abs=2 * tol)
    cell = res["tables"]["scale_path_ratio"]["cells"]["gt"]["scaled"]
    assert cell["mean"] == sc["path_ratio"] and cell["n_ok"] == 1
    summary = (out / "summary.md").read_text()
    for title in ("### Scale: path-length ratio [est/GT]", "### Scale: median step-length ratio (GT steps >= 1 cm)"):
        table = summary.split(title)[1].split("###")[0]
        assert _row(table, "gt") == ["gt", "1.080"]
    for key in ("scale_path_ratio", "scale_step_ratio_median"):
        assert (out / "tables" / f"{key}.csv").read_text().startswith("sequence,statistic,scaled\n")
        assert (out / "tables" / f"{key}.tex").is_file()
    header = (out / "runs.csv").read_text().splitlines()[0].split(",")
    assert "scale_path_ratio" in header and "scale_step_ratio_median" in header
    assert "Scale: path-length ratio [est/GT]" in p.stdout  # the console tables
