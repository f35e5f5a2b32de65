"""Stereo–IMU initialisation (spec 9): noise-free exactness, noisy cases, b_a prior, errors.

Simulation: ``simulation.SinTraj`` gives the *measured* IMU samples
(closed-form rate and specific force at 200 Hz, plus constant biases); the ground-truth IMU poses
and velocities are the exact zero-order-hold integration of the noise-free samples, so that
noise-free preintegration is exact (no discretisation error). Keyframes every 20 samples (10 Hz)
over 3 s (31 keyframes); forward-looking camera ``R_IC`` with a lever arm.
"""

import numpy as np
import pytest

from gevi_cli.estimators import DegenerateInput, NonFiniteInput, TooFewPoints
from gevi_cli.estimators.initialization import (
    InitOptions,
    gravity_to_R_WV,
    stereo_imu_init,
)
from gevi_cli.geometry import exp_so3
from gevi_cli.studies.simulation import G_W, R_IC_FORWARD, SinTraj

RATE = 200
DT_NS = 5_000_000
P_IC = np.array([0.05, -0.02, 0.03])


def simulate(seed, T=3.0, kf_every=20, traj=None, b_g=(0.01, -0.02, 0.015), b_a=(0.08, -0.05, 0.1),
             acc_density=0.0, gyro_density=0.0, pos_sigma=0.0, rot_sigma_deg=0.0):
    rng = np.random.default_rng(seed)
    tr = traj or SinTraj()
    m = int(round(T * RATE))
    ts = np.arange(m + 1) / RATE
    w, a = tr.omega(ts), tr.specific_force(ts)
    dt = 1.0 / RATE
    # discrete (ZOH) truth
    E = exp_so3(w * dt)
    R = np.empty((m + 1, 3, 3))
    R[0] = tr.R(0.0)[0]
    for k in range(m):
        R[k + 1] = R[k] @ E[k]
    acc_w = np.einsum("kij,kj->ki", R, a) + G_W
    v = np.vstack([tr.pos(0.0, 1), tr.pos(0.0, 1)[0] + np.cumsum(acc_w[:-1] * dt, axis=0)])
    p = np.vstack([tr.pos(0.0), tr.pos(0.0)[0] + np.cumsum(v[:-1] * dt + 0.5 * acc_w[:-1] * dt**2, axis=0)])
    gyro = w + np.asarray(b_g) + rng.normal(size=w.shape) * gyro_density * np.sqrt(RATE)
    acc = a + np.asarray(b_a) + rng.normal(size=a.shape) * acc_density * np.sqrt(RATE)
    kf = np.arange(0, m + 1, kf_every)
    R_WC = R[kf] @ R_IC_FORWARD
    p_WC = p[kf] + R[kf] @ P_IC
    R_VW = R_WC[0].T
    R_VC = R_VW @ R_WC
    p_VC = (p_WC - p_WC[0]) @ R_VW.T
    if rot_sigma_deg > 0:
        R_VC = R_VC @ exp_so3(rng.normal(size=(len(kf), 3)) * np.deg2rad(rot_sigma_deg))
    p_VC = p_VC + rng.normal(size=p_VC.shape) * pos_sigma
    return dict(
        t_kf=kf * DT_NS, R_VC=R_VC, p_VC=p_VC, imu_t=np.arange(m + 1) * DT_NS, gyro=gyro, acc=acc,
        g_V=R_VW @ G_W, v_V=v[kf] @ R_VW.T, b_g=np.asarray(b_g), b_a=np.asarray(b_a), R_VW=R_VW,
    )


def run(sim, **opt):
    return stereo_imu_init(sim["t_kf"], sim["R_VC"], sim["p_VC"], sim["imu_t"], sim["gyro"], sim["acc"],
                           R_IC_FORWARD, P_IC, InitOptions(**opt))


def grav_err_deg(res, sim):
    c = res.gravity_V @ sim["g_V"] / (np.linalg.norm(res.gravity_V) * np.linalg.norm(sim["g_V"]))
    return np.rad2deg(np.arccos(np.clip(c, -1, 1)))


@pytest.mark.parametrize("prior", [None, 0.05])
def test_noise_free_recovery(prior):
    """Spec 15: initialisation exact to 1e-9 without noise (prior off; with the zero-mean prior the
    b_a estimate is shrunk, so there only gravity/b_g are exact and b_a is close)."""
    sim = simulate(0)
    res = run(sim, ba_prior_sigma=prior)
    assert np.abs(res.b_g - sim["b_g"]).max() < 1e-9
    assert np.abs(res.gravity_V - sim["g_V"]).max() < 1e-9 * 9.81 or prior is not None
    if prior is None:
        assert np.abs(res.b_a - sim["b_a"]).max() < 1e-9
        assert np.abs(res.velocities - sim["v_V"]).max() < 1e-9
        assert res.rms_p < 1e-10 and res.rms_v < 1e-10
        assert abs(res.gravity_norm_linear - 9.81) < 1e-9
    else:
        # the data are much tighter than the prior (default noise density): b_a nearly exact
        assert np.abs(res.b_a - sim["b_a"]).max() < 1e-3
        assert grav_err_deg(res, sim) < 1e-2  # measured 0.0019 deg
    assert res.rms_rot < 1e-12
    # R_WV maps the estimated gravity to -g e3, and V's gravity to W's
    assert np.allclose(res.R_WV @ res.gravity_V, [0, 0, -9.81], atol=1e-12)
    assert np.allclose(res.R_WV.T @ res.R_WV, np.eye(3), atol=1e-12)


