"""A KITTI ground truth (no stamps) with a `gevi run` of its sequence (stamped): issue 35, bullet 2.

The run folder names its sequence (config.yaml ``sequence``, ``kind: kitti``), whose times.txt
stamps the KITTI rows (row i = frame i): `gevi run SEQ --gt poses/NN.txt` and
`gevi eval --gt poses/NN.txt -e name=RUN` give the numbers `gevi run SEQ` gives without --gt.
End to end on kitti06_head (51 frames, about 4 s per run); skipped without the shared data.
"""
from __future__ import annotations

import json
import shutil

import pytest
import yaml

from support import run_cli, shared_path


def _gevi(args) -> int:
    from gevi_cli.cli import main

    try:
        main(list(map(str, args)))
    except SystemExit as exit_:
        return exit_.code if isinstance(exit_.code, int) else 1
    return 0


@pytest.fixture(scope="module")
def kitti06(tmp_path_factory):
    """(sequence folder, poses/06.txt, the folder of `gevi run SEQ --gt poses/06.txt`)."""
    seq = shared_path("kitti06_head", "dataset", "sequences", "06")
    poses = shared_path("kitti06_head", "dataset", "poses", "06.txt")
    run = tmp_path_factory.mktemp("kitti06") / "run"
    assert _gevi(["run", seq, "--gt", poses, "-o", run, "-q"]) == 0
    return seq, poses, run


def _one_error_line(code: int, err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("gevi: error: "), err
    return lines[0]


def _ate_rpe(metrics_json) -> tuple[float, float]:
    r = json.loads(metrics_json.read_text())["results"][0]
    assert r["status"] == "ok", r["reason"]
    return r["ate"]["trans_rmse"], r["rpe"]["trans_rmse"]


def test_run_with_kitti_gt_file_evaluates_like_without_it(kitti06, tmp_path, capsys):
    seq, poses, run = kitti06
    evaluation = json.loads((run / "status.json").read_text())["evaluation"]
    assert "failed" not in evaluation and evaluation["matched"] == 51
    # what `gevi run SEQ` (no --gt) evaluates: the dataset's ground truth, stamped by the dataset reader
    code, _, err = run_cli(["eval", "--gt", seq, "-e", f"cfo={run}", "--align", "se3", "--no-plots",
                            "-o", tmp_path / "dataset_gt"], capsys)
    assert code == 0, err
    assert _ate_rpe(tmp_path / "dataset_gt" / "metrics.json") == (evaluation["ate_m"], evaluation["rpe_m"])
    assert _ate_rpe(run / "eval" / "metrics.json") == (evaluation["ate_m"], evaluation["rpe_m"])
    stamped = json.loads((run / "eval" / "metrics.json").read_text())["sequences"]["06"]["stamped_from"]
    assert stamped == [str(seq / "times.txt")]


def test_eval_with_kitti_gt_and_a_run_folder(kitti06, tmp_path, capsys):
    seq, poses, run = kitti06
    code, _, err = run_cli(["eval", "--gt", poses, "-e", f"cfo={run}", "--align", "se3", "--no-plots",
                            "-o", tmp_path / "ev"], capsys)
    assert code == 0, err
    evaluation = json.loads((run / "status.json").read_text())["evaluation"]
    assert _ate_rpe(tmp_path / "ev" / "metrics.json") == (evaluation["ate_m"], evaluation["rpe_m"])


def test_a_kitti_gt_of_another_length_is_refused_in_one_line(kitti06, tmp_path, capsys):
    seq, poses, run = kitti06
    cut = tmp_path / "cut06.txt"
    cut.write_text("\n".join(poses.read_text().splitlines()[:40]) + "\n")
    line = _one_error_line(*run_cli(["eval", "--gt", cut, "-e", f"cfo={run}", "--no-plots", "-o", tmp_path / "ev"],
                                    capsys)[::2])
    assert f"{cut}: has 40 poses but {seq / 'times.txt'} lists 51 frames" in line
    line = _one_error_line(*run_cli(["run", seq, "--gt", cut, "-o", tmp_path / "run", "-q"], capsys)[::2])
    assert f"{cut}: has 40 poses but times.txt lists 51 frames" in line
    assert not (tmp_path / "run").exists()  # refused before the run folder is made


def test_a_run_folder_whose_sequence_moved_is_refused_in_one_line(kitti06, tmp_path, capsys):
    seq, poses, run = kitti06
    moved = shutil.copytree(run, tmp_path / "run")
    config = yaml.safe_load((moved / "config.yaml").read_text())
    config["sequence"] = str(tmp_path / "gone" / "06")
    (moved / "config.yaml").write_text(yaml.safe_dump(config, sort_keys=False))
    line = _one_error_line(*run_cli(["eval", "--gt", poses, "-e", f"cfo={moved}", "--no-plots",
                                     "-o", tmp_path / "ev"], capsys)[::2])
    assert f"{moved / 'config.yaml'}: its KITTI sequence {tmp_path / 'gone' / '06'} has no times.txt" in line
