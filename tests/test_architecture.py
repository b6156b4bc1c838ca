"""The house rules: each package one floor that imports only the floors below it, the studies
on the public interface, and every index of the engine's vectors read from its one home."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FLOORS = ("drill_env", "baselines", "agents", "experiments")
"""From the bottom up: a package may import the ones before it, never those after."""


def _imports(path: Path) -> set[str]:
    """Top-level packages and modules imported anywhere in ``path`` (also inside functions)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def _sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


@pytest.mark.parametrize("floor", range(len(FLOORS)), ids=FLOORS)
def test_no_package_imports_a_higher_floor(floor: int) -> None:
    package, higher = FLOORS[floor], FLOORS[floor + 1 :]
    offenders = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in _sources(package)
        for name in _imports(path)
        if name.split(".")[0] in higher
    ]
    assert not offenders, "\n".join(offenders)


def test_studies_use_the_public_interface_only() -> None:
    """The studies use gym.make/make_vec, rollout and the registry, never the engine."""
    internal = ("drill_env.batch", "drill_env.kernel", "drill_env.layout")
    offenders = [
        f"{path.relative_to(ROOT)} imports {name}"
        for path in _sources("experiments")
        for name in _imports(path)
        if name in internal
    ]
    assert not offenders, "\n".join(offenders)
    for path in _sources("experiments"):
        text = path.read_text()
        assert ".batch." not in text and "REC_" not in text, path


def test_plant_vector_is_read_by_name() -> None:
    """The compiled physics reads the plant parameter vector through ``layout.P_*``."""
    for name in ("dynamics.py", "integration.py", "kernel.py"):
        text = (ROOT / "drill_env" / name).read_text()
        assert not re.search(r"\bp\[\d", text), f"drill_env/{name} indexes p with a bare number"


def test_records_and_reports_are_read_by_name() -> None:
    """No module picks a column of the records (their third axis) or of the report (its
    second) with a bare number."""
    pattern = re.compile(
        r"\b(records|rec)\[[^\],]*,[^\],]*,\s*\d+\s*\]|\b(report|rep)\[[^\],]*,\s*\d+\s*\]"
    )
    for package in FLOORS:
        for path in _sources(package):
            for k, line in enumerate(path.read_text().splitlines(), 1):
                assert not pattern.search(line), f"{path.relative_to(ROOT)}:{k}: {line.strip()}"


def test_importing_the_core_loads_no_higher_floor_nor_plotting() -> None:
    """``import drill_env`` and a direct-mode env pull in no controllers, agents, studies,
    plotting or torch."""
    code = (
        "import sys, gymnasium as gym, drill_env\n"
        "env = gym.make('DrillString-v0'); env.reset(seed=0); env.step(env.action_space.sample())\n"
        "bad = [m for m in ('baselines', 'agents', 'experiments', 'matplotlib', 'tqdm', 'torch',"
        " 'stable_baselines3') if m in sys.modules]\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == ""


def test_a_controller_name_is_found_without_importing_baselines() -> None:
    """The core finds a built-in controller by name through the registry's entry points."""
    code = (
        "import gymnasium as gym, drill_env\n"
        "env = gym.make('DrillString-v0', base_controller='proposed')\n"
        "print(type(env.unwrapped.batch.controllers[0]).__module__)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "baselines.proposed"
