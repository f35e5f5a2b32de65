"""`gevi run` configuration and bad input: one line, exit 2, never a traceback."""
from __future__ import annotations

import pytest

from support import run_cli


def test_dump_config_lists_every_key_with_its_default(capsys):
    # without a SEQUENCE: the pool sample's configuration (pool.yaml leaves these keys at their defaults)
    code, out, _ = run_cli(["run", "--dump-config", "--method", "cfo"], capsys)
    assert code == 0
    keys = dict(line.split("=", 1)[0:2] for line in out.splitlines() if "=" in line and not line.startswith("#"))
    for key in ("frontend.cell_px", "verify.ransac", "verify.l1", "pnp.method", "keyframe.min_tracked",
                "ba.enabled", "run.seed", "triangulation.max_depth_m", "noise.method"):
        assert key in keys, key
    assert keys["pnp.method"].split()[0] == "be-w" and keys["verify.l1"].split()[0] == "irls"


def test_set_and_shortcuts_override_in_order(capsys):
    code, out, _ = run_cli(["run", "--dump-config", "--set", "pnp.method=epnp", "--set", "keyframe.min_tracked=50",
                            "--no-ba", "--seed", "7"], capsys)
    assert code == 0
    assert "pnp.method=epnp" in out and "keyframe.min_tracked=50" in out
    assert "ba.enabled=false" in out and "run.seed=7" in out


@pytest.mark.parametrize("args, what", [
    (["--set", "pnp.nope=1"], "--set: unknown key pnp.nope; known: method, "),
    (["--set", "zzz.k=1"], "--set: unknown key zzz; known: frontend, verify, "),
    (["--set", "keyframe.min_tracked=many"], "--set: keyframe.min_tracked=many: expected int in [0, inf)"),
    (["--set", "pnp.method=magic"], "--set: pnp.method=magic: not one of be-w, be, ls, epnp, sqpnp"),
    (["--set", "justakey"], "--set: expected stage.key=value"),
])
def test_bad_set_is_one_line(args, what, capsys):
    code, _, err = run_cli(["run", "--dump-config"] + args, capsys)
    assert code == 2
    assert err.startswith(f"gevi: error: {what}") and err.count("\n") == 1


def test_bad_config_file_names_file_and_line(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("keyframe:\n  min_tracked_ratio: 0.5\n  min_tracked: [1,\n")
    code, _, err = run_cli(["run", "--dump-config", "--config", bad], capsys)
    assert code == 2 and err.count("\n") == 1 and f"{bad}:" in err and "not valid YAML" in err
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text("keyframe:\n  min_tracked: 1.5\n")
    code, _, err = run_cli(["run", "--dump-config", "--config", wrong], capsys)
    assert code == 2 and err == f"gevi: error: {wrong}: keyframe.min_tracked=1.5: expected int in [0, inf)\n"


def test_not_a_sequence(tmp_path, capsys):
    (tmp_path / "junk.txt").write_text("hello")
    code, _, err = run_cli(["run", tmp_path, "-o", tmp_path / "out"], capsys)
    assert code == 2 and err.count("\n") == 1 and str(tmp_path) in err
    code, _, err = run_cli(["run", tmp_path / "missing"], capsys)
    assert code == 2 and "no such file or folder" in err


@pytest.mark.parametrize("method", ["gevi", "cfo"])
def test_calibration_for_other_image_size_is_one_line(pool_render, tmp_path, capsys, method):
    """Intrinsics for another resolution would be silently wrong: refused with both sizes, exit 2."""
    import shutil

    d = tmp_path / "seq"
    shutil.copytree(pool_render, d)
    for cam in ("cam0", "cam1"):
        y = d / "mav0" / cam / "sensor.yaml"
        y.write_text(y.read_text().replace("resolution: [376, 240]", "resolution: [752, 480]"))
    code, _, err = run_cli(["run", d, "--method", method, "-q", "-o", tmp_path / "r"], capsys)
    assert code == 2 and err.count("\n") == 1 and "376x240" in err and "752x480" in err


def test_every_kind_config_ships_and_a_missing_one_is_one_line(pool_render, tmp_path, monkeypatch, capsys):
    """Every kind has its configuration (package data: tests/test_packaged_configs.py).  An installation
    without them must not fall back silently to the bare defaults (for a pool render that is another
    front end than the documented one)."""
    from gevi_cli.run import session

    assert all((session.config_dir() / name).is_file() for name in session.KIND_CONFIG.values())
    monkeypatch.setattr(session, "config_dir", lambda: tmp_path / "nowhere")
    code, out, err = run_cli(["run", pool_render, "--max-frames", "3", "-o", tmp_path / "r"], capsys)
    assert code == 2
    assert err.strip().splitlines() == [f"gevi: error: {tmp_path / 'nowhere' / 'pool.yaml'}: the configuration for "
                                        "pool sequences is missing (broken installation?)"]
