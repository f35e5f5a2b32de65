"""Bad input through the CLI: one line, exit 2, no traceback; failed/coverage rules."""
import json

import numpy as np
from eval_support import run_cli, synthetic, write_tum

from gevi_cli.trajectory import Trajectory


def _one_error_line(p):
    assert p.returncode == 2, (p.stdout, p.stderr)
    lines = [line for line in p.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, p.stderr
    assert "Traceback" not in p.stderr
    assert lines[0].startswith("gevi: error: ")
    return lines[0]


def test_corrupt_estimate_is_rejected_with_file_and_row(tmp_path):
    gt = write_tum(synthetic(), tmp_path / "gt.tum")
    bad = write_tum(synthetic(), tmp_path / "est.tum", scale_from_row=300, factor=1e9)
    line = _one_error_line(run_cli(["--gt", gt, "-e", f"ours={bad}", "--no-plots", "-o", tmp_path / "o"], tmp_path))
    # header is line 1, row k (0-based) is line k + 2
    assert f"{bad}:302:" in line and "not plausible" in line
    assert not (tmp_path / "o").exists()


def test_no_stamp_overlap_names_both_time_ranges(tmp_path):
    g = synthetic()
    gt = write_tum(g, tmp_path / "gt.tum")
    late = Trajectory(g.t_ns + 10**12, g.positions, g.quat_wxyz)  # 1000 s later
    est = write_tum(late, tmp_path / "late.tum")
    line = _one_error_line(run_cli(["--gt", gt, "-e", f"late={est}", "--no-plots", "-o", tmp_path / "o"], tmp_path))
    t0, t1 = g.t_ns[0] * 1e-9, g.t_ns[-1] * 1e-9
    assert str(est) in line and "no pose matches the ground truth within 10 ms" in line
    assert f"estimate spans {t0 + 1000:.3f}..{t1 + 1000:.3f} s" in line
    assert f"ground truth spans {t0:.3f}..{t1:.3f} s" in line


def test_missing_estimate_file_and_bad_options(tmp_path):
    gt = write_tum(synthetic(), tmp_path / "gt.tum")
    line = _one_error_line(run_cli(["--gt", gt, "-e", f"x={tmp_path / 'nope.txt'}"], tmp_path))
    assert "nope.txt: no such file" in line
    line = _one_error_line(run_cli(["--gt", gt, "-e", "nonamepath"], tmp_path))
    assert "expected NAME=PATH" in line


def test_existing_out_folder_is_not_overwritten(tmp_path):
    gt = write_tum(synthetic(), tmp_path / "gt.tum")
    (tmp_path / "o").mkdir()
    (tmp_path / "o" / "keep.txt").write_text("x")
    line = _one_error_line(run_cli(["--gt", gt, "-e", f"a={gt}", "--no-plots", "-o", tmp_path / "o"], tmp_path))
    assert "exists and is not empty" in line
    # default folder: eval/<name>, then eval/<name>-2
    for k in range(2):
        p = run_cli(["--gt", gt, "-e", f"a={gt}", "--no-plots"], tmp_path)
        assert p.returncode == 0, p.stderr
    assert (tmp_path / "eval/gt_a/metrics.json").is_file() and (tmp_path / "eval/gt_a-2/metrics.json").is_file()


def test_failed_cells_missing_empty_and_low_coverage(tmp_path):
    g = synthetic(n=400)
    root = tmp_path / "results"
    for m in ("good", "short", "empty"):
        (root / m / "seqA").mkdir(parents=True)
    write_tum(g, root / "good/seqA/traj.tum")
    write_tum(g.select(slice(0, 300)), root / "short/seqA/traj.tum")  # 75 % of the span
    (root / "empty/seqA/traj.tum").write_text("# timestamp tx ty tz qx qy qz qw\n")
    (root / "good/seqB").mkdir()
    write_tum(g, root / "good/seqB/traj.tum")
    gtd = tmp_path / "gt"
    gtd.mkdir()
    write_tum(g, gtd / "seqA.txt")
    write_tum(g, gtd / "seqB.txt")
    p = run_cli(["--results", root, "--gt-root", gtd, "--no-plots", "-o", tmp_path / "o"], tmp_path)
    assert p.returncode == 0, p.stderr
    assert "short/seqA: matched 300 of 300 poses, coverage 74.9 % of the GT time span" in p.stdout
    m = json.loads((tmp_path / "o/metrics.json").read_text())
    status = {(r["method"], r["sequence"]): (r["status"], r["reason"]) for r in m["results"]}
    assert status[("good", "seqA")] == ("ok", "")
    assert status[("short", "seqA")][0] == "failed" and "coverage 74.9 %" in status[("short", "seqA")][1]
    assert status[("empty", "seqA")] == ("failed", "no valid poses")
    assert status[("short", "seqB")] == ("failed", "missing")
    md = (tmp_path / "o/tables/ate_trans_rmse.md").read_text()
    row_a = next(line for line in md.splitlines() if line.startswith("| seqA"))
    assert row_a.count("failed") == 2
    avg = next(line for line in md.splitlines() if line.startswith("| average"))
    assert "n/a" in avg  # short/empty failed on a sequence: no average
    # a lower threshold accepts the short run
    p = run_cli(["--results", root, "--gt-root", gtd, "--no-plots", "--min-coverage", "70", "-o", tmp_path / "o2"], tmp_path)
    m = json.loads((tmp_path / "o2/metrics.json").read_text())
    assert {(r["method"], r["sequence"]): r["status"] for r in m["results"]}[("short", "seqA")] == "ok"


def test_frame_conversion_and_mixup_warning(tmp_path):
    """cam0 estimates vs body GT: converted with T_B_C0 they are exact; unconverted a warning is printed."""
    from scipy.spatial.transform import Rotation

    gt = synthetic(n=500)
    T_B_C0 = np.eye(4)
    T_B_C0[:3, :3] = Rotation.from_euler("zyx", [np.pi / 2, 0, np.pi / 2]).as_matrix()
    T_B_C0[:3, 3] = [0.05, -0.1, 0.02]
    cam = gt.with_sensor_frame(T_B_C0, "cam0")
    est_file = write_tum(cam, tmp_path / "cam.tum")
    gt_file = write_tum(gt, tmp_path / "gt.tum")
    np.savetxt(tmp_path / "T_B_C0.txt", T_B_C0)
    p = run_cli(["--gt", gt_file, "-e", f"cam={est_file}", "--est-frame", "cam0", "--T-B-C0", tmp_path / "T_B_C0.txt",
                 "--no-plots", "-o", tmp_path / "ok"], tmp_path)
    assert p.returncode == 0, p.stderr
    r = json.loads((tmp_path / "ok/metrics.json").read_text())["results"][0]
    assert r["ate"]["trans_rmse"] < 1e-6 and r["rpe"]["trans_rmse"] < 1e-6
    assert "different sensor frames" not in p.stderr
    p = run_cli(["--gt", gt_file, "-e", f"cam={est_file}", "--no-plots", "-o", tmp_path / "mix"], tmp_path)
    assert p.returncode == 0, p.stderr
    assert "gevi: warning:" in p.stderr and "different sensor frames" in p.stderr
    # cam0 estimate without a T_B_C0 source: one-line error
    line = _one_error_line(run_cli(["--gt", gt_file, "-e", f"cam={est_file}", "--est-frame", "cam0", "-o",
                                    tmp_path / "x"], tmp_path))
    assert "--T-B-C0" in line


def test_T_B_C0_from_an_euroc_sensor_yaml_and_yaml_errors_in_one_line(tmp_path):
    """`--T-B-C0 mav0/cam0/sensor.yaml` takes the file the EuRoC reader takes (its %YAML:1.0 header);
    a broken YAML anywhere is one line with file and line."""
    from gevi_cli.datasets.yamlio import load_yaml, matrix
    from support import shared_path

    sensor = shared_path("euroc_micro", "mav0", "cam0", "sensor.yaml")
    assert sensor.read_text().startswith("%YAML:1.0")
    gt = synthetic(n=300)
    T_B_C0 = matrix(load_yaml(sensor)["T_BS"], sensor, "T_BS")
    est_file = write_tum(gt.with_sensor_frame(T_B_C0, "cam0"), tmp_path / "cam.tum")
    gt_file = write_tum(gt, tmp_path / "gt.tum")
    p = run_cli(["--gt", gt_file, "-e", f"cam={est_file}", "--est-frame", "cam0", "--T-B-C0", sensor,
                 "--no-plots", "-o", tmp_path / "ok"], tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "ok/metrics.json").read_text())["results"][0]["ate"]["trans_rmse"] < 1e-6
    broken = tmp_path / "broken.yaml"
    broken.write_text("%YAML:1.0\nT_BS: !!opencv-matrix\n  rows: 4\n  data: [1, 0, 0\n  cols: 4\n")
    line = _one_error_line(run_cli(["--gt", gt_file, "-e", f"cam={est_file}", "--est-frame", "cam0", "--T-B-C0",
                                    broken, "--no-plots", "-o", tmp_path / "x"], tmp_path))
    assert f"{broken}:" in line and "not valid YAML" in line


