"""The run configuration's schema (gevi_cli/config.py): every setting has a type and a domain, ordered
pairs, unknown keys refused with the nearest name, and what does not apply to the method or the input
refused - each as one line and exit 2 through every door (--set, --config, options, batch entries)."""
from __future__ import annotations

import math

import annotated_types as at
import pytest

from gevi_cli.config import choices, fields, leaves, type_name
from gevi_cli.pipelines.config import OdometryConfig
from support import run_cli, shared_path

SETTINGS = leaves(OdometryConfig)


def _outside(cls, name) -> str:
    """A --set value outside the setting's domain (type or range)."""
    info = fields(cls)[name]
    if choices(info) is not None:
        return "bogus"
    kind = type_name(info)
    if kind == "bool":
        return "maybe"
    for m in info.metadata:
        if isinstance(m, at.Ge):
            return str(m.ge - 1)
        if isinstance(m, at.Gt):
            return str(m.gt)
        if isinstance(m, at.Le):
            return str(m.le + 1)
        if isinstance(m, at.Lt):
            return str(m.lt)
    return "nan"  # unbounded: still a finite number


def _one_line(err: str) -> bool:
    return err.startswith("gevi: error: ") and err.count("\n") == 1


def test_every_setting_has_a_domain_narrower_than_any_value():
    """No unbounded number where the code needs less: an int or float setting without a bound is named here."""
    unbounded = []
    for key, cls, name in SETTINGS:
        info = fields(cls)[name]
        if type_name(info) in ("int", "float", "odd int") and not any(
                isinstance(m, (at.Ge, at.Gt, at.Le, at.Lt)) for m in info.metadata):
            unbounded.append(key)
    assert unbounded == []
    # +inf is a value only where it means "unbounded" (the far depth gates); NaN never
    from gevi_cli.config import domain
    assert [k for k, c, n in SETTINGS if domain(c, n).endswith("inf]")] == ["triangulation.max_depth_m"]


def test_at_most_50_settings():
    """Issue 46: every setting changes a result on the real-data board or is a documented ablation; the
    rest are module constants (gevi_cli/frontend/config.py, gevi_cli/pipelines/config.py).  The count is
    read from the schema, every stage included (no setting outside it is accepted)."""
    assert 30 <= len(SETTINGS) <= 50, len(SETTINGS)


def test_help_says_what_a_setting_does_not_where_it_was_tuned():
    """No help string carries a proposal tag, a dataset or a measurement (their history is in docs/)."""
    import re

    history = re.compile(r"PROPOSAL|KITTI|EuRoC|euroc|kitti|pool-|measured|\bATE\b|\d+ ms\b", re.I)
    cited = [k for k, c, n in SETTINGS if history.search(fields(c)[n].description or "")]
    assert cited == []


@pytest.mark.parametrize("key, cls, name", SETTINGS, ids=[k for k, _, _ in SETTINGS])
def test_a_value_outside_the_domain_is_one_line(key, cls, name, capsys):
    bad = _outside(cls, name)
    code, out, err = run_cli(["run", "--dump-config", "--method", "gevi", "--set", f"{key}={bad}"], capsys)
    assert code == 2 and out == "" and _one_line(err), err
    assert err.startswith(f"gevi: error: --set: {key}=") and ("expected" in err or "not one of" in err), err


@pytest.mark.parametrize("key", [k for k, c, n in SETTINGS if type_name(fields(c)[n]) == "int"])
def test_an_int_setting_refuses_a_fraction_and_a_bool(key, capsys):
    for bad in ("2.5", "true"):
        code, _, err = run_cli(["run", "--dump-config", "--method", "gevi", "--set", f"{key}={bad}"], capsys)
        assert code == 2 and _one_line(err) and f"{key}=" in err and "expected int" in err, err


PAIRS = [(f"{stage}.{lo}", f"{stage}.{hi}", strict) for stage, info in fields(OdometryConfig).items()
         for lo, hi, strict in getattr(info.annotation, "ORDERED", ())]


def test_the_pairs_are_the_ones_the_code_needs():
    assert {(lo, hi) for lo, hi, _ in PAIRS} == {
        ("triangulation.min_depth_m", "triangulation.max_depth_m")}


