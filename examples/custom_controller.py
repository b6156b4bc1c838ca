"""Plug your own controller into either env as its base controller.

Any object with ``reset()`` and ``torque(measurement, reference_speed_rad_s, dt_s)`` works; the
env calls it at every 1 ms plant step from Python (the slow path; the built-in controllers run
compiled inside the plant loop, and so can yours: see examples/compiled_controller.py). The
measurement (``drill_env.control.Measurement``) names its signals: here the top-drive speed
measured at surface, which both envs provide. A signal the env does not measure (the bit speed
on ``DrillStringField-v0``, which sees only surface signals and telemetry) raises an error that
names the env keyword providing it.

Here: a proportional-integral top-drive speed loop, which stick-slips at this low speed and high
WOB (docs/specification.md section 6): watch stuck_fraction.

Run: .venv/bin/python examples/custom_controller.py [--env DrillStringField-v0], or score it
beside the built-in controllers (importing the file runs no episode):
.venv/bin/drill-gym compare --controllers proposed examples/custom_controller.py:SpeedPI
"""

from __future__ import annotations

import argparse
from typing import Any

import gymnasium as gym

import drill_env  # noqa: F401  (registers DrillString-v0 and DrillStringField-v0)
from drill_env.control import Measurement
from drill_env.evaluation import ZeroAction, episode_metrics, rollout


class SpeedPI:
    """u = u_ff + kp (V_ref - w_dt) + ki * integral, with the steady drilling torque as
    feed-forward."""

    def __init__(self, kp: float = 2000.0, ki: float = 500.0, feedforward_nm: float = 13_000.0):
        self.kp, self.ki, self.feedforward_nm = kp, ki, feedforward_nm
        self.integral = 0.0

    def reset(self) -> None:
        self.integral = 0.0

    def torque(self, measurement: Measurement, reference_speed_rad_s: float, dt_s: float) -> float:
        error = reference_speed_rad_s - measurement.surface_top_drive_speed_rad_s
        self.integral += error * dt_s
        return self.feedforward_nm + self.kp * error + self.ki * self.integral


def main(env_id: str = "DrillString-v0", episode_s: float = 40.0) -> dict[str, Any]:
    """One run of :class:`SpeedPI` on ``env_id`` at 5 rad/s and 150 kN; returns its metrics."""
    env = gym.make(
        env_id,
        randomize=False,
        base_controller=SpeedPI(),
        reference_speed_rad_s=5.0,
        wob_n=150_000.0,
        episode_s=episode_s,
        control_dt_s=1.0,
    )
    return episode_metrics(rollout(env, ZeroAction(), seed=0))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--env", default="DrillString-v0", help="DrillString-v0 (default) or DrillStringField-v0"
    )
    parser.add_argument("--episode-s", type=float, default=40.0, help="run length, s")
    args = parser.parse_args()
    metrics = main(args.env, args.episode_s)
    print({k: round(v, 3) if isinstance(v, float) else v for k, v in metrics.items()})
