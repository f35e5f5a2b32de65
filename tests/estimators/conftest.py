import numpy as np
import pytest

from gevi_cli.studies import simulation as sim


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def _central_diff(f, x, h=1e-6):
    """Central-difference Jacobian of f: R^m -> R^k at x."""
    x = np.asarray(x, dtype=float)
    f0 = np.asarray(f(x))
    J = np.empty(f0.shape + x.shape)
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = h
        J[..., i] = (np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h)
    return J


@pytest.fixture
def scene4(rng):
    return sim.scene4(rng, 150)


@pytest.fixture
def scene_fwd(rng):
    return sim.scene4(rng, 150, R_ic=sim.R_IC_FORWARD)


@pytest.fixture
def central_diff():
    return _central_diff
