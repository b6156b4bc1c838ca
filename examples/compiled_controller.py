"""Run your own controller at compiled speed inside the 1 ms plant loop.

A controller that also has ``compiled_law(model, torque_limits)`` hands the env a numba
``cfunc`` with the law signature ``drill_env.control.LAW_SIGNATURE``: it reads its parameter
vector and the measurement vector (``drill_env.layout.M_*``: here the top-drive speed measured
at surface, which both envs provide), updates its own state vector and returns the top-drive
torque in N m. The env's compiled loop calls it by
its address at every plant step, like the built-in controllers, with no Python call per step.
Here: the same speed PI as examples/custom_controller.py, compiled; both give the same run.

Run: .venv/bin/python examples/compiled_controller.py [--env DrillStringField-v0]
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
from numba import carray, cfunc

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.control import LAW_SIGNATURE, CompiledLaw, Measurement
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.layout import M_TOP_DRIVE_SPEED, N_MEASUREMENT


@cfunc(LAW_SIGNATURE, cache=True)
def speed_pi_law(params_ptr, state_ptr, measurement_ptr, reference_rad_s, dt_s):  # type: ignore[no-untyped-def]
    """u = u_ff + kp e + ki integral(e), e = V_ref - w_dt; params (kp, ki, u_ff), state (I,)."""
    params = carray(params_ptr, (3,))
    state = carray(state_ptr, (1,))
    measurement = carray(measurement_ptr, (N_MEASUREMENT,))
    error = reference_rad_s - measurement[M_TOP_DRIVE_SPEED]  # rad/s
    state[0] += error * dt_s
    return params[2] + params[0] * error + params[1] * state[0]


class CompiledSpeedPI:
    """The speed PI as a compiled controller (its Python ``torque`` is the slow-path twin)."""

    def __init__(self, kp: float = 2000.0, ki: float = 500.0, feedforward_nm: float = 13_000.0):
        self.params = np.array([kp, ki, feedforward_nm])
        self.integral = 0.0

    def reset(self) -> None:
        self.integral = 0.0

    def torque(self, measurement: Measurement, reference_speed_rad_s: float, dt_s: float) -> float:
        error = reference_speed_rad_s - measurement.surface_top_drive_speed_rad_s
        self.integral += error * dt_s
        return float(self.params[2] + self.params[0] * error + self.params[1] * self.integral)

    def compiled_law(self, model: object = None, torque_limits: object = None) -> CompiledLaw:
        # error_slot: the state entry the env reports as the controller's error signal (none).
        return CompiledLaw(speed_pi_law, self.params, np.zeros(1))


class PythonOnly:
    """Hides ``compiled_law``: the env then calls ``torque()`` from Python at every step."""

    def __init__(self, controller: CompiledSpeedPI) -> None:
        self.controller = controller

    def reset(self) -> None:
        self.controller.reset()

    def torque(self, measurement: Measurement, reference_speed_rad_s: float, dt_s: float) -> float:
        return self.controller.torque(measurement, reference_speed_rad_s, dt_s)


def main(env_id: str = "DrillString-v0", episode_s: float = 40.0) -> dict[str, dict[str, Any]]:
    """The compiled PI and its Python twin on ``env_id`` at 5 rad/s and 150 kN: their metrics
    and wall times (``wall_s``) by run."""
    scenario = {"randomize": False, "reference_speed_rad_s": 5.0, "wob_n": 150_000.0}
    runs = {"compiled": CompiledSpeedPI(), "python": PythonOnly(CompiledSpeedPI())}
    results = {}
    for name, controller in runs.items():
        env = gym.make(
            env_id, base_controller=controller, episode_s=episode_s, control_dt_s=1.0,
            **scenario,
        )  # fmt: skip
        start = time.perf_counter()
        metrics = episode_metrics(rollout(env, ZeroAction(), seed=0))
        results[name] = {**metrics, "wall_s": time.perf_counter() - start}
    return results


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--env", default="DrillString-v0", help="DrillString-v0 (default) or DrillStringField-v0"
    )
    parser.add_argument("--episode-s", type=float, default=40.0, help="run length, s")
    args = parser.parse_args()
    for name, metrics in main(args.env, args.episode_s).items():
        print(
            f"{name:>8}: IAE {metrics['iae']:.2f} rad, stuck fraction "
            f"{metrics['stuck_fraction']:.3f}, {metrics['wall_s']:.2f} s wall"
        )
