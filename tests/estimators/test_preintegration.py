"""Preintegration (spec 9.2): accuracy on an analytic trajectory, bias Jacobians, batching.

The analytic trajectory (closed-form body rate and specific force) is ``simulation.SinTraj``.
"""

import numpy as np
import pytest

from gevi_cli.estimators import DegenerateInput, NonFiniteInput
from gevi_cli.estimators.preintegration import (
    imu_segment,
    integrate_increments,
    preintegrate,
    preintegrate_batch,
    preintegrate_reference,
)
from gevi_cli.geometry import exp_so3, log_so3
from gevi_cli.studies.simulation import G_W, SinTraj


def _relative_truth(tr, t0, t1):
    R0, R1 = tr.R(t0)[0], tr.R(t1)[0]
    v0, v1 = tr.pos(t0, 1)[0], tr.pos(t1, 1)[0]
    p0, p1 = tr.pos(t0)[0], tr.pos(t1)[0]
    T = t1 - t0
    return R0.T @ R1, R0.T @ (v1 - v0 - G_W * T), R0.T @ (p1 - p0 - v0 * T - 0.5 * G_W * T**2)


def _errors(tr, t0, T, rate):
    m = int(round(T * rate))
    ts = t0 + np.arange(m) / rate
    pi = preintegrate(tr.omega(ts), tr.specific_force(ts), np.full(m, 1.0 / rate))
    dR, dv, dp = _relative_truth(tr, t0, t0 + T)
    return (np.linalg.norm(log_so3(dR.T @ pi.dR)), np.linalg.norm(pi.dv - dv), np.linalg.norm(pi.dp - dp))


def _error_bounds(tr, t0, T, dt):
    """First-order (left-rectangle / ZOH) error bounds derived in the test docstring."""
    s = np.linspace(t0, t0 + T, 4001)
    h = 1e-5
    w, a = tr.omega(s), tr.specific_force(s)
    wdot = (tr.omega(s + h) - tr.omega(s - h)) / (2 * h)
    adot = (tr.specific_force(s + h) - tr.specific_force(s - h)) / (2 * h)
    W1 = np.linalg.norm(wdot, axis=1).max()
    F1 = np.linalg.norm(np.cross(w, a) + adot, axis=1).max()
    A0 = np.linalg.norm(a, axis=1).max()
    return (0.5 * W1 * T * dt, dt * (0.5 * T * F1 + 0.25 * T**2 * W1 * A0),
            dt * (0.25 * T**2 * F1 + T**3 * W1 * A0 / 12.0))


def test_analytic_trajectory_first_order_accuracy():
    """Zero-noise samples of a closed-form trajectory, 200 Hz, 0.5 s interval.

    The spec-9.2 scheme holds each sample over its period (left rectangle rule), so it is first
    order. With W1 = max|w'|, A0 = max|a|, F1 = max|w x a + a'| over the interval:
      rotation  |Log(dR_true^T dR)| <= 1/2 W1 T dt,
      velocity  |dv - dv_true| <= dt (1/2 T F1 + 1/4 T^2 W1 A0),
      position  |dp - dp_true| <= dt (1/4 T^2 F1 + 1/12 T^3 W1 A0)
    (per step the local error of a held sample is <= 1/2 |f'| dt^2; the rotation error feeds the
    velocity through |dR error| |a|; position integrates the velocity error; the position update
    itself is exact for held samples). Checked: each error below its bound (+10 % for the O(dt^2)
    terms), and halving dt halves the error (order 1).
    """
    tr = SinTraj()
    T, t0 = 0.5, 0.37
    e200 = _errors(tr, t0, T, 200)
    e400 = _errors(tr, t0, T, 400)
    bounds = _error_bounds(tr, t0, T, 1 / 200)
    for e, b in zip(e200, bounds):
        assert e <= 1.1 * b, (e200, bounds)
    ratios = np.array(e200) / np.array(e400)
    assert np.all((ratios > 1.8) & (ratios < 2.2)), ratios
    # absolute level at 200 Hz for this trajectory (documentation of the numbers)
    assert e200[0] < 2e-3 and e200[1] < 2e-2 and e200[2] < 5e-3


def test_vectorised_equals_literal_recursion_and_batch():
    rng = np.random.default_rng(3)
    m = 40
    w = rng.normal(size=(m, 3))
    a = rng.normal(size=(m, 3)) + [0, 0, 9.81]
    d = rng.uniform(0.004, 0.006, m)
    bg, ba = rng.normal(size=3) * 0.05, rng.normal(size=3) * 0.1
    p = preintegrate(w, a, d, bg, ba)
    r = preintegrate_reference(w, a, d, bg, ba)
    for k in ("dR", "dv", "dp", "J_R_g", "J_v_g", "J_v_a", "J_p_g", "J_p_a"):
        assert np.allclose(getattr(p, k), getattr(r, k), rtol=0, atol=1e-13), k
    batch = preintegrate_batch([(w, a, d), (w[:7], a[:7], d[:7]), (w[5:], a[5:], d[5:])], bg, ba)
    for q, (lo, hi) in zip(batch, [(0, m), (0, 7), (5, m)]):
        s = preintegrate(w[lo:hi], a[lo:hi], d[lo:hi], bg, ba)
        for k in ("dR", "dv", "dp", "J_R_g", "J_v_g", "J_p_g", "J_p_a"):
            assert np.allclose(getattr(q, k), getattr(s, k), rtol=0, atol=1e-14), k
        assert q.dt == pytest.approx(s.dt)


