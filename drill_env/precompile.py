"""Compile the package's numba code ahead of its first use and leave it in numba's cache.

``python -m drill_env.precompile`` builds, resets and steps each env once in the configurations
a user meets first: ``DrillString-v0`` in direct mode and on every registered compiled
controller, its native vector env (serial, and on numba's threads for 64 strings or more),
``DrillStringField-v0`` with its field defaults, and the slow path of a Python controller.
Everything compiled is written to numba's on-disk cache (``__pycache__`` beside the sources,
or ``NUMBA_CACHE_DIR`` when it is set), so that the first ``gym.make`` of a new process only
loads it. ``scripts/setup.sh`` runs it after installing; running it again costs a few seconds.

Options: ``--quiet`` (no progress lines), ``--skip-controllers`` (the envs only).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import gymnasium as gym
import numpy as np

import drill_env
from drill_env.control import CompiledController, controller_names, make_controller
from drill_env.layout import N_STATE
from drill_env.validation import shown

__all__ = ["main", "precompile"]


class _HoldTorque:
    """A Python controller (the slow path): a constant torque, N m."""

    def reset(self) -> None:
        pass

    def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
        return 13_000.0


def _run_env(env_id: str, **kwargs: Any) -> None:
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.step(np.zeros(1, dtype=np.float32))
    env.close()


def _run_vector(num_envs: int) -> None:
    env = gym.make_vec(drill_env.ENV_ID, num_envs=num_envs)
    env.reset(seed=0)
    env.step(np.zeros((num_envs, 1)))
    env.close()


def _jobs(controllers: bool) -> Iterator[tuple[str, Callable[[], None]]]:
    yield f"{drill_env.ENV_ID}, direct mode", lambda: _run_env(drill_env.ENV_ID)
    yield f"{drill_env.FIELD_ENV_ID}, field defaults", lambda: _run_env(drill_env.FIELD_ENV_ID)
    yield f"{drill_env.ENV_ID}, vector env (threads)", lambda: _run_vector(64)
    yield (
        f"{drill_env.ENV_ID}, a Python controller",
        lambda: _run_env(drill_env.ENV_ID, base_controller=_HoldTorque(), episode_s=1.0),
    )
    if not controllers:
        return
    for name in controller_names():
        try:
            controller = make_controller(name)
        except Exception as error:  # a broken third-party entry point must not stop the rest
            print(f"precompile: skipped controller {shown(name)}: {error}", file=sys.stderr)
            continue
        if isinstance(controller, CompiledController):
            yield (
                f"controller {name}",
                lambda name=name: _run_env(  # type: ignore[misc]
                    drill_env.ENV_ID, base_controller=name
                ),
            )


def precompile(controllers: bool = True, quiet: bool = False) -> float:
    """Compile (or load from the cache) everything the first use of the envs needs.

    Args:
        controllers: Also each registered compiled controller's law.
        quiet: Print nothing.

    Returns:
        The wall time taken, s.
    """
    assert N_STATE == 7  # the 4-DOF state the envs run on
    start = time.perf_counter()
    for label, job in _jobs(controllers):
        began = time.perf_counter()
        job()
        if not quiet:
            print(f"precompile: {label}: {time.perf_counter() - began:.1f} s", file=sys.stderr)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    """``python -m drill_env.precompile [--quiet] [--skip-controllers]``."""
    parser = argparse.ArgumentParser(
        prog="python -m drill_env.precompile",
        description="Compile the envs' numba code into numba's on-disk cache ahead of first use.",
    )
    parser.add_argument("--quiet", action="store_true", help="print nothing")
    parser.add_argument(
        "--skip-controllers",
        action="store_true",
        help="compile the envs only, not the registered controllers' laws",
    )
    args = parser.parse_args(argv)
    seconds = precompile(controllers=not args.skip_controllers, quiet=args.quiet)
    if not args.quiet:
        print(f"precompile: done in {seconds:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
