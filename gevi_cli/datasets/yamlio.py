"""Reading the calibration YAML files real datasets ship.

EuRoC ``sensor.yaml`` files begin with the OpenCV directive ``%YAML:1.0``, which PyYAML rejects,
and store matrices as ``{rows, cols, data}``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from gevi_cli.errors import DataError, GeviError


def load_yaml(path: Path) -> dict:
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise GeviError(path, "no such file") from None
    lines = text.splitlines()
    if lines and lines[0].startswith("%YAML"):
        lines = lines[1:]
    try:
        data = yaml.safe_load("\n".join(lines))
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        raise DataError(where, f"is not valid YAML ({getattr(err, 'problem', err)})") from None
    if not isinstance(data, dict):
        raise DataError(path, "expected a YAML mapping")
    return data


def matrix(value, path: Path, key: str, shape=(4, 4)) -> np.ndarray:
    """A matrix from ``{rows, cols, data}`` or a nested list."""
    try:
        if isinstance(value, dict):
            M = np.asarray(value["data"], dtype=np.float64).reshape(int(value["rows"]), int(value["cols"]))
        else:
            M = np.asarray(value, dtype=np.float64)
        M = M.reshape(shape)
    except (KeyError, TypeError, ValueError):
        raise DataError(path, f"'{key}' is not a {shape[0]}x{shape[1]} matrix") from None
    if not np.isfinite(M).all():
        raise DataError(path, f"'{key}' contains non-finite values")
    if shape == (4, 4):
        R = M[:3, :3]
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-3 or np.linalg.det(R) < 0:
            raise DataError(path, f"'{key}' does not hold a rotation in its upper-left 3x3 block")
    return M


def require(data: dict, key: str, path: Path):
    if key not in data:
        raise DataError(path, f"missing key '{key}'")
    return data[key]
