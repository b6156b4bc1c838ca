"""What drilling at the reference costs in torque, against what controllers spend, on a suite
of ``DrillString-v0``.

For every scenario of the suite, the steady-drilling torque: the top-drive torque that holds the
whole string turning at the reference, ``(c_dt + c_bit) V + T_0 + (T_a - T_0) exp(-xi V)``
(``DrillStringParameters.steady_torque_nm``, docs/specification.md section 2) at the WOB of
each moment, averaged over the run. Summing the string's equations of motion, the couplings
cancel, so a run that tracks the reference after a short start-up has a mean torque, and so an
RMSD, at least close to this (docs/specification.md section 6); a controller that spends less
leaves the bit stuck or slow for part of the run. Beside it, each named controller's or model's
mean RMSD and stuck share over the suite's first ``--runs`` reset seeds.

Run from the repository root (about 20 s per controller on the corner set on one core, warm)::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/drilling_torque.py --suite corners-v1 \\
        proposed soft_speed_tuned agents/models/residual_ppo
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np

from agents import load_policy
from drill_env.control import controller_names
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.parameters import DrillStringParameters
from drill_env.scenarios import Scenario
from experiments.arguments import number_type
from experiments.benchmark import SuiteScenario, load_suite


def steady_drilling_torque_nm(scenario: Scenario, duration_s: float) -> float:
    """The steady-drilling torque of ``scenario``'s true plant at its reference, averaged over
    ``duration_s`` of its WOB profile, N m."""
    plant, wob = scenario.plant, scenario.wob
    if not isinstance(plant, DrillStringParameters):
        raise ValueError("the steady-drilling torque is that of the 4-DOF string")
    speed = scenario.reference.value(0.0)
    step = wob.step_time_s
    if step is None or wob.final_n is None or step >= duration_s:
        return plant.steady_torque_nm(speed, wob.initial_n)
    before = plant.steady_torque_nm(speed, wob.initial_n) * step
    after = plant.steady_torque_nm(speed, wob.final_n) * (duration_s - step)
    return (before + after) / duration_s


def _runs(suite_env: str, kwargs: dict[str, Any], policy: Any, seeds: tuple[int, ...]) -> Any:
    env = gym.make(suite_env, **kwargs)
    try:
        return [episode_metrics(rollout(env, policy, seed)) for seed in seeds]
    finally:
        env.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("entries", nargs="*", default=["proposed"],
                        help="registered controllers or model folders (proposed)")  # fmt: skip
    parser.add_argument("--suite", default="corners-v1", help="a DrillString-v0 suite")
    parser.add_argument("--runs", type=number_type(1, 1000, integer=True), default=5,
                        help="reset seeds per scenario (5)")  # fmt: skip
    args = parser.parse_args()
    columns: list[tuple[str, Any, dict[str, Any]]] = []
    try:
        suite = load_suite(args.suite)
        for entry in args.entries:
            if "/" in entry:
                agent = load_policy(entry)
                if agent.env_id != suite.env_id:
                    raise ValueError(f"{entry}: a model of {agent.env_id}, not {suite.env_id}")
                columns.append((entry.rstrip("/").rsplit("/", 1)[-1], agent, agent.env_kwargs))
            elif entry in controller_names():
                columns.append((entry, ZeroAction(), {"base_controller": entry}))
            else:
                raise ValueError(f"unknown controller {entry!r}: allowed {controller_names()}")
    except (ValueError, OSError) as error:
        parser.error(str(error))
    if suite.env_id != "DrillString-v0":
        parser.error(f"--suite {args.suite}: a suite of DrillString-v0 is needed")
    print(f"{suite.label}: steady-drilling torque and mean RMSD (N m), stuck share")
    print("scenario | steady drilling | " + " | ".join(name for name, _, _ in columns))
    steady_all, rmsd_all = [], []
    scenario: SuiteScenario
    for scenario in suite.scenarios:
        steady = steady_drilling_torque_nm(scenario.held.scenario, suite.episode_s)
        cells, rmsds = [], []
        for _, policy, kwargs in columns:
            seeds = scenario.seeds[: args.runs]
            metrics = _runs(suite.env_id, {**suite.env_kwargs(scenario), **kwargs}, policy, seeds)
            rmsd = float(np.mean([m["rmsd_nm"] for m in metrics]))
            stuck = float(np.mean([m["stuck_fraction"] for m in metrics]))
            rmsds.append(rmsd)
            cells.append(f"{rmsd:,.0f} (steady {steady / rmsd - 1:+.1%}), stuck {stuck:.2f}")
        steady_all.append(steady)
        rmsd_all.append(rmsds)
        print(f"{scenario.id} | {steady:,.0f} | " + " | ".join(cells), flush=True)
    mean_steady = float(np.mean(steady_all))
    means = np.mean(np.array(rmsd_all), axis=0)
    print(
        f"mean | {mean_steady:,.0f} | "
        + " | ".join(f"{m:,.0f} (steady {mean_steady / m - 1:+.1%})" for m in means)
    )


if __name__ == "__main__":
    main()
