"""`gevi batch` on the shared small batch: results tree, report, resume after a kill, determinism
across --jobs and the dask executor, and the regression gate failing on a worsened estimator."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import markers, trajectory_bytes, tree

from support import run_cli

# every test here uses the session's small batch (about 25 s to make) and runs batches of its own
pytestmark = pytest.mark.slow


def test_small_batch_results_tree_and_report(small_batch):
    out, code, lines = small_batch
    assert code == 0, lines
    runs = markers(out)
    # CFO takes no seed: one run however many trials (the render is the same); GeVI's trial k has seed k
    assert sorted(runs) == ["cfo/pool-easy-5s/trial1", "gevi/pool-easy-5s/trial1", "gevi/pool-easy-5s/trial2"]
    for rid, marker in runs.items():
        run = marker.parent
        doc = json.loads(marker.read_text())
        status = json.loads((run / "status.json").read_text())
        assert doc["state"] == status["state"] == "ok"
        assert doc["seed"] == (None if rid.startswith("cfo/") else int(rid[-1]))
        assert status["gevi_version"] and (run / "config.yaml").is_file() and (run / "timing.csv").is_file()
        assert f"seed: {doc['seed'] or 0}" in (run / "config.yaml").read_text()
        assert (run / "traj_body.tum").stat().st_size > 0
    rep = out / "report"
    md = (rep / "report.md").read_text()
    # a row per sequence, a column per method, ATE and RPE tables, the runtime table
    assert "| sequence" in md and "| gevi" in md and "| cfo" in md.split("### ATE translation")[1]
    assert "### ATE translation RMSE" in md and "### RPE translation RMSE" in md and "### Runtime per stage" in md
    assert "| pool-easy-5s " in md and "posyaw" in md
    for ext in ("md", "csv", "tex"):
        assert (rep / "tables" / f"ate_trans_rmse.{ext}").is_file()
        assert (rep / "tables" / f"runtime.{ext}").is_file()
    html = (rep / "report.html").read_text()
    pngs = list((rep / "plots").glob("*.png"))
    assert pngs and html.count("src='data:image/png;base64,") == len(pngs) and "<table>" in html
    res = json.loads((rep / "results.json").read_text())
    assert len(res["runs"]) == 3 and all(r["ate_m"] > 0 and r["rpe_m"] > 0 for r in res["runs"])
    assert "cfo: deterministic" in md
    # scale next to ATE/RPE: its tables (SE(3) only: no alignment enters), per run in results.json, per
    # estimate in metrics.json; read before alignment, so the posyaw evaluation reads the same bits
    assert "### Scale: path-length ratio [est/GT]" in md and "### Scale: median step-length ratio" in md
    assert "posyaw (4-DOF, gravity known): Scale" not in md
    scale = {}
    for r in json.loads((rep / "metrics.json").read_text())["results"]:
        scale.setdefault((r["method"], r["trial"]), []).append(r["scale"])
    for r in res["runs"]:
        se3_posyaw = scale[(r["method"], f"trial{r['trial']}")]
        assert all(sc == se3_posyaw[0] for sc in se3_posyaw)
        assert r["path_ratio"] == se3_posyaw[0]["path_ratio"] > 0
        assert r["step_ratio_median"] == se3_posyaw[0]["step_ratio_median"] > 0
    for m, n in (("cfo", 1), ("gevi", 2)):
        trials = [r["path_ratio"] for r in res["runs"] if r["method"] == m]
        cell = res["cells"]["scale_path_ratio"]["pool-easy-5s"][m]
        assert cell["n_ok"] == n and cell["mean"] == pytest.approx(sum(trials) / n, rel=1e-15)


def test_resume_after_kill_completes_only_missing_runs(small_config, small_batch, tmp_path):
    """Kill a --jobs 1 batch after its first run finished, restart: only the missing runs run; and the
    trajectories equal the --jobs 2 ones byte for byte."""
    out = tmp_path / "out"
    env = dict(os.environ)
    proc = subprocess.Popen([sys.executable, "-m", "gevi_cli.cli", "batch", str(small_config), "-o", str(out),
                             "--jobs", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env,
                            start_new_session=True)
    try:
        while not markers(out) and proc.poll() is None:  # no deadline: the batch ends by itself (no clock)
            time.sleep(0.02)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    first = markers(out)
    assert len(first) >= 1, "no run finished before the kill"
    assert len(first) < 3, "the batch finished before it could be killed"
    before = {rid: p.stat().st_mtime_ns for rid, p in first.items()}
    from gevi_cli.batch.runner import run_batch

    lines = []
    code = run_batch(small_config, out, jobs=1, echo=lines.append, progress=False)
    assert code == 0
    assert f"gevi batch: {len(first)} of 3 runs already finished (--force redoes them)" in lines
    ran = [ln for ln in lines if ln.startswith("[")]
    assert len(ran) == 3 - len(first)
    after = markers(out)
    assert len(after) == 3
    assert all(after[rid].stat().st_mtime_ns == t for rid, t in before.items())  # not redone
    # determinism: --jobs 1 (and a resumed batch) gives the bytes of --jobs 2
    assert trajectory_bytes(out) == trajectory_bytes(small_batch[0])


def test_dask_localcluster_gives_the_same_tree_and_bytes(small_config, small_batch, tmp_path):
    distributed = pytest.importorskip("distributed")
    from gevi_cli.batch.runner import run_batch

    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl:
        code = run_batch(small_config, out, executor="dask", scheduler=cl.scheduler_address, echo=lambda *a: None,
                         progress=False)
    assert code == 0
    assert tree(out) == tree(small_batch[0])
    assert trajectory_bytes(out) == trajectory_bytes(small_batch[0])


def test_worse_estimator_fails_the_gate(small_config, small_batch, tmp_path, monkeypatch, capsys):
    from gevi_cli.batch.regress import write_expected
    from gevi_cli.batch.runner import run_batch
    from gevi_cli.run import folder

    expected = write_expected(small_batch[0], tmp_path / "expected.yaml")
    code, out_text, _ = run_cli(["regress", small_batch[0], "--against", expected], capsys)
    assert code == 0 and "0 worse than expected" in out_text

    import numpy as np

    rng = np.random.default_rng(0)
    original = folder.PoseStream.append

    def noisy(self, t_ns, T):  # a worse estimator: 5 mm of position noise on every pose it outputs
        T = T.copy()
        T[:3, 3] += rng.normal(0.0, 0.005, 3)
        original(self, t_ns, T)

    monkeypatch.setattr(folder.PoseStream, "append", noisy)
    out = tmp_path / "worse"
    assert run_batch(small_config, out, jobs=1, echo=lambda *a: None, progress=False) == 0
    code, out_text, _ = run_cli(["regress", out, "--against", expected], capsys)
    assert code == 1
    assert "| pool-easy-5s | gevi | ATE |" in out_text and "WORSE" in out_text
    assert "worse than expected" in out_text.splitlines()[-1]


def test_baselines_and_a_crashing_run(small_batch, tmp_path):
    """A baseline declared in the cam0 frame is converted with the sequence's T_B_C0 (same ATE as the
    run it came from); declared as body it is not, and reads worse (the ORB-SLAM3 cam0-as-body mistake);
    a sequence without the system's folder is n/a, a folder without its file is failed.  A run that
    crashes (here: a sequence folder that is no dataset) is recorded with its message, the batch goes
    on (the other new run is made) and exits 3; finished runs of the copied tree are not redone."""
    from gevi_cli.batch.runner import run_batch

    out = tmp_path / "out"
    shutil.copytree(small_batch[0], out)
    base = tmp_path / "other_system"
    (base / "pool-easy-5s").mkdir(parents=True)
    shutil.copy(out / "runs/cfo/pool-easy-5s/trial1/traj_cam0.tum", base / "pool-easy-5s/traj.txt")
    (base / "pool-easy-5s-empty").mkdir()
    (tmp_path / "not_a_dataset").mkdir()
    cfg_text = Path(small_batch[0] / "config.yaml").read_text()
    cfg_text += f"""\
  - name: pool-easy-5s-empty
    simulate: {{preset: pool-easy, seed: 3, duration: 5, rate: 10, resolution: 376x240}}
    methods: [cfo]
  - name: broken
    path: {tmp_path / "not_a_dataset"}
    methods: [cfo]
