"""Helpers of the batch tests (imported as ``helpers`` next to them)."""
from __future__ import annotations

from pathlib import Path


def tree(out: Path) -> set:
    """Relative paths of every file under OUT/runs (the results tree)."""
    root = Path(out) / "runs"
    return {str(p.relative_to(root)) for p in root.rglob("*") if p.is_file()}


def trajectory_bytes(out: Path) -> dict:
    root = Path(out) / "runs"
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("traj_*")) if p.is_file()}


def markers(out: Path) -> dict:
    """run id -> done.json path, for the runs that finished."""
    root = Path(out) / "runs"
    return {str(p.parent.relative_to(root)): p for p in root.rglob("done.json")}
