"""RecentMotion: velocity and acceleration of the body from its recent visually tracked positions."""
import numpy as np
import pytest

from gevi_cli.pipelines.recent_motion import RecentMotion

PERIOD_NS = 50_000_000  # 20 Hz


def feed(motion: RecentMotion, p_of_t, n: int, noise: float = 0.0, seed: int = 0):
    rng = np.random.default_rng(seed)
    for k in range(n):
        t = k * PERIOD_NS
        motion.add(t, p_of_t(t * 1e-9) + noise * rng.standard_normal(3))
    return (n - 1) * PERIOD_NS


A = np.array([0.3, -0.2, 0.05])  # m/s^2
J = np.array([0.4, 0.1, -0.2])  # m/s^3
V0 = np.array([0.1, 0.2, 0.0])


def cubic(t):
    return V0 * t + 0.5 * A * t**2 + J * t**3 / 6


@pytest.mark.parametrize("order", [0, 3])
def test_noise_free_cubic_gives_the_exact_acceleration_at_the_frame(order):
    m = RecentMotion(0.4, order)
    t_last = feed(m, cubic, 30)
    t_next = t_last + PERIOD_NS  # the frame being tracked: extrapolated from the past window
    for t in (t_next, t_last - 4 * PERIOD_NS):  # and a window frame re-read with later frames known
        np.testing.assert_allclose(m.acceleration(t), A + J * t * 1e-9, atol=1e-7)


def test_degree_two_lags_by_half_the_window():
    """Degree 2 over a window ending at t gives the window's mean acceleration, a(t - W/2) for a cubic."""
    m = RecentMotion(0.4, 2)
    t_last = feed(m, cubic, 30)
    t = t_last + PERIOD_NS
    tau = (np.arange(t_last - 400_000_000, t_last + 1, PERIOD_NS)) * 1e-9
    got = m.acceleration(t)
    np.testing.assert_allclose(got, A + J * tau.mean(), atol=5e-3)
    assert np.linalg.norm(got - (A + J * t * 1e-9)) > 0.05  # the lag is real: 0.2+ s of jerk


def test_velocity_of_uniform_motion():
    m = RecentMotion(0.4)
    feed(m, lambda t: V0 * t + 1.0, 15)
    np.testing.assert_allclose(m.velocity(), V0, atol=1e-9)


def test_noise_is_shrunk_not_passed_on():
    """A platform at rest seen with 2 mm position noise per frame (a turbid floor): the raw second
    derivative of a 0.4 s cubic fit has a std of several m/s^2 * 0.1; the shrunk estimate stays far below."""
    m = RecentMotion(0.4, 0)
    t_last = feed(m, lambda t: np.zeros(3), 200, noise=2e-3)
    est = [m.acceleration(t_last - k * PERIOD_NS + PERIOD_NS) for k in range(40)]
    rms = np.sqrt(np.mean(np.square(est)))
    # theory: var(a3) = 4 sigma^2 [(V^T V)^-1]_22 over the window's frames (the 8 before the frame)
    tau = np.arange(-8, 0) * PERIOD_NS * 1e-9
    V = np.vander(tau, 4, increasing=True)
    raw_std = 2 * 2e-3 * np.sqrt(np.linalg.inv(V.T @ V)[2, 2])
    assert raw_std > 0.2
    assert rms < 0.25 * raw_std


def test_too_short_a_history_or_a_reset_gives_zero():
    m = RecentMotion(0.4)
    feed(m, cubic, 5)
    assert np.all(m.acceleration(5 * PERIOD_NS) == 0)
    feed(m, cubic, 30)
    assert np.any(m.acceleration(30 * PERIOD_NS) != 0)
    m.reset()
    assert m.velocity() is None and np.all(m.acceleration(30 * PERIOD_NS) == 0)
    assert np.all(RecentMotion(0.0).acceleration(0) == 0)  # acc_window_s = 0: the paper's model