def test_T_B_C0_from_an_opencv_filestorage_yaml(tmp_path):
    """OpenCV FileStorage YAML (``%YAML:1.0``, ``---``, ``!!opencv-matrix``, CRLF): what cv2 and ORB-SLAM3 write."""
    gt = synthetic(n=300)
    T = np.eye(4)
    T[:3, 3] = [0.1, -0.2, 0.05]
    cv = tmp_path / "cv.yaml"
    data = ", ".join(f"{v:.17g}" for v in T.ravel())
    cv.write_bytes(f"%YAML:1.0\r\n---\r\nT_B_C0: !!opencv-matrix\r\n   rows: 4\r\n   cols: 4\r\n   dt: d\r\n"
                   f"   data: [ {data} ]\r\n".encode())
    est_file = write_tum(gt.with_sensor_frame(T, "cam0"), tmp_path / "cam.tum")
    gt_file = write_tum(gt, tmp_path / "gt.tum")
    p = run_cli(["--gt", gt_file, "-e", f"cam={est_file}", "--est-frame", "cam0", "--T-B-C0", cv,
                 "--no-plots", "-o", tmp_path / "ok"], tmp_path)
    assert p.returncode == 0, p.stderr
    assert json.loads((tmp_path / "ok/metrics.json").read_text())["results"][0]["ate"]["trans_rmse"] < 1e-6
