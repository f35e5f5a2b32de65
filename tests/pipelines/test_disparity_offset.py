"""The disparity-offset self-calibration recovers a known offset from two-view geometry alone."""
import numpy as np
import pytest

from gevi_cli.geometry import exp_so3, make_T
from gevi_cli.pipelines.disparity_offset import MIN_OFFSET_PX, DisparityOffset, step_offset, two_view_inverse_depth

FX, BASELINE = 718.856, 0.5372  # a KITTI-like rig: px, m


def _step(rng, delta_px, noise_px=0.1, n=250, t_len=1.0):
    """Keyframe points 4-90 m ahead, a forward step of ``t_len`` m with a small turn; returns what
    DisparityOffset.observe takes: keyframe and current normalized pixels, measured disparities, T_ck."""
    Z = 1.0 / rng.uniform(1 / 90.0, 1 / 4.0, n)
    z = rng.uniform([-0.8, -0.25], [0.8, 0.25], (n, 2))
    P = np.column_stack([z * Z[:, None], Z])
    R = exp_so3(rng.normal(0, 0.01, 3))
    t = np.array([0.05, 0.01, -t_len])  # the keyframe seen from a frame t_len m further on
    X = P @ R.T + t
    q = X[:, :2] / X[:, 2:] + rng.normal(0, noise_px / FX, (n, 2))
    d = FX * BASELINE / Z - delta_px + rng.normal(0, noise_px, n)
    return z + rng.normal(0, noise_px / FX, (n, 2)), q, d, make_T(R, t)


@pytest.mark.parametrize("delta", [0.8, -0.6, 0.4])
def test_a_known_offset_is_recovered(delta):
    rng = np.random.default_rng(3)
    est = DisparityOffset()
    for k in range(10):
        est.observe(k, *_step(rng, delta))
    assert len(est.steps) == 10
    # 250 points with 0.1 px noise: each step's intercept is good to ~0.02 px; the median of 10 to better
    assert est.value == pytest.approx(delta, abs=0.05)


def test_no_offset_is_not_corrected_and_the_scale_does_not_matter():
    rng = np.random.default_rng(4)
    est = DisparityOffset()
    for k in range(10):
        est.observe(k, *_step(rng, 0.0, t_len=0.5 + 0.3 * k))  # steps of different length: a scale-free fit
    assert abs(float(np.median(est.steps))) < 0.05 < MIN_OFFSET_PX and est.value == 0.0


def test_too_few_steps_or_no_translation_give_nothing():
    rng = np.random.default_rng(5)
    est = DisparityOffset()
    for k in range(4):
        est.observe(k, *_step(rng, 0.8))
    assert est.value == 0.0  # fewer than MIN_STEPS
    z, q, d, T = _step(rng, 0.8)
    T[:3, 3] = 0.0
    est.observe(4, z, q, d, T)  # pure rotation: no depth from two views
    assert len(est.steps) == 4


def test_step_offset_is_the_intercept_of_an_exact_line():
    inv = np.linspace(0.01, 0.2, 50)
    delta, se = step_offset(inv, 386.0 * inv - 0.7)
    assert delta == pytest.approx(0.7, abs=1e-9) and se < 1e-6
    inv_d, par = two_view_inverse_depth(np.zeros((1, 2)), np.zeros((1, 2)), np.eye(3), np.array([0.0, 0.0, -1.0]))
    assert np.isnan(inv_d[0]) or par[0] == 0.0  # on the epipole: no parallax


def test_the_first_estimate_calls_for_one_restart_that_carries_the_steps():
    """The keyframes made before the offset was known lack it: the first pass asks for a restart once the
    estimate exists; the carried estimate holds the steps, is known from the first frame, skips the
    frames the first pass observed and never asks again."""
    rng = np.random.default_rng(6)
    est = DisparityOffset()
    k = 0
    while True:
        est.observe(k, *_step(rng, 0.8))
        if est.calls_for_restart:
            break
        k += 1
    assert k == 4 and len(est.steps) == 5  # the MIN_STEPS-th counted step (every step counts here)
    again = est.carried(through=k)
    assert again.value == pytest.approx(0.8, abs=0.05) and not again.calls_for_restart
    for k in range(5):
        again.observe(k, *_step(rng, 0.8))  # the restarted run re-tracks frames 0-4: already counted
    assert len(again.steps) == len(est.steps)
    again.observe(5, *_step(rng, 0.8))
    assert len(again.steps) == len(est.steps) + 1 and not again.calls_for_restart
