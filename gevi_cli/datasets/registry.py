"""Registry of dataset readers and kind auto-detection.

A reader registers with ``@register("kind")`` and implements ``detect(path) -> bool`` (cheap: only
looks at names of files/folders) and ``__init__(path, **options)``.  Readers are tried in
``_DETECT_FIRST`` order: the more specific layouts first (pool is an EuRoC folder plus mocap0).
"""
from __future__ import annotations

import importlib
import inspect
from pathlib import Path

from gevi_cli.errors import GeviError, LayoutError

_READERS: dict[str, type] = {}
_DETECT_FIRST = ("pool", "euroc", "kitti", "rosbag")
_MODULES = ("gevi_cli.datasets.pool", "gevi_cli.datasets.euroc", "gevi_cli.datasets.kitti", "gevi_cli.datasets.rosbag")


def register(kind: str):
    def wrap(cls):
        cls.kind = kind
        _READERS[kind] = cls
        return cls

    return wrap


def _load_all():
    for module in _MODULES:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as err:
            if err.name != module:
                raise


def kinds() -> list[str]:
    _load_all()
    return list(_READERS)


def detect_kind(path: str | Path) -> str:
    """The kind of dataset at ``path``; raises :class:`LayoutError` with what was expected."""
    _load_all()
    path = Path(path)
    if not path.exists():
        raise GeviError(path, "no such file or folder")
    ordered = sorted(_READERS.items(), key=lambda item: _DETECT_FIRST.index(item[0]) if item[0] in _DETECT_FIRST else 99)
    for kind, cls in ordered:
        if cls.detect(path):
            return kind
    raise LayoutError(
        path,
        "not a recognised dataset: expected an EuRoC/pool ASL folder (mav0/cam0, mav0/cam1), a KITTI odometry "
        "sequence (image_0, image_1, calib.txt, times.txt), or a ROS1 .bag / ROS2 bag folder; see datasets/README.md",
    )


def open_sequence(path: str | Path, kind: str | None = None, **options):
    """Open the dataset at ``path`` as a :class:`~gevi_cli.datasets.sequence.Sequence`.

    ``kind`` forces a reader (see :func:`kinds`); ``options`` go to the reader (e.g.
    ``groundtruth=FILE`` overrides the ground truth, ``topics=...``/``calib=...`` for bags).
    """
    _load_all()
    if kind is None:
        kind = detect_kind(path)
    elif kind not in _READERS:
        raise GeviError("--kind", f"unknown dataset kind {kind!r}; choose one of {', '.join(_READERS)}")
    reader = _READERS[kind]
    accepted = inspect.signature(reader.__init__).parameters
    for key in options:
        if key not in accepted:
            flag = "--" + key.replace("_", "-")
            raise GeviError(flag, f"does not apply to {kind} sequences ({path})")
    return reader(Path(path), **options)


def sequence_kwargs(groundtruth=None, calib=None, topics=None, cameras=None, imu_calib=None) -> dict:
    """The readers' options (``open_sequence(path, **options)``) from the command-line values, only those
    given; a ground-truth file that does not exist is a one-line GeviError."""
    from gevi_cli.errors import GeviError

    options = {}
    if groundtruth is not None:
        import pathlib

        if not pathlib.Path(groundtruth).is_file():
            raise GeviError("--gt", f"{groundtruth}: no such file")
        options["groundtruth"] = groundtruth
    if calib is not None:
        options["calib"] = calib
    if imu_calib is not None:
        options["imu_calib"] = imu_calib
    if topics is not None:
        options["topics"] = topics
    if cameras is not None:
        options["cameras"] = cameras
    return options
