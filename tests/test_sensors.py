"""The measurement channel (drill_env.sensors) as the envs deliver it: the telemetry's sample
instants, delivery, hold and age against the true bit speed at the sample instant; the surface
signals' sampling and hold; no downhole data without telemetry; determinism and the native
vector env with every channel feature on; bad channel keywords."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from drill_env.layout import (
    M_STATE,
    M_SURFACE_TORQUE,
    M_TELEMETRY_AGE,
    M_TELEMETRY_BIT_SPEED,
    M_TOP_DRIVE_SPEED,
    N_STATE,
    REC_SURFACE_TORQUE,
    REC_X0,
    X_BIT_SPEED,
)
from drill_env.parameters import PLANT_DT_S

DT = PLANT_DT_S


def _run(env_id: str, decisions: int, seed: int = 0, **kwargs: Any) -> tuple[list[dict], Any]:
    """Step ``env_id`` with action 0 (direct mode: half the torque range; residual mode: the
    base controller alone); returns the infos after every step (the reset's first) and the
    records of every plant step from the start, (steps, N_RECORD), one row per step."""
    env = gym.make(env_id, max_episode_steps=-1, **kwargs)
    records = env.unwrapped.batch.records  # type: ignore[attr-defined]
    _, info = env.reset(seed=seed)
    infos = [info]
    chunks = []
    for _ in range(decisions):
        _, _, terminated, _, info = env.step(np.zeros(1, dtype=np.float32))
        assert not terminated
        infos.append(info)
        chunks.append(records[0].copy())
    return infos, (env, np.concatenate(chunks))


def _last_sample(k: int, period: int, delay: int) -> int | None:
    """The sample delivered last by plant step k: the latest multiple of ``period`` at least
    ``delay`` steps old (None before the first delivery)."""
    if k < delay:
        return None
    return ((k - delay) // period) * period


@pytest.mark.parametrize(
    ("period_s", "delay_s", "control_dt_s"),
    [(0.5, 0.3, 0.05), (0.037, 0.12, 0.05), (0.2, 0.0, 0.04), (0.1, 0.25, 0.01)],
    ids=["delay < period", "period not a decision multiple", "no delay", "2 in flight"],
)
def test_telemetry_is_sampled_delayed_and_held_as_configured(
    period_s: float, delay_s: float, control_dt_s: float
) -> None:
    """At every decision the telemetry in info is the true bit speed (records) at the last
    sample instant (a multiple of the period) whose delay has passed, its age the time since
    that instant; 0, the time since the start and not received before the first delivery."""
    infos, (_, records) = _run(
        "DrillString-v0", round(8.0 / control_dt_s), randomize=False, noise_std_rad_s=0.0,
        telemetry_period_s=period_s, telemetry_delay_s=delay_s, control_dt_s=control_dt_s,
    )  # fmt: skip
    period, delay = round(period_s / DT), round(delay_s / DT)
    bit = records[:, REC_X0 + X_BIT_SPEED]
    assert bit.max() > 1.0  # the bit turns: the values are not all alike
    delivered = 0
    for info in infos:
        k = round(info["time_s"] / DT)
        sample = _last_sample(k, period, delay)
        if sample is None:  # nothing received yet: 0, the time since the start, not received
            assert info["telemetry_bit_speed_rad_s"] == 0.0
            assert info["telemetry_age_s"] == pytest.approx(k * DT, abs=1e-12)
            assert not info["telemetry_received"]
            continue
        delivered += 1
        assert info["telemetry_received"]
        truth = bit[sample] if sample < k else info["bit_speed_rad_s"]  # sampled now: the end
        assert info["telemetry_bit_speed_rad_s"] == truth
        assert info["telemetry_age_s"] == pytest.approx((k - sample) * DT, abs=1e-12)
    assert delivered > 50


def test_telemetry_noise_has_the_configured_spread() -> None:
    """The telemetry value minus the true bit speed at its instant: zero mean, the configured
    standard deviation (0.5 rad/s; 400 samples, within 15 %)."""
    infos, (_, records) = _run(
        "DrillString-v0", 400, randomize=False, noise_std_rad_s=0.0, control_dt_s=0.05,
        telemetry_period_s=0.05, telemetry_delay_s=0.0, telemetry_noise_std_rad_s=0.5,
    )  # fmt: skip
    errors = [  # every decision's end is a sample instant, delivered at once
        info["telemetry_bit_speed_rad_s"] - info["bit_speed_rad_s"] for info in infos[1:]
    ]
    assert len(records) == 400 * 50
    assert abs(np.mean(errors)) < 0.1
    assert np.std(errors) == pytest.approx(0.5, rel=0.15)


def test_telemetry_none_gives_no_downhole_data() -> None:
    """``telemetry_period_s=None``: no telemetry in info or the observation, NaN in the
    measurement vector a compiled law reads."""
    infos, (env, _) = _run(
        "DrillStringField-v0", 5, randomize=False, telemetry_period_s=None, episode_s=2.0
    )
    assert all("telemetry_bit_speed_rad_s" not in info for info in infos)
    names = [f.name for f in env.unwrapped.batch.fields]
    assert not any("telemetry" in name for name in names)
    m = env.unwrapped.batch.measurement(0)
    assert math.isnan(m[M_TELEMETRY_BIT_SPEED]) and math.isnan(m[M_TELEMETRY_AGE])
    with_telemetry = gym.make("DrillStringField-v0", randomize=False)
    fields = [f.name for f in with_telemetry.unwrapped.batch.fields]  # type: ignore[attr-defined]
    assert fields[4:6] == ["telemetry_bit_speed_rad_s", "telemetry_age_s"]


@pytest.mark.parametrize("sensor_period_s", [0.001, 0.007, 0.05])
def test_surface_signals_are_sampled_every_sensor_period_and_held(sensor_period_s: float) -> None:
    """The measured top-drive speed and surface torque (the measurement vector and
    ``info["surface_torque_nm"]``) are the true values at the last multiple of the sensor
    period, held until the next; in surface mode the state entries are NaN."""
    env = gym.make(
        "DrillStringField-v0", randomize=False, noise_std_rad_s=0.0, torque_noise_std_nm=0.0,
        sensor_period_s=sensor_period_s, control_dt_s=0.001, base_controller="soft_speed",
        episode_s=5.0,
    )  # fmt: skip
    batch = env.unwrapped.batch  # type: ignore[attr-defined]
    env.reset(seed=0)
    period = round(sensor_period_s / DT)
    truth_speed, truth_torque, seen = [], [], []
    for _ in range(300):
        m = batch.measurement(0)  # the vector of this plant step (already sensed)
        seen.append((m[M_TOP_DRIVE_SPEED], m[M_SURFACE_TORQUE]))
        assert np.isnan(m[M_STATE : M_STATE + N_STATE]).all()
        _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
        row = batch.records[0, 0]
        truth_speed.append(row[REC_X0])
        truth_torque.append(row[REC_SURFACE_TORQUE])
        assert info["surface_torque_nm"] == batch.measurement(0)[M_SURFACE_TORQUE]
    for k, (speed, torque) in enumerate(seen):
        held = (k // period) * period
        assert speed == truth_speed[held]
        assert torque == truth_torque[held]
    start = 50  # past the actuator's dead time and the first sample of a moving drive
    changes = sum(seen[k] != seen[k - 1] for k in range(start + 1, len(seen)))
    assert changes == (len(seen) - 1) // period - start // period  # new at each sample only


def test_surface_noise_is_held_with_the_sample() -> None:
    """With noise, a held sample repeats exactly until the next instant; successive samples
    differ by the torque noise (250 N m)."""
    env = gym.make(
        "DrillStringField-v0", randomize=False, sensor_period_s=0.01, control_dt_s=0.001,
        base_controller="soft_speed", episode_s=2.0,
    )  # fmt: skip
    batch = env.unwrapped.batch  # type: ignore[attr-defined]
    env.reset(seed=1)
    torques, truth = [], []
    for _ in range(400):
        torques.append(batch.measurement(0)[M_SURFACE_TORQUE])
        env.step(np.zeros(1, dtype=np.float32))
        truth.append(batch.records[0, 0, REC_SURFACE_TORQUE])
    t = np.array(torques).reshape(40, 10)
    assert (t == t[:, :1]).all()
    noise = t[:, 0] - np.array(truth)[::10]
    assert np.std(noise) == pytest.approx(250.0, rel=0.3)


FEATURES = {
    "DrillStringField-v0": {"base_controller": "proposed", "episode_s": 3.0, "control_dt_s": 0.05},
    "DrillString-v0": {
        "base_controller": "proposed", "observation": "surface", "episode_s": 3.0,
        "control_dt_s": 0.05,
        "torque_noise_std_nm": 100.0, "sensor_period_s": 0.005, "telemetry_period_s": 0.4,
        "telemetry_delay_s": 0.6, "telemetry_noise_std_rad_s": 0.2,
        "actuator_dead_time_s": 0.01, "actuator_lag_s": 0.03,
        "torque_rate_limit_nm_per_s": 2e5,
    },
}  # fmt: skip
KEYS = ("telemetry_bit_speed_rad_s", "telemetry_age_s", "surface_torque_nm",
        "torque_command_nm", "top_drive_torque_nm", "estimated_bit_speed_rad_s")  # fmt: skip


def _trajectory(env: Any, seed: int, steps: int) -> list[bytes]:
    """The bytes of every observation, reward, flag and channel info value of a run with
    random actions (NaN compares as itself)."""
    out: list[Any] = []
    obs, info = env.reset(seed=seed)
    out.append(obs)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        obs, reward, terminated, truncated, info = env.step(
            rng.uniform(-1, 1, 1).astype(np.float32)
        )
        out += [obs, reward, terminated, truncated, *(info[k] for k in KEYS)]
        if terminated or truncated:
            obs, info = env.reset()
    return [np.asarray(value, dtype=np.float64).tobytes() for value in out]


@pytest.mark.parametrize("env_id", list(FEATURES))
def test_runs_with_every_channel_feature_are_deterministic(env_id: str) -> None:
    first = _trajectory(gym.make(env_id, **FEATURES[env_id]), 3, 80)
    assert first == _trajectory(gym.make(env_id, **FEATURES[env_id]), 3, 80)
    assert first != _trajectory(gym.make(env_id, **FEATURES[env_id]), 4, 80)


@pytest.mark.parametrize("env_id", list(FEATURES))
def test_vector_env_reproduces_single_envs_with_every_channel_feature(env_id: str) -> None:
    """String i of the native vector env, reset with seed s, is the single env reset with
    s + i, bit for bit: observations, rewards and the channel's and actuator's info."""
    n = 3
    venv = gym.make_vec(env_id, num_envs=n, **FEATURES[env_id])
    singles = [gym.make(env_id, **FEATURES[env_id]) for _ in range(n)]
    obs, _ = venv.reset(seed=20)
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(obs[i], env.reset(seed=20 + i)[0])
    rng = np.random.default_rng(0)
    for _ in range(50):
        actions = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        obs, rewards, terminated, truncated, infos = venv.step(actions)
        assert not (terminated.any() or truncated.any())
        for i, env in enumerate(singles):
            o, r, _, _, info = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o)
            assert rewards[i] == r
            for key in KEYS:
                np.testing.assert_array_equal(infos[key][i], info[key])


@pytest.mark.parametrize(
    ("keywords", "error", "message"),
    [
        ({"telemetry_delay_s": -1.0}, ValueError,
         r"telemetry_delay_s = -1.0 is out of range: allowed \[0, 600\]"),
        ({"telemetry_period_s": 0.0015}, ValueError,
         r"telemetry_period_s = 0.0015 is out of range: allowed a multiple of plant_dt = 0.001 s"),
        ({"telemetry_delay_s": 0.0025}, ValueError,
         r"telemetry_delay_s = 0.0025 is out of range: allowed a multiple of plant_dt"),
        ({"telemetry_period_s": 0.0}, ValueError,
         r"telemetry_period_s = 0.0 is out of range: allowed \[0.001, 600\]"),
        ({"sensor_period_s": 0.0105}, ValueError,
         r"sensor_period_s = 0.0105 is out of range: allowed a multiple of plant_dt = 0.001 s"),
        ({"sensor_period_s": 0.0}, ValueError,
         r"sensor_period_s = 0.0 is out of range: allowed \[0.001, 10\]"),
        ({"torque_noise_std_nm": -1.0}, ValueError,
         r"torque_noise_std_nm = -1.0 is out of range: allowed \[0, 100000\]"),
        ({"telemetry_noise_std_rad_s": "a"}, TypeError,
         r"telemetry_noise_std_rad_s must be a real number, got 'a' \(str\)"),
        ({"observation": "bit"}, ValueError,
         r"observation = 'bit' is not a known mode: allowed \['estimate', 'state', 'surface'\]"),
    ],
)  # fmt: skip
@pytest.mark.parametrize("env_id", ["DrillString-v0", "DrillStringField-v0"])
def test_bad_channel_keywords_are_clear_errors(
    env_id: str, keywords: dict[str, Any], error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        gym.make(env_id, **keywords)
