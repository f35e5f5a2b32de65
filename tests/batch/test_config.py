"""Bad batch configs: one line naming the config line or key, exit 2, before any run starts; and the
ready configs in configs/batch/ parse (with their baselines resolved where ../shared/data exists)."""
from __future__ import annotations

from pathlib import Path

import pytest

from support import REPO, SHARED_DATA, run_cli

GOOD = """\
name: t
methods:
  - cfo
sequences:
  - name: s
    simulate: {preset: pool-easy, duration: 1}
"""

BAD = {
    "unknown top-level key": (GOOD + "colour: red\n", ":7:", "colour: unknown key"),
    "unknown sequence key": (GOOD.replace("    simulate:", "    speed: 3\n    simulate:"), ":6:",
                             "sequences[].speed: unknown key"),
    "unknown simulate option": (GOOD.replace("duration: 1", "duraton: 1"), ":6:", "sequences.s.simulate.duraton"),
    "missing sequence path": (GOOD.replace("simulate: {preset: pool-easy, duration: 1}", "path: no/such/folder"),
                              ":6:", "sequences.s.path: "),
    "unknown method": (GOOD.replace("  - cfo", "  - orbslam"), ":3:", "unknown method 'orbslam'"),
    "unknown method option": (GOOD.replace("  - cfo", "  - cfo --fast"), ":3:", "--fast"),
    "bad option value": (GOOD.replace("  - cfo", "  - cfo --pnp foo"), ":3:", "'foo'"),
    "batch option in a method": (GOOD.replace("  - cfo", "  - cfo --seed 3"), ":3:", "not a method option"),
    "gevi on an IMU-less render": (GOOD.replace("  - cfo", "  - gevi").replace("duration: 1", "duration: 1, format: kitti"),
                                   ":5:", "needs an IMU"),
    "unreadable baseline file": (GOOD + "baselines:\n  - {name: orb, path: '{base}/{{sequence}}', file: f.txt, "
                                        "format: tum, frame: cam0}\n", ":8:", "baselines.orb: unreadable"),
    "baseline format mismatch": (GOOD + "baselines:\n  - {name: orb, path: '{base}/{{sequence}}', file: g.txt, "
                                        "format: kitti, frame: cam0}\n", ":8:", "declares format: kitti"),
    "baseline without a frame": (GOOD + "baselines:\n  - {name: orb, path: '{base}/{{sequence}}', file: g.txt, "
                                        "format: tum}\n", ":8:", "baselines.orb.frame: missing"),
    "stride below 1": (GOOD.replace("    simulate:", "    stride: 0\n    simulate:"), ":6:",
                       "sequences.s.stride: must be at least 1"),
    "stamps on a stamped baseline": (GOOD + "baselines:\n  - {name: orb, path: '{base}/{{sequence}}', file: g.txt, "
                                            "format: tum, frame: cam0, stamps: sequence}\n", ":8:",
                                     "baselines.orb.stamps: only for format: kitti"),
    "stride template without sequences": (GOOD + "baselines:\n  - {name: orb, path: '{base}/s{stride}', "
                                                 "file: g.txt, format: tum, frame: cam0}\n", ":8:",
                                          "baselines.orb.path: expected a path template"),
    "stamps for a render": (GOOD + "baselines:\n  - {name: orb, path: '{base}/{{sequence}}', file: k.txt, "
                                   "format: kitti, frame: cam0, stamps: sequence}\n", ":8:",
                            "stamps: sequence needs a dataset (path:) sequence"),
    "not YAML": ("methods: [cfo\n", ":", "not valid YAML"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_config_is_one_line_exit_2_before_any_run(case, tmp_path, capsys):
    text, where, what = BAD[case]
    base = tmp_path / "base"
    (base / "s").mkdir(parents=True)
    (base / "s" / "f.txt").write_text("1.0 2.0 garbage\n")  # not a trajectory
    (base / "s" / "g.txt").write_text("0.0 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n")  # a TUM trajectory
    (base / "s" / "k.txt").write_text("1 0 0 0 0 1 0 0 0 0 1 0\n" * 2)  # KITTI rows (no stamps)
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text.replace("{base}", str(base)).replace("{{sequence}}", "{sequence}"))
    out = tmp_path / "out"
    code, _, stderr = run_cli(["batch", cfg, "-o", out], capsys)
    assert code == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"gevi: error: {cfg}"), stderr
    assert where in lines[0] and what in lines[0], lines[0]
    assert "Traceback" not in stderr and not out.exists()  # nothing started


def test_ready_configs_parse():
    from gevi_cli.batch.config import load_batch_config
    from gevi_cli.batch.plan import baseline_runs, expand

    for name in ("ci", "pool", "kitti-like", "gevi_sweep", "sim_sweep"):
        cfg = load_batch_config(REPO / "configs" / "batch" / f"{name}.yaml")
        assert expand(cfg, Path("/tmp/x")), name
    pool = load_batch_config(REPO / "configs" / "batch" / "pool.yaml")
    assert {m.name for m in pool.methods} >= {"gevi", "gevi --no-adaptive", "cfo"}
    if not (SHARED_DATA / "sim_baselines").is_dir():
        pytest.skip(f"real data not available: {SHARED_DATA / 'sim_baselines'} is absent")
    runs = {(b.name, b.sequence): b for b in baseline_runs(pool)}
    assert runs[("ORB-SLAM3 stereo", "pool-easy_s1")].state == "ok"
    assert runs[("ORB-SLAM3 stereo", "pool-hard_s1")].state == "ok"
    assert runs[("ORB-SLAM3 stereo", "pool-easy_s2")].state == "n/a"  # no baseline for that seed
    assert runs[("ORB-SLAM3 stereo-inertial", "pool-easy_s1")].state == "failed"  # it wrote no trajectory


def test_pool_config_reproduces_the_baseline_renders():
    """The seed-1 sequences of pool.yaml are the renders of sim_baselines/SOURCE.md (preset, seed, 30 s,
    everything else at `gevi simulate`'s defaults): same resolved simulator configuration."""
    import yaml

    from gevi_cli.batch.config import load_batch_config
    from gevi_cli.batch.renders import simulation_config
    from gevi_cli.simulate.generate import SimulationConfig

    root = SHARED_DATA / "sim_baselines"
    if not root.is_dir():
        pytest.skip(f"real data not available: {root} is absent")
    pool = load_batch_config(REPO / "configs" / "batch" / "pool.yaml")
    for name, preset in (("pool-easy_s1", "pool-easy"), ("pool-hard_s1", "pool-hard")):
        seq = next(s for s in pool.sequences if s.name == name)
        ours = simulation_config(seq.sim).resolved()
        theirs = SimulationConfig(preset, seed=1, duration_s=30.0).resolved()
        assert ours == theirs
        recorded = yaml.safe_load((root / name / "simulation.yaml").read_text())  # the render's own record
        opts = recorded["options"]
        assert (recorded["preset"], recorded["seed"], recorded["format"]) == (preset, ours.seed, seq.sim.fmt)
        assert (opts["duration_s"], opts["rate_hz"], tuple(opts["resolution"]), opts["baseline_m"]) == \
            (ours.duration_s, ours.rate_hz, ours.resolution, ours.baseline_m)
        assert (opts["distortion"], opts["image_noise"], opts["supersample"]) == \
            (ours.distortion, ours.image_noise, ours.supersample)
        assert recorded["imu"]["acc_noise_density"] == ours.imu.acc_noise_density