@pytest.mark.parametrize("lo, hi, strict", PAIRS, ids=[lo for lo, _, _ in PAIRS])
def test_a_crossed_pair_is_one_line(lo, hi, strict, capsys):
    defaults = OdometryConfig()
    stage, hi_name = hi.split(".")
    high = getattr(getattr(defaults, stage), hi_name)
    high = 10.0 if math.isinf(high) else high
    crossed = [f"{hi}={high}", f"{lo}={high if strict else high + 1}"]
    code, _, err = run_cli(["run", "--dump-config", "--method", "gevi", "--set", crossed[0], "--set", crossed[1]],
                           capsys)
    assert code == 2 and _one_line(err), err
    assert f"--set: {lo}=" in err and f"must be {'below' if strict else 'at most'} {hi}" in err
    # in order, the same values are fine
    ok = [f"{hi}={high}", f"{lo}={high / 2 if strict else high}"]
    assert run_cli(["run", "--dump-config", "--method", "gevi", "--set", ok[0], "--set", ok[1]], capsys)[0] == 0


@pytest.mark.parametrize("args, line", [
    # without a SEQUENCE, the configuration of what `gevi run` then runs: the pool sample (pool.yaml: 10 m)
    (["--set", "triangulation.min_depth_m=200"],
     "--set: triangulation.min_depth_m=200.0 must be below triangulation.max_depth_m (10.0)"),
    (["--set", "keyframe.min_tracked_ratio=-3"], "--set: keyframe.min_tracked_ratio=-3.0: expected float in [0, 1]"),
    # a bad front-end value: one line, not the whole dataclass
    (["--set", "frontend.lk_window=4"], "--set: frontend.lk_window=4: expected odd int in [3, inf)"),
    (["--set", "frontend.cell_px=0"], "--set: frontend.cell_px=0: expected int in [1, inf)"),
    (["--set", "frontend.derotate_prior=gyro"], "--set: frontend.derotate_prior=gyro: not one of pose, image"),
    (["--set", "pnp.methd=epnp"], "--set: unknown key pnp.methd; did you mean pnp.method?"),
    (["--set", "fusion.mode=false"], "--set: fusion.mode=false: not one of bcd, 4dof"),
    (["--set", "imu.time_offset_s=inf"], "--set: imu.time_offset_s=inf: expected float or null in (-inf, inf)"),
    (["--pnp", "epnp", "--set", "triangulation.max_depth_m=0.3"],
     "--set: triangulation.min_depth_m=0.5 must be below triangulation.max_depth_m (0.3)"),
])
def test_the_issue_examples_are_one_line(args, line, capsys):
    code, _, err = run_cli(["run", "--dump-config"] + args, capsys)
    assert code == 2 and err == f"gevi: error: {line}\n"


def test_a_config_file_is_checked_as_set(tmp_path, capsys):
    f = tmp_path / "c.yaml"
    f.write_text("triangulation:\n  max_depth_m: 0.01\n")
    code, _, err = run_cli(["run", "--dump-config", "--config", f], capsys)
    assert code == 2 and err == (f"gevi: error: {f}: triangulation.min_depth_m=0.5 must be below "
                                 "triangulation.max_depth_m (0.01)\n")
    f.write_text("keyfram:\n  min_tracked: 3\n")
    code, _, err = run_cli(["run", "--dump-config", "--config", f], capsys)
    assert code == 2 and err == f"gevi: error: {f}: unknown key keyfram; did you mean keyframe?\n"


def test_the_packaged_kind_configs_are_valid():
    from gevi_cli.run.session import KIND_CONFIG, RunRequest, resolve_config

    for kind in KIND_CONFIG:
        for method in ("cfo", "gevi"):
            cfg, sources = resolve_config(RunRequest(sequence=None), kind, method)
            assert sources[-1].startswith("gevi_cli/configs/")


