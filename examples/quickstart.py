"""Run the paper's proposed adaptive SMC on the default scenario and print its metrics.

On ``DrillStringField-v0`` the same controller runs on the distributed field string from the
surface signals (its state observer estimates the rest).

Run: .venv/bin/python examples/quickstart.py [--env DrillStringField-v0]
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym

import drill_env  # noqa: F401  (registers DrillString-v0 and DrillStringField-v0)
from drill_env.evaluation import ZeroAction, episode_metrics, rollout


def main(env_id: str = "DrillString-v0", episode_s: float = 150.0) -> dict[str, Any]:
    """The proposed SMC alone (zero residual) on ``env_id``; returns its metrics."""
    # The paper's protocol (docs/specification.md section 2): WOB 97,347 N, V_ref 12 rad/s,
    # 150 s from rest.
    env = gym.make(
        env_id,
        randomize=False,
        wob_n=97_347.0,
        reference_speed_rad_s=12.0,
        base_controller="proposed",  # runs inside the 1 ms plant loop
        noise_std_rad_s=0.0,
        episode_s=episode_s,
        control_dt_s=0.5,  # the agent's decision period; the base controller still acts every 1 ms
    )
    trace = rollout(env, ZeroAction(), seed=0)  # zero residual: the base controller alone
    return episode_metrics(trace)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--env", default="DrillString-v0", help="DrillString-v0 (default) or DrillStringField-v0"
    )
    parser.add_argument("--episode-s", type=float, default=150.0, help="run length, s")
    args = parser.parse_args()
    for key, value in main(args.env, args.episode_s).items():
        print(f"{key:>22}: {value}")
