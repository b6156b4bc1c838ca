"""What ``observation="estimate"`` costs the field env as a learned policy trains on it.

``DrillStringField-v0`` under its native vector env (16 strings, field defaults, randomised
strings, the base controller ``z_torque_tuned``, zero residual), stepped for one 100 s episode
(500 decisions, the resets at its start included) with ``observation="surface"`` and with
``observation="estimate"`` (the same loop with the state observer beside it, whose estimate
the observation then shows): decisions per wall second of each and their ratio. The two modes
alternate, each the best of ``--repeats`` runs, all warm (an untimed run first); the machine
is shared, so only the ratio of one run is meaningful.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/estimate_observation_cost.py [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import drill_env  # noqa: F401  (registers DrillStringField-v0)

NUM_ENVS = 16
DECISIONS = 500


def decisions_per_second(observation: str) -> float:
    """Decisions of all strings per wall second over one episode (resets included)."""
    venv = gym.make_vec(
        "DrillStringField-v0",
        num_envs=NUM_ENVS,
        base_controller="z_torque_tuned",
        observation=observation,
    )
    action = np.zeros((NUM_ENVS, 1), dtype=np.float32)
    start = time.perf_counter()
    venv.reset(seed=0)
    for _ in range(DECISIONS):
        venv.step(action)
    return NUM_ENVS * DECISIONS / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per mode (best kept)")
    args = parser.parse_args()
    modes = ("surface", "estimate")
    for mode in modes:  # warm-up: compile or load the laws and the kernel
        decisions_per_second(mode)
    best = dict.fromkeys(modes, 0.0)
    for _ in range(args.repeats):
        for mode in modes:
            best[mode] = max(best[mode], decisions_per_second(mode))
    for mode in modes:
        print(f"observation={mode!r}: {best[mode]:,.0f} decisions/s")
    print(f"estimate / surface: {best['estimate'] / best['surface']:.3f}")


if __name__ == "__main__":
    main()
