"""Wall time to the first step of each env in a fresh process, cold and warm.

For each case a fresh Python process imports the package, makes the env, resets it and takes
one step; the time from the start of the process to the end of that step is printed, wall and
CPU (user + system: on a loaded machine the CPU time is the steadier of the two). "cold"
runs each case with its own empty numba cache (``NUMBA_CACHE_DIR`` set to a new temporary
directory, so nothing compiled earlier is reused); "warm" runs the same case again on the cache
the cold run filled. Cases:

* ``DrillString-v0`` in direct mode (``gym.make`` + ``reset`` + ``step``);
* ``DrillString-v0`` in residual mode on the ``proposed`` controller;
* the native vector env, ``gym.make_vec("DrillString-v0", num_envs=4)``;
* ``DrillStringField-v0`` with its field defaults.

``--precompiled`` adds a row per case after ``python -m drill_env.precompile`` has filled the
cache (what ``scripts/setup.sh`` does after installing).

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/cold_start.py [--cases direct field]``.
The machine's load changes the numbers; compare rows of the same run.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time

CASES = {
    "direct": 'env = gym.make("DrillString-v0")\n'
    "env.reset(seed=0)\n"
    "env.step(env.action_space.sample())",
    "residual": 'env = gym.make("DrillString-v0", base_controller="proposed")\n'
    "env.reset(seed=0)\n"
    "env.step(env.action_space.sample())",
    "vector": 'env = gym.make_vec("DrillString-v0", num_envs=4)\n'
    "env.reset(seed=0)\n"
    "env.step(env.action_space.sample())",
    "field": 'env = gym.make("DrillStringField-v0")\n'
    "env.reset(seed=0)\n"
    "env.step(env.action_space.sample())",
}
"""The code each fresh process runs after ``import gymnasium as gym, drill_env``."""

LABELS = {
    "direct": "DrillString-v0, direct",
    "residual": "DrillString-v0, residual (proposed)",
    "vector": "gym.make_vec DrillString-v0, 4 envs",
    "field": "DrillStringField-v0, field defaults",
}


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def first_step_seconds(case: str, cache_dir: str) -> tuple[float, float, str]:
    """Wall and CPU seconds from the start of a fresh process to the end of its first step,
    and what the process wrote on stderr."""
    code = "import gymnasium as gym, drill_env\n" + CASES[case]
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    cpu = _children_cpu_s()
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False
    )
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"cold_start: case {case} failed:\n{done.stderr}")
    return elapsed, _children_cpu_s() - cpu, done.stderr.strip()


def precompile(cache_dir: str) -> float:
    """Run ``python -m drill_env.precompile`` into ``cache_dir``; its wall seconds."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir}
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "drill_env.precompile", "--quiet"], env=env, check=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cases", nargs="+", choices=list(CASES), default=list(CASES), help="cases to run"
    )
    parser.add_argument(
        "--precompiled",
        action="store_true",
        help="also time each case after python -m drill_env.precompile filled the cache",
    )
    args = parser.parse_args()
    header = f"{'case':<38} {'cold s':>7} {'(CPU s)':>8} {'warm s':>7} {'(CPU s)':>8}"
    if args.precompiled:
        header += f" {'precompiled s':>14}"
    print(header)
    messages: dict[str, str] = {}
    for case in args.cases:
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
            cold, cold_cpu, message = first_step_seconds(case, cache)
            warm, warm_cpu, warm_message = first_step_seconds(case, cache)
        messages[case] = message
        line = f"{LABELS[case]:<38} {cold:>7.1f} {cold_cpu:>8.1f} {warm:>7.1f} {warm_cpu:>8.1f}"
        if warm_message:
            line += f"  (the warm run wrote: {warm_message!r})"
        if args.precompiled:
            with tempfile.TemporaryDirectory(prefix="numba-pre-") as cache:
                precompile(cache)
                ready, _, _ = first_step_seconds(case, cache)
            line += f" {ready:>14.1f}"
        print(line, flush=True)
    print("\nstderr of the cold runs:")
    for case, message in messages.items():
        print(f"  {case}: {message or '(nothing)'}")


if __name__ == "__main__":
    main()
