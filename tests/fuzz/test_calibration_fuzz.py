"""Fuzzing the calibration YAML readers: Kalibr camchain and imu.yaml, EuRoC camera sensor.yaml.

Files are written valid (gevi's Kalibr writers; a copy of EuRoC's sensor.yaml layout with random
numbers), then mutated.  A number replaced by nan/inf/text/a bool must be refused naming the file;
benign mutations (BOM, CRLF, comments, ``%YAML:1.0``) must read the written numbers exactly.
"""
from __future__ import annotations

import re
import tempfile
from pathlib import Path

import numpy as np
from fuzz_support import FUZZ, check_error, count_lines
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from gevi_cli.camera import Intrinsics
from gevi_cli.datasets.calibration import StereoRig
from gevi_cli.datasets.euroc import camera_from_sensor_yaml
from gevi_cli.datasets.kalibr import (
    read_camchain,
    read_imu_noise,
    write_camchain,
    write_imu_yaml,
)
from gevi_cli.errors import GeviError

BENIGN = ("none", "bom", "crlf", "comments", "yaml-directive")
KINDS = BENIGN + ("truncate", "bad-number", "delete-line", "duplicate-line", "empty", "garbage")
BAD_NUMBERS = (".nan", ".inf", "-.inf", "nan_x", "true", "[1, 2]", "{a: 1}", "''", "1e999")

_NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?(?![\w.])")


def _pose(rng) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(size=3) * 0.2).as_matrix()
    T[:3, 3] = rng.normal(size=3) * 0.1
    return T


def _camera(rng, model) -> Intrinsics:
    dist = {"radtan": tuple(rng.normal(size=4) * [0.2, 0.05, 1e-3, 1e-3]),
            "equidistant": tuple(rng.normal(size=4) * 0.01), "none": ()}[model]
    return Intrinsics(int(rng.integers(320, 1920)), int(rng.integers(240, 1200)), *map(float, rng.uniform(300, 900, 2)),
                      *map(float, rng.uniform(150, 500, 2)), model, tuple(map(float, dist)))


def _mutate_yaml(data, text: str, kind: str, checked_numbers: list[tuple[int, int]]):
    """(bytes, expectation).  ``checked_numbers``: spans of numbers the reader validates."""
    if kind in BENIGN:
        if kind == "comments":
            lines = text.splitlines()
            # OpenCV's %YAML:1.0 directive must stay the first line
            at = data.draw(st.integers(1 if text.startswith("%YAML") else 0, len(lines)))
            text = "\n".join(lines[:at] + ["# a comment", ""] + lines[at:]) + "\n"
        if kind == "yaml-directive" and not text.startswith("%YAML"):
            text = "%YAML:1.0\n" + text
        raw = text.replace("\n", "\r\n").encode() if kind == "crlf" else text.encode()
        return (b"\xef\xbb\xbf" + raw if kind == "bom" else raw), {"same": True}
    if kind == "truncate":
        raw = text.encode()
        return raw[:data.draw(st.integers(0, len(raw) - 1))], {}
    if kind == "bad-number":
        a, b = data.draw(st.sampled_from(checked_numbers))
        return (text[:a] + data.draw(st.sampled_from(BAD_NUMBERS)) + text[b:]).encode(), {"refused": True}
    lines = text.splitlines()
    if kind in ("delete-line", "duplicate-line"):
        r = data.draw(st.integers(0, len(lines) - 1))
        lines = lines[:r] + ([lines[r]] * 2 if kind == "duplicate-line" else []) + lines[r + 1:]
        return ("\n".join(lines) + "\n").encode(), {}
    if kind == "empty":
        return b"", {"file_error": True}
    if kind == "garbage":
        return data.draw(st.binary(min_size=1, max_size=200)), {}
    raise AssertionError(kind)


def _run(read, path: Path, raw: bytes, expect: dict, same):
    try:
        result = read()
    except GeviError as err:
        assert not expect.get("same"), f"a valid file was refused: {err.one_line()}"
        check_error(err, path, None, count_lines(raw))
        if expect.get("file_error"):
            assert err.where == str(path)
        return
    assert not expect.get("refused") and not expect.get("file_error"), f"accepted a bad file: {expect}"
    if expect.get("same"):
        same(result)


def _numbers_under(text: str, keys: tuple[str, ...]) -> list[tuple[int, int]]:
    """Spans of the numbers that belong to the given keys (a key's value runs to the next key)."""
    spans = []
    starts = [(m.start(), m.group(1)) for m in re.finditer(r"^\s*([A-Za-z_]\w*):", text, flags=re.MULTILINE)]
    for i, (start, key) in enumerate(starts):
        if key not in keys:
            continue
        end = starts[i + 1][0] if i + 1 < len(starts) else len(text)
        line_end = text.index(":", start) + 1
        spans += [m.span() for m in _NUMBER.finditer(text, line_end, end)]
    return spans