def test_b_a_linearisation_point_subtlety():
    """Spec 9.4: with b_a_lin != 0 the LS unknown is db_a; the returned bias is b_a_lin + db_a."""
    sim = simulate(0)
    res = run(sim, ba_prior_sigma=None, b_a_lin=np.array([0.3, -0.2, 0.1]))
    assert np.abs(res.b_a - sim["b_a"]).max() < 1e-9
    assert np.abs(res.gravity_V - sim["g_V"]).max() < 1e-9 * 9.81


NOISY = dict(acc_density=2.0e-3, gyro_density=1.7e-4)  # EuRoC-like MEMS densities


def test_noisy_imu_exact_poses():
    """Spec 9 table row 'noisy IMU, exact poses': 0.05 deg / 0.009 m/s^2 (mean). Our noise
    (spec gives none): acc 2e-3 (m/s^2)/sqrt(Hz), gyro 1.7e-4 rad/s/sqrt(Hz) at 200 Hz, prior on.
    Tolerance: 2x the spec numbers (0.1 deg, 0.02 m/s^2), mean over 5 seeds."""
    g_err, ba_err, bg_err = [], [], []
    for seed in range(5):
        sim = simulate(100 + seed, **NOISY)
        res = run(sim, acc_noise_density=NOISY["acc_density"])
        g_err.append(grav_err_deg(res, sim))
        ba_err.append(np.linalg.norm(res.b_a - sim["b_a"]))
        bg_err.append(np.linalg.norm(res.b_g - sim["b_g"]))
        assert 0.3 < res.rms_whitened < 3.0  # weights consistent with the simulated noise
    assert np.mean(g_err) < 0.1, g_err
    assert np.mean(ba_err) < 0.02, ba_err
    assert np.mean(bg_err) < 1e-3, bg_err


LOW_ROT = SinTraj(rot_amp=(0.01, 0.01, 0.02))  # ~0.6 deg tilt, 1.1 deg yaw excursions


def test_bias_prior_under_low_rotation():
    """Spec 9 table: poses with 2 mm / 0.05 deg noise and low rotation: without the b_a prior the
    gravity direction is lost in the bias/tilt ambiguity (spec: 5.0 deg), with it it stays near the
    ambiguity floor |b_a_perp|/g (spec: 0.55 deg). Checked: prior at least 3x better (mean over 4
    seeds) and below 1.5 deg."""
    with_p, without = [], []
    for seed in range(4):
        sim = simulate(200 + seed, traj=LOW_ROT, pos_sigma=0.002, rot_sigma_deg=0.05, **NOISY)
        kw = dict(acc_noise_density=NOISY["acc_density"], pose_pos_sigma=0.002)
        without.append(grav_err_deg(run(sim, ba_prior_sigma=None, **kw), sim))
        with_p.append(grav_err_deg(run(sim, ba_prior_sigma=0.05, **kw), sim))
    assert np.mean(with_p) < 1.5, with_p
    assert np.mean(with_p) * 3 < np.mean(without), (with_p, without)


def test_degenerate_inputs():
    sim = simulate(0, T=1.0)
    with pytest.raises(TooFewPoints):
        stereo_imu_init(sim["t_kf"][:3], sim["R_VC"][:3], sim["p_VC"][:3], sim["imu_t"], sim["gyro"], sim["acc"],
                        R_IC_FORWARD, P_IC)
    # IMU stream stops before the last keyframe -> interval not covered
    with pytest.raises(DegenerateInput):
        stereo_imu_init(sim["t_kf"], sim["R_VC"], sim["p_VC"], sim["imu_t"][:150], sim["gyro"][:150],
                        sim["acc"][:150], R_IC_FORWARD, P_IC)
    # two keyframes 2 ms apart, between two 5-ms IMU samples: no sample in that interval
    with pytest.raises(DegenerateInput):
        _gap_case(sim)
    bad = sim["acc"].copy()
    bad[10, 2] = np.nan
    with pytest.raises(NonFiniteInput):
        stereo_imu_init(sim["t_kf"], sim["R_VC"], sim["p_VC"], sim["imu_t"], sim["gyro"], bad, R_IC_FORWARD, P_IC)
    # no rotation at all and no b_a prior: gravity and b_a are not separable -> DegenerateInput
    still = simulate(0, T=1.0, traj=SinTraj(rot_amp=(0.0, 0.0, 0.0)))
    with pytest.raises(DegenerateInput):
        run(still, ba_prior_sigma=None)
    res = run(still)  # the prior makes it well posed
    assert np.isfinite(res.gravity_V).all()


def _gap_case(sim):
    """Keyframe stamps shifted off the 5-ms sample grid by 1 ms; kf 5 only 2 ms after kf 4."""
    t_kf = sim["t_kf"][:7].copy()
    t_kf[5] = t_kf[4] + 2_000_000  # 2 ms after kf 4: between two 5-ms samples
    return stereo_imu_init(t_kf + 1_000_000, sim["R_VC"][:7], sim["p_VC"][:7], sim["imu_t"], sim["gyro"],
                           sim["acc"], R_IC_FORWARD, P_IC)


def test_gravity_to_R_WV_edge_cases():
    for g in ([0, 0, -1.0], [0, 0, 1.0], [0.3, -0.2, -0.9]):
        R = gravity_to_R_WV(np.array(g) * 9.81)
        assert np.allclose(R @ (np.array(g) / np.linalg.norm(g)), [0, 0, -1], atol=1e-12)
        assert np.isclose(np.linalg.det(R), 1.0)
