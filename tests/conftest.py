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
