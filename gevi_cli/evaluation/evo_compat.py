"""The one place gevi imports evo (1.38.x: pyproject.toml).

evo's *core* (metrics, sync, geometry, lie algebra) and its file reader do not touch matplotlib or the
user's ``~/.evo``; but ``evo.tools.settings`` -- pulled in by evo's plotting and CLI modules -- creates
``~/.evo/settings.json`` on import and ``evo.tools.plot`` switches the matplotlib backend to the one
stored there.  This module therefore

* loads ``evo.tools.settings`` once with ``HOME`` pointed at a private temporary folder (deleted
  right after), so nothing is written to the user's home; the settings then live in memory only, with
  ``plot_backend`` set to ``Agg`` so that an accidental import of ``evo.tools.plot`` cannot open a GUI;
* never imports ``evo.tools.plot`` or ``matplotlib`` (gevi draws its own figures with Agg canvases,
  see :mod:`gevi_cli.evaluation.plots`).

Everything else in gevi imports evo names from here.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
import threading

import numpy as np

_LOCK = threading.Lock()


def _isolate_settings() -> None:
    """Import ``evo.tools.settings`` without writing to the real ``~/.evo``."""
    if "evo.tools.settings" in sys.modules:
        mod = sys.modules["evo.tools.settings"]
    else:
        with _LOCK:
            tmp = tempfile.mkdtemp(prefix="gevi-evo-")
            old_home = os.environ.get("HOME")
            os.environ["HOME"] = tmp
            try:
                import contextlib
                import io

                with contextlib.redirect_stdout(io.StringIO()):  # "Initialized new ...settings.json"
                    import evo.tools.settings as mod  # noqa: F401
            finally:
                if old_home is None:
                    os.environ.pop("HOME", None)
                else:
                    os.environ["HOME"] = old_home
                shutil.rmtree(tmp, ignore_errors=True)
    try:
        mod.SETTINGS.plot_backend = "Agg"
    except Exception:  # pragma: no cover - defensive: settings layout changed
        pass


_isolate_settings()

from evo.core import filters, geometry, lie_algebra, metrics, sync  # noqa: E402
from evo.core.metrics import APE, RPE, PoseRelation, Unit  # noqa: E402
from evo.core.trajectory import PosePath3D, PoseTrajectory3D  # noqa: E402

__all__ = [
    "APE", "RPE", "PoseRelation", "Unit", "PosePath3D", "PoseTrajectory3D", "file_interface",  # noqa: F822 (lazy)
    "filters", "geometry", "lie_algebra", "metrics", "sync", "to_evo", "EVO_VERSION",
]

import evo as _evo  # noqa: E402


def __getattr__(name: str):
    # evo's file reader, imported on first use: it imports rosbags (~45 ms of every `gevi run` otherwise),
    # and gevi reads trajectories with its own readers; the tests use it as an independent reader
    if name == "file_interface":
        from evo.tools import file_interface

        return file_interface
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


EVO_VERSION = _evo.__version__


def to_evo(traj, t0_ns: int = 0) -> PoseTrajectory3D:
    """A :class:`gevi_cli.trajectory.Trajectory` as an evo ``PoseTrajectory3D``.

    Stamps become float seconds relative to ``t0_ns`` (keeps sub-microsecond precision at epoch times).
    """
    stamps = (traj.t_ns - np.int64(t0_ns)).astype(np.float64) * 1e-9
    return PoseTrajectory3D(
        positions_xyz=np.array(traj.positions, dtype=np.float64),
        orientations_quat_wxyz=np.array(traj.quat_wxyz, dtype=np.float64),
        timestamps=stamps,
        name=traj.name or None,
    )


