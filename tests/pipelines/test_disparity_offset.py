"""The disparity-offset self-calibration: each step's fit recovers a known offset whatever pose it starts
from, the estimate is one value fixed when found, found only with evidence, and restarts only early."""
import numpy as np
import pytest

from gevi_cli.geometry import exp_so3, make_T
from gevi_cli.pipelines import disparity_offset as mod
from gevi_cli.pipelines.disparity_offset import DisparityOffset, OffsetEstimate, Step, step_offset

FX, BASELINE = 718.856, 0.5372  # a KITTI-like rig: px, m


def _step(rng, delta_px, noise_px=0.1, n=250, t_len=1.0):
    """Keyframe points 4-90 m ahead, a forward step of ``t_len`` m with a small turn: keyframe and current
    normalized pixels, measured disparities (``delta_px`` short) and the true ``T_ck``."""
    Z = 1.0 / rng.uniform(1 / 90.0, 1 / 4.0, n)
    z = rng.uniform([-0.8, -0.25], [0.8, 0.25], (n, 2))
    P = np.column_stack([z * Z[:, None], Z])
    R = exp_so3(rng.normal(0, 0.01, 3))
    t = np.array([0.05, 0.01, -t_len])  # the keyframe seen from a frame t_len m further on
    X = P @ R.T + t
    q = X[:, :2] / X[:, 2:] + rng.normal(0, noise_px / FX, (n, 2))
    d = FX * BASELINE / Z - delta_px + rng.normal(0, noise_px, n)
    return z + rng.normal(0, noise_px / FX, (n, 2)), q, d, make_T(R, t)


def _leaning(T, rng):
    """The pose as a stereo tracker with the wrong depths would give it: turned and stretched."""
    return make_T(exp_so3(rng.normal(0, 0.003, 3)) @ T[:3, :3], T[:3, 3] * 1.05)


def test_an_exact_step_gives_its_offset_from_a_leaning_start():
    rng = np.random.default_rng(1)
    z, q, d, T = _step(rng, 0.7, noise_px=0.0)
    delta, se = step_offset(z, q, d, _leaning(T, rng), FX, BASELINE, iterations=20)
    assert delta == pytest.approx(0.7, abs=1e-6) and se < 1e-6


@pytest.mark.parametrize("delta", [0.8, -0.6, 0.3, 0.0])
def test_a_noisy_step_is_within_its_standard_error(delta):
    """0.1 px noise on 250 points: the fit's stated standard error holds over 40 steps (|z| < 3 for all, the
    mean error within 3 standard errors of the mean), from the leaning start."""
    rng = np.random.default_rng(2)
    err, ses = [], []
    for _ in range(40):
        z, q, d, T = _step(rng, delta)
        got, se = step_offset(z, q, d, _leaning(T, rng), FX, BASELINE)
        err.append(got - delta)
        ses.append(se)
    err, ses = np.array(err), np.array(ses)
    assert np.all(ses < mod.MAX_STEP_SE_PX) and np.all(np.abs(err) < 4 * ses)
    assert abs(err.mean()) < 3 * np.sqrt(np.mean(ses**2) / len(err))


def test_a_pure_rotation_says_nothing_and_does_not_count():
    rng = np.random.default_rng(3)
    z, q, d, T = _step(rng, 0.8)
    T[:3, 3] = 0.0
    q = (np.column_stack([z, np.ones(len(z))]) @ T[:3, :3].T)
    q = q[:, :2] / q[:, 2:]
    est = DisparityOffset()
    est.observe(1, 0, z, q, d, T, FX, BASELINE)
    assert est.steps == []


def _steps(values, first_kf=0):
    """One counted step per keyframe, at frames first_kf + 1, ..."""
    return [Step(first_kf + k + 1, first_kf + k, float(v), 0.05) for k, v in enumerate(values)]


def test_the_offset_is_found_once_at_min_keyframes_and_then_fixed():
    """0.8 px read on every keyframe: found at the MIN_KEYFRAMES-th; what comes after is a diagnostic that
    never moves the applied value (one calibration per run)."""
    est = DisparityOffset()
    for i, s in enumerate(_steps([0.8] * 12)):
        est.keyframe_made(s.keyframe, est.value)
        est.add(s)
        if i + 1 < mod.MIN_KEYFRAMES:
            assert est.value == 0.0 and est.found is None
        elif i + 1 == mod.MIN_KEYFRAMES:
            assert est.value == 0.8 and est.calls_for_restart and est.found_at_frame == s.index
    assert len(est.steps) == mod.MIN_KEYFRAMES and len(est.diagnostic) == 12 - mod.MIN_KEYFRAMES
    est.add(Step(99, 98, 1.5, 0.05))
    assert est.value == 0.8
    again = est.carried()
    assert again.value == 0.8 and again.found == est.found and not again.calls_for_restart
    again.add(Step(1, 0, 1.5, 0.05))
    assert again.value == 0.8 and len(again.diagnostic) == 1 and again.steps == est.steps
    again.keyframe_made(0, again.value)
    rec = again.record()
    assert rec["applied_px"] == rec["estimate_px"] == 0.8 and rec["restarted"] and rec["applied_from_frame"] == 0
    assert rec["diagnostic_px"] == 1.5 and rec["diagnostic_steps"] == 1


def test_a_small_scattered_offset_is_not_evidence():
    """Keyframes scattered 0.14 px around 0.12 px (KITTI 06's steps): 0.12 is within three total sigmas of
    zero, so nothing is applied however long the run; the estimate is still recorded."""
    rng = np.random.default_rng(4)
    est = DisparityOffset()
    for s in _steps(0.12 + 0.14 * rng.standard_normal(40)):
        est.add(s)
    assert est.found is None and est.value == 0.0
    rec = est.record()
    e = OffsetEstimate.of(est.steps)
    assert rec["estimate_px"] == e.value_px and abs(e.value_px) < mod.EVIDENCE_SIGMAS * e.total_sigma_px
    assert rec["sigma_px"] > 0 and rec["keyframes"] == 40 and rec["applied_px"] == 0.0


def test_steps_against_one_keyframe_count_once():
    """Ten steps against the same keyframe share its disparities: one keyframe's worth of evidence."""
    est = DisparityOffset()
    for i in range(10):
        est.add(Step(i + 1, 0, 0.8, 0.05))
    assert est.found is None and OffsetEstimate.of(est.steps).keyframes == 1


def test_found_late_it_applies_from_the_next_keyframe_without_a_restart():
    est = DisparityOffset()
    for k in range(mod.RESTART_MAX_KEYFRAMES + 1):
        est.keyframe_made(k, est.value)
    for s in _steps([0.8] * mod.MIN_KEYFRAMES, first_kf=30):
        est.add(s)
    assert est.value == 0.8 and not est.calls_for_restart
    est.keyframe_made(40, est.value)
    rec = est.record()
    assert rec["applied_from_frame"] == 40 and not rec["restarted"] and rec["found_at_frame"] == 35


def test_no_steps_record_no_estimate():
    rec = DisparityOffset().record()
    assert rec["estimate_px"] is None and rec["applied_px"] == 0.0 and rec["steps"] == 0
