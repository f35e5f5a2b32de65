"""`gevi run --method gevi` end to end: real EuRoC stereo + IMU, a simulated pool render, bad inputs,
determinism and the IMU-gap degradation."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest

from support import run_cli, shared_path


def _status(run):
    return json.loads((run / "status.json").read_text())


@pytest.fixture(scope="module")
def gevi_sim_run(pool_render, tmp_path_factory):
    from gevi_cli.cli import main

    out = tmp_path_factory.mktemp("gevi_sim") / "run"
    try:
        main(["run", str(pool_render), "-q", "-o", str(out)])
    except SystemExit as e:  # click's standalone exit
        assert e.code in (0, None)
    return out


def test_euroc_micro_real_stereo_imu(tmp_path, capsys):
    """95 real EuRoC pairs at rest with the real IMU: all tracked and within ORB-SLAM3 stereo's figures
    there (ATE 0.73 mm, RPE 0.56 mm; body frame, SE(3)); initialised from the standstill."""
    seq = shared_path("euroc_micro")
    code, out, err = run_cli(["run", seq, "--gt", seq / "groundtruth" / "V1_01_easy.csv", "-q", "-o", tmp_path / "r"], capsys)
    assert code == 0, err
    assert out.splitlines()[0].startswith("gevi run: method gevi (the sequence has an IMU")
    st = _status(tmp_path / "r")
    assert st["frames_tracked"] == 95 and st["frames_done"] == 95 and not st["inertial_frames"]
    ev = st["evaluation"]
    assert ev["align"] == "se3" and ev["ate_m"] <= 0.73e-3 and ev["rpe_m"] <= 0.56e-3
    assert ev["posyaw"]["align"] == "posyaw"
    assert st["imu"]["initialisation"]["method"] == "standstill"
    # gyro bias from the whole standstill, against the ground truth's (rad/s)
    gt = pd.read_csv(seq / "groundtruth" / "V1_01_easy.csv")
    assert np.all(np.abs(np.array(st["imu"]["gyro_bias"]) - gt.iloc[0, 11:14].to_numpy(float)) < 2e-3)
    states = pd.read_csv(tmp_path / "r" / "imu_states.csv")
    assert len(states) == 95 and {"roll", "pitch", "sigma_trace", "bgx"} <= set(states.columns)


def test_simulated_run_end_to_end(gevi_sim_run, pool_render):
    st = _status(gevi_sim_run)
    n = len(pd.read_csv(pool_render / "mav0" / "cam0" / "data.csv"))
    assert st["state"] == "ok" and st["frames_tracked"] == n == st["frames_done"]
    assert st["imu"]["initialised"] and st["imu"]["initialisation"]["method"] == "standstill"
    ev = st["evaluation"]
    # sub-centimetre on 6 s of 376x240 pool imagery; roll/pitch within the spec's 0.3 deg
    assert ev["ate_m"] < 0.01 and ev["tilt_rmse_deg"] < 0.3
    for f in ("traj_body.tum", "traj_cam0.tum", "traj_online_body.tum", "config.yaml", "timing.csv", "imu_states.csv"):
        assert (gevi_sim_run / f).is_file(), f
    states = pd.read_csv(gevi_sim_run / "imu_states.csv")
    assert set(states.phase) <= {"init", "standstill", "gevi", "visual", "inertial", "bridged"}
    assert (states.phase == "gevi").sum() > n // 2


def test_online_trajectory_is_one_piece_in_the_gravity_aligned_world(gevi_sim_run):
    """The initialisation window is tracked before W exists; its online poses are written once they
    can be re-expressed in W, like the final ones (they were written in the first camera's frame: a
    0.2 m jump at the initialisation).  Online and after-BA poses then differ by the BA's corrections
    only, sub-millimetre on this render."""
    from gevi_cli.trajectory import read_trajectory

    online = read_trajectory(gevi_sim_run / "traj_online_body.tum", frame="body")
    final = read_trajectory(gevi_sim_run / "traj_body.tum", frame="body")
    assert np.array_equal(online.t_ns, final.t_ns)
    assert np.max(np.linalg.norm(online.positions - final.positions, axis=1)) < 2e-3
    dot = np.abs(np.sum(online.quat_wxyz * final.quat_wxyz, axis=1))
    assert np.degrees(2 * np.arccos(np.clip(dot, 0, 1))).max() < 0.1


def test_refined_accelerometer_bias_after_a_standstill_is_along_gravity(gevi_sim_run, pool_render):
    """After a standstill start only the gravity component of the refined b_a is adopted: the horizontal
    one is already in the standstill's tilt (spec 9.6).  The adopted bias is along the body's up
    direction (the ground truth's, which the estimate is within a fraction of a degree of), and its
    size is the refinement's projection on it."""
    from scipy.spatial.transform import Rotation as Rot

    st = _status(gevi_sim_run)
    info = st["imu"]["initialisation"]["acc_bias_refined"]
    assert "rejected" not in info, info
    b, full = np.asarray(info["adopted"]), np.asarray(info["b_a"])
    assert np.allclose(st["imu"]["acc_bias"], b, rtol=0, atol=1e-15)
    gt = np.loadtxt(pool_render / "mav0" / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")
    t_first = int(pd.read_csv(pool_render / "mav0" / "cam0" / "data.csv").iloc[0, 0])
    i = int(np.searchsorted(gt[:, 0], t_first + info["at_s"] * 1e9))
    up = Rot.from_quat(gt[i, [5, 6, 7, 4]]).as_matrix().T @ [0.0, 0.0, 1.0]
    tilt_err = np.radians(0.5)  # the estimated up against the truth's (the run's roll/pitch error is < 0.3 deg)
    assert np.linalg.norm(b - up * (b @ up)) <= np.linalg.norm(b) * tilt_err + 1e-12
    assert abs(b @ up - full @ up) <= np.linalg.norm(full) * tilt_err + 1e-12


@pytest.mark.slow
def test_written_trajectory_has_no_attitude_step_at_keyframes(tmp_path, capsys):
    """The gravity re-levelling of a keyframe is spread over the frames since the previous keyframe:
    the frame-to-frame rotation error of the steps that end at a keyframe is of the size of the others
    (as one step at the keyframe it was 11-24x larger on pool-easy renders; docs/method.md 9b).  A
    20 Hz full-size render, so that keyframes are several frames apart."""
    from gevi_cli.datasets import open_sequence
    from gevi_cli.estimators import log_so3
    from gevi_cli.evaluation.associate import associate
    from gevi_cli.simulate.generate import SimulationConfig, simulate
    from gevi_cli.trajectory import read_trajectory

    seq = simulate(SimulationConfig("pool-easy", seed=5, duration_s=8.0), tmp_path / "pe", "euroc",
                   progress=False, workers=1)
    code, _, err = run_cli(["run", seq, "-q", "-o", tmp_path / "r"], capsys)
    assert code == 0, err
    run = tmp_path / "r"
    est = read_trajectory(run / "traj_body.tum", frame="body")
    a = associate(open_sequence(seq).groundtruth, est, max_diff_s=0.01)
    Re, Rg = a.est.rotations, a.gt.rotations
    e = np.array([np.linalg.norm(log_so3((Rg[k].T @ Rg[k + 1]).T @ (Re[k].T @ Re[k + 1]))) for k in range(len(Re) - 1)])
    frames = pd.read_csv(run / "frames.csv")
    t_kf = set(frames.t_ns[frames.keyframe.astype(bool)].tolist())
    into_kf = np.array([int(t) in t_kf for t in a.est.t_ns[1:]])
    assert into_kf.sum() >= 10 and (~into_kf).sum() >= 2 * into_kf.sum()
    rms = lambda x: float(np.sqrt(np.mean(x ** 2)))  # noqa: E731
    assert rms(e[into_kf]) < 3.0 * rms(e[~into_kf]), (rms(e[into_kf]), rms(e[~into_kf]))


def test_deterministic(gevi_sim_run, pool_render, tmp_path):
    from gevi_cli.cli import main

    try:
        main(["run", str(pool_render), "-q", "-o", str(tmp_path / "again")])
    except SystemExit as e:
        assert e.code in (0, None)
    for f in ("traj_body.tum", "imu_states.csv"):
        assert (tmp_path / "again" / f).read_bytes() == (gevi_sim_run / f).read_bytes()


def _copy(render, tmp_path):
    dst = tmp_path / "seq"
    shutil.copytree(render, dst)
    return dst


def _imu_rows(seq):
    p = seq / "mav0" / "imu0" / "data.csv"
    lines = p.read_text().splitlines()
    return p, lines[0], lines[1:]


def test_imu_out_of_order_is_one_line(pool_render, tmp_path, capsys):
    seq = _copy(pool_render, tmp_path)
    p, head, rows = _imu_rows(seq)
    rows[100], rows[101] = rows[101], rows[100]
    p.write_text("\n".join([head] + rows) + "\n")
    code, _, err = run_cli(["run", seq, "--method", "gevi", "-q", "-o", tmp_path / "r"], capsys)
    assert code == 2 and err.count("\n") == 1 and "order" in err


def test_no_imu_over_the_initialisation_window(pool_render, tmp_path, capsys):
    seq = _copy(pool_render, tmp_path)
    p, head, rows = _imu_rows(seq)
    p.write_text("\n".join([head] + rows[:40]) + "\n")  # 0.2 s of IMU
    code, _, err = run_cli(["run", seq, "--method", "gevi", "-q", "-o", tmp_path / "r"], capsys)
    assert code == 2 and err.count("\n") == 1 and "initialisation window" in err


def test_extrinsic_that_is_not_a_rotation(pool_render, tmp_path, capsys):
    seq = _copy(pool_render, tmp_path)
    y = seq / "mav0" / "cam0" / "sensor.yaml"
    text = y.read_text()
    start = text.index("data: [") + len("data: [")
    first = text[start:text.index(",", start)]
    y.write_text(text[:start] + str(2.0 * float(first)) + text[start + len(first):])
    code, _, err = run_cli(["run", seq, "--method", "gevi", "-q", "-o", tmp_path / "r"], capsys)
    assert code == 2 and err.count("\n") == 1 and ("rotation" in err or "T_BS" in err)


def test_no_imu_needs_cfo(tmp_path, capsys):
    seq = shared_path("kitti06_head", "dataset", "sequences", "06")
    code, _, err = run_cli(["run", seq, "--method", "gevi", "-q", "-o", tmp_path / "r"], capsys)
    assert code == 2 and err.count("\n") == 1 and "no IMU" in err and "--method cfo" in err
    code, out, _ = run_cli(["run", seq, "--max-frames", "3", "-q", "-o", tmp_path / "c"], capsys)
    assert out.splitlines()[0] == "gevi run: method cfo (the sequence has no IMU)"


def test_imu_gap_degrades_to_visual_and_is_reported(pool_render, tmp_path, capsys):
    seq = _copy(pool_render, tmp_path)
    p, head, rows = _imu_rows(seq)
    t = np.array([int(r.split(",")[0]) for r in rows])
    gap = (t > t[0] + 3.0e9) & (t < t[0] + 3.6e9)
    p.write_text("\n".join([head] + [r for r, g in zip(rows, gap) if not g]) + "\n")
    code, _, err = run_cli(["run", seq, "--method", "gevi", "-q", "-o", tmp_path / "r"], capsys)
    assert code == 0, err
    st = _status(tmp_path / "r")
    gaps = st["imu"]["imu_gaps"]
    assert len(gaps) == 1 and 5 <= gaps[0]["frames"] <= 7
    states = pd.read_csv(tmp_path / "r" / "imu_states.csv")
    assert set(states.phase[gaps[0]["first_index"]:gaps[0]["last_index"] + 1]) == {"visual"}
    assert st["frames_tracked"] == st["frames_done"]


@pytest.mark.slow
def test_slow_moving_start_initialises_from_stereo_odometry(tmp_path, capsys):
    """Accelerations below 0.15 m/s^2 and no standstill: the first 2 s of stereo odometry give gravity
    within 0.5 deg and the gyro bias within 2e-3 rad/s per axis (spec 9, with the b_a prior), and the
    run tracks to the end."""
    from scipy.spatial.transform import Rotation

    from gevi_cli import estimators as est
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    cfg = SimulationConfig("pool-easy", seed=7, duration_s=5.0, rate_hz=10.0, resolution=(376, 240), a_max=0.15,
                           moving_start=True)
    seq = simulate(cfg, tmp_path / "slow", "euroc", progress=False, workers=1)
    code, _, err = run_cli(["run", seq, "-q", "-o", tmp_path / "r"], capsys)
    assert code == 0, err
    st = _status(tmp_path / "r")
    assert st["imu"]["initialisation"]["method"] == "stereo-imu" and st["frames_tracked"] == st["frames_done"] == 50
    s = pd.read_csv(tmp_path / "r" / "imu_states.csv")
    k = int((s.phase != "init").to_numpy().argmax())  # the frame the initialisation ran at
    gt = np.loadtxt(seq / "mav0" / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")
    i = np.searchsorted(gt[:, 0].astype(np.int64), s.t_ns[k])
    R_WB = Rotation.from_quat(gt[i, [5, 6, 7, 4]]).as_matrix()
    g_est = est.rtilt(s.roll[k], s.pitch[k]).T @ [0, 0, 1]
    assert np.degrees(np.arccos(min(1.0, g_est @ (R_WB.T @ [0, 0, 1])))) < 0.5
    assert np.all(np.abs(s.loc[k, ["bgx", "bgy", "bgz"]].to_numpy(float) - gt[i, 11:14]) < 2e-3)


@pytest.mark.slow
def test_standstill_on_a_faint_lamp_lit_floor_ends_when_the_motion_starts(tmp_path, capsys):
    """pool-hard seed 1 (a feature-poor floor under the vehicle's lamps; gevi_cli/configs/pool.yaml removes the
    shading): at rest for 1.5 s, then a smooth start.  The floor's faint features random-walk at rest
    and most are lost within 0.5 s; the standstill must be recognised (not the moving-start
    initialisation at rest) and must end within 0.5 s of the first motion, so that the gyro bias of
    the standstill is within the issue's 2e-3 rad/s per axis (docs/method.md, 9b "Standstill start").
    """
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    seq = simulate(SimulationConfig("pool-hard", seed=1, duration_s=4.0), tmp_path / "ph", "euroc",
                   progress=False, workers=1)
    gt = np.loadtxt(seq / "mav0" / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")
    t = (gt[:, 0] - gt[0, 0]) * 1e-9
    moved = np.linalg.norm(gt[:, 1:4] - gt[0, 1:4], axis=1) > 1e-4
    t_start = t[np.argmax(moved)]
    assert 1.0 < t_start < 2.5  # the render starts at rest (what this test is about)
    code, _, err = run_cli(["run", seq, "-q", "-o", tmp_path / "r"], capsys)
    assert code == 0, err
    init = _status(tmp_path / "r")["imu"]["initialisation"]
    assert init["method"] == "standstill"
    assert t_start - 0.2 <= init["standstill_s"] <= t_start + 0.5
    b_g = np.asarray(_status(tmp_path / "r")["imu"]["gyro_bias"])
    assert np.all(np.abs(b_g - gt[0, 11:14]) < 2e-3), (b_g, gt[0, 11:14])


def test_run_without_arguments_renders_the_sample_and_runs_gevi(monkeypatch, tmp_path, capsys):
    """`gevi run` alone: the sample is rendered on first use into the cache, GeVI runs on it and the
    ATE/RPE and roll/pitch lines are printed (a smaller sample here, the real one takes 11 s)."""
    from gevi_cli.simulate import sample as sample_mod
    from gevi_cli.simulate.generate import SimulationConfig

    monkeypatch.setattr(sample_mod, "SAMPLE_CONFIG", SimulationConfig("pool-easy", seed=0, duration_s=4.0,
                                                                      rate_hz=10.0, resolution=(376, 240)))
    monkeypatch.setenv("GEVI_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(["run", "-q"], capsys)
    assert code == 0, err
    lines = out.splitlines()
    assert "rendering the built-in pool-easy sample" in lines[0]
    assert lines[1].startswith("gevi run: method gevi (the sequence has an IMU")
    assert any(x.startswith("ATE ") and "SE3" in x for x in lines) and any("roll/pitch error" in x for x in lines)
    assert (tmp_path / "results" / "gevi" / "sample-pool-easy-v1" / "latest" / "status.json").is_file()


def test_window_gravity_on_an_accelerating_render_is_within_the_bias_of_the_truth(pool_render, tmp_path, monkeypatch):
    """The gravity direction the BCD compares with (pipelines/window_gravity.py), on the frames where
    the window gives one: off the truth by the accelerometer-bias error over g (plus position noise,
    hundredths of a degree), where the unit specific force, the spec's measurement, is degrees off
    under the render's accelerations (up to 0.5 m/s^2: ~3 deg)."""
    from scipy.spatial.transform import Rotation as Rot

    from gevi_cli.pipelines import window_gravity as wg
    from gevi_cli.run.session import RunRequest, execute

    answers = []
    real = wg.WindowGravity.up

    def spy(self, t_ns):
        u = real(self, t_ns)
        if u is not None:
            answers.append((int(t_ns), u))
        return u

    monkeypatch.setattr(wg.WindowGravity, "up", spy)
    execute(RunRequest(sequence=str(pool_render), method="gevi", out=str(tmp_path / "r"), quiet=True),
            echo=lambda *a, **k: None)
    gt = np.loadtxt(pool_render / "mav0" / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")
    imu = np.loadtxt(pool_render / "mav0" / "imu0" / "data.csv", delimiter=",", comments="#")
    b_a = np.asarray(_status(tmp_path / "r")["imu"]["acc_bias"])
    assert len(answers) > 40  # from 1 s after the standstill on (6 s render, 10 Hz)
    err_w, err_f, err_b = [], [], []
    for t, u in answers:
        i = int(np.searchsorted(gt[:, 0], t))
        up = Rot.from_quat(gt[i, [5, 6, 7, 4]]).as_matrix().T @ [0.0, 0.0, 1.0]
        j = int(np.searchsorted(imu[:, 0], t))
        f = imu[j - 5:j + 5, 4:7].mean(0)
        err_w.append(np.degrees(np.arccos(min(1.0, u @ up))))
        err_f.append(np.degrees(np.arccos(min(1.0, f @ up / np.linalg.norm(f)))))
        err_b.append(np.degrees(np.linalg.norm((b_a - gt[i, 14:17])[:2]) / 9.81))
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    assert rms(err_w) <= rms(err_b) + 0.1, (rms(err_w), rms(err_b))
    assert rms(err_f) > 3.0 * rms(err_w) and max(err_f) > 2.0


def test_a_run_that_ends_before_the_initialisation_has_no_roll_pitch_figure(pool_render, tmp_path, capsys):
    """5 frames of the still start (0.5 s, less than the 1 s a standstill initialisation needs): the
    poses are in the first camera's frame, so no angle to gravity is printed or recorded."""
    code, out, err = run_cli(["run", pool_render, "--max-frames", "5", "-o", tmp_path / "r"], capsys)
    assert code == 0, err
    st = _status(tmp_path / "r")
    assert st["imu"]["initialised"] is False
    assert "roll/pitch not evaluated: the run ended before the stereo-IMU initialisation" in out
    assert "tilt_rmse_deg" not in st["evaluation"] and "roll/pitch error" not in out


def test_negative_gravity_window_is_one_line(pool_render, tmp_path, capsys):
    code, _, err = run_cli(["run", pool_render, "--set", "fusion.gravity_window_s=-1", "-o", tmp_path / "r"], capsys)
    assert code == 2 and "fusion.gravity_window_s" in err and len(err.strip().splitlines()) == 1, err


def test_start_of_motion_after_the_standstill_is_not_read_as_gravity(pool_render, tmp_path, monkeypatch):
    """The standstill test sees the start of motion late (here the render moves from 1.5 s, its
    accelerations reach 0.2-0.5 m/s^2 within 0.3 s: 1-3 deg in the specific force).  The gravity
    directions the BCD compares with on the frames still called at rest after the motion began must be
    off the truth only by the accelerometer-bias error over g (the window gravity keeps running through
    the standstill), not by the acceleration over g."""
    from scipy.spatial.transform import Rotation as Rot

    from gevi_cli.pipelines.gevi import GeviOdometry
    from gevi_cli.run.session import RunRequest, execute

    used = {}  # t_ns -> (acc_dir the BCD used, standstill?) for the current frame of each GeVI pose step
    real = GeviOdometry._gevi_pose

    def spy(self, m, cov):
        cur = self.plan.sample
        used[int(cur.t_ns)] = (cur.acc_dir.copy(), bool(self.start.still))
        return real(self, m, cov)

    monkeypatch.setattr(GeviOdometry, "_gevi_pose", spy)
    execute(RunRequest(sequence=str(pool_render), method="gevi", out=str(tmp_path / "r"), quiet=True),
            echo=lambda *a, **k: None)
    gt = np.loadtxt(pool_render / "mav0" / "state_groundtruth_estimate0" / "data.csv", delimiter=",", comments="#")
    b_a = np.asarray(_status(tmp_path / "r")["imu"]["acc_bias"])
    dt = np.diff(gt[:, 0]).mean() * 1e-9
    acc = np.linalg.norm(np.gradient(gt[:, 8:11], dt, axis=0), axis=1)  # |a| (m/s^2), W
    moving_still, err, bound = 0, [], []
    for t, (u, still) in used.items():
        i = int(np.searchsorted(gt[:, 0], t))
        if not still or acc[i] < 0.1:
            continue
        moving_still += 1
        up = Rot.from_quat(gt[i, [5, 6, 7, 4]]).as_matrix().T @ [0.0, 0.0, 1.0]
        err.append(np.degrees(np.arccos(min(1.0, u @ up))))
        # the bias error over g (the standstill's b_a is the prior, 0) plus hundredths of position noise
        bound.append(np.degrees(np.linalg.norm((b_a - gt[i, 14:17])[:2]) / 9.81) + 0.1)
    assert moving_still >= 3, "the render no longer has a late-detected start of motion to test"
    assert np.all(np.array(err) <= np.array(bound)), list(zip(err, bound))


@pytest.mark.parametrize("setting", ["fusion.bias_window_s=-1", "fusion.gravity_window_s=-1"])
def test_bad_in_flight_bias_settings_are_one_line(pool_render, tmp_path, capsys, setting):
    code, _, err = run_cli(["run", pool_render, "--set", setting, "-o", tmp_path / "r"], capsys)
    assert code == 2 and setting.split("=")[0] in err and len(err.strip().splitlines()) == 1, err


def test_in_flight_bias_is_adopted_and_recorded(pool_render, tmp_path, capsys, monkeypatch):
    """The plumbing of pipelines/acc_bias.py in a run: a 3 s window and a gate that takes any estimate
    (the 6 s render is too short for the default 20 s / 0.02 m/s^2 to adopt one).  The estimates move
    only the horizontal bias: the vertical part stays the standstill refinement's."""
    import gevi_cli.pipelines.gevi as gevi_pipeline

    monkeypatch.setattr(gevi_pipeline, "BIAS_MAX_STD", 1.0)
    code, _, err = run_cli(["run", pool_render, "--set", "fusion.bias_window_s=3", "-o", tmp_path / "r"], capsys)
    assert code == 0, err
    st = _status(tmp_path / "r")
    flight = st["imu"]["acc_bias_in_flight"]
    assert flight["updates"] > 5 and flight["first_at_s"] > 1.5 and 0 < flight["last_std"] < 0.06
    states = pd.read_csv(tmp_path / "r" / "imu_states.csv")
    # after the one-off refinement along gravity (which sets the vertical part)
    t_ref = st["imu"]["initialisation"]["acc_bias_refined"]["at_s"]
    after = states[(states.t_ns - states.t_ns.iloc[0]) * 1e-9 > t_ref + 0.05]
    assert len(after) > 10
    b = after[["bax", "bay", "baz"]].to_numpy()
    # the render's body z is up to within a few degrees: the updates move x and y, z only by that tilt
    assert np.ptp(b[:, 2]) < 0.1 * (np.ptp(b[:, 0]) + np.ptp(b[:, 1]))


@pytest.mark.slow
def test_chi_square_gate_keeps_wrong_stereo_depths_out_of_the_bcd(pool_render, tmp_path, monkeypatch):
    """Every 7th keyframe point gets twice its depth (a wrong stereo match the 2D-2D RANSAC cannot
    see; the l1 stage is off so that only the gate stands between them and the BCD, and the BA too, so
    that the tracking is what is judged).  Without the gate the BCD's quadratic visual cost follows
    them."""
    from gevi_cli.cli import main
    from gevi_cli.pipelines.odometry import KeyframeOdometry, Matches

    def ate(out, *extra):
        try:
            main(["run", str(pool_render), "-q", "-o", str(out), "--no-ba", "--set", "verify.l1=none", *extra])
        except SystemExit as e:
            assert e.code in (0, None)
        return _status(out)["evaluation"]["ate_m"]

    clean = ate(tmp_path / "clean")
    match = KeyframeOdometry._match

    def corrupted(self, ids, q_all):
        m = match(self, ids, q_all)
        p = m.p.copy()
        p[m.ids % 7 == 0] *= 2.0
        return Matches(m.ids, m.z, m.y, m.q, p, m.cov_unit)

    monkeypatch.setattr(KeyframeOdometry, "_match", corrupted)
    gated = ate(tmp_path / "gated")
    import gevi_cli.pipelines.tilt_window as tilt_window

    monkeypatch.setattr(tilt_window, "CHI2_GATE", 0.0)
    open_gate = ate(tmp_path / "open")
    # measured (no BA, so the tracking is what is judged): clean 0.52 mm, gated 4.2 mm, open 7.2 mm; the
    # corrupted points the gate cannot flag (far ones, whose depth covariance covers a doubling) and
    # the 4-DOF start they drag keep the gated run above the clean one
    assert clean < gated < 0.75 * open_gate
