"""The versions the project claims are the ones it tests: the Python floor is CI's interpreter, the
dependencies are ranges, and evo (every ATE/RPE) stays on one minor version."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())


def test_python_floor_is_the_interpreter_ci_builds_with():
    """requires-python's floor, ruff's target and the python3.X that .ci/run creates its venv with agree."""
    floor = re.fullmatch(r">=3\.(\d+)", _pyproject()["project"]["requires-python"])
    assert floor, "requires-python must be a bare floor '>=3.X'"
    ci = re.search(r"^PYTHON=python3\.(\d+)$", (REPO / ".ci" / "run").read_text(), re.MULTILINE)
    assert ci, ".ci/run must name its interpreter as PYTHON=python3.X"
    assert ci.group(1) == floor.group(1)
    assert _pyproject()["tool"]["ruff"]["target-version"] == f"py3{floor.group(1)}"


def test_runtime_dependencies_are_ranges_and_evo_one_minor():
    """No exact pin: each runtime dependency has a lower and an upper bound; evo's upper bound is its next
    minor release, so the metrics compared to the bit come from one evo version line."""
    deps = {re.match(r"[A-Za-z0-9_.-]+", d).group(0).lower(): d for d in _pyproject()["project"]["dependencies"]}
    for name, spec in deps.items():
        assert "==" not in spec and ">=" in spec and "<" in spec, spec
    low = re.search(r">=(\d+)\.(\d+)", deps["evo"])
    assert f"<{low.group(1)}.{int(low.group(2)) + 1}" in deps["evo"], deps["evo"]
