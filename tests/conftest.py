"""Fixtures for all tests; helpers are in support.py."""
from __future__ import annotations

from pathlib import Path

import pytest

from support import shared_path


@pytest.fixture
def euroc_micro() -> Path:
    return shared_path("euroc_micro")


@pytest.fixture
def trajectories_dir() -> Path:
    return shared_path("trajectories")


@pytest.fixture(scope="session")
def pool_render(tmp_path_factory) -> Path:
    """A small stereo-IMU pool render shared by the stereo-inertial tests (6 s, 10 Hz, 376x240,
    still start of 1.5 s, then underwater-like accelerations up to 0.5 m/s^2)."""
    from gevi_cli.simulate.generate import SimulationConfig, simulate

    cfg = SimulationConfig("pool-easy", seed=5, duration_s=6.0, rate_hz=10.0, resolution=(376, 240))
    return simulate(cfg, tmp_path_factory.mktemp("pool_render") / "pool-easy", "euroc", progress=False, workers=1)
