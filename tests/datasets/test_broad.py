"""BROAD trials (.mat) read natively: `gevi imu` reproduces the benchmark's published-style VQF figures
through gevi's own reader and metric, and a malformed trial is one line naming the file and the field."""
from __future__ import annotations

import re

import numpy as np
import pytest
from scipy.io import savemat
from scipy.spatial.transform import Rotation

from support import run_cli, shared_path

TRIAL_02 = ("broad", "data_mat", "02_undisturbed_slow_rotation_B.mat")


def _trial(n: int = 600, rate: float = 100.0) -> dict:
    """A small valid trial: a slow tilt, the IMU's own attitude as reference, the second half scored."""
    t = np.arange(n) / rate
    rv = np.stack([0.3 * np.sin(0.5 * t), 0.2 * np.sin(0.3 * t), 0.1 * t], axis=1)
    R = Rotation.from_rotvec(rv)
    gyr = np.vstack([np.zeros(3), (R[:-1].inv() * R[1:]).as_rotvec() * rate])
    acc = R.inv().apply([0.0, 0.0, 9.81])
    q = R.as_quat()[:, [3, 0, 1, 2]]
    return {"imu_gyr": gyr, "imu_acc": acc, "opt_quat": q, "movement": (t > t[-1] / 2).astype(np.uint8),
            "sampling_rate": rate, "imu_mag": np.zeros((n, 3)), "opt_pos": np.zeros((n, 3)), "info": "test trial"}


def test_small_trial_is_read_and_scored_over_its_movement_samples(tmp_path, capsys):
    from gevi_cli.datasets.broad import BroadTrial

    d = _trial()
    d["opt_quat"][10:20] = np.nan  # occluded markers
    f = tmp_path / "trial.mat"
    savemat(f, d)
    trial = BroadTrial(f)
    assert len(trial.imu) == 600 and trial.imu.rate_hz == pytest.approx(100.0)
    assert len(trial.groundtruth) == 590 and len(trial.scored_t_ns) == int(d["movement"].sum())
    code, out, err = run_cli(["imu", f, "-o", tmp_path / "imu", "--no-plots"], capsys)
    assert code == 0, err
    assert f"scored over {len(trial.scored_t_ns)} samples" in out and "reference used as given" in out
    code, out, err = run_cli(["info", f], capsys)
    assert code == 0, err
    assert "(broad: BROAD benchmark trial" in out and "590 of 600 samples valid" in out


@pytest.mark.parametrize("field", ["imu_gyr", "imu_acc", "opt_quat", "movement", "sampling_rate"])
def test_missing_field_is_one_line_naming_file_and_field(tmp_path, capsys, field):
    d = _trial()
    del d[field]
    f = tmp_path / f"no_{field}.mat"
    savemat(f, d)
    for cmd in ("imu", "info"):
        code, out, err = run_cli([cmd, f, "-o", tmp_path / "o"] if cmd == "imu" else [cmd, f], capsys)
        assert code == 2
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"gevi: error: {f}: ") and f"'{field}'" in lines[0]


@pytest.mark.parametrize("field", ["imu_acc", "opt_quat", "movement"])
def test_mismatched_lengths_name_the_field(tmp_path, capsys, field):
    d = _trial()
    d[field] = d[field][:-7]
    f = tmp_path / "short.mat"
    savemat(f, d)
    code, _, err = run_cli(["imu", f, "-o", tmp_path / "o"], capsys)
    assert code == 2
    assert re.fullmatch(rf"gevi: error: {re.escape(str(f))}: field '{field}' has 593 samples, 'imu_gyr' has 600",
                        err.strip())


def test_not_a_mat_file(tmp_path, capsys):
    f = tmp_path / "junk.mat"
    f.write_text("not matlab\n")
    code, _, err = run_cli(["imu", f, "-o", tmp_path / "o"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and str(f) in err


def test_tilt_metric_is_broads_inclination_error():
    """gevi's tilt (angle between the two gravity directions seen from the body) is BROAD's inclination
    error 2 acos(sqrt(w^2 + z^2)) of q_err = q_est q_ref^-1 (broad_utils.py), for any pair of attitudes."""
    from gevi_cli.evaluation.tilt import gravity_angle_deg

    rng = np.random.default_rng(3)
    Re, Rr = Rotation.random(500, random_state=rng), Rotation.random(500, random_state=rng)
    q = (Re * Rr.inv()).as_quat()  # x y z w
    broad = np.degrees(2 * np.arccos(np.clip(np.sqrt(q[:, 3] ** 2 + q[:, 2] ** 2), 0, 1)))
    assert np.allclose(gravity_angle_deg(Re.as_matrix(), Rr.as_matrix()), broad, atol=1e-6)


@pytest.mark.slow
def test_trial_02_reproduces_vqf_figures(tmp_path, capsys):
    """`gevi imu` on BROAD trial 02 as it is: VQF 6D online 0.429 and offline 0.312 deg (inclination RMSE over
    the movement samples, the benchmark's metric; ../shared/data/broad/SOURCE.md), +-0.002 deg."""
    f = shared_path(*TRIAL_02)
    code, out, err = run_cli(["imu", f, "-o", tmp_path / "imu", "--no-plots"], capsys)
    assert code == 0, err
    rows = {c[1].strip(): float(c[2]) for c in (line.split("|") for line in out.splitlines())
            if len(c) > 5 and re.fullmatch(r" [0-9.]+ ", c[2])}
    online = next(v for k, v in rows.items() if k.startswith("VQF 6D online"))
    offline = next(v for k, v in rows.items() if k.startswith("VQF 6D offline"))
    assert online == pytest.approx(0.429, abs=0.002) and offline == pytest.approx(0.312, abs=0.002)
    assert "285.7 Hz" in out and "reference used as given" in out


@pytest.mark.slow
@pytest.mark.parametrize("trial", ["02_undisturbed_slow_rotation_B.mat", "07_undisturbed_fast_rotation_B.mat"])
def test_attitude_files_score_as_their_rows_on_broads_stamps(tmp_path, capsys, trial):
    """attitude.tum and attitude_offline.tum, scored independently against BROAD's own reference at BROAD's
    stamps over its movement samples (its inclination metric), give the report's rows for the same filters:
    one stamp convention for every file and row."""
    from gevi_cli.datasets.broad import BroadTrial
    from gevi_cli.evaluation.tilt import gravity_angle_deg
    from gevi_cli.trajectory import read_trajectory

    f = shared_path("broad", "data_mat", trial)
    code, out, err = run_cli(["imu", f, "-o", tmp_path / "imu", "--no-plots"], capsys)
    assert code == 0, err
    rows = {c[1].strip(): float(c[2]) for c in (line.split("|") for line in out.splitlines())
            if len(c) > 5 and re.fullmatch(r" [0-9.]+ ", c[2])}
    ref = BroadTrial(f)
    gt = ref.groundtruth
    for name, row in (("attitude.tum", "standstill-compensated VQF online (gevi imu attitude.tum), causal"),
                      ("attitude_offline.tum", "standstill-compensated VQF offline (gevi imu attitude_offline.tum), "
                                               "offline")):
        est = read_trajectory(tmp_path / "imu" / name, frame="body")
        common, i_est, i_gt = np.intersect1d(est.t_ns, gt.t_ns, return_indices=True)
        moving = np.isin(common, ref.scored_t_ns)
        err_deg = gravity_angle_deg(est.rotations[i_est][moving], gt.rotations[i_gt][moving])
        assert float(np.sqrt(np.mean(err_deg**2))) == pytest.approx(rows[row], abs=0.0015), name
