"""Where a field agent's stick-slip severity on prone scenarios that do not stick comes from.

For every prone scenario of a field suite, runs a model as it is, with its residual smoothed
over decisions (a first-order low-pass ``a'_k = keep a'_(k-1) + (1 - keep) a_k`` for each
``--keep``) and with a zero residual (its base loop alone), on the suite's first
``--runs`` reset seeds, and prints the mean stick-slip severity, IAE (rad) and RMSD (N m) of
each, and, over every decision of the runs, the median chattering term of the reward
(``info["reward_terms"]["chattering"]``) and the median step of the action from one decision to
the next (the residual's step is that times ``residual_scale_nm``). If smoothing the residual
lowered the severity, a penalty on its step would be a lever; if the chattering term is the
same with and without the residual, a weight on it does not see what the agent does.

Run from the repository root (about a minute per scenario on one core, warm)::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/field_ripple.py agents/models/field_agent
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from agents import load_policy
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from experiments.arguments import number_type
from experiments.benchmark import load_suite


class Smoothed:
    """``policy`` with its action low-passed over the decisions of an episode."""

    def __init__(self, policy: Any, keep: float) -> None:
        self.policy, self.keep = policy, keep
        self.last: npt.NDArray[np.float32] | None = None

    def predict(self, obs: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[npt.NDArray[np.float32], Any]:  # fmt: skip
        action, state = self.policy.predict(obs, state, episode_start, deterministic)
        if self.last is None or (episode_start is not None and bool(np.any(episode_start))):
            self.last = np.zeros_like(action)
        self.last = (self.keep * self.last + (1.0 - self.keep) * action).astype(np.float32)
        return self.last, state


class ChatteringLog(gym.Wrapper[Any, Any, Any, Any]):
    """Keeps the chattering term of every step's reward."""

    def __init__(self, env: gym.Env[Any, Any]) -> None:
        super().__init__(env)
        self.values: list[float] = []

    def step(self, action: Any) -> Any:
        result = self.env.step(action)
        self.values.append(float(result[4]["reward_terms"]["chattering"]))
        return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", help="a field model folder")
    parser.add_argument("--suite", default="field-v1", help="a field suite (default field-v1)")
    parser.add_argument("--runs", type=number_type(1, 1000, integer=True), default=2,
                        help="reset seeds per scenario (2)")  # fmt: skip
    parser.add_argument("--keep", type=number_type(0, 1), nargs="*", default=[0.5, 0.8],
                        help="low-pass factors of the smoothed residual (0.5 0.8)")  # fmt: skip
    args = parser.parse_args()
    agent = load_policy(args.model)
    suite = load_suite(args.suite)
    variants: list[tuple[str, Any]] = [("model", lambda: agent)]
    variants += [(f"keep {k}", lambda k=k: Smoothed(agent, k)) for k in args.keep]
    variants.append(("zero residual", ZeroAction))  # the base loop alone
    print("scenario | " + " | ".join(name for name, _ in variants))
    print("  each: severity / IAE / RMSD / median chattering term / median action step")
    for scenario in (s for s in suite.scenarios if s.prone):
        kwargs = {**suite.env_kwargs(scenario), **agent.env_kwargs}
        cells = []
        for _, make in variants:
            metrics, steps, env = [], [], ChatteringLog(gym.make(suite.env_id, **kwargs))
            for seed in scenario.seeds[: args.runs]:
                trace = rollout(env, make(), seed)
                metrics.append(episode_metrics(trace))
                steps.append(np.abs(np.diff(trace.actions[:, 0])))
            env.close()
            mean = {
                k: np.mean([m[k] for m in metrics])
                for k in ("stick_slip_severity", "iae", "rmsd_nm")
            }
            cells.append(
                f"{mean['stick_slip_severity']:.4f} / {mean['iae']:.1f} / {mean['rmsd_nm']:,.0f}"
                f" / {np.median(env.values):.3f} / {np.median(np.concatenate(steps)):.4f}"
            )
        print(f"{scenario.id} | " + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
