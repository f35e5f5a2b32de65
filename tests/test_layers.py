"""Strict layering of ``gevi_cli`` (issue 37): every import, function-level (lazy) ones included, points
to the same layer or a lower one of :data:`LAYERS`.

Bottom to top: the building blocks (the package's version, errors, geometry, camera intrinsics, configuration I/O,
trajectories, the estimators, the dataset readers, the values a front end hands a back end); what turns sensor data into
measurements (front end, IMU handling, simulator); the odometry pipelines; what runs and judges them
(a run, the evaluation, batches); the user-facing surfaces (the Python API, the commands, the CLI).
"""
from __future__ import annotations

import pytest

from test_import_cycles import import_graph

LAYERS = [
    {"__init__", "errors", "geometry", "camera", "config", "shared_data", "observations", "trajectory", "estimators",
     "datasets"},
    {"frontend", "inertial", "simulate", "studies"},
    {"pipelines"},
    {"run", "evaluation", "batch"},
    {"api", "commands", "cli"},
]


def _unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _layer(module: str) -> int:
    unit = _unit(module)
    for k, units in enumerate(LAYERS):
        if unit in units:
            return k
    raise AssertionError(f"{module}: package {unit!r} is in no layer of tests/test_layers.py")


def wrong_way(graph) -> set[tuple[str, str]]:
    return {(src, dst) for src, targets in graph.items() for dst in targets
            if dst.startswith("gevi_cli") and _layer(dst) > _layer(src)}


def test_every_import_points_down_or_across():
    graph = import_graph(include_lazy=True)
    found = wrong_way(graph)
    lines = {(s, d): graph[s][d] for s, d in found}
    new = sorted(found)
    assert not new, "wrong-way imports:\n" + "\n".join(
        f"  {s} (line {lines[(s, d)]}) -> {d}: layer {_layer(s)} imports layer {_layer(d)}" for s, d in new)


@pytest.mark.parametrize("src, dst", [("gevi_cli.datasets.registry", "gevi_cli.frontend.stereo"),
                                      ("gevi_cli.estimators.pnp6", "gevi_cli.pipelines.config"),
                                      ("gevi_cli.pipelines.odometry", "gevi_cli.run.driver")])
def test_a_planted_wrong_way_import_is_found(src, dst):
    """The check sees an upward import wherever it is (here added to the graph as a lazy import would be)."""
    graph = import_graph(include_lazy=True)
    graph[src] = {**graph[src], dst: 1}
    assert (src, dst) in wrong_way(graph)


def test_every_package_has_a_layer():
    for module in import_graph():
        _layer(module)
