"""Run the paper's proposed adaptive SMC on the default scenario and print its metrics.

Run: .venv/bin/python examples/quickstart.py
"""

from __future__ import annotations

import gymnasium as gym

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import ZeroAction, episode_metrics, rollout

# The paper's protocol (docs/specification.md section 2): WOB 97,347 N, V_ref 12 rad/s,
# 150 s from rest.
env = gym.make(
    "DrillString-v0",
    randomize=False,
    base_controller="proposed",  # runs inside the 1 ms plant loop
    noise_std_rad_s=0.0,
    episode_s=150.0,
    control_dt_s=0.5,  # the agent's decision period; the base controller still acts every 1 ms
)
trace = rollout(env, ZeroAction(), seed=0)  # zero residual: the base controller alone
for key, value in episode_metrics(trace).items():
    print(f"{key:>22}: {value}")
