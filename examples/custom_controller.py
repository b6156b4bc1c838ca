"""Plug your own controller into DrillString-v0 as its base controller.

Any object with ``reset()`` and ``torque(measurement, reference_speed_rad_s, dt_s)`` works; the
env calls it at every 1 ms plant step from Python (the slow path; the built-in controllers run
compiled inside the plant loop, and so can yours: see examples/compiled_controller.py). Here: a proportional-integral top-drive speed loop, which
stick-slips at this low speed and high WOB (docs/specification.md section 6): watch
stuck_fraction.

Run: .venv/bin/python examples/custom_controller.py, or score it beside the built-in controllers:
.venv/bin/drill-gym compare --controllers proposed examples/custom_controller.py:SpeedPI
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import ZeroAction, episode_metrics, rollout


class SpeedPI:
    """u = kp (V_ref - w_dt) + ki * integral, with the steady drilling torque as feed-forward."""

    def __init__(self, kp: float = 2000.0, ki: float = 500.0, feedforward_nm: float = 13_000.0):
        self.kp, self.ki, self.feedforward_nm = kp, ki, feedforward_nm
        self.integral = 0.0

    def reset(self) -> None:
        self.integral = 0.0

    def torque(self, measurement: np.ndarray, reference_speed_rad_s: float, dt_s: float) -> float:
        error = reference_speed_rad_s - measurement[0]  # top-drive speed, rad/s
        self.integral += error * dt_s
        return self.feedforward_nm + self.kp * error + self.ki * self.integral


if __name__ == "__main__":  # importing the file (PATH.py:SpeedPI) runs nothing
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller=SpeedPI(),
        reference_speed_rad_s=5.0,
        wob_n=150_000.0,
        episode_s=40.0,
        control_dt_s=1.0,
    )
    metrics = episode_metrics(rollout(env, ZeroAction(), seed=0))
    print({k: round(v, 3) if isinstance(v, float) else v for k, v in metrics.items()})
