"""What the SMC's state observer costs per plant step, in one process.

For ``DrillString-v0`` (the 4-DOF plant, an observer of 8 states) and ``DrillStringField-v0``
(``field_2500m``, 103 nodes, 8 modes: 16 states), each with the proposed SMC and
``randomize=False``, this prints

(a) the env's ``step`` per plant step on one and the same trajectory: the law measuring the
    whole state, and the same law that also runs its observer on the surface signals at every
    plant step (its estimate unused, so the run is the same; the env then also reports the
    estimates in ``info``), and their ratio;
(b) ``step`` per plant step in surface mode (the law on its estimate: another trajectory);
(c) the law alone, called through its address from compiled code 2,000 times over fixed
    measurement vectors, with the state measured and not;
(d) the observer's design in numpy (:func:`baselines.observer.design_observer`, its cache
    cleared), which runs when a law is packed, at every reset with a new model.

Every number is warm (an untimed warm-up first) and the best of ``--repeats`` runs; the
machine is shared, so only the ratios of one run are meaningful.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/observer_cost.py [--repeats 7]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from typing import Any

import gymnasium as gym
import numpy as np
from numba import carray, cfunc, njit

import baselines  # noqa: F401  (registers the controllers)
import drill_env  # noqa: F401  (registers the envs)
from baselines import ProposedASMC
from baselines.observer import OP_NZ, ObserverGains, design_observer, observer_update
from baselines.proposed import proposed_law
from baselines.smc import (
    N_SMC_PARAMS,
    S_OBSERVER,
    SMC_PARAMS_SIZE,
    SMC_STATE_SIZE,
    VARIANT_PROPOSED,
    smc_torque,
)
from drill_env.control import LAW_SIGNATURE, call_law
from drill_env.layout import (
    M_APPLIED_TORQUE,
    M_STATE,
    M_SURFACE_TORQUE,
    M_TOP_DRIVE_SPEED,
    N_MEASUREMENT,
)

PLANT_STEPS_PER_DECISION = 50  # control_dt_s = 0.05 s at 1 ms


@cfunc(LAW_SIGNATURE)
def _law_and_observer(lp_ptr, ls_ptr, m_ptr, ref, dt):  # type: ignore[no-untyped-def]
    """The proposed law on the measured state, running its observer alongside."""
    head = carray(lp_ptr, (N_SMC_PARAMS,))
    lp = carray(lp_ptr, (int(head[SMC_PARAMS_SIZE]),))
    ls = carray(ls_ptr, (int(head[SMC_STATE_SIZE]),))
    m = carray(m_ptr, (N_MEASUREMENT,))
    observer_update(lp, N_SMC_PARAMS, ls, S_OBSERVER, m, dt)
    return smc_torque(VARIANT_PROPOSED, lp, ls, m, ref, dt)


class _AlsoObserving(ProposedASMC):
    """The proposed SMC whose law also runs the observer designed for the surface signals."""

    law = _law_and_observer

    def compiled_law(self, model: Any = None, torque_limits: Any = None, channel: Any = None):  # type: ignore[no-untyped-def, override]
        if channel is not None:
            channel = dataclasses.replace(channel, observation="surface")
        return super().compiled_law(model, torque_limits, channel)


def _env(env_id: str, controller: Any, observation: str) -> gym.Env:  # type: ignore[type-arg]
    env = gym.make(
        env_id, base_controller=controller, randomize=False, observation=observation,
        max_episode_steps=-1, episode_s=1e4,
    )  # fmt: skip
    env.reset(seed=0)
    return env


def _time_steps(env: gym.Env, steps: int) -> float:  # type: ignore[type-arg]
    action = np.zeros(1, dtype=np.float32)
    start = time.perf_counter()
    for _ in range(steps):
        env.step(action)
    return (time.perf_counter() - start) / (steps * PLANT_STEPS_PER_DECISION)


@njit  # not cached: numba would not notice a change of the observer the laws call
def _calls(address, lp, ls, measurements, reps):  # type: ignore[no-untyped-def]
    total = 0.0
    for _ in range(reps):
        for k in range(measurements.shape[0]):
            total += call_law(address, lp, ls, measurements[k], 12.0, 1e-3)
    return total


def _time_law(address: int, lp: Any, ls: Any, measurements: Any, repeats: int) -> float:
    _calls(address, lp, ls.copy(), measurements, 1)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        _calls(address, lp, ls.copy(), measurements, 20)
        best = min(best, (time.perf_counter() - start) / (20 * measurements.shape[0]))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=300, help="decisions per timed run")
    parser.add_argument("--repeats", type=int, default=7, help="timed runs (best kept)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    surface = np.full((2000, N_MEASUREMENT), np.nan)
    surface[:, M_TOP_DRIVE_SPEED] = 10.0 + 0.1 * rng.standard_normal(2000)
    surface[:, M_SURFACE_TORQUE] = 8000.0 + 250.0 * rng.standard_normal(2000)
    surface[:, M_APPLIED_TORQUE] = 12_000.0
    measured = surface.copy()
    measured[:, M_STATE : M_STATE + 7] = (10.0, 11.0, 10.0, 0.5, 10.0, 0.2, 10.0)
    for env_id in ("DrillString-v0", "DrillStringField-v0"):
        envs = {
            "state": _env(env_id, "proposed", "state"),
            "state + observer": _env(env_id, _AlsoObserving(), "state"),
            "surface": _env(env_id, "proposed", "surface"),
        }
        arrays = envs["surface"].unwrapped.batch.arrays  # type: ignore[attr-defined]
        lp, ls = arrays.law_params[0].copy(), arrays.law_state[0].copy()  # as reset
        for env in envs.values():  # warm-up
            _time_steps(env, 20)
        best = dict.fromkeys(envs, np.inf)
        for _ in range(args.repeats):
            for name, env in envs.items():
                best[name] = min(best[name], _time_steps(env, args.steps))
        same = [e.unwrapped.batch.x[0].tolist() for e in list(envs.values())[:2]]  # type: ignore[attr-defined]
        assert same[0] == same[1], "the observer changed the trajectory"
        address = proposed_law.address
        without = _time_law(address, lp, ls, measured, args.repeats)
        with_observer = _time_law(address, lp, ls, surface, args.repeats)
        us = {name: value * 1e6 for name, value in best.items()}
        print(
            f"{env_id}: step per plant step, same trajectory: state {us['state']:.3f} us, "
            f"+ observer {us['state + observer']:.3f} us (ratio "
            f"{best['state + observer'] / best['state']:.2f}); surface mode "
            f"{us['surface']:.3f} us. The law alone: {without * 1e9:.0f} ns, with the "
            f"observer (nz = {int(lp[N_SMC_PARAMS + OP_NZ])}) {with_observer * 1e9:.0f} ns"
        )
        batch = envs["surface"].unwrapped.batch  # type: ignore[attr-defined]
        model = batch.episodes[0].scenario.controller_model
        channel = envs["surface"].unwrapped.config.measurement_channel()  # type: ignore[attr-defined]
        design_s = np.inf
        for _ in range(args.repeats):
            design_observer.cache_clear()
            start = time.perf_counter()
            design_observer(model, channel, ObserverGains())
            design_s = min(design_s, time.perf_counter() - start)
        print(f"{env_id}: the observer's design {design_s * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
