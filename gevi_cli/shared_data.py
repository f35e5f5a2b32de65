"""Where the read-only shared data is: ``$GEVI_SHARED_DATA`` when set, else ``../shared/data`` next to
the repository.

The tests, the benchmark scripts and the batch configs all find it here.  The ready batch configs
(``configs/batch/*.yaml``) write its files as ``../shared/data/...`` from the repository root;
:func:`redirect` sends such a path to ``$GEVI_SHARED_DATA`` instead, so the data can live anywhere
(a worktree, a CI cache) without editing a config.
"""
from __future__ import annotations

import os
from pathlib import Path

ENV = "GEVI_SHARED_DATA"
#: how configs and docs write the shared data folder: relative to the repository root
PREFIX = ("..", "shared", "data")
REPO = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path:
    """``$GEVI_SHARED_DATA``, else ``../shared/data`` next to the repository (it may not exist)."""
    env = os.environ.get(ENV)
    return Path(env).expanduser() if env else REPO.parent.joinpath(*PREFIX[1:])


def redirect(path: str | Path) -> Path | None:
    """``$GEVI_SHARED_DATA/rest`` for a relative ``../shared/data/rest`` when the variable is set, else None
    (resolve ``path`` as usual)."""
    parts = Path(path).parts
    if os.environ.get(ENV) and parts[:len(PREFIX)] == PREFIX:
        return shared_data_dir().joinpath(*parts[len(PREFIX):])
    return None
