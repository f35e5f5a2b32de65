"""The one YAML loader: what real files hold is read, every error is one line with file and line."""
from __future__ import annotations

import numpy as np
import pytest

from gevi_cli.datasets.yamlio import load_yaml, matrix
from gevi_cli.errors import GeviError


def _err(path, **kw) -> str:
    with pytest.raises(GeviError) as info:
        load_yaml(path, **kw)
    line = info.value.one_line()
    assert "\n" not in line
    return line


def test_duplicate_keys_are_refused_at_their_line(tmp_path):
    p = tmp_path / "dup.yaml"
    p.write_text("cam0:\n  intrinsics: [1, 2, 3, 4]\n  resolution: [8, 6]\n  intrinsics: [5, 6, 7, 8]\n")
    assert _err(p).startswith(f"{p}:4: is not valid YAML (key 'intrinsics' given twice (first on line 2))")


def test_opencv_headers_bom_crlf_and_empty(tmp_path):
    p = tmp_path / "cv.yaml"
    p.write_bytes("\ufeff%YAML:1.0\r\n---\r\nT: !!opencv-matrix\r\n  rows: 2\r\n  cols: 2\r\n  dt: d\r\n"
                  "  data: [1, 2, 3, 4]\r\n".encode())
    np.testing.assert_array_equal(matrix(load_yaml(p)["T"], p, "T", shape=(2, 2)), [[1, 2], [3, 4]])
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    assert load_yaml(empty, empty_ok=True) == {}
    assert "expected a YAML mapping (the file is empty)" in _err(empty)
    assert "is a folder" in _err(tmp_path)


def test_matrix_entries_must_be_numbers_and_poses_rigid(tmp_path):
    p = tmp_path / "x.yaml"
    with pytest.raises(GeviError, match="holds True, not a number"):
        matrix([[True, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], p, "T")
    with pytest.raises(GeviError, match=r"last row is \[5.0, 5.0, 5.0, 1.0\]"):
        matrix([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [5, 5, 5, 1]], p, "T")
    np.testing.assert_array_equal(matrix({"rows": 4, "cols": 4, "data": np.eye(4).ravel().tolist()}, p, "T"), np.eye(4))
