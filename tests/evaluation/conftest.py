"""Fixtures for the evaluation tests; helpers are in eval_support.py."""
from __future__ import annotations

from pathlib import Path

import pytest
from eval_support import TRAJ


@pytest.fixture
def traj_data() -> Path:
    if not TRAJ.is_dir():
        pytest.skip(f"reference trajectories not found: {TRAJ} (the shared data folder next to the repo)")
    return TRAJ
