"""Opening ROS bags as real recorders and tools leave them, and the low-level pieces every bag reader shares.

Accepted (read with :class:`rosbags.highlevel.AnyReader`, no ROS install):

* a ROS1 ``.bag`` file (any chunk compression rosbags reads: none, bz2, lz4);
* a ROS2 bag folder (``metadata.yaml`` + ``.db3``/``.mcap``; the old Dashing layout whose file paths
  repeat the folder name included), or that folder's ``metadata.yaml`` or storage file;
* a lone ``.mcap`` or ``.db3`` file without ``metadata.yaml`` (shared like that all the time), and a
  folder holding exactly one such file and nothing that makes it another dataset.

Message types come from the definitions stored in the bag, else from the ROS2 Humble (ROS1: Noetic)
type store.  Every failure to open is one line naming the file.
"""
from __future__ import annotations

import struct
from pathlib import Path

from gevi_cli.errors import DataError, GeviError

STORAGE_SUFFIXES = (".db3", ".mcap")


def _lone_storage_in(folder: Path) -> Path | None:
    """The one ``.db3``/``.mcap`` file of a folder without ``metadata.yaml`` (else None)."""
    if not folder.is_dir() or (folder / "metadata.yaml").is_file():
        return None
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix in STORAGE_SUFFIXES]
    return files[0] if len(files) == 1 else None


def bag_root(path: Path) -> Path:
    """What to hand the reader for ``path``: the ``.bag`` file, the ROS2 folder (for its ``metadata.yaml``
    or storage file), or the lone storage file (given itself, or a folder holding only it)."""
    path = Path(path)
    if path.is_file():
        if path.suffix != ".bag" and (path.parent / "metadata.yaml").is_file():
            return path.parent
        return path
    lone = _lone_storage_in(path)
    return lone if lone is not None else path


def is_bag(path: Path) -> bool:
    """Cheap detection from names only."""
    path = Path(path)
    if path.is_file():
        if path.suffix in (".bag",) + STORAGE_SUFFIXES:
            return True
        return path.name == "metadata.yaml"
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return any(p.suffix in STORAGE_SUFFIXES for p in path.iterdir())
        return _lone_storage_in(path) is not None
    return False


def is_ros2(root: Path) -> bool:
    return Path(root).suffix != ".bag"


def bag_format(root: Path) -> str:
    """Human name of the container: ``ROS1 bag``, ``ROS2 mcap``, ``ROS2 sqlite3 (db3)``, with ``(no metadata.yaml)``."""
    root = Path(root)
    if root.suffix == ".bag":
        return "ROS1 bag"
    if root.is_file():
        return ("ROS2 mcap" if root.suffix == ".mcap" else "ROS2 sqlite3 (db3)") + " (no metadata.yaml)"
    storage = {p.suffix for p in root.iterdir() if p.suffix in STORAGE_SUFFIXES}
    return "ROS2 mcap" if ".mcap" in storage else "ROS2 sqlite3 (db3)"


def describe_error(err: Exception) -> str:
    text = " ".join(str(a) for a in err.args) if err.args else type(err).__name__
    return " ".join(text.split()) or type(err).__name__


def open_reader(root: Path):
    """An opened :class:`AnyReader` for the bag at ``root`` (see :func:`bag_root`); the caller closes it."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise GeviError(root, "reading ROS bags needs the 'rosbags' package (pip install rosbags)") from None
    ros2 = is_ros2(root)
    try:
        reader = AnyReader([Path(root)], default_typestore=get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC))
        reader.open()
    except GeviError:
        raise
    except Exception as err:
        hint = "" if ros2 else "; a bag whose recording was interrupted needs 'rosbag reindex'"
        raise DataError(root, f"cannot read the {'ROS2' if ros2 else 'ROS1'} bag ({describe_error(err)}){hint}") from err
    return reader


def header_stamp(raw, is2: bool) -> int:
    """Header stamp (ns) of a serialized message that starts with ``std_msgs/Header``.

    ROS1: ``uint32 seq, uint32 sec, uint32 nsec``; ROS2 CDR: 4-byte encapsulation header (byte 1 odd =
    little endian), then ``int32 sec, uint32 nanosec``.  Both put the stamp at bytes 4..12.
    """
    if is2:
        sec, nsec = struct.unpack_from("<iI" if raw[1] & 1 else ">iI", raw, 4)
    else:
        sec, nsec = struct.unpack_from("<II", raw, 4)
    return sec * 1_000_000_000 + nsec


def stamp_ns(stamp) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
