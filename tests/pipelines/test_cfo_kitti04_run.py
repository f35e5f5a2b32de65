"""`gevi run` on the authors' real KITTI 04 tracks (OV2SLAM export): the issue's acceptance numbers.

The thresholds are the issue's: better than the authors' own re-run of their released code
(gray 1.043 m / 0.0216 m, colour 2.717 / 0.0394) with margins measured here (gray 0.349 / 0.0159,
colour 2.653 / 0.0374 without OV2SLAM's outlier flags).
"""
from __future__ import annotations

import json

import pytest

from support import run_cli, shared_path

EXPORTS = {"gray": ("ov2slam_data_kitti_04_gray", "gray_calib.txt", 0.40, 0.0170),
           "colour": ("ov2slam_data_kitti_04", "colour_calib.txt", 2.70, 0.0390)}


def _args(cameras: str, out):
    root = shared_path("cfo_kitti04")
    folder, calib, _, _ = EXPORTS[cameras]
    return ["run", root / "data/ov2slam_data" / folder, "--calib", root / "calib" / calib,
            "--gt", root / "data/gt_poses/kitti_gt_pose/04.txt", "-o", out, "-q"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """One full run per camera pair, shared by the tests of this module."""
    out = {}
    for cameras in EXPORTS:
        d = tmp_path_factory.mktemp(f"kitti04_{cameras}")
        from gevi_cli.cli import main

        try:
            main(list(map(str, _args(cameras, d))))
            code = 0
        except SystemExit as e:
            code = e.code
        out[cameras] = (code, d)
    return out


@pytest.mark.parametrize("cameras", list(EXPORTS))
def test_kitti04_tracks_meet_the_issue_numbers(runs, cameras):
    code, d = runs[cameras]
    status = json.loads((d / "status.json").read_text())
    assert code == 0 and status["state"] == "ok"
    assert status["frames_tracked"] == status["frames_done"] == 271
    ev = status["evaluation"]
    _, _, ate_max, rpe_max = EXPORTS[cameras]
    assert ev["align"] == "se3" and ev["matched"] == 271
    assert ev["ate_m"] <= ate_max, ev
    assert ev["rpe_m"] <= rpe_max, ev
    # a real estimate, not the ground truth echoed back: the error is not implausibly small either
    assert ev["ate_m"] > 0.05 and ev["rpe_m"] > 0.005


def test_run_folder_contract(runs, capsys):
    code, d = runs["gray"]
    status = json.loads((d / "status.json").read_text())
    assert status["primary"] == "traj_body_kitti.txt" and status["frame"] == "body"
    import yaml

    cfg = yaml.safe_load((d / "config.yaml").read_text())
    assert cfg["align"] == "se3" and cfg["method"] == "cfo" and cfg["pnp"]["method"] == "be-w"
    for name in ("traj_body.tum", "traj_cam0.tum", "traj_online_body.tum"):
        rows = [r for r in (d / name).read_text().splitlines() if not r.startswith("#")]
        assert len(rows) == 271, name
    assert len((d / "traj_cam0_kitti.txt").read_text().splitlines()) == 271
    # exact ns stamps (nominal 10 Hz): second row is 0.1 s
    assert (d / "traj_body.tum").read_text().splitlines()[2].startswith("0.100000000 ")
    timing = (d / "timing.csv").read_text().splitlines()
    assert timing[0].startswith("index,t_ns,total_ms,read_ms,frontend_ms") and len(timing) == 272
    # gevi eval on the run folder evaluates the primary trajectory and gives the run's own numbers
    gt = shared_path("cfo_kitti04") / "data/gt_poses/kitti_gt_pose/04.txt"
    code, out, err = run_cli(["eval", "-e", f"cfo={d}", "--gt", gt, "-o", d.parent / "ev"], capsys)
    assert code == 0
    assert f"{status['evaluation']['ate_m']:.4f}" in out


def test_outlier_flags_and_determinism(runs, tmp_path, capsys):
    """OV2SLAM's own flags help a little (reported both ways); a second run gives the same bytes."""
    a, b = tmp_path / "a", tmp_path / "b"
    for out in (a, b):
        code, _, _ = run_cli(_args("gray", out) + ["--max-frames", "80"], capsys)
        assert code == 0
    for name in ("traj_body.tum", "traj_cam0.tum", "traj_online_body.tum", "traj_cam0_kitti.txt"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    code, _, _ = run_cli(_args("gray", tmp_path / "flags") + ["--set", "verify.use_export_flags=true"], capsys)
    assert code == 0
    ev_flags = json.loads((tmp_path / "flags/status.json").read_text())["evaluation"]
    ev = json.loads((runs["gray"][1] / "status.json").read_text())["evaluation"]
    assert ev_flags["ate_m"] <= 0.36 and ev_flags["rpe_m"] <= 0.0160
    assert abs(ev_flags["ate_m"] - ev["ate_m"]) < 0.1
