"""Compiling ahead and saying so: ``python -m drill_env.precompile``, the one-line note on
stderr while numba compiles (only on a cache miss), and controller laws compiled at first use."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numba import njit

from drill_env._cache import announce_compilation
from drill_env.control import CompiledLaw, LazyLaw, compiled_law_function
from drill_env.layout import N_MEASUREMENT

ROOT = Path(__file__).resolve().parents[1]


def test_the_note_is_written_once_and_only_when_numba_compiles(
    capsys: pytest.CaptureFixture[str],
) -> None:
    @njit
    def twice(x: float) -> float:
        return 2.0 * x

    with announce_compilation("a test function", 1):
        assert twice(1.5) == 3.0  # compiles: the note
    with announce_compilation("a test function", 1):
        twice(2.0)  # already compiled: silent
    with announce_compilation("another test function", 1):
        twice(3.0)  # nothing compiles: silent
    lines = capsys.readouterr().err.splitlines()
    assert lines == [
        "drill_env: compiling a test function (first use, about 1 s; cached afterwards)"
    ]


def _double_reference(lp, ls, m, ref, dt):  # type: ignore[no-untyped-def]
    return 2.0 * ref


def test_a_lazy_law_compiles_at_first_use_and_runs() -> None:
    law = compiled_law_function(_double_reference)
    assert isinstance(law, LazyLaw)
    assert law._compiled is None  # nothing compiled at decoration
    compiled = CompiledLaw(law, np.zeros(1), np.zeros(1)).validated()
    assert law._compiled is not None and compiled.address == law.address != 0
    state = np.zeros(1)
    assert compiled.torque(state, np.zeros(N_MEASUREMENT), 4.0, 1e-3) == 8.0


@pytest.mark.slow
def test_precompile_fills_the_cache_so_a_new_process_compiles_nothing(tmp_path: Path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "OMP_NUM_THREADS": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "drill_env.precompile", "--skip-controllers"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert "precompile: done" in done.stderr
    first_use = subprocess.run(
        [
            sys.executable,
            "-c",
            "import gymnasium as gym, drill_env\n"
            "for env_id in ('DrillString-v0', 'DrillStringField-v0'):\n"
            "    env = gym.make(env_id); env.reset(seed=0); env.step(env.action_space.sample())\n",
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert first_use.stderr == ""  # loaded from the cache: no compilation, no note


@pytest.mark.slow
def test_the_first_step_compiles_each_function_of_the_plant_once(tmp_path: Path) -> None:
    """An empty cache, the first step of the 4-DOF string, then of the field string: neither
    compiles a function of the project for two signatures (a literal argument, ``0`` for a
    variable mode, makes numba compile a second copy: seconds of a cold start)."""
    code = (
        "import collections, gymnasium as gym\n"
        "from numba.core import event\n"
        "seen = collections.defaultdict(set)\n"
        "class Signatures(event.Listener):\n"
        "    def on_start(self, ev):\n"
        "        function = ev.data['dispatcher'].py_func\n"
        "        seen[function.__module__ + '.' + function.__qualname__].add(str(ev.data['args']))\n"
        "    def on_end(self, ev):\n"
        "        pass\n"
        "event.register('numba:compile', Signatures())\n"
        "import drill_env\n"
        "twice = []\n"
        "for env_id in ('DrillString-v0', 'DrillStringField-v0'):\n"
        "    seen.clear()\n"
        "    env = gym.make(env_id); env.reset(seed=0); env.step(env.action_space.sample())\n"
        "    twice += [(env_id, name) for name, signatures in seen.items()\n"
        "              if name.startswith('drill_env.') and len(signatures) > 1]\n"
        "print(sorted(twice))\n"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "OMP_NUM_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"
