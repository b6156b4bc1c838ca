"""Simulated seconds per wall second of the distributed-string plant step, in one process.

For the ``field_2500m`` string discretised into 25, 50, 100, 200 and 400 elements (the element
length is chosen so that the count is exact), this prints the throughput of

(a) ``drill_env.chain.chain_step``, the event-located step the kernel uses, on an open-loop
    stick-slip run (constant torque 9,500 N m, WOB 100 kN: the bit sticks and slips), and
(b) a plain compiled RK4 of the same chain (interleaved state, ``chain_derivative``, frozen slip
    mode, no events), the textbook implementation,

their ratio, the cost per element and step, and a straight-line fit of the cost per step against
the element count (a fixed part per step plus a part per element); then, for 25, 100 and 400
elements, the whole environment:

(c) one ``DrillStringField-v0`` through ``gym.make`` with its field defaults (surface
    signals, telemetry, actuator), stepped with a constant action: the full observation,
    reward and info path, and
(d) the batched kernel under the native vector env, 64 strings, serial and on numba's threads
    (aggregate simulated seconds of all strings per wall second),

each beside (b) in the same run.
All numbers are warm (compiled code cached, one untimed warm-up run). The machine is shared, so
only the ratios measured in the same run are meaningful.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/chain_throughput.py [--seconds 2]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import gymnasium as gym
import numpy as np
from numba import njit

import drill_env  # noqa: F401  (registers DrillStringField-v0)
from drill_env import kernel
from drill_env.chain import chain_derivative, chain_parameter_vector, chain_step, chain_work
from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    section_element_counts,
)
from drill_env.friction import STUCK

WOB_N = 100e3
TORQUE_NM = 9_500.0
STEP_S = 1e-3


def string_with_elements(count: int) -> DistributedStringParameters:
    """``field_2500m`` with the longest element length that gives exactly ``count`` elements."""
    base = DISTRIBUTED_PRESETS["field_2500m"]
    for length in np.linspace(400.0, 1.0, 400_000):
        p = dataclasses.replace(base, element_length_m=float(length))
        if sum(section_element_counts(p)) == count:
            return p
    raise ValueError(f"no element length gives {count} elements")


@njit(cache=True)
def _run_chain_step(x, mode, p, t_a, t_0, u, h, n_steps, work) -> tuple[int, int]:
    switches = 0
    for _ in range(n_steps):
        new_mode = chain_step(x, mode, u, p, t_a, t_0, h, work)
        if new_mode != mode:
            switches += 1
        mode = new_mode
    return mode, switches


@njit(cache=True)
def _run_plain_rk4(x, p, t_a, t_0, u, h, n_steps, k1, k2, k3, k4, tmp) -> None:
    size = x.shape[0]
    for _ in range(n_steps):
        chain_derivative(x, u, p, t_a, t_0, 1, k1)
        for j in range(size):
            tmp[j] = x[j] + 0.5 * h * k1[j]
        chain_derivative(tmp, u, p, t_a, t_0, 1, k2)
        for j in range(size):
            tmp[j] = x[j] + 0.5 * h * k2[j]
        chain_derivative(tmp, u, p, t_a, t_0, 1, k3)
        for j in range(size):
            tmp[j] = x[j] + h * k3[j]
        chain_derivative(tmp, u, p, t_a, t_0, 1, k4)
        for j in range(size):
            x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


def measure(count: int, seconds: float) -> tuple[int, float, float, int]:
    """(elements, chain_step sim-s/s, plain RK4 sim-s/s, mode switches seen) for one string."""
    params = string_with_elements(count)
    p = chain_parameter_vector(params)
    n = int(p[0])
    t_a = params.static_torque_nm(WOB_N)
    t_0 = params.sliding_torque_nm(WOB_N)
    work = chain_work(n)
    size = 2 * n - 1
    scratch = [np.zeros(size) for _ in range(5)]
    n_steps = 1000
    _run_chain_step(np.zeros(size), STUCK, p, t_a, t_0, TORQUE_NM, STEP_S, n_steps, work)
    _run_plain_rk4(np.zeros(size), p, t_a, t_0, TORQUE_NM, STEP_S, n_steps, *scratch)

    def rate(call) -> float:
        best = 0.0
        for _ in range(3):  # best of three: the machine is shared
            steps = 0
            start = time.perf_counter()
            while time.perf_counter() - start < seconds / 3:
                call()
                steps += n_steps
            best = max(best, steps * STEP_S / (time.perf_counter() - start))
        return best

    x_event = np.zeros(size)  # from rest, bit stuck; the mode is carried from call to call
    state = [STUCK, 0]  # mode, switches

    def event_run() -> None:
        mode, switches = _run_chain_step(
            x_event, state[0], p, t_a, t_0, TORQUE_NM, STEP_S, n_steps, work
        )
        state[0] = mode
        state[1] += switches

    x_plain = np.zeros(size)
    x_plain[0::2] = 5.0  # slipping, well away from any event

    def plain_run() -> None:
        _run_plain_rk4(x_plain, p, t_a, t_0, TORQUE_NM, STEP_S, n_steps, *scratch)

    event_rate = rate(event_run)
    plain_rate = rate(plain_run)
    return n - 1, event_rate, plain_rate, state[1]


def env_rate(params: DistributedStringParameters, seconds: float) -> float:
    """(c) Simulated s per wall s of one ``gym.make`` env with the field defaults."""
    env = gym.make("DrillStringField-v0", parameters=params, randomize=False, episode_s=1e5)
    env.reset(seed=0)
    action = np.zeros(1, dtype=np.float32)
    for _ in range(20):
        env.step(action)
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        env.step(action)
        steps += 1
    return steps * 0.05 / (time.perf_counter() - start)


def batch_rate(params: DistributedStringParameters, seconds: float, parallel: bool) -> float:
    """(d) Aggregate simulated s per wall s of 64 strings in the batched kernel."""
    venv = gym.make_vec(
        "DrillStringField-v0", num_envs=64, parameters=params, randomize=False,
        episode_s=1e5, control_dt_s=0.5,
    )  # fmt: skip
    venv.reset(seed=0)
    batch = venv.unwrapped.batch  # type: ignore[attr-defined]
    dispatcher = kernel.advance_chain_batch_parallel if parallel else kernel.advance_chain_batch
    batch._advance = kernel.fast_entry(dispatcher, batch._kernel_input, batch.settings)
    actions = np.zeros(64)
    batch.step(actions)
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        batch.step(actions)
        steps += 1
    return steps * 0.5 * 64 / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="wall time per measurement")
    args = parser.parse_args()
    print(f"field_2500m, WOB {WOB_N:.0f} N, constant torque {TORQUE_NM:.0f} N m, step {STEP_S} s")
    print(
        f"{'elements':>8} {'chain_step sim-s/s':>19} {'plain RK4 sim-s/s':>18} "
        f"{'ratio':>6} {'ns/element/step':>16} {'switches':>9}"
    )
    sizes, costs = [], []
    for count in (25, 50, 100, 200, 400):
        elements, event_rate, plain_rate, switches = measure(count, args.seconds)
        per_element = 1e9 * STEP_S / event_rate / elements
        print(
            f"{elements:>8} {event_rate:>19,.0f} {plain_rate:>18,.0f} "
            f"{event_rate / plain_rate:>6.2f} {per_element:>16.2f} {switches:>9}"
        )
        sizes.append(elements)
        costs.append(1e9 * STEP_S / event_rate)  # ns of wall time per step
    slope, intercept = np.polyfit(sizes, costs, 1)
    worst = max(abs(c - (intercept + slope * e)) / c for e, c in zip(sizes, costs, strict=True))
    print(
        f"chain_step cost per step = {intercept:.0f} ns + {slope:.2f} ns x elements "
        f"(least-squares line over the sizes, worst deviation {worst:.0%})"
    )
    print()
    print(
        f"{'elements':>8} {'gym.make env':>13} {'batch serial':>13} {'batch threads':>14} "
        f"{'plain RK4':>10}  (sim-s/s; env / RK4)"
    )
    for count in (25, 100, 400):
        params = string_with_elements(count)
        elements, _, plain_rate, _ = measure(count, args.seconds / 2)
        single = env_rate(params, args.seconds)
        serial = batch_rate(params, args.seconds, parallel=False)
        threads = batch_rate(params, args.seconds, parallel=True)
        print(
            f"{elements:>8} {single:>13,.0f} {serial:>13,.0f} {threads:>14,.0f} "
            f"{plain_rate:>10,.0f}  ({single / plain_rate:.2f})"
        )


if __name__ == "__main__":
    main()
