"""What the SMC's state observer costs per plant step, in one process.

For ``DrillString-v0`` (the 4-DOF plant) and ``DrillStringField-v0`` (``field_2500m``, 103
nodes), each with ``base_controller="proposed"``, ``randomize=False``, this times the env's
``step`` (the whole compiled loop: plant, channel, actuator, law) with the state measured
(``observation="state"``: the law without its observer) and not (``"surface"``: the law runs
the observer at every plant step), and prints the wall time per plant step and the ratio (the
two runs follow different trajectories, so the plant's own cost differs a little too). It also
times the law alone (:func:`baselines.smc.smc_step`, replayed over 2,000 measurement vectors)
with the state measured and not: the difference is the observer's cost per plant step.

Every number is warm (one untimed warm-up run first) and the best of ``--repeats`` interleaved
runs; the machine is shared, so only the ratios of one run are meaningful.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/observer_cost.py [--steps 400]``.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
from numba import njit

import baselines  # noqa: F401  (registers the controllers)
import drill_env  # noqa: F401  (registers the envs)
from baselines.observer import OP_NZ
from baselines.smc import N_SMC_PARAMS, VARIANT_PROPOSED, smc_step
from drill_env.layout import (
    M_APPLIED_TORQUE,
    M_STATE,
    M_SURFACE_TORQUE,
    M_TOP_DRIVE_SPEED,
    N_MEASUREMENT,
)

PLANT_STEPS_PER_DECISION = 50  # control_dt_s = 0.05 s at 1 ms


def _env(env_id: str, observation: str) -> gym.Env:  # type: ignore[type-arg]
    env = gym.make(
        env_id,
        base_controller="proposed",
        randomize=False,
        observation=observation,
        max_episode_steps=-1,
        episode_s=1e4,
    )
    env.reset(seed=0)
    return env


def _time_steps(env: gym.Env, steps: int) -> float:  # type: ignore[type-arg]
    action = np.zeros(1, dtype=np.float32)
    start = time.perf_counter()
    for _ in range(steps):
        env.step(action)
    return (time.perf_counter() - start) / (steps * PLANT_STEPS_PER_DECISION)


@njit(cache=True)
def _replay(lp, ls, measurements, reps):  # type: ignore[no-untyped-def]
    total = 0.0
    for _ in range(reps):
        for k in range(measurements.shape[0]):
            total += smc_step(VARIANT_PROPOSED, lp, ls, measurements[k], 12.0, 1e-3)
    return total


def _time_law(lp, ls, measurements, repeats: int) -> float:  # type: ignore[no-untyped-def]
    _replay(lp, ls.copy(), measurements, 1)  # warm-up
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        _replay(lp, ls.copy(), measurements, 20)
        best = min(best, (time.perf_counter() - start) / (20 * measurements.shape[0]))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=400, help="decisions per timed run")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved timed runs")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    measurements = np.full((2000, N_MEASUREMENT), np.nan)
    measurements[:, M_TOP_DRIVE_SPEED] = 10.0 + 0.1 * rng.standard_normal(2000)
    measurements[:, M_SURFACE_TORQUE] = 8000.0 + 250.0 * rng.standard_normal(2000)
    measurements[:, M_APPLIED_TORQUE] = 12_000.0
    measured = measurements.copy()  # the same, with a measured state
    measured[:, M_STATE : M_STATE + 7] = (10.0, 11.0, 10.0, 0.5, 10.0, 0.2, 10.0)
    for env_id in ("DrillString-v0", "DrillStringField-v0"):
        envs = {mode: _env(env_id, mode) for mode in ("state", "surface")}
        arrays = envs["surface"].unwrapped.batch.arrays  # type: ignore[attr-defined]
        lp, ls = arrays.law_params[0].copy(), arrays.law_state[0].copy()  # as reset
        for env in envs.values():  # warm-up
            _time_steps(env, 20)
        best = {mode: np.inf for mode in envs}
        for _ in range(args.repeats):
            for mode, env in envs.items():
                best[mode] = min(best[mode], _time_steps(env, args.steps))
        without = _time_law(lp, ls, measured, args.repeats)
        with_observer = _time_law(lp, ls, measurements, args.repeats)
        print(
            f"{env_id}: env step per plant step, state measured {best['state'] * 1e6:.3f} us, "
            f"with the observer {best['surface'] * 1e6:.3f} us (ratio "
            f"{best['surface'] / best['state']:.2f}); the law alone {without * 1e9:.0f} ns, "
            f"with the observer (nz = {int(lp[N_SMC_PARAMS + OP_NZ])}) "
            f"{with_observer * 1e9:.0f} ns"
        )


if __name__ == "__main__":
    main()