def test_dump_config_shows_type_default_and_domain(capsys):
    code, out, _ = run_cli(["run", "--dump-config", "--method", "gevi", "--set", "triangulation.max_depth_m=40"], capsys)
    assert code == 0
    lines = {line.split("=", 1)[0]: line for line in out.splitlines() if not line.startswith("#")}
    assert set(lines) == {k for k, _, _ in SETTINGS}
    assert lines["triangulation.max_depth_m"].startswith(
        "triangulation.max_depth_m=40.0    # float in (min_depth_m, inf] (default 100.0) ")
    assert lines["verify.ransac"].startswith("verify.ransac=3pt    # choice in {5pt, 3pt, none} (default 5pt) ")
    assert "[gevi only]" in lines["fusion.mode"] and "[images only]" in lines["frontend.cell_px"]


# ---------------------------------------------------------------------------------------- what does not apply
CFO_REFUSED = [
    (["--ransac", "3pt"], "--ransac: does not apply to cfo (3pt is GeVI's upright RANSAC"),
    (["--no-fusion"], "--no-fusion: does not apply to cfo (GeVI only: the gravity fusion"),
    (["--no-adaptive"], "--no-adaptive: does not apply to cfo (GeVI only: the gravity fusion"),
    (["--imu-time-offset", "0.01"], "--imu-time-offset: does not apply to cfo (GeVI only: the IMU settings"),
    (["--set", "verify.ransac=3pt"], "--set: verify.ransac=3pt: does not apply to cfo (3pt is GeVI's"),
    (["--seed", "3"], "--seed: does not apply to cfo (CFO's OpenCV 5-point RANSAC keeps its own fixed seed"),
    (["--set", "run.seed=2"], "--set: run.seed=2: does not apply to cfo (CFO's OpenCV 5-point RANSAC"),
    (["--set", "fusion.mode=4dof"], "--set: fusion.mode=4dof: does not apply to cfo (GeVI only"),
    (["--set", "fusion.adaptive=false"], "--set: fusion.adaptive=false: does not apply to cfo (GeVI only"),
    (["--set", "init.window_s=3"], "--set: init.window_s=3.0: does not apply to cfo (GeVI only: the initialisation"),
    (["--set", "imu.max_gap_factor=3"], "--set: imu.max_gap_factor=3.0: does not apply to cfo (GeVI only"),
]


@pytest.mark.parametrize("args, line", CFO_REFUSED, ids=[" ".join(a) for a, _ in CFO_REFUSED])
def test_cfo_refuses_what_is_gevis(args, line, capsys):
    code, _, err = run_cli(["run", "--dump-config", "--method", "cfo"] + args, capsys)
    assert code == 2 and _one_line(err) and err.startswith(f"gevi: error: {line}"), err
    # GeVI takes them
    assert run_cli(["run", "--dump-config", "--method", "gevi"] + args, capsys)[0] == 0


def test_cfo_takes_gevi_keys_at_their_defaults_and_its_own_verification(capsys):
    for args in (["--set", "fusion.mode=bcd"], ["--ransac", "5pt"], ["--set", "verify.ransac=none"]):
        assert run_cli(["run", "--dump-config", "--method", "cfo"] + args, capsys)[0] == 0, args


def test_cfo_refuses_gevi_keys_in_a_config_file(tmp_path, capsys):
    f = tmp_path / "c.yaml"
    f.write_text("verify:\n  ransac: 3pt\n")
    code, _, err = run_cli(["run", "--dump-config", "--method", "cfo", "--config", f], capsys)
    assert code == 2 and err.startswith(f"gevi: error: {f}: verify.ransac=3pt: does not apply to cfo")


def test_a_track_export_refuses_front_end_settings():
    from gevi_cli.errors import GeviError
    from gevi_cli.run.session import RunRequest, resolve_config

    req = RunRequest(sequence=None, sets=("frontend.cell_px=16", "frontend.lk_window=5"))
    with pytest.raises(GeviError) as err:
        resolve_config(req, "ov2slam-tracks", "cfo")
    assert err.value.one_line() == ("--set: frontend.cell_px=16: does not apply to ov2slam-tracks sequences (a track "
                                    "export is its own front end)")
    resolve_config(req, "kitti", "cfo")  # images: it applies
    flags = RunRequest(sequence=None, sets=("verify.use_export_flags=true",))
    resolve_config(flags, "ov2slam-tracks", "cfo")
    with pytest.raises(GeviError, match="use_export_flags=true: does not apply to kitti sequences"):
        resolve_config(flags, "kitti", "cfo")


