"""The per-kind configurations are package data: found inside the installed package, whatever the install."""
from __future__ import annotations

import tomllib
from pathlib import Path

import gevi_cli
from gevi_cli.run import session

REPO = Path(__file__).resolve().parents[1]


def test_kind_configs_live_in_the_package():
    """config_dir() is the package's own configs/ (no path outside the package is searched), it holds
    every kind's file, and pyproject ships that folder's YAMLs as package data."""
    folder = session.config_dir()
    assert folder.resolve() == (Path(gevi_cli.__file__).resolve().parent / "configs")
    assert all((folder / name).is_file() for name in session.KIND_CONFIG.values())
    pyproject = tomllib.loads((REPO / "pyproject.toml").read_text())
    globs = pyproject["tool"]["setuptools"]["package-data"]["gevi_cli"]
    shipped = {p.name for g in globs for p in (REPO / "gevi_cli").glob(g)}
    assert set(session.KIND_CONFIG.values()) <= shipped
