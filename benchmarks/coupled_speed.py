"""Cost of the coupled axial-torsional model with the regenerative bit, in one process.

Prints, per operating point of the standard run (P1-P4), the CPU time of
``drill_env.coupled.simulate`` per simulated second at the 1e-4 s step and the ratio of
simulated to CPU time; then the same for ``DrillStringCoupled-v0`` stepped with a zero action
(the 4-DOF string on the bit, 50 ms decisions). The first call of each compiles or loads the
numba cache and is not counted. Run: ``OMP_NUM_THREADS=1 .venv/bin/python
benchmarks/coupled_speed.py [--seconds 50]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from drill_env.coupled import STANDARD_POINTS, simulate
from drill_env.coupled_env import DrillStringCoupledEnv


def lumped_cost(seconds: float) -> dict[str, float]:
    """CPU seconds per simulated second of ``simulate`` at each standard point."""
    simulate("rgd_a", 4.0, 90e3, 0.1)  # compile or load the cache
    costs = {}
    for point, (force, speed) in STANDARD_POINTS.items():
        start = time.process_time()
        simulate("rgd_a", speed, force, seconds)
        costs[point] = (time.process_time() - start) / seconds
    return costs


def env_cost(seconds: float) -> float:
    """CPU seconds per simulated second of ``DrillStringCoupled-v0`` with a zero action."""
    env = DrillStringCoupledEnv(episode_s=seconds + 1.0)
    env.reset(seed=0)
    action = np.zeros(2, dtype=np.float32)
    env.step(action)
    steps = round(seconds / env.config.control_dt_s)
    start = time.process_time()
    for _ in range(steps):
        env.step(action)
    return (time.process_time() - start) / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=50.0, help="simulated seconds per run")
    args = parser.parse_args()
    for point, cost in lumped_cost(args.seconds).items():
        print(f"simulate {point}: {cost * 1e3:6.2f} ms CPU per simulated s ({1 / cost:7.1f}x)")
    cost = env_cost(args.seconds)
    print(f"DrillStringCoupled-v0: {cost * 1e3:6.2f} ms CPU per simulated s ({1 / cost:7.1f}x)")


if __name__ == "__main__":
    main()