def test_increments_without_jacobians_are_preintegrations_numbers():
    """integrate_increments skips only the Jacobians: dt, dR, dv, dp are the very same floats."""
    rng = np.random.default_rng(4)
    w, a = rng.normal(size=(12, 3)), rng.normal(size=(12, 3)) + [0, 0, 9.81]
    d = rng.uniform(0.004, 0.006, 12)
    d[3] = 0.0  # a zero hold time as imu_segment produces at an interval's end
    bg, ba = rng.normal(size=3) * 0.05, rng.normal(size=3) * 0.1
    p, q = preintegrate(w, a, d, bg, ba), integrate_increments(w, a, d, bg, ba)
    assert q.dt == p.dt
    for k in ("dR", "dv", "dp"):
        assert np.array_equal(getattr(q, k), getattr(p, k)), k
    with pytest.raises(DegenerateInput):
        integrate_increments(w[:0], a[:0], d[:0])


def test_bias_jacobians_vs_central_differences():
    """All five Jacobians vs central differences of re-integration, 40 samples at 200 Hz,
    non-zero linearisation point. Tolerance 1e-6 relative (observed ~1e-9)."""
    tr = SinTraj()
    ts = 0.2 + np.arange(40) / 200
    w, a, d = tr.omega(ts), tr.specific_force(ts), np.full(40, 1 / 200)
    bg, ba = np.array([0.01, -0.02, 0.015]), np.array([0.1, -0.05, 0.08])
    p0 = preintegrate(w, a, d, bg, ba)
    h = 1e-4
    JRg, Jvg, Jpg, Jva, Jpa = (np.zeros((3, 3)) for _ in range(5))
    for i in range(3):
        e = np.zeros(3)
        e[i] = h
        gp, gm = preintegrate(w, a, d, bg + e, ba), preintegrate(w, a, d, bg - e, ba)
        JRg[:, i] = (log_so3(p0.dR.T @ gp.dR) - log_so3(p0.dR.T @ gm.dR)) / (2 * h)
        Jvg[:, i] = (gp.dv - gm.dv) / (2 * h)
        Jpg[:, i] = (gp.dp - gm.dp) / (2 * h)
        ap, am = preintegrate(w, a, d, bg, ba + e), preintegrate(w, a, d, bg, ba - e)
        Jva[:, i] = (ap.dv - am.dv) / (2 * h)
        Jpa[:, i] = (ap.dp - am.dp) / (2 * h)
    for name, fd in (("J_R_g", JRg), ("J_v_g", Jvg), ("J_p_g", Jpg), ("J_v_a", Jva), ("J_p_a", Jpa)):
        J = getattr(p0, name)
        assert np.abs(J - fd).max() <= 1e-6 * np.abs(J).max(), name


def test_predict_first_order_and_reintegrate():
    tr = SinTraj()
    ts = np.arange(20) / 200
    w, a, d = tr.omega(ts), tr.specific_force(ts), np.full(20, 1 / 200)
    p0 = preintegrate(w, a, d)
    db_g, db_a = np.array([1e-3, -2e-3, 5e-4]), np.array([0.02, 0.01, -0.03])
    exact = p0.reintegrate(db_g, db_a)
    dR, dv, dp = p0.predict(db_g, db_a)
    # second-order remainder: dominated by the b_g x b_a cross term ~ T^2/2 |db_a| |db_g| ~ 4e-7
    assert np.linalg.norm(log_so3(dR.T @ exact.dR)) < 1e-8
    assert np.abs(dv - exact.dv).max() < 1e-6 and np.abs(dp - exact.dp).max() < 1e-7
    dR, dv, dp = p0.predict(None, db_a)
    exact_a = p0.reintegrate(np.zeros(3), db_a)
    assert np.allclose(dv, exact_a.dv, atol=1e-14) and np.allclose(dp, exact_a.dp, atol=1e-14)


def test_imu_segment_and_errors():
    t = np.arange(0, 100) * 5_000_000
    g = np.arange(300, dtype=float).reshape(100, 3)
    gs, _, dts = imu_segment(t, g, g, 12_000_000, 52_000_000)
    assert dts.sum() == pytest.approx(0.040)
    assert gs[0, 0] == g[2, 0] and gs[-1, 0] == g[10, 0]
    assert dts[0] == pytest.approx(0.003) and dts[-1] == pytest.approx(0.002)
    with pytest.raises(DegenerateInput):
        imu_segment(t, g, g, -1, 10_000_000)  # not covered
    with pytest.raises(DegenerateInput):
        imu_segment(t, g, g, 10_000_000, 10_000_000)
    with pytest.raises(DegenerateInput):
        imu_segment(t, g, g, 11_000_000, 12_000_000)  # no sample inside
    with pytest.raises(DegenerateInput):
        preintegrate(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    bad = np.zeros((3, 3))
    bad[1, 1] = np.nan
    with pytest.raises(NonFiniteInput):
        preintegrate(bad, np.zeros((3, 3)), np.full(3, 0.005))
    assert np.allclose(preintegrate(np.zeros((2, 3)), np.zeros((2, 3)), np.full(2, 0.005)).dR, np.eye(3))
    assert np.allclose(exp_so3(np.zeros(3)), np.eye(3))
