"""Helpers shared by the test folders (imported as ``support``; conftest.py only holds fixtures).

Test helpers live here rather than in conftest.py because every folder has its own conftest and
``from conftest import ...`` would pick whichever was imported first.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from gevi_cli.shared_data import shared_data_dir

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = shared_data_dir()
"""The read-only data folder: $GEVI_SHARED_DATA, else ../shared/data next to the repo (the one resolver the
batch configs use too: gevi_cli/shared_data.py)."""


def shared_path(*parts: str) -> Path:
    """Path under ../shared/data, or skip the test with the reason when it is absent."""
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"real data not available: {path} is absent (the read-only ../shared/data next to the repo, "
                    "or $GEVI_SHARED_DATA)")
    return path


def run_cli(args, capsys):
    """Run `gevi ARGS` in-process; return (exit code, stdout, stderr)."""
    from gevi_cli.cli import main

    try:
        main(list(map(str, args)))
        code = 0
    except SystemExit as exit_:
        code = exit_.code if isinstance(exit_.code, int) else 1
    out = capsys.readouterr()
    return code, out.out, out.err
