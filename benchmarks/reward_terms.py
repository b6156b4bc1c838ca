"""The range each reward term covers under the envs' default keywords.

For each env and mode (direct with action 0 and with uniform random actions; residual on the
env's recipe base controller with a zero and a random residual) prints the 5th, 50th and 95th
percentiles of every term of ``info["reward_terms"]`` and of the reward over a few randomised
episodes, and the share of decisions at which the chattering term is at its cap of 1: a term
pinned at a bound on every step gives an agent no signal. On ``DrillStringField-v0`` it also
runs the field agent's training conditions (``drill-gym train --env DrillStringField-v0``'s
defaults: its ranges, weights and base loop) with a zero residual and with Gaussian residuals of
the policy's initial exploration noise (standard deviation ``exp(log_std_init)``): a term that
moves no more under that noise than under the zero residual does not see what the agent does.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/reward_terms.py [--episodes 3]``.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

import drill_env  # noqa: F401  (registers the envs)
from agents.config import FIELD_ENV_ID, TrainConfig
from agents.train import env_kwargs
from drill_env.rewards import TERMS

Policy = Callable[[Any], np.ndarray]


def term_ranges(env_id: str, base: str | None, policy: Policy, episodes: int, **kwargs: Any) -> str:
    """One line: the percentiles of each term and of the reward over ``episodes`` episodes
    (``kwargs``: more env keywords)."""
    env = gym.make(env_id, base_controller=base, **kwargs)
    env.action_space.seed(0)
    values: dict[str, list[float]] = {t: [] for t in (*TERMS, "reward")}
    for seed in range(episodes):
        env.reset(seed=seed)
        done = False
        while not done:
            _, reward, terminated, truncated, info = env.step(policy(env))
            done = terminated or truncated
            values["reward"].append(float(reward))
            for term in TERMS:
                values[term].append(float(info["reward_terms"][term]))
    cells = [
        f"{name} {' / '.join(f'{p:.2f}' for p in np.percentile(v, [5, 50, 95]))}"
        for name, v in values.items()
    ]
    capped = float(np.mean(np.asarray(values["chattering"]) >= 1.0))
    return f"{env_id}, base {base}: " + "; ".join(cells) + f"; chattering at cap {capped:.0%}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=3, help="episodes per line")
    args = parser.parse_args()
    zero: Policy = lambda env: np.zeros(1, dtype=np.float32)  # noqa: E731
    random: Policy = lambda env: env.action_space.sample()  # noqa: E731
    print("percentiles 5 / 50 / 95 over the decisions")
    for env_id, base in (("DrillString-v0", None), ("DrillString-v0", "proposed"),
                         ("DrillStringField-v0", "soft_speed")):  # fmt: skip
        for name, policy in (("action 0", zero), ("random actions", random)):
            print(f"[{name}] {term_ranges(env_id, base, policy, args.episodes)}")
    config = TrainConfig.for_env(FIELD_ENV_ID)
    recipe = env_kwargs(config)
    base = recipe.pop("base_controller")
    noise = np.random.default_rng(0)
    std = float(np.exp(config.log_std_init))

    def gauss(env: Any) -> np.ndarray:
        return noise.normal(0.0, std, 1).clip(-1, 1).astype(np.float32)

    for name, policy in (("action 0", zero), (f"N(0, {std:.2f}) actions", gauss)):
        line = term_ranges(FIELD_ENV_ID, base, policy, args.episodes, **recipe)
        print(f"[field training, {name}] {line}")


if __name__ == "__main__":
    main()