# ------------------------------------------------------------------------------- Kalibr camchain
@settings(FUZZ, max_examples=180)
@given(seed=st.integers(0, 2**32 - 1), model=st.sampled_from(["radtan", "equidistant", "none"]),
       kind=st.sampled_from(KINDS), data=st.data())
def test_kalibr_camchain(seed, model, kind, data):
    rng = np.random.default_rng(seed)
    T_B_C0 = _pose(rng)
    T_C0_C1 = np.eye(4)
    T_C0_C1[:3, 3] = [rng.uniform(0.05, 0.6), 0, 0]
    rig = StereoRig(_camera(rng, model), _camera(rng, model), T_B_C0, T_B_C0 @ T_C0_C1)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "camchain.yaml"
        write_camchain(path, rig, {"left": "/cam0/image_raw", "right": "/cam1/image_raw"})
        text = path.read_text()
        checked = _numbers_under(text, ("T_cam_imu", "intrinsics", "resolution", "distortion_coeffs",
                                        "T_cn_cnm1", "timeshift_cam_imu"))
        raw, expect = _mutate_yaml(data, text, kind, checked)
        path.write_bytes(raw)

        def same(chain):
            assert (chain.rig.cam0, chain.rig.cam1) == (rig.cam0, rig.cam1)  # intrinsics, resolution, distortion exactly
            np.testing.assert_allclose(chain.rig.T_B_C0, rig.T_B_C0, atol=1e-12)
            np.testing.assert_allclose(chain.rig.T_B_C1, rig.T_B_C1, atol=1e-12)
            assert chain.topics == {"left": "/cam0/image_raw", "right": "/cam1/image_raw"}
            assert chain.time_shift_s == 0.0

        _run(lambda: read_camchain(path), path, raw, expect, same)


# ------------------------------------------------------------------------------- Kalibr imu.yaml
@settings(FUZZ, max_examples=180)
@given(noise=st.lists(st.floats(1e-7, 1.0), min_size=4, max_size=4), kind=st.sampled_from(KINDS), data=st.data())
def test_kalibr_imu_yaml(noise, kind, data):
    names = ("gyro_noise_density", "gyro_random_walk", "acc_noise_density", "acc_random_walk")
    want = dict(zip(names, noise))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "imu.yaml"
        write_imu_yaml(path, **want, update_rate=200.0)
        text = path.read_text()
        checked = _numbers_under(text, ("accelerometer_noise_density", "accelerometer_random_walk",
                                        "gyroscope_noise_density", "gyroscope_random_walk"))
        raw, expect = _mutate_yaml(data, text, kind, checked)
        path.write_bytes(raw)
        _run(lambda: read_imu_noise(path), path, raw, expect, lambda got: (got == want) or _fail(got, want))


def _fail(got, want):
    raise AssertionError(f"{got} != {want}")


# ------------------------------------------------------------------------------- EuRoC sensor.yaml
SENSOR_YAML = """%YAML:1.0
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [{T0}, {T1}, {T2}, {T3},
         {T4}, {T5}, {T6}, {T7},
         {T8}, {T9}, {T10}, {T11},
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [{w}, {h}]
camera_model: pinhole
intrinsics: [{fu}, {fv}, {cu}, {cv}] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [{k1}, {k2}, {p1}, {p2}]
"""


@settings(FUZZ, max_examples=180)
@given(seed=st.integers(0, 2**32 - 1), kind=st.sampled_from(KINDS), data=st.data())
def test_euroc_sensor_yaml(seed, kind, data):
    rng = np.random.default_rng(seed)
    cam, T_B_C = _camera(rng, "radtan"), _pose(rng)
    fields = {f"T{i}": repr(float(v)) for i, v in enumerate(T_B_C[:3].ravel())}
    fields.update(w=cam.width, h=cam.height, **{k: repr(float(v)) for k, v in zip(
        ("fu", "fv", "cu", "cv", "k1", "k2", "p1", "p2"), (cam.fx, cam.fy, cam.cx, cam.cy, *cam.distortion))})
    text = SENSOR_YAML.format(**fields)
    data_start = text.index("data:")
    checked = [s for s in _numbers_under(text, ("resolution", "intrinsics", "distortion_coefficients"))]
    checked += [m.span() for m in _NUMBER.finditer(text, data_start + 5, text.index("# Camera"))]
    raw, expect = _mutate_yaml(data, text, kind, checked)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sensor.yaml"
        path.write_bytes(raw)

        def same(got):
            assert got[0] == cam
            np.testing.assert_array_equal(got[1], T_B_C)

        _run(lambda: camera_from_sensor_yaml(path), path, raw, expect, same)
