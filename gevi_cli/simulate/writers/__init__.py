"""Dataset writers: EuRoC ASL folders, KITTI odometry folders and ROS1 bags.

Every writer is deterministic: no creation times, fixed PNG compression, numbers printed with
``repr`` (shortest round-trip form), so equal seeds and options give byte-identical files.
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 1]


def fmt(x) -> str:
    """Shortest round-trip text of a float (``repr``), integers without a decimal point."""
    x = float(x)
    if x == 0.0:
        return "0.0"
    return repr(x)


def write_png(path: Path, img: np.ndarray) -> None:
    ok, buf = cv2.imencode(".png", img, PNG_PARAMS)
    if not ok:
        raise OSError(f"could not encode {path}")
    Path(path).write_bytes(buf.tobytes())


def plain(obj):
    """Recursively convert numpy scalars/arrays and tuples to plain Python for YAML."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def write_simulation_yaml(path: Path, description: dict) -> None:
    import yaml

    description = plain(description)

    Path(path).write_text("# Written by `gevi simulate`; everything needed to regenerate this sequence.\n"
                          + yaml.safe_dump(description, sort_keys=False, default_flow_style=None, width=120))


def get_writer(fmt_name: str):
    if fmt_name == "euroc":
        from gevi_cli.simulate.writers.euroc import write_euroc

        return write_euroc
    if fmt_name == "kitti":
        from gevi_cli.simulate.writers.kitti import write_kitti

        return write_kitti
    if fmt_name == "bag":
        from gevi_cli.simulate.writers.bag import write_bag

        return write_bag
    raise ValueError(f"unknown format {fmt_name!r}")


FORMATS = ("euroc", "kitti", "bag")
