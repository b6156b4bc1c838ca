"""How well the SMC's state observer estimates the string's state, and what it costs the
controller in closed loop (the numbers of docs/observer.md).

1. The estimate errors ``info["estimate_error_*"]`` after 20 s of a 100 s run of the proposed
   SMC in surface mode (sampled at every decision, 50 ms): the bit speed's maximum and rms,
   the top-drive and pipe speeds' maxima, for the nominal plants without and with noise, the
   4-DOF plant under the paper's uncertainty conditions without and with bit-speed telemetry,
   and randomized scenarios.
2. The episode metrics of the same SMC measuring the whole state and on its observer, for
   randomized scenarios of both envs.
3. The observer alone, open loop, on the surface signals of a recorded noise-free run of the
   field string (the SMC measuring the state, the sensors' 10 ms hold): with the string's own
   chain in 8 modes as its model, and with the string's 4-DOF ``lumped_equivalent``; and the
   slowest time constant of each filter's transition ``F`` (how long it remembers a
   correction) and the standard deviation of the bit-speed error the filter's own model
   predicts (its steady-state covariance).

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/observer_accuracy.py [--seeds 4]``.
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym
import numpy as np

import baselines  # noqa: F401  (registers the controllers)
import drill_env  # noqa: F401  (registers the envs)
from baselines.observer import (
    OS_ESTIMATE,
    ObserverGains,
    design_observer,
    initial_observer_state,
    observer_update,
    pack_observer,
)
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.layout import (
    M_APPLIED_TORQUE,
    M_SURFACE_TORQUE,
    M_TOP_DRIVE_SPEED,
    N_MEASUREMENT,
    REC_SURFACE_TORQUE,
    REC_TORQUE,
    REC_X0,
    X_BIT_SPEED,
)
from drill_env.modes import lumped_equivalent
from drill_env.parameters import PLANT_DT_S

QUIET = {"noise_std_rad_s": 0.0, "torque_noise_std_nm": 0.0, "telemetry_noise_std_rad_s": 0.0}
FAST_TELEMETRY = {"telemetry_period_s": 0.1, "telemetry_delay_s": 0.3}
TELEMETRY_NOISE = {"telemetry_noise_std_rad_s": 0.1}


def estimate_errors(env_id: str, seed: int, **kwargs: Any) -> np.ndarray:
    """Estimate errors x1..x7 at every decision after 20 s, (n, 7)."""
    env = gym.make(env_id, base_controller="proposed", max_episode_steps=-1, **kwargs)
    env.reset(seed=seed)
    names = env.unwrapped.batch.law_info().keys()  # type: ignore[attr-defined]
    keys = [k for k in names if k.startswith("estimate_error_")]
    rows = []
    done = False
    while not done:
        _, _, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
        done = terminated or truncated
        if info["time_s"] > 20.0:
            rows.append([info[k] for k in keys])
    return np.array(rows)


def open_loop(hold_steps: int = 10) -> None:
    """Section 3: the observer replayed on a recorded field run, two models."""
    env = gym.make(
        "DrillStringField-v0", base_controller="proposed", observation="state",
        randomize=False, max_episode_steps=-1, **QUIET,
    )  # fmt: skip
    records_of = env.unwrapped.batch.records  # type: ignore[attr-defined]
    env.reset(seed=0)
    chunks = []
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.zeros(1, dtype=np.float32))
        done = terminated or truncated
        chunks.append(records_of[0].copy())
    records = np.concatenate(chunks)
    n = records.shape[0]
    held = (np.arange(n) // hold_steps) * hold_steps
    m = np.full((n, N_MEASUREMENT), np.nan)
    m[:, M_TOP_DRIVE_SPEED] = records[held, REC_X0]
    m[:, M_SURFACE_TORQUE] = records[held, REC_SURFACE_TORQUE]
    m[1:, M_APPLIED_TORQUE] = records[:-1, REC_TORQUE]
    m[0, M_APPLIED_TORQUE] = 0.0
    string = env.unwrapped.batch.episodes[0].scenario.controller_model  # type: ignore[attr-defined]
    channel = env.unwrapped.config.measurement_channel(0.0)  # type: ignore[attr-defined]
    late = slice(round(20.0 / PLANT_DT_S), None)
    for label, model in (
        ("chain, 8 modes", string),
        ("lumped_equivalent", lumped_equivalent(string)),
    ):
        design = design_observer(model, channel, ObserverGains())
        lp, ls = pack_observer(design), initial_observer_state(design)
        bit = np.empty(n)
        for k in range(n):
            observer_update(lp, 0, ls, 0, m[k], PLANT_DT_S)
            bit[k] = ls[OS_ESTIMATE + X_BIT_SPEED]
        e = (bit - records[:, REC_X0 + X_BIT_SPEED])[late]
        slowest = float(np.abs(np.linalg.eigvals(design.F)).max())
        memory = -PLANT_DT_S / np.log(slowest)
        believed = float(np.sqrt(design.prediction_covariance[X_BIT_SPEED, X_BIT_SPEED]))
        print(
            f"| {label} | {abs(e).max():.3f} | {np.sqrt(np.mean(e**2)):.3f} | {memory:.2f} | "
            f"{believed:.2f} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=4, help="randomized scenarios per env")
    args = parser.parse_args()
    cases: list[tuple[str, str, int, dict[str, Any]]] = [
        ("4-DOF nominal, no noise", "DrillString-v0", 0,
         {"randomize": False, "observation": "surface", **QUIET}),
        ("4-DOF nominal, speed noise 0.1 rad/s", "DrillString-v0", 0,
         {"randomize": False, "observation": "surface"}),
        ("field nominal, no noise", "DrillStringField-v0", 0, {"randomize": False, **QUIET}),
        ("field nominal, defaults", "DrillStringField-v0", 1, {"randomize": False}),
        ("field nominal, defaults, no telemetry", "DrillStringField-v0", 1,
         {"randomize": False, "telemetry_period_s": None}),
        ("field nominal, defaults, telemetry 0.1 s, 0.3 s late", "DrillStringField-v0", 1,
         {"randomize": False, **FAST_TELEMETRY}),
    ]  # fmt: skip
    for condition in ("condition1", "condition2", "condition3"):
        base = {"randomize": False, "observation": "surface", "uncertainty": condition}
        cases.append((f"4-DOF {condition}", "DrillString-v0", 0, base))
        cases.append(
            (f"4-DOF {condition}, telemetry 0.1 s, 0.3 s late", "DrillString-v0", 0,
             {**base, **FAST_TELEMETRY, **TELEMETRY_NOISE})
        )  # fmt: skip
    for seed in range(1, args.seeds + 1):
        cases.append((f"4-DOF randomized seed {seed}", "DrillString-v0", seed,
                      {"observation": "surface"}))  # fmt: skip
        cases.append((f"field randomized seed {seed}", "DrillStringField-v0", seed, {}))
    print("| scenario | bit speed max (rad/s) | bit speed rms | top drive max | pipe max |")
    print("|---|---|---|---|---|")
    for label, env_id, seed, kwargs in cases:
        e = estimate_errors(env_id, seed, **kwargs)
        print(
            f"| {label} | {abs(e[:, 6]).max():.3f} | {np.sqrt(np.mean(e[:, 6] ** 2)):.3f} | "
            f"{abs(e[:, 0]).max():.3f} | {abs(e[:, 2]).max():.3f} |"
        )
    print()
    print(
        "| env | seed | IAE state / surface (rad) | RMSE (rad/s) | severity | "
        "chattering (N m/s) | diverged |"
    )
    print("|---|---|---|---|---|---|---|")
    for env_id in ("DrillString-v0", "DrillStringField-v0"):
        for seed in range(1, args.seeds + 1):
            m = {}
            for observation in ("state", "surface"):
                env = gym.make(
                    env_id, base_controller="proposed", observation=observation,
                    max_episode_steps=-1,
                )  # fmt: skip
                m[observation] = episode_metrics(rollout(env, ZeroAction(), seed=seed))
            cells = [
                f"{m['state'][k]:.3g} / {m['surface'][k]:.3g}"
                for k in ("iae", "rmse", "stick_slip_severity", "chattering_nm_per_s")
            ]
            print(f"| {env_id} | {seed} | {' | '.join(cells)} | {m['surface']['diverged']} |")
    print()
    print(
        "| observer's model (open loop, field string) | bit speed max (rad/s) | rms | "
        "slowest time constant of F (s) | the filter's own bit-speed std (rad/s) |"
    )
    print("|---|---|---|---|---|")
    open_loop()


if __name__ == "__main__":
    main()
