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


def _mapping_without_duplicates(loader, node, deep=False):
    # PyYAML keeps the last of two equal keys silently: a calibration edited twice must say so
    seen = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=True)
        if key in seen:
            raise yaml.constructor.ConstructorError(None, None, f"key '{key}' given twice (first on line "
                                                    f"{seen[key] + 1})", key_node.start_mark)
        seen[key] = key_node.start_mark.line
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_OpenCVLoader.add_constructor("tag:yaml.org,2002:map", _mapping_without_duplicates)
_OpenCVLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", yaml.SafeLoader.construct_mapping)
_OpenCVLoader.add_constructor("tag:yaml.org,2002:opencv-nd-matrix", yaml.SafeLoader.construct_mapping)


YamlLoader = _OpenCVLoader  # for readers that need YAML's nodes (line numbers): yaml.compose(text, Loader=YamlLoader)


def yaml_text(path: Path, what: str = "file") -> str:
    """The text of a YAML file as :func:`load_yaml` parses it (BOM dropped, ``%YAML:1.0`` line blanked)."""
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
    return "\n".join(lines)


def yaml_error(path: Path, err: Exception) -> DataError:
    """A PyYAML error as one line with the file and the line."""
    mark = getattr(err, "problem_mark", None)
    where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
    problem = " ".join(str(getattr(err, "problem", None) or "syntax error").split())
    return DataError(where, f"is not valid YAML ({problem})")


def load_yaml(path: Path, *, empty_ok: bool = False, what: str = "file") -> dict:
    """A YAML mapping from ``path``; every error is one line naming the file (and the line).

    Takes what real datasets write: OpenCV's ``%YAML:1.0`` directive (PyYAML rejects it; the line is
    blanked, not dropped, so YAML's line numbers stay the file's) and ``!!opencv-matrix`` tags, a
    UTF-8 BOM, CRLF line ends.  Duplicate keys are refused at their line.
    ``empty_ok``: an empty file is ``{}`` (configs) instead of an error.
    """
    path = Path(path)
    text = yaml_text(path, what)
    try:
        data = yaml.load(text, Loader=YamlLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as err:
        raise yaml_error(path, err) from None
    if data is None and empty_ok:
        return {}
    if not isinstance(data, dict):
        raise DataError(path, "expected a YAML mapping" + (" (the file is empty)" if data is None else ""))
    return data


def matrix(value, path: Path, key: str, shape=(4, 4)) -> np.ndarray:
    """A matrix from ``{rows, cols, data}`` (OpenCV) or a nested list.

    Every entry must be a number (a YAML ``true`` would otherwise read as 1.0) and finite; a 4x4 must
    be a rigid transform: a rotation in its upper-left block and a last row ``0 0 0 1`` (anything else
    would be silently ignored by the inversion).
    """
    entries = value.get("data") if isinstance(value, dict) else value
    stack = [entries]
    while stack:
        item = stack.pop()
        if isinstance(item, np.ndarray):
            stack.extend(item.tolist())
        elif isinstance(item, (list, tuple)):
            stack.extend(item)
        elif isinstance(item, bool) or (item is not None and not isinstance(item, (int, float, str))):
            raise DataError(path, f"'{key}' holds {item!r}, not a number")
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
        if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
            raise DataError(path, f"'{key}' is not a rigid transform: its last row is {M[3].tolist()}, not [0, 0, 0, 1]")
    return M


def require(data: dict, key: str, path: Path):
    if key not in data:
        raise DataError(path, f"missing key '{key}'")
    return data[key]
