"""Decisions per second of the default training recipe (``agents.train`` with the default
``TrainConfig``: residual PPO on ``DrillString-v0``), in one process:

(a) its training environment alone (``agents.train.make_training_env``: the native vector env
    of ``num_envs`` randomised strings behind SB3's API, episode statistics and normalisation),
    stepped with zero actions (the base controller alone) and with random actions;
(b) with torch and stable-baselines3 installed: PPO with the default hyperparameters for
    ``--rollouts`` rollouts of ``n_steps * num_envs`` decisions, timed while it collects them
    (policy inference and the environment) and end to end (with the updates), and what the
    updates alone cost per decision; alternately, the same with the policy answering through
    SB3's own methods (the baseline of ``agents.ppo.LeanActorCriticPolicy``, same process);
(c) where a step of the training env goes: the compiled plant loops, the measurement-noise
    draws, the rest of the native vector env, and SB3's side (the adapter, episode statistics
    and normalisation), microseconds per step of all ``num_envs`` strings.

Each rate is the best of ``--repeat`` runs (CPU time of this process: steadier than the wall
clock on a shared machine). ``--against <checkout>`` compares with another version of the
code: this file runs ``--rounds`` times with each checkout on ``PYTHONPATH``, alternately, and
prints each rate's range, the ratio of the best rates and the median (and range) of the
rounds' ratios, each round's two runs being one after the other (the other version needs only
``drill_env`` and ``agents``).

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/train_throughput.py`` (from the checkout
to measure, or with it on ``PYTHONPATH``).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

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


def ppo_rates(config: TrainConfig, rollouts: int, repeat: int) -> dict[str, float]:
    """(b) Decisions per CPU second of PPO while collecting rollouts (``collect``), and end to
    end (``total``); CPU microseconds of the updates per decision (``update_us``, the least of
    the runs). Where ``make_model``'s policy is ``agents.ppo.LeanActorCriticPolicy``, each run
    is followed by one of the same model answering with SB3's own ``forward`` and
    ``evaluate_actions`` (``sb3_*``): the same numbers, a baseline in the same process."""
    import types

    import torch as th
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.policies import ActorCriticPolicy

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
    lean = importlib.util.find_spec("agents.ppo") is not None  # not in versions before it
    rates: dict[str, float] = {}
    for _ in range(repeat):
        for prefix in ("", "sb3_") if lean else ("",):  # alternately
            venv = make_training_env(config)
            model = make_model(config, venv)
            if prefix:
                for name in ("forward", "evaluate_actions"):
                    method = getattr(ActorCriticPolicy, name)
                    setattr(model.policy, name, types.MethodType(method, model.policy))
            timer = RolloutTimer()
            start = time.process_time()
            model.learn(total_timesteps=rollouts * config.n_steps * config.num_envs, callback=timer)
            total_s = time.process_time() - start
            measured = {
                "collect": model.num_timesteps / timer.collecting_s,
                "total": model.num_timesteps / total_s,
                "update_us": 1e6 * (total_s - timer.collecting_s) / model.num_timesteps,
            }
            for key, value in measured.items():  # the best: the highest rate, the least cost
                best = min if key == "update_us" else max
                rates[prefix + key] = best(rates.get(prefix + key, value), value)
            venv.close()
    return rates


def step_parts(config: TrainConfig, steps: int, repeat: int) -> dict[str, float]:
    """(c) CPU microseconds per step of the training env (random actions), by part: the
    kernel calls and the noise refills timed inside the native vector env, the native env's
    own rate, and the whole training env's (the least of ``repeat`` runs of each)."""
    venv = make_training_env(config)
    venv.seed(config.seed)
    venv.reset()
    native = venv
    while not hasattr(native, "batch"):  # down SB3's wrappers and the adapter
        native = native.venv if hasattr(native, "venv") else native.env
    batch = native.batch
    spent = {"kernel": 0.0, "noise": 0.0}

    def timed(name: str, function: Any) -> Any:
        def call(*args: Any) -> Any:
            start = time.process_time()
            result = function(*args)
            spent[name] += time.process_time() - start
            return result

        return call

    batch._advance = timed("kernel", batch._advance)
    batch._refill_noise = timed("noise", batch._refill_noise)
    rng = np.random.default_rng(0)
    actions = [rng.uniform(-1, 1, (venv.num_envs, 1)).astype(np.float32) for _ in range(100)]
    step_native = getattr(native, "step_without_info", native.step)
    parts = dict.fromkeys(("native", "training", "kernel", "noise"), float("inf"))
    for _ in range(repeat):  # the least of each, the two envs alternately
        for name, step in (("native", step_native), ("training", venv.step)):
            spent.update(kernel=0.0, noise=0.0)
            start = time.process_time()
            for k in range(steps):
                step(actions[k % 100])
            parts[name] = min(parts[name], 1e6 * (time.process_time() - start) / steps)
            if name == "native":
                parts["kernel"] = min(parts["kernel"], 1e6 * spent["kernel"] / steps)
                parts["noise"] = min(parts["noise"], 1e6 * spent["noise"] / steps)
    venv.close()
    return parts


