"""Reading the calibration YAML files real datasets ship.

EuRoC ``sensor.yaml`` files begin with the OpenCV directive ``%YAML:1.0``, which PyYAML rejects,
and store matrices as ``{rows, cols, data}``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from gevi_cli.errors import DataError, GeviError


class _OpenCVLoader(yaml.SafeLoader):
    """Safe loading plus OpenCV FileStorage's ``!!opencv-matrix`` (ORB-SLAM3 settings, cv2 calibration
    output): read as the plain ``{rows, cols, dt, data}`` mapping that :func:`matrix` takes."""


_OpenCVLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", yaml.SafeLoader.construct_mapping)
_OpenCVLoader.add_constructor("tag:yaml.org,2002:opencv-nd-matrix", yaml.SafeLoader.construct_mapping)


def load_yaml(path: Path, *, empty_ok: bool = False, what: str = "file") -> dict:
    """A YAML mapping from ``path``; every error is one line naming the file (and the line).

    Takes what real datasets write: OpenCV's ``%YAML:1.0`` directive (PyYAML rejects it; the line is
    blanked, not dropped, so YAML's line numbers stay the file's) and ``!!opencv-matrix`` tags, a
    UTF-8 BOM, CRLF line ends.
    ``empty_ok``: an empty file is ``{}`` (configs) instead of an error.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise GeviError(path, f"no such {what}") from None
    except IsADirectoryError:
        raise GeviError(path, f"is a folder, expected a YAML {what}") from None
    except (UnicodeDecodeError, OSError) as err:
        raise DataError(path, f"cannot be read as text ({type(err).__name__})") from None
    lines = text.splitlines()
    if lines and lines[0].startswith("%YAML") and ":" in lines[0]:
        lines[0] = ""
    try:
        data = yaml.load("\n".join(lines), Loader=_OpenCVLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        problem = " ".join(str(getattr(err, "problem", None) or "syntax error").split())
        raise DataError(where, f"is not valid YAML ({problem})") from None
    if data is None and empty_ok:
        return {}
    if not isinstance(data, dict):
        raise DataError(path, "expected a YAML mapping" + (" (the file is empty)" if data is None else ""))
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
