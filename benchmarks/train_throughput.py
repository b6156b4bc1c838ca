"""Decisions per second of the default training recipe (``agents.train`` with the default
``TrainConfig``: residual PPO on ``DrillString-v0``), in one process:

(a) its training environment alone (``agents.train.make_training_env``: the native vector env
    of ``num_envs`` randomised strings behind SB3's API, episode statistics and normalisation),
    stepped with zero actions (the base controller alone) and with random actions;
(b) with torch and stable-baselines3 installed: PPO with the default hyperparameters for
    ``--rollouts`` rollouts of ``n_steps * num_envs`` decisions, timed while it collects them
    (policy inference and the environment) and end to end (with the updates).

Each rate is the best of ``--repeat`` runs (CPU time of this process: steadier than the wall
clock on a shared machine). To compare two versions of the code, run this file with each on
the path, e.g. ``PYTHONPATH=<checkout>``.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/train_throughput.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import time

import numpy as np

import drill_env
from agents.config import TrainConfig
from agents.train import make_model, make_training_env


def env_rate(config: TrainConfig, decisions: int, action: str, repeat: int) -> float:
    """(a) Decisions per CPU second of the training env under zero or random actions."""
    venv = make_training_env(config)
    venv.seed(config.seed)
    venv.reset()
    n = venv.num_envs
    rng = np.random.default_rng(0)
    zeros = np.zeros((n, 1), dtype=np.float32)
    best = 0.0
    for _ in range(repeat):
        start = time.process_time()
        for _ in range(decisions // n):
            venv.step(zeros if action == "zero" else rng.uniform(-1, 1, (n, 1)).astype(np.float32))
        best = max(best, (decisions // n) * n / (time.process_time() - start))
    venv.close()
    return best


def ppo_rates(config: TrainConfig, rollouts: int, repeat: int) -> tuple[float, float]:
    """(b) Decisions per CPU second of PPO while collecting rollouts, and end to end."""
    import torch as th
    from stable_baselines3.common.callbacks import BaseCallback

    class RolloutTimer(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.collecting_s = 0.0
            self._start = 0.0

        def _on_rollout_start(self) -> None:
            self._start = time.process_time()

        def _on_rollout_end(self) -> None:
            self.collecting_s += time.process_time() - self._start

        def _on_step(self) -> bool:
            return True

    th.set_num_threads(config.torch_threads)
    best_collect = best_total = 0.0
    for _ in range(repeat):
        venv = make_training_env(config)
        model = make_model(config, venv)
        timer = RolloutTimer()
        start = time.process_time()
        model.learn(total_timesteps=rollouts * config.n_steps * config.num_envs, callback=timer)
        total_s = time.process_time() - start
        best_collect = max(best_collect, model.num_timesteps / timer.collecting_s)
        best_total = max(best_total, model.num_timesteps / total_s)
        venv.close()
    return best_collect, best_total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--decisions", type=int, default=32_000, help="decisions per environment-alone run"
    )
    parser.add_argument("--rollouts", type=int, default=1, help="PPO rollouts per run")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each measurement")
    args = parser.parse_args()
    config = dataclasses.replace(TrainConfig(), verbose=0)
    print(
        f"drill_env from {drill_env.__file__}\n"
        f"default recipe: {config.env_id}, base controller {config.base_controller}, "
        f"{config.num_envs} envs x {config.n_steps} steps per rollout, "
        f"{config.control_dt_s} s decisions"
    )
    for action in ("zero", "random"):
        rate = env_rate(config, args.decisions, action, args.repeat)
        print(f"(a) training env alone, {action + ' actions:':<16} {rate:10,.0f} decisions/s")
    if importlib.util.find_spec("torch") is None:
        print("(b) PPO: torch is not installed (pip install '.[rl]')")
        return
    collect, total = ppo_rates(config, args.rollouts, args.repeat)
    print(f"(b) PPO collecting rollouts:              {collect:10,.0f} decisions/s")
    print(f"(b) PPO end to end (rollouts + updates):  {total:10,.0f} decisions/s")


if __name__ == "__main__":
    main()