def test_a_track_export_run_refuses_front_end_settings(tmp_path, capsys):
    root = shared_path("cfo_kitti04")
    export = root / "data" / "ov2slam_data" / "ov2slam_data_kitti_04_gray"
    code, _, err = run_cli(["run", export, "--calib", root / "calib" / "gray_calib.txt", "--set",
                            "frontend.cell_px=16", "-o", tmp_path / "r"], capsys)
    assert code == 2 and err == ("gevi: error: --set: frontend.cell_px=16: does not apply to ov2slam-tracks sequences "
                                 "(a track export is its own front end)\n")
    assert not (tmp_path / "r").exists()


def test_a_bad_setting_fails_before_the_run_starts(tmp_path, capsys):
    seq = shared_path("euroc_micro")
    code, out, err = run_cli(["run", seq, "--set", "triangulation.min_depth_m=200", "-o", tmp_path / "r"], capsys)
    assert code == 2 and _one_line(err) and "triangulation.min_depth_m=200.0 must be below" in err
    assert not (tmp_path / "r").exists() and "frames tracked" not in out


def _batch(tmp_path, methods: str, sequences: str = "  - name: s\n    simulate: {preset: pool-easy}\n"):
    f = tmp_path / "b.yaml"
    f.write_text(f"methods:\n{methods}sequences:\n{sequences}")
    return f


@pytest.mark.parametrize("entry", ["cfo --ransac 3pt", "cfo --no-fusion", "cfo --no-adaptive",
                                   "cfo --imu-time-offset 0.1", "cfo --set verify.ransac=3pt",
                                   "gevi --set triangulation.min_depth_m=200"])
def test_a_batch_entry_is_checked_with_its_line(entry, tmp_path):
    from gevi_cli.batch.config import load_batch_config
    from gevi_cli.errors import GeviError

    f = _batch(tmp_path, f"  - gevi\n  - {entry}\n")
    with pytest.raises(GeviError) as err:
        load_batch_config(f)
    assert err.value.where == f"{f}:3" and err.value.message.startswith(f"methods: {entry!r}: ")
    assert "does not apply to cfo" in err.value.message or "must be below" in err.value.message


def test_a_batch_refuses_front_end_settings_on_a_track_export(tmp_path):
    from gevi_cli.batch.config import load_batch_config
    from gevi_cli.batch.plan import check_methods_fit
    from gevi_cli.errors import GeviError

    root = shared_path("cfo_kitti04")
    export = root / "data" / "ov2slam_data" / "ov2slam_data_kitti_04_gray"
    f = _batch(tmp_path, "  - cfo --set frontend.cell_px=16\n",
               f"  - name: k04\n    path: {export}\n    calib: {root / 'calib' / 'gray_calib.txt'}\n")
    with pytest.raises(GeviError) as err:
        check_methods_fit(load_batch_config(f))
    assert err.value.one_line() == (f"{f}:2: methods: 'cfo --set frontend.cell_px=16' on sequences.k04: --set: "
                                    "frontend.cell_px=16: does not apply to ov2slam-tracks sequences (a track export "
                                    "is its own front end)")


# ------------------------------------------------------------------------- what another setting turns off
SWITCHED_OFF = [
    (["--no-ba", "--set", "ba.kernel=huber"], "--no-ba: ba.kernel=huber does nothing with ba.enabled=false"),
    (["--set", "ba.delta_sigmas=2", "--no-ba"], "--no-ba: ba.delta_sigmas=2.0 does nothing with ba.enabled=false"),
    (["--set", "verify.ransac=none", "--set", "verify.ransac_threshold_px=2"],
     "--set: verify.ransac_threshold_px=2.0 does nothing with verify.ransac=none"),
    (["--method", "gevi", "--no-fusion", "--no-adaptive"],
     "--no-fusion: fusion.adaptive=false does nothing with fusion.mode=4dof"),
]


