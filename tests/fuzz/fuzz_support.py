"""Shared pieces of the reader fuzz suite: hypothesis settings, trajectory strategy, error checks.

Every reader is driven with valid files written by gevi's own writers and with mutations of them;
the property is always the same: a valid read, or a :class:`~gevi_cli.errors.GeviError` whose
``where`` names the file (``file`` or ``file:line``), never another exception and never a silently
wrong number.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from gevi_cli.errors import GeviError
from gevi_cli.trajectory import Trajectory

#: Reproducible in CI (derandomize, no example database) and within the suite's time budget.
FUZZ = settings(max_examples=60, deadline=None, derandomize=True, database=None, print_blob=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

#: Offsets of real ground truth: none, local, UTM (easting, northing), ECEF (|p| ~ 6.4e6 m).
OFFSETS = (
    (0.0, 0.0, 0.0),
    (-312.5, 87.25, 3.0),
    (512_345.678, 4_512_345.678, 250.0),
    (4_205_000.0, 168_000.0, 4_778_000.0),
)


@st.composite
def trajectories(draw, min_len: int = 2, max_len: int = 200) -> Trajectory:
    """Stamps strictly increasing at a random rate, positions random-walking around a random
    offset (UTM/ECEF-like included), unit quaternions."""
    n = draw(st.integers(min_len, max_len))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    rate_hz = draw(st.sampled_from([1.0, 10.0, 20.0, 200.0, 1000.0]))
    t0 = draw(st.sampled_from([0, 5_000_000_000, 1_403_715_273_262_142_976, 1_700_000_000_123_456_789]))
    period = int(1e9 / rate_hz)
    t_ns = t0 + np.cumsum(rng.integers(period // 2, period * 3 // 2 + 1, size=n))
    speed = draw(st.sampled_from([0.0, 0.01, 1.0, 30.0]))  # m/s; 0: standing still
    offset = np.array(draw(st.sampled_from(OFFSETS)))
    steps = rng.normal(size=(n, 3)) * speed / rate_hz
    positions = offset + rng.uniform(-5, 5, size=3) + np.cumsum(steps, axis=0)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return Trajectory(t_ns, positions, q, frame="unknown")


def check_error(err: GeviError, path: Path, line: int | None = None, n_lines: int | None = None) -> None:
    """``err.where`` is ``path`` or ``path:LINE`` (LINE = ``line`` when given, within the file otherwise)."""
    assert err.where is not None, err
    assert err.where == str(path) or err.where.startswith(f"{path}:"), err.where
    rest = err.where[len(str(path)):]
    if line is not None:
        assert rest == f":{line}", f"expected {path}:{line}, got {err.one_line()}"
    elif rest:
        assert re.fullmatch(r":\d+", rest), err.where
        if n_lines is not None:
            assert 1 <= int(rest[1:]) <= max(n_lines, 1), err.one_line()
    assert "\n" not in err.one_line()
    assert err.message


def count_lines(data: bytes) -> int:
    return len(data.decode("utf-8", errors="replace").splitlines())
