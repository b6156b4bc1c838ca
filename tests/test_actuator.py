"""The top drive as an actuator (drill_env.actuator) in the env's loop: dead time, an exact
first-order lag, the rate limit and their combination against closed-form step responses, the
ideal actuator as the identity, the command and the applied torque in info, and bad actuator
keywords."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from drill_env.actuator import lag_factor
from drill_env.layout import REC_COMMAND, REC_TORQUE
from drill_env.parameters import PLANT_DT_S

DT = PLANT_DT_S
MAX_NM = 50_000.0  # DrillString-v0's torque range is [0, 50,000] N m


def _torques(actions: list[float], control_dt_s: float = 0.001, **kwargs: Any) -> np.ndarray:
    """(command, applied) at every plant step of a direct-mode DrillString-v0 run with
    ``actions``, (steps, 2), N m."""
    env = gym.make(
        "DrillString-v0", randomize=False, noise_std_rad_s=0.0, control_dt_s=control_dt_s,
        max_episode_steps=-1, **kwargs,
    )  # fmt: skip
    records = env.unwrapped.batch.records  # type: ignore[attr-defined]
    env.reset(seed=0)
    rows = []
    for a in actions:
        env.step(np.array([a], dtype=np.float32))
        rows.append(records[0][:, [REC_COMMAND, REC_TORQUE]].copy())
    return np.concatenate(rows)


def _command(action: float) -> float:
    """The direct-mode command of ``action``: ``min + (a + 1) / 2 (max - min)``, N m."""
    return (float(np.float32(action)) + 1.0) / 2.0 * MAX_NM


STEP_ACTIONS = [-1.0] * 5 + [0.6] * 200  # 0 N m for 5 ms, then a step to 40,000 N m


def test_dead_time_delays_the_command_by_whole_steps() -> None:
    """With a dead time of D steps alone, the applied torque is the command of D steps ago
    (0 before), exactly, for any command sequence."""
    rng = np.random.default_rng(0)
    actions = list(rng.uniform(-1, 1, 300))
    t = _torques(actions, actuator_dead_time_s=0.017)
    np.testing.assert_array_equal(t[17:, 1], t[:-17, 0])
    np.testing.assert_array_equal(t[:17, 1], 0.0)


def test_lag_is_the_exact_first_order_step_response() -> None:
    """Dead time D = 10 ms and lag tau = 30 ms: a command step U at step s acts from step
    s + D; over step j the drive applies U (1 - exp(-(j - s - D + 1) dt / tau)), the first-order
    response at the end of the step (to 1e-9 relative)."""
    t = _torques(STEP_ACTIONS, actuator_dead_time_s=0.01, actuator_lag_s=0.03)
    u, start = _command(0.6), 5 + 10
    assert (t[:start, 1] == 0.0).all()
    j = np.arange(start, len(t))
    expected = u * -np.expm1(-(j - start + 1) * DT / 0.03)
    np.testing.assert_allclose(t[start:, 1], expected, rtol=1e-9)
    assert t[-1, 1] == pytest.approx(u, rel=1e-2)
    assert lag_factor(0.03, DT) == pytest.approx(1.0 - math.exp(-DT / 0.03), rel=1e-15)


def test_rate_limit_ramps_the_torque_at_the_configured_rate() -> None:
    """A rate limit R alone: after a command step the torque ramps by R dt per step (a
    straight line to the command) and then holds it."""
    rate = 2e6  # N m/s: 2,000 N m per step, 20 steps to 40,000 N m
    t = _torques(STEP_ACTIONS, torque_rate_limit_nm_per_s=rate)
    u = _command(0.6)
    j = np.arange(len(t))
    expected = np.where(j < 5, 0.0, np.minimum(u, rate * DT * (j - 4)))
    np.testing.assert_allclose(t[:, 1], expected, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(np.diff(t[5:40, 1]) <= rate * DT * (1 + 1e-12), True)


def test_lag_and_rate_limit_combine_step_by_step() -> None:
    """Lag and rate limit together: each step's change is the lag's, capped at R dt (an
    independent recursion of the documented rule)."""
    rate, tau = 5e5, 0.02
    t = _torques(STEP_ACTIONS, actuator_lag_s=tau, torque_rate_limit_nm_per_s=rate)
    factor = -math.expm1(-DT / tau)
    applied, expected = 0.0, []
    for command in t[:, 0]:
        applied += float(np.clip((command - applied) * factor, -rate * DT, rate * DT))
        expected.append(applied)
    np.testing.assert_allclose(t[:, 1], expected, rtol=1e-12, atol=1e-9)
    assert (np.abs(np.diff(t[:, 1])) <= rate * DT * (1 + 1e-12)).all()
    assert np.abs(np.diff(t[:, 1])).max() == pytest.approx(rate * DT)  # the limit binds


def test_ideal_actuator_is_the_identity() -> None:
    """No dead time, lag or rate limit: the applied torque is the command at every step, in
    direct mode and with a base controller."""
    rng = np.random.default_rng(1)
    t = _torques(list(rng.uniform(-1, 1, 200)))
    np.testing.assert_array_equal(t[:, 1], t[:, 0])
    env = gym.make("DrillString-v0", base_controller="proposed", max_episode_steps=-1)
    records = env.unwrapped.batch.records  # type: ignore[attr-defined]
    env.reset(seed=2)
    for a in rng.uniform(-1, 1, 50):
        env.step(np.array([a], dtype=np.float32))
        np.testing.assert_array_equal(records[0, :, REC_TORQUE], records[0, :, REC_COMMAND])


@pytest.mark.parametrize("env_id", ["DrillString-v0", "DrillStringField-v0"])
def test_info_holds_the_command_and_the_applied_torque(env_id: str) -> None:
    """``torque_command_nm`` is the last plant step's command, ``top_drive_torque_nm`` the
    torque applied over it (they differ under the field's actuator), both within the torque
    range."""
    kwargs: dict[str, Any] = {"base_controller": "soft_speed", "max_episode_steps": -1}
    if env_id == "DrillString-v0":
        kwargs.update(actuator_dead_time_s=0.02, actuator_lag_s=0.05)
    env = gym.make(env_id, **kwargs)
    records = env.unwrapped.batch.records  # type: ignore[attr-defined]
    env.reset(seed=0)
    upper = env.unwrapped.config.max_torque_nm  # type: ignore[attr-defined]
    differed = False
    for a in np.random.default_rng(3).uniform(-1, 1, 40):
        _, _, _, _, info = env.step(np.array([a], dtype=np.float32))
        assert info["torque_command_nm"] == records[0, -1, REC_COMMAND]
        assert info["top_drive_torque_nm"] == records[0, -1, REC_TORQUE]
        assert 0.0 <= info["top_drive_torque_nm"] <= upper
        differed |= info["torque_command_nm"] != info["top_drive_torque_nm"]
    assert differed


def test_actuator_restarts_at_rest_every_episode() -> None:
    """A reset empties the dead-time line and the lag: the second episode starts like the
    first."""
    env = gym.make(
        "DrillString-v0", randomize=False, control_dt_s=0.001, actuator_dead_time_s=0.01,
        actuator_lag_s=0.02, torque_rate_limit_nm_per_s=1e6, max_episode_steps=-1,
    )  # fmt: skip
    records = env.unwrapped.batch.records  # type: ignore[attr-defined]
    runs = []
    for _ in range(2):
        env.reset(seed=0)
        rows = []
        for a in STEP_ACTIONS[:60]:
            env.step(np.array([a], dtype=np.float32))
            rows.append(records[0, 0, REC_TORQUE])
        runs.append(rows)
    assert runs[0] == runs[1]
    assert runs[0][10] == 0.0 and runs[0][-1] > 0.0


@pytest.mark.parametrize(
    ("keywords", "error", "message"),
    [
        ({"actuator_dead_time_s": 2.5}, ValueError,
         r"actuator_dead_time_s = 2.5 is out of range: allowed \[0, 2\]"),
        ({"actuator_dead_time_s": -0.01}, ValueError,
         r"actuator_dead_time_s = -0.01 is out of range: allowed \[0, 2\]"),
        ({"actuator_dead_time_s": 0.0125}, ValueError,
         r"actuator_dead_time_s = 0.0125 is out of range: allowed a multiple of plant_dt = "
         r"0.001 s"),
        ({"actuator_lag_s": -0.1}, ValueError,
         r"actuator_lag_s = -0.1 is out of range: allowed \[0, 10\]"),
        ({"torque_rate_limit_nm_per_s": 0.0}, ValueError,
         r"torque_rate_limit_nm_per_s = 0.0 is out of range: allowed \(0, 1e\+09\] \(or None: "
         r"no limit\)"),
        ({"torque_rate_limit_nm_per_s": -5.0}, ValueError,
         r"torque_rate_limit_nm_per_s = -5.0 is out of range: allowed \(0, 1e\+09\]"),
        ({"torque_rate_limit_nm_per_s": math.inf}, ValueError,
         r"torque_rate_limit_nm_per_s = inf is out of range"),
        ({"actuator_lag_s": "fast"}, TypeError,
         r"actuator_lag_s must be a real number, got 'fast' \(str\)"),
    ],
)  # fmt: skip
@pytest.mark.parametrize("env_id", ["DrillString-v0", "DrillStringField-v0"])
def test_bad_actuator_keywords_are_clear_errors(
    env_id: str, keywords: dict[str, Any], error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        gym.make(env_id, **keywords)
