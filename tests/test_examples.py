"""Every example in ``examples/`` runs on both envs (a short episode), and from the command
line with ``--env``."""

from __future__ import annotations

import importlib.util
import math
import os
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))
ENVS = ("DrillString-v0", "DrillStringField-v0")


def _load(path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"example_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_examples_are_found() -> None:
    assert {p.stem for p in EXAMPLES} >= {"quickstart", "custom_controller", "compiled_controller"}


@pytest.mark.parametrize("env_id", ENVS)
@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_runs_on_both_envs(path: Path, env_id: str) -> None:
    result = _load(path).main(env_id, 2.0)
    runs = result.values() if path.stem == "compiled_controller" else [result]
    for metrics in runs:
        assert not metrics["diverged"], metrics
        assert math.isfinite(metrics["iae"]) and metrics["iae"] > 0.0
        assert math.isfinite(metrics["rmsd_nm"]) and metrics["rmsd_nm"] > 0.0


@pytest.mark.parametrize("env_id", ENVS)
def test_compiled_and_python_controllers_agree(env_id: str) -> None:
    runs = _load(ROOT / "examples" / "compiled_controller.py").main(env_id, 2.0)
    for key in ("iae", "rmsd_nm", "stuck_fraction"):
        assert runs["compiled"][key] == runs["python"][key], key


def test_example_command_line_takes_the_env() -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    result = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "custom_controller.py"),
         "--env", "DrillStringField-v0", "--episode-s", "2"],
        capture_output=True, text=True, check=False, timeout=300, env=env, cwd=ROOT,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "'diverged': False" in result.stdout