def measure(args: argparse.Namespace) -> None:
    """Measure this version (the one on the path) and print the rates."""
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
    if importlib.util.find_spec("torch") is not None:
        rates = ppo_rates(config, args.rollouts, args.repeat)
        print(f"(b) PPO collecting rollouts:              {rates['collect']:10,.0f} decisions/s")
        print(f"(b) PPO end to end (rollouts + updates):  {rates['total']:10,.0f} decisions/s")
        print(
            f"(b) PPO updates alone:                    {rates['update_us']:10.1f} us per decision"
        )
        if "sb3_collect" in rates:
            print(
                f"    the same with SB3's MlpPolicy methods: collecting {rates['sb3_collect']:,.0f}"
                f" decisions/s, end to end {rates['sb3_total']:,.0f}, updates "
                f"{rates['sb3_update_us']:.1f} us (this version's policy: "
                f"x{rates['collect'] / rates['sb3_collect']:.2f}, "
                f"x{rates['total'] / rates['sb3_total']:.2f}, "
                f"x{rates['sb3_update_us'] / rates['update_us']:.2f})"
            )
    else:
        print("(b) PPO: torch is not installed (pip install '.[rl]')")
    parts = step_parts(config, max(1, args.decisions // config.num_envs), args.repeat)
    print(
        f"(c) per step of {config.num_envs} strings, us: plant loops {parts['kernel']:.0f}, "
        f"noise draws {parts['noise']:.0f}, rest of the vector env "
        f"{parts['native'] - parts['kernel'] - parts['noise']:.0f}, SB3 side "
        f"{parts['training'] - parts['native']:.0f}; training env {parts['training']:.0f}"
    )


RATE_LINE = re.compile(r"^\((a|b)\) (.+?):?\s+([\d,.]+) (decisions/s|us per decision)$")


def compare(args: argparse.Namespace) -> None:
    """Run this file alternately with this checkout and ``args.against`` on the path; print
    each rate's range per version, the ratio of the best and the rounds' ratios."""
    here = Path(__file__).resolve().parents[1]
    versions = {"this version": here, "other version": Path(args.against).resolve()}
    if not (versions["other version"] / "drill_env").is_dir():
        sys.exit(f"--against {args.against}: no drill_env package there")
    rates: dict[str, dict[str, list[float]]] = {name: {} for name in versions}
    options = ["--decisions", str(args.decisions), "--rollouts", str(args.rollouts)]
    options += ["--repeat", str(args.repeat)]
    for round_ in range(args.rounds):
        for name, root in versions.items():
            environment = dict(os.environ, PYTHONPATH=str(root))
            load = os.getloadavg()[0]
            print(f"round {round_ + 1}, {name} ({root}), load average {load:.1f}", flush=True)
            output = subprocess.run(
                [sys.executable, __file__, *options], env=environment, check=True,
                capture_output=True, text=True,
            ).stdout  # fmt: skip
            for line in output.splitlines():
                match = RATE_LINE.match(line)
                if match:
                    key = f"({match[1]}) {match[2]}"
                    rates[name].setdefault(key, []).append(float(match[3].replace(",", "")))
    print(
        f"\n{'':42} {'other version':>17} {'this version':>17} {'best/best':>9}"
        f" {'rounds: range, median':>22}"
    )
    for key, ours in rates["this version"].items():
        theirs = rates["other version"].get(key)
        if not theirs:
            continue
        # A rate's best is its highest; the updates' is a cost, the lowest.
        cost = key.startswith("(b) PPO updates alone")
        ratio = min(theirs) / min(ours) if cost else max(ours) / max(theirs)
        # each round's pair, run one after the other: steadier when the machine's speed drifts
        paired = sorted(t / o if cost else o / t for o, t in zip(ours, theirs, strict=True))
        print(
            f"{key:42} {min(theirs):8,.0f}-{max(theirs):<8,.0f} {min(ours):8,.0f}-{max(ours):<8,.0f}"
            f" {ratio:9.2f} {paired[0]:9.2f}-{paired[-1]:<5.2f} {float(np.median(paired)):6.2f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--decisions", type=int, default=32_000, help="decisions per environment-alone run"
    )
    parser.add_argument("--rollouts", type=int, default=1, help="PPO rollouts per run")
    parser.add_argument("--repeat", type=int, default=3, help="runs of each measurement")
    parser.add_argument(
        "--against", metavar="CHECKOUT", help="another version's checkout to compare with"
    )
    parser.add_argument("--rounds", type=int, default=2, help="alternate runs with --against")
    args = parser.parse_args()
    if args.against:
        compare(args)
    else:
        measure(args)


if __name__ == "__main__":
    main()
