"""Fuzzing the bag readers: truncated and corrupted bags end in a read or a one-line GeviError.

Property (hypothesis, derandomized so CI is reproducible): for a small stereo-IMU bag in each
container (ROS1 .bag, ROS2 mcap, ROS2 sqlite3), cut at any byte or with bytes overwritten, opening it
(`open_sequence`), describing it (`inventory`), reading its IMU (`BagImu`) and streaming its frames
either succeed or raise :class:`GeviError` naming the bag, in one line: never another exception.  A
successful read of a truncated bag holds no more than was written, with the stamps written.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_rosbag import BagBuilder, _tiny_camchain

from gevi_cli.datasets import open_sequence
from gevi_cli.datasets.bag_imu import BagImu
from gevi_cli.datasets.bag_inventory import inventory
from gevi_cli.errors import GeviError

STAMPS = 2_000_000_000 + np.arange(4) * 50_000_000


def _write(folder: Path, kind: str) -> Path:
    b = BagBuilder(ros2=kind != "ros1")
    img = (np.arange(48, dtype=np.uint8).reshape(6, 8) * 5)
    for t in STAMPS:
        b.image("/cam0/image_raw", int(t), img)
        b.image("/cam1/image_raw", int(t), img[:, ::-1].copy())
        for j in range(5):
            b.imu("/imu0", int(t) + j * 10_000_000, (1e-3, -2e-3, 5e-4), (0.1, 0.0, 9.81))
        b.pose("/groundtruth/pose", "geometry_msgs/msg/PoseStamped", int(t), (float(t) * 1e-9, 0, 0), (1, 0, 0, 0))
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / ("b.bag" if kind == "ros1" else "b")
    b.write(path, storage="mcap" if kind == "mcap" else "sqlite3")
    _tiny_camchain(folder / "camchain.yaml")
    return path


@pytest.fixture(scope="module")
def originals(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzzbags")
    out = {}
    for kind in ("ros1", "mcap", "db3"):
        path = _write(root / kind, kind)
        file = path if path.is_file() else next(p for p in path.iterdir() if p.suffix in (".mcap", ".db3"))
        out[kind] = (path, file.relative_to(path) if path.is_dir() else None, file.read_bytes())
    return out


def _exercise(path: Path) -> None:
    try:
        seq = open_sequence(path)
    except GeviError as err:
        assert "\n" not in err.one_line() and err.where
        seq = None
    if seq is not None:
        assert len(seq) <= len(STAMPS)
        assert set(seq.stamps_ns.tolist()) <= set(STAMPS.tolist())
        try:
            for frame in seq.frames():
                assert frame.left.shape == (6, 8)
        except GeviError as err:
            assert "\n" not in err.one_line()
    for reader in (inventory, BagImu):
        try:
            reader(path)
        except GeviError as err:
            assert "\n" not in err.one_line() and err.where


def _mutated(originals, kind: str, data: bytes):
    path, inner, _ = originals[kind]
    tmp = Path(tempfile.mkdtemp(prefix="fuzzbag"))
    target = tmp / path.name
    if inner is None:
        target.write_bytes(data)
    else:
        target.mkdir()
        for p in path.iterdir():
            (target / p.name).write_bytes(p.read_bytes())
        (target / inner).write_bytes(data)
    (tmp / "camchain.yaml").write_bytes((path.parent / "camchain.yaml").read_bytes())
    return target


# GEVI_FUZZ_EXAMPLES=300 for a longer hunt (300 each: 25 s, nothing found at commit time)
FUZZ = settings(max_examples=int(os.environ.get("GEVI_FUZZ_EXAMPLES", 12)), deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(kind=st.sampled_from(["ros1", "mcap", "db3"]), cut=st.floats(0.0, 1.0))
def test_truncated_bags(originals, kind, cut):
    data = originals[kind][2]
    _exercise(_mutated(originals, kind, data[: int(cut * len(data))]))


@FUZZ
@given(kind=st.sampled_from(["ros1", "mcap", "db3"]), where=st.lists(st.floats(0.0, 0.999), min_size=1, max_size=8),
       junk=st.binary(min_size=1, max_size=16))
def test_overwritten_bytes(originals, kind, where, junk):
    data = bytearray(originals[kind][2])
    for w in where:
        i = int(w * len(data))
        data[i:i + len(junk)] = junk[: len(data) - i]
    _exercise(_mutated(originals, kind, bytes(data)))


def test_the_unmutated_bags_read_back_exactly(originals):
    for kind, (path, _, _) in originals.items():
        seq = open_sequence(path)
        np.testing.assert_array_equal(seq.stamps_ns, STAMPS)
        assert len(seq.imu) == 20 and len(seq.groundtruth) == 4
        np.testing.assert_allclose(seq.groundtruth.positions[:, 0], STAMPS * 1e-9)
