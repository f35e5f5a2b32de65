"""`gevi simulate mav`: the IMU-only high-dynamics regime (exact kinematics, tilts, band-limited rotor
vibration, the same flight at any IMU rate) and `gevi imu` on it end to end."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli import estimators as est
from gevi_cli.simulate.imu import ImuParams
from gevi_cli.simulate.mav import MavParams, band_noise, build_mav_motion, mav_imu
from support import run_cli

SHORT = MavParams(duration_s=30.0)


def test_flight_is_exact_aggressive_and_thrust_tilted():
    """Noise-free: the specific force is R^T (a + g e3) to rounding, integrating the body rate (trapezoid at
    400 Hz: O(dt^2) ~ 1e-5 rad) reproduces the attitude over the 30 s, |a| peaks at a_max, tilts pass 60 deg."""
    quiet = MavParams(duration_s=30.0, vib_gyro=0.0, vib_acc=0.0, gyro_scale=0.0, gyro_bias_flight=0.0)
    s, gt = mav_imu(quiet, ImuParams(rate_hz=400.0).noise_free(), seed=1, t0_ns=0)
    f = np.einsum("nji,nj->ni", gt.R_WB, gt.a_W + [0.0, 0.0, 9.81])
    assert np.abs(f - s.acc).max() < 1e-9
    R = gt.R_WB[0].copy()
    for k in range(len(s.t_ns) - 1):
        R = R @ est.exp_so3((s.gyro[k] + s.gyro[k + 1]) / 2.0 / 400.0)
    assert np.degrees(np.linalg.norm(est.log_so3(R.T @ gt.R_WB[-1]))) < 0.01
    assert np.linalg.norm(gt.a_W, axis=1).max() == pytest.approx(quiet.a_max, rel=0.01)
    tilt = np.degrees(np.arccos(np.clip(gt.R_WB[:, 2, 2], -1.0, 1.0)))
    assert tilt.max() > 60.0
    still = (s.t_ns * 1e-9) < quiet.still_start_s
    assert np.abs(gt.v_W[still]).max() == 0.0 and np.abs(s.gyro[still]).max() < 1e-9


def test_vibration_is_band_limited_and_above_the_white_noise():
    x = band_noise(np.random.default_rng(0), 20000, 2000.0, (70.0, 180.0))
    P = np.abs(np.fft.rfft(x, axis=0)) ** 2
    f = np.fft.rfftfreq(20000, 1 / 2000.0)
    inside = (f >= 70.0) & (f <= 180.0)
    assert P[~inside].sum() < 1e-20 * P[inside].sum() and np.allclose(np.sqrt((x * x).mean(0)), 1.0)
    # in flight, at 200 Hz, the gyro's deviation from its true rate is the vibration (0.05 rad/s per axis)
    s, gt = mav_imu(SHORT, ImuParams(rate_hz=200.0), seed=2, t0_ns=0)
    ts = s.t_ns * 1e-9
    fly = (ts > 12.0) & (ts < 22.0)
    dev = s.gyro[fly] - s.gyro_true[fly] * 1.0 - s.bias_gyro[fly]
    white = ImuParams().gyro_noise_density * np.sqrt(200.0)  # 2.4e-3 rad/s per sample
    rms = np.sqrt(np.mean(dev ** 2, axis=0))
    assert np.all(rms > 10 * white) and np.all(rms < 0.05 * 1.15 + 0.03 * np.abs(s.gyro_true[fly]).max())


def test_same_flight_at_any_imu_rate():
    a, ga = mav_imu(SHORT, ImuParams(rate_hz=200.0), seed=3, t0_ns=0)
    b, gb = mav_imu(SHORT, ImuParams(rate_hz=50.0), seed=3, t0_ns=0)
    assert np.array_equal(a.t_ns[::4], b.t_ns)
    assert np.allclose(ga.R_WB[::4], gb.R_WB, atol=1e-12) and np.allclose(ga.p_W[::4], gb.p_W, atol=1e-12)
    assert build_mav_motion(SHORT, 3) == build_mav_motion(SHORT, 3)


def _rows(out: str) -> dict:
    return {line.split("|")[1].strip(): (float(line.split("|")[2]), line.split("|")[5].strip())
            for line in out.splitlines() if line.startswith("| ") and "RMSE" not in line}


def test_vibration_render_end_to_end(tmp_path, capsys):
    """Render (30 s at 50 Hz, 8 s still, vibration) and report: the velocity-aided filter beats plain gyro
    integration and the fixed-weight gravity prior (which follows the thrust tilt), the complementary grid's
    best is inside it, and the stated white-noise model is the one used."""
    seq = tmp_path / "mav50"
    code, out, err = run_cli(["simulate", "mav", seq, "--imu-rate", "50", "--seed", "1", "--duration", "30"], capsys)
    assert code == 0, err
    code, out, err = run_cli(["imu", seq, "-o", tmp_path / "imu", "--no-plots"], capsys)
    assert code == 0, err
    rows = _rows(out)
    ours = rows["velocity-aided filter (gevi imu), causal"][0]
    assert ours < 2.5
    assert ours < rows["gyro-only integration"][0] and ours < rows["gravity-prior filter, fixed weight, causal"][0]
    assert "EDGE" not in rows["complementary filter, fixed gain (oracle)"][1]
    assert "50.0 Hz" in out and "noise model: as stated by the dataset" in out
    assert "standstill (IMU at rest, s): 0.0-8.0" in out
    states = (tmp_path / "imu" / "imu_states.csv").read_text().splitlines()
    assert states[0] == "t_ns,roll,pitch,yaw,bgx,bgy,bgz,sgx,sgy,sgz,tilt_std" and len(states) > 1400


def test_render_without_noise_model_uses_the_one_measured_at_rest(tmp_path, capsys):
    seq = tmp_path / "mav"
    code, _, err = run_cli(["simulate", "mav", seq, "--imu-rate", "50", "--seed", "2", "--duration", "20",
                            "--no-noise-model"], capsys)
    assert code == 0, err
    assert "noise_density" not in (seq / "mav0" / "imu0" / "sensor.yaml").read_text()
    code, out, err = run_cli(["imu", seq, "-o", tmp_path / "imu", "--no-plots"], capsys)
    assert code == 0, err
    line = next(x for x in out.splitlines() if x.startswith("white noise at rest"))
    gyro = line.split("gyro ")[1].split(" ")[0]
    note = next(x for x in out.splitlines() if x.startswith("noise model:"))
    assert note.startswith("noise model: none stated; using the white noise measured at rest (0.0-8.0 s): gyro "
                           f"{gyro} rad/s/sqrt(Hz)")
    assert "none stated" in line and "ADIS16448 values" not in err
    assert err.count("noise model: none stated") == 1  # said once, as a warning, besides the report line


@pytest.mark.parametrize("args, where", [(["--format", "kitti"], "--format"), (["--resolution", "64x48"], "--resolution"),
                                         (["--duration", "10"], "--duration"), (["--a-max", "12"], "--a-max")])
def test_imu_only_output_refuses_image_options(tmp_path, capsys, args, where):
    code, _, err = run_cli(["simulate", "mav", tmp_path / "x", *args], capsys)
    assert code == 2 and err.startswith(f"gevi: error: {where}") and len(err.strip().splitlines()) == 1


def test_imu_only_preset_has_the_full_renders_imu(tmp_path, capsys):
    """--imu-only writes a preset's IMU and ground truth without images: the same samples as the render's."""
    from gevi_cli.datasets.euroc import read_imu
    from gevi_cli.simulate.generate import SimulationConfig, build_sequence

    code, _, err = run_cli(["simulate", "pool-easy", tmp_path / "p", "--imu-only", "--duration", "3", "--seed", "4"],
                           capsys)
    assert code == 0, err
    imu = read_imu(tmp_path / "p" / "mav0" / "imu0")
    ref = build_sequence(SimulationConfig("pool-easy", seed=4, duration_s=3.0)).imu
    assert np.array_equal(imu.t_ns, ref.t_ns) and np.allclose(imu.gyro, ref.gyro, rtol=0, atol=1e-15)
    assert not (tmp_path / "p" / "mav0" / "cam0").exists()