baselines:
  - {{name: other-cam0, path: '{base}/{{sequence}}', file: traj.txt, format: tum, frame: cam0, T_B_C0: sequence}}
  - {{name: other-as-body, path: '{base}/{{sequence}}', file: traj.txt, format: tum, frame: body}}
  - {{name: other-missing, path: '{base}/{{sequence}}/none', file: traj.txt, format: tum, frame: body}}
"""
    cfg = tmp_path / "with_baselines.yaml"
    cfg.write_text(cfg_text)
    lines = []
    assert run_batch(cfg, out, jobs=1, echo=lines.append, progress=False) == 3
    assert "gevi batch: 3 of 5 runs already finished (--force redoes them)" in lines  # cfo: one run a sequence
    crashed = json.loads((out / "runs/cfo/broken/trial1/done.json").read_text())
    assert crashed["state"] == "crashed" and "not_a_dataset" in crashed["message"]
    assert json.loads((out / "runs/cfo/broken/trial1/status.json").read_text())["state"] == "crashed"
    assert any(ln.startswith("gevi batch: cfo/broken/trial1: crashed: ") for ln in lines)
    assert (out / "runs/cfo/pool-easy-5s-empty/trial1/done.json").is_file()  # the batch went on
    cells = json.loads((out / "report/results.json").read_text())["cells"]["ate_trans_rmse"]["pool-easy-5s"]
    run_ate = json.loads((out / "runs/cfo/pool-easy-5s/trial1/done.json").read_text())
    ate_cfo1 = next(r for r in json.loads((out / "report/results.json").read_text())["runs"]
                    if r["run_id"] == "cfo/pool-easy-5s/trial1")["ate_m"]
    assert run_ate["state"] == "ok"
    assert cells["other-cam0"]["mean"] == pytest.approx(ate_cfo1, rel=1e-6, abs=1e-9)
    # read as body poses the lever arm of cam0 is left in (16 % worse on this short, slowly turning render)
    assert cells["other-as-body"]["mean"] > 1.1 * ate_cfo1
    md = (out / "report/report.md").read_text()
    ate_table = md.split("### ATE translation RMSE")[1].split("###")[0]
    empty_row = next(ln for ln in ate_table.splitlines() if ln.startswith("| pool-easy-5s-empty "))
    cols = [c.strip() for c in ate_table.splitlines()[2].strip("|").split("|")]
    vals = dict(zip(cols, [c.strip() for c in empty_row.strip("|").split("|")]))
    assert vals["gevi"] == "n/a"  # not run there (methods: [cfo])
    assert vals["other-cam0"] == "failed"  # folder without the trajectory: the system wrote nothing
    assert vals["other-missing"] == "n/a"  # never run on any sequence
    broken_row = next(ln for ln in ate_table.splitlines() if ln.startswith("| broken "))
    assert dict(zip(cols, [c.strip() for c in broken_row.strip("|").split("|")]))["cfo"] == "failed"
    assert "| cfo/broken/trial1 | crashed |" in md


def test_absent_optional_sequence_is_skipped_and_left_out_by_regress(small_batch, tmp_path, capsys):
    """An optional sequence whose data is absent is skipped with the reason printed; `gevi regress`
    leaves its rows out and says so, and still gates the rest."""
    import yaml

    from gevi_cli.batch.regress import write_expected
    from gevi_cli.batch.runner import run_batch

    out = tmp_path / "out"
    shutil.copytree(small_batch[0], out)
    cfg = tmp_path / "with_absent.yaml"
    cfg.write_text((small_batch[0] / "config.yaml").read_text()
                   + f"  - {{name: gone, path: '{tmp_path / 'absent_data'}', optional: true}}\n")
    lines = []
    assert run_batch(cfg, out, jobs=1, echo=lines.append, progress=False) == 0
    assert any(ln.startswith("gevi batch: skipping sequence gone: ") and "absent_data" in ln for ln in lines)
    expected = write_expected(small_batch[0], tmp_path / "expected.yaml")
    doc = yaml.safe_load(expected.read_text())
    doc["entries"]["gone"] = {"cfo": {"ate_m": {"expected": 0.001, "tol": 0.0001}}}
    expected.write_text(yaml.safe_dump(doc))
    code, text, _ = run_cli(["regress", out, "--against", expected], capsys)
    assert code == 0, text
    assert "note: gone: left out, the batch skipped it" in text and "| gone |" not in text
    assert "| pool-easy-5s | cfo | ATE |" in text


def test_report_has_online_and_roll_pitch_tables(small_batch):
    """eval: online adds the as-tracked trajectories' ATE/RPE; GeVI's roll/pitch error is tabulated per trial."""
    out, code, _ = small_batch
    tables = out / "report" / "tables"
    assert (tables / "online_ate_trans_rmse.csv").is_file() and (tables / "online_rpe_trans_rmse.csv").is_file()
    assert (tables / "tilt_rmse_deg.csv").is_file()
    md = (out / "report" / "report.md").read_text()
    assert "## Online trajectories" in md and "Roll/pitch error RMSE" in md
    rows = (tables / "tilt_rmse_deg.csv").read_text()
    assert "gevi" in rows and "cfo" not in rows.splitlines()[0]
