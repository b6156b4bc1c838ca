"""Simulated seconds per wall second of the drill-string engine, in one process.

Prints, for the default scenario (100 s episodes, 50 ms decisions, noise on):

(a) one env through ``gym.make("DrillString-v0")``, the full observation/reward/info path;
(b) the raw batched kernel at N = 1024 strings (aggregate), serial and with numba threads;
(c) a naive per-step numpy implementation of the same dynamics (matrix form, RK4, Karnopp);

and the ratios between them. Then, side by side, the single env against the compiled floor of
the same plant: the same configuration under the same constant action run in compiled calls
of 10 s (a batch of one), in direct mode and in residual mode on ``proposed``,
and ``DrillStringField-v0`` with its field defaults against its own floor (each with
``randomize=False``, so that env and floor run the same string: the nominal scenario); the rates are
measured in alternating slices of CPU time (the machine is shared) and the best slice of each
is kept.

Run: ``.venv/bin/python benchmarks/step_throughput.py``.
Thread pools: set ``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1`` (scripts/ do) so that BLAS does
not fight numba's threads on 2 cores.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import gymnasium as gym
import numba
import numpy as np

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env import kernel
from drill_env.batch import StringBatch
from drill_env.layout import REP_TIME, STATUS_OK
from drill_env.options import EnvConfig, FieldEnvConfig
from drill_env.parameters import PRESETS

WOB_N = 97_347.0


def env_throughput(seconds: float, **kwargs: object) -> float:
    """(a) Simulated s per wall s of one gym.make env stepped with a constant action."""
    env = gym.make("DrillString-v0", **kwargs)
    env.reset(seed=0)
    # 13 kN m in direct mode (about the steady drilling torque), no residual in residual mode.
    residual = env.unwrapped.config.residual
    action = np.array([0.0 if residual else 2 * 13_000 / 50_000 - 1], dtype=np.float32)
    for _ in range(50):  # warm up (compilation is cached, but first calls allocate)
        env.step(action)
    dt = env.unwrapped.config.control_dt_s
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(200):
            _, _, terminated, truncated, _ = env.step(action)
            steps += 1
            if terminated or truncated:
                env.reset()
    return steps * dt / (time.perf_counter() - start)


def _constant_action(config: EnvConfig) -> float:
    """13 kN m in direct mode (about the steady drilling torque of the 4-DOF string), no
    residual in residual mode."""
    return 0.0 if config.residual else 2 * 13_000 / config.max_torque_nm - 1


def _env_stepper(env_id: str, **kwargs: object) -> tuple[object, float]:
    """A ``gym.make`` env ready to step with a constant action, and its decision period, s."""
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    config = env.unwrapped.config  # type: ignore[attr-defined]
    action = np.array([_constant_action(config)], dtype=np.float32)
    for _ in range(50):
        env.step(action)

    def run(seconds: float) -> float:
        steps = 0
        start = time.process_time()
        while time.process_time() - start < seconds:
            for _ in range(100):
                _, _, terminated, truncated, _ = env.step(action)
                steps += 1
                if terminated or truncated:
                    env.reset()
        return steps

    return run, env.unwrapped.config.control_dt_s  # type: ignore[attr-defined]


def _floor_stepper(config: EnvConfig) -> tuple[object, float]:
    """The same episodes of the same plant (from rest, reset without a seed at their end, as
    the env's) as compiled calls of 10 s (the longest decision period: a call's own cost is
    then below 0.1 % of it) on a batch of one under the env's constant action, and that
    period, s."""
    whole = dataclasses.replace(config, control_dt_s=10.0)
    batch = StringBatch(whole, 1)
    batch.reset_string(0, 0, None)
    action = np.array([float(np.float32(_constant_action(config)))])
    duration_s = whole.episode_s

    def run(seconds: float) -> float:
        calls = 0
        start = time.process_time()
        while time.process_time() - start < seconds:
            batch.step(action)
            calls += 1
            if batch.report[0, REP_TIME] >= duration_s or batch.status[0] != STATUS_OK:
                batch.reset_string(0, None, None)
        return calls

    run(0.0)
    return run, whole.control_dt_s


def side_by_side(seconds: float, env_id: str, **kwargs: object) -> tuple[float, float]:
    """(env, floor) simulated s per wall s of one ``gym.make`` env and of its compiled floor,
    measured alternately in slices; the best slice of each. The time is this process's CPU
    time (one thread each: on a shared machine it is steadier than the wall clock)."""
    env_run, env_dt = _env_stepper(env_id, **kwargs)
    config_type = FieldEnvConfig if env_id == "DrillStringField-v0" else EnvConfig
    floor_run, floor_dt = _floor_stepper(config_type.from_kwargs(dict(kwargs)))
    best_env = best_floor = 0.0
    rounds = 6
    for _ in range(rounds):
        start = time.process_time()
        steps = env_run(seconds / (2 * rounds))  # type: ignore[operator]
        best_env = max(best_env, steps * env_dt / (time.process_time() - start))
        start = time.process_time()
        episodes = floor_run(seconds / (2 * rounds))  # type: ignore[operator]
        best_floor = max(best_floor, episodes * floor_dt / (time.process_time() - start))
    return best_env, best_floor


def kernel_throughput(num: int, seconds: float, parallel: bool) -> float:
    """(b) Aggregate simulated s per wall s of the raw batched kernel for ``num`` strings."""
    config = EnvConfig(randomize=False, base_controller="proposed", control_dt_s=1.0, episode_s=1e4)
    batch = StringBatch(config, num)
    for i in range(num):
        batch.reset_string(i, i, None)
    dispatcher = kernel.advance_batch_parallel if parallel else kernel.advance_batch
    batch._advance = kernel.fast_entry(dispatcher, batch._kernel_input, batch.settings)
    actions = np.zeros(num)
    batch.step(actions)  # warm up
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        batch.step(actions)
        steps += 1
    return steps * config.control_dt_s * num / (time.perf_counter() - start)


def _naive_derivative(
    x: np.ndarray, u: float, a: np.ndarray, b: np.ndarray, p, stuck: bool
) -> np.ndarray:
    t_a = p.mu_a * WOB_N * p.R
    t_0 = p.mu_0 * WOB_N * p.R
    dx = a @ x + b * u
    if stuck:
        dx[6] = 0.0
    else:
        dx[6] -= math.copysign(t_0 + (t_a - t_0) * math.exp(-p.xi * abs(x[6])), x[6]) / p.J_bi
    return dx


def naive_throughput(seconds: float) -> float:
    """(c) Simulated s per wall s of a per-step numpy RK4 with a simple stick rule."""
    p = PRESETS["zribi2024"]
    a = np.zeros((7, 7))
    a[0, :3] = [-(p.c_dt + p.c_pi) / p.J_dt, -p.k_pi / p.J_dt, p.c_pi / p.J_dt]
    a[1, [0, 2]] = [1.0, -1.0]
    a[2, :5] = [
        p.c_pi / p.J_pi,
        p.k_pi / p.J_pi,
        -(p.c_pi + p.c_co) / p.J_pi,
        -p.k_co / p.J_pi,
        p.c_co / p.J_pi,
    ]
    a[3, [2, 4]] = [1.0, -1.0]
    a[4, 2:7] = [
        p.c_co / p.J_co,
        p.k_co / p.J_co,
        -(p.c_co + p.c_bi) / p.J_co,
        -p.k_bi / p.J_co,
        p.c_bi / p.J_co,
    ]
    a[5, [4, 6]] = [1.0, -1.0]
    a[6, 4:7] = [p.c_bi / p.J_bi, p.k_bi / p.J_bi, -(p.c_bi + p.c_bit) / p.J_bi]
    b = np.zeros(7)
    b[0] = 1.0 / p.J_dt
    t_a = p.mu_a * WOB_N * p.R
    h = 1e-3
    x = np.zeros(7)
    stuck = True
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(1000):
            u = 13_000.0
            k1 = _naive_derivative(x, u, a, b, p, stuck)
            k2 = _naive_derivative(x + 0.5 * h * k1, u, a, b, p, stuck)
            k3 = _naive_derivative(x + 0.5 * h * k2, u, a, b, p, stuck)
            k4 = _naive_derivative(x + h * k3, u, a, b, p, stuck)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            t_e = p.c_bi * (x[4] - x[6]) + p.k_bi * x[5] - p.c_bit * x[6]
            if stuck:
                stuck = abs(t_e) <= t_a
            elif abs(x[6]) < p.Dw or x[6] < 0:
                x[6] = 0.0
                stuck = abs(t_e) <= t_a
            steps += 1
    return steps * h / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="wall time per measurement")
    parser.add_argument("--num", type=int, default=1024, help="strings in the batched run")
    parser.add_argument(
        "--side-by-side-only", action="store_true", help="only the env-beside-floor ratios"
    )
    args = parser.parse_args()
    print(
        f"numba threads: {numba.get_num_threads()}, threading layer: {numba.config.THREADING_LAYER}"
    )
    if args.side_by_side_only:
        _print_side_by_side(args.seconds)
        return
    results = {
        "(a) gym.make env, direct": env_throughput(args.seconds),
        "(a') gym.make env, residual on proposed": env_throughput(
            args.seconds, base_controller="proposed"
        ),
        f"(b) batched kernel N={args.num}, serial": kernel_throughput(
            args.num, args.seconds, False
        ),
        f"(b') batched kernel N={args.num}, threads": kernel_throughput(
            args.num, args.seconds, True
        ),
        "(c) naive numpy per-step": naive_throughput(args.seconds),
    }
    naive = results["(c) naive numpy per-step"]
    print(f"{'run':<44} {'sim s / wall s':>15} {'x naive':>9}")
    for name, value in results.items():
        print(f"{name:<44} {value:>15,.0f} {value / naive:>9.1f}")
    a = results["(a) gym.make env, direct"]
    b = max(v for k, v in results.items() if k.startswith("(b"))
    print(f"batched kernel / single env: {b / a:.1f}")
    print()
    _print_side_by_side(args.seconds)


def _print_side_by_side(seconds: float) -> None:
    print(f"{'one env beside its compiled floor':<44} {'env':>9} {'floor':>9} {'ratio':>6}")
    for label, env_id, kwargs in (
        ("DrillString-v0, direct", "DrillString-v0", {"randomize": False}),
        (
            "DrillString-v0, residual on proposed",
            "DrillString-v0",
            {"randomize": False, "base_controller": "proposed"},
        ),
        ("DrillStringField-v0, field defaults", "DrillStringField-v0", {"randomize": False}),
    ):
        env_rate, floor_rate = side_by_side(2 * seconds, env_id, **kwargs)
        print(f"{label:<44} {env_rate:>9,.0f} {floor_rate:>9,.0f} {env_rate / floor_rate:>6.2f}")


if __name__ == "__main__":
    main()
