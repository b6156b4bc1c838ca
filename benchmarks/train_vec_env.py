"""Decisions per second of the training environment: the native vector env behind
:class:`agents.vec_env.GymnasiumVecEnv` against SB3's ``DummyVecEnv`` over single envs.

Two measurements per variant, with the shipped agent's environment settings (residual on the
proposed SMC, 0.1 s decisions, randomised scenarios, 100 s episodes):

(a) the environment alone, stepped with random actions through SB3's VecEnv API;
(b) PPO end to end (rollouts and updates, the default hyperparameters) for a short run.

Run from the repository root::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/train_vec_env.py [--envs 16] [--steps 50000]

The machine's other load changes the absolute numbers; the ratio is the point.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from typing import Any

import gymnasium as gym
import numpy as np

import drill_env  # noqa: F401  (registers DrillString-v0)
from agents.config import TrainConfig
from agents.train import env_kwargs, make_model


def native(config: TrainConfig) -> Any:
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from agents.vec_env import GymnasiumVecEnv

    steps = round(config.episode_s / config.control_dt_s)
    vector_env = gym.make_vec(
        "DrillString-v0", num_envs=config.num_envs, max_episode_steps=steps, **env_kwargs(config)
    )
    return VecNormalize(VecMonitor(GymnasiumVecEnv(vector_env)), gamma=config.gamma)


def dummy(config: TrainConfig) -> Any:
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor, VecNormalize

    steps = round(config.episode_s / config.control_dt_s)
    kwargs = env_kwargs(config)

    def make() -> gym.Env[Any, Any]:
        return gym.make("DrillString-v0", max_episode_steps=steps, **kwargs)

    venv = DummyVecEnv([make] * config.num_envs)
    return VecNormalize(VecMonitor(venv), gamma=config.gamma)


def env_rate(venv: Any, steps: int) -> float:
    venv.seed(0)
    venv.reset()
    rng = np.random.default_rng(0)
    n = venv.num_envs
    t0 = time.perf_counter()
    for _ in range(steps // n):
        venv.step(rng.uniform(-1, 1, (n, 1)).astype(np.float32))
    return (steps // n) * n / (time.perf_counter() - t0)


def ppo_rate(venv: Any, config: TrainConfig, steps: int) -> float:
    import torch as th

    th.set_num_threads(config.torch_threads)
    model = make_model(config, venv)
    t0 = time.perf_counter()
    model.learn(total_timesteps=steps)
    return model.num_timesteps / (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--envs", type=int, default=TrainConfig.num_envs)
    parser.add_argument("--steps", type=int, default=50_000)
    args = parser.parse_args()
    config = dataclasses.replace(TrainConfig(), num_envs=args.envs)
    results: dict[str, tuple[float, float]] = {}
    for name, build in (("native vector env", native), ("DummyVecEnv", dummy)):
        venv = build(config)
        env_only = env_rate(venv, args.steps)
        venv.close()
        venv = build(config)
        end_to_end = ppo_rate(venv, config, args.steps)
        venv.close()
        results[name] = (env_only, end_to_end)
        print(
            f"{name:>18}: env alone {env_only:8.0f} decisions/s, PPO {end_to_end:6.0f} decisions/s"
        )
    (a_env, a_ppo), (b_env, b_ppo) = results.values()
    print(f"native / Dummy: env alone x{a_env / b_env:.2f}, PPO x{a_ppo / b_ppo:.2f}")


if __name__ == "__main__":
    main()