@pytest.mark.parametrize("args,message", SWITCHED_OFF)
def test_a_setting_another_one_turns_off_is_refused(args, message, capsys):
    """Accepted before and without effect (the trajectories identical to the byte): now one line."""
    code, _, err = run_cli(["run", "--dump-config", *args], capsys)
    assert code == 2 and err.startswith(f"gevi: error: {message}"), err


def test_the_switched_on_forms_are_accepted(capsys):
    for args in (["--set", "ba.kernel=huber"], ["--set", "verify.ransac_threshold_px=2"],
                 ["--method", "gevi", "--no-adaptive"], ["--no-ba"], ["--method", "gevi", "--no-fusion"]):
        assert run_cli(["run", "--dump-config", *args], capsys)[0] == 0, args


def test_a_track_export_refuses_keyframe_settings():
    from gevi_cli.errors import GeviError
    from gevi_cli.run.session import RunRequest, resolve_config

    req = RunRequest(sequence=None, sets=("keyframe.min_tracked=50",))
    with pytest.raises(GeviError, match="keyframe.min_tracked=50: does not apply to ov2slam-tracks sequences"):
        resolve_config(req, "ov2slam-tracks", "cfo")
    resolve_config(req, "kitti", "cfo")


def test_a_batch_refuses_a_method_that_does_not_fit_an_image_sequence_at_the_door(tmp_path):
    """verify.use_export_flags on a render (images) is refused when the config is read, not per run."""
    from gevi_cli.batch.config import load_batch_config
    from gevi_cli.batch.plan import check_methods_fit
    from gevi_cli.errors import GeviError

    f = tmp_path / "b.yaml"
    f.write_text("name: b\nroot: .\ntrials: 1\nmethods:\n  - {name: flags, run: cfo --set verify.use_export_flags=true}\n"
                 "sequences:\n  - name: kl\n    simulate: {preset: kitti-like, seed: 1, duration: 2, format: kitti}\n")
    with pytest.raises(GeviError, match="'flags' on sequences.kl: .*use_export_flags=true: does not apply to kitti"):
        check_methods_fit(load_batch_config(f))


def test_each_number_is_defined_once():
    """What counts as a gap and as rest, and the initialisation's bounds, come from one definition each: the
    setting's default and domain are the constants the other commands and the odometry use."""
    import pydantic

    from gevi_cli.datasets.sequence import GAP_FACTOR
    from gevi_cli.evaluation import imu_report
    from gevi_cli.inertial import imu_stream, reference_alignment, standstill
    from gevi_cli.pipelines import config as pc

    assert pc.OdometryConfig().imu.max_gap_factor == GAP_FACTOR
    assert not hasattr(imu_stream, "IMU_GAP_FACTOR") and reference_alignment.GAP_FACTOR is GAP_FACTOR
    assert imu_report.STILL_LIMITS is standstill.STILL_LIMITS == (
        standstill.STILL_MAX_GYRO_STD, standstill.STILL_MAX_ACC_STD, standstill.STILL_MAX_GRAVITY_ERR)
    assert not hasattr(pc, "STILL_MAX_GYRO_STD")
    with pytest.raises(pydantic.ValidationError):
        pc.InitConfig(still_min_s=pc.STILL_LAG_S)
    pc.InitConfig(window_s=pc.MAX_WINDOW_S)
    with pytest.raises(pydantic.ValidationError):
        pc.InitConfig(window_s=pc.MAX_WINDOW_S + 0.01)


def test_dump_config_without_a_sequence_is_the_run_without_one(capsys):
    """`gevi run` without a SEQUENCE runs GeVI on the pool sample with pool.yaml: --dump-config says that."""
    code, out, _ = run_cli(["run", "--dump-config"], capsys)
    assert code == 0 and out.startswith("# effective configuration for gevi on the built-in pool-easy sample")
    assert "gevi_cli/configs/pool.yaml" in out.splitlines()[0]
    lines = {line.split("=", 1)[0]: line for line in out.splitlines() if not line.startswith("#")}
    assert lines["verify.ransac"].startswith("verify.ransac=3pt")  # GeVI's, as the run would use
