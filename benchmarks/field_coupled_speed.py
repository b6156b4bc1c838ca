"""Cost of the field string with axial elements and the regenerative bit, in one process.

Prints the CPU time per simulated second of ``drill_env.coupled_chain.simulate_field`` (top
drive held at 10 rad/s, 80 kN at the top, 1e-4 s steps) for the ``field_2500m`` and
``deep_5000m`` strings, then that of ``DrillStringField-v0`` with ``bit="rgd"`` (fixed scenario,
the soft speed loop, zero action) and, for the ratio, with the default Karnopp bit. The first
call of each compiles or loads the numba cache and is not counted. Run:
``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/field_coupled_speed.py [--seconds 10]``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import drill_env
from drill_env.coupled_chain import coupled_chain, simulate_field


def simulate_cost(name: str, seconds: float) -> float:
    """CPU seconds per simulated second of ``simulate_field`` on the preset ``name``."""
    simulate_field(name, 10.0, 80e3, 0.01)  # compile or load the cache
    start = time.process_time()
    simulate_field(name, 10.0, 80e3, seconds)
    return (time.process_time() - start) / seconds


def env_cost(bit: str, seconds: float) -> float:
    """CPU seconds per simulated second of ``DrillStringField-v0`` with ``bit``."""
    env = gym.make(
        drill_env.FIELD_ENV_ID, bit=bit, randomize=False, base_controller="soft_speed",
        episode_s=seconds + 1.0,
    )  # fmt: skip
    env.reset(seed=0)
    action = np.zeros(1, dtype=np.float32)
    env.step(action)
    steps = round(seconds / env.unwrapped.config.control_dt_s)  # type: ignore[attr-defined]
    start = time.process_time()
    for _ in range(steps):
        env.step(action)
    return (time.process_time() - start) / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per run")
    args = parser.parse_args()
    for name in ("field_2500m", "deep_5000m"):
        cost = simulate_cost(name, args.seconds)
        nodes = coupled_chain(name).n_nodes
        print(f"simulate_field {name} ({nodes} nodes): {cost * 1e3:6.1f} ms CPU per simulated s")
    rgd, karnopp = env_cost("rgd", args.seconds), env_cost("karnopp", args.seconds)
    print(f"DrillStringField-v0 bit='rgd': {rgd * 1e3:6.1f} ms CPU per simulated s")
    print(f"DrillStringField-v0 bit='karnopp': {karnopp * 1e3:6.1f} ms CPU per simulated s")
    print(f"ratio rgd / karnopp: {rgd / karnopp:.1f}")


if __name__ == "__main__":
    main()
