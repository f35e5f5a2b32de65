"""The built-in sample: a short pool-easy sequence in the EuRoC layout, rendered once into a cache.

Cache folder: ``$GEVI_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/gevi``, else ``~/.cache/gevi``.  The
sample is rendered into a temporary sibling folder and renamed into place, so an interrupted render
never leaves a half sample behind.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from gevi_cli.simulate.generate import SimulationConfig

#: bump the suffix whenever the simulator's output for the sample changes
SAMPLE_NAME = "sample-pool-easy-v1"
SAMPLE_CONFIG = SimulationConfig("pool-easy", seed=0, duration_s=12.0, rate_hz=10.0, resolution=(640, 360))


def cache_dir() -> Path:
    """The gevi user cache folder (not created)."""
    if os.environ.get("GEVI_CACHE_DIR"):
        return Path(os.environ["GEVI_CACHE_DIR"]).expanduser()
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]).expanduser() / "gevi"
    return Path.home() / ".cache" / "gevi"


def sample_path() -> Path:
    return cache_dir() / SAMPLE_NAME


def sample_sequence(progress: bool = True) -> Path:
    """Path of the sample sequence root (it holds ``mav0/``), rendering it on first use (~10 s)."""
    from gevi_cli.simulate.generate import build_sequence
    from gevi_cli.simulate.writers.euroc import write_euroc

    target = sample_path()
    if (target / "mav0").is_dir() and (target / "simulation.yaml").is_file():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{SAMPLE_NAME}.partial-", dir=target.parent))
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)
    try:
        write_euroc(build_sequence(SAMPLE_CONFIG), tmp, progress=progress)
        try:
            os.rename(tmp, target)
        except OSError:
            if not (target / "mav0").is_dir():  # not a concurrent render that won the race
                raise
            shutil.rmtree(tmp, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target
