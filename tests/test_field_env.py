"""``DrillStringField-v0``: the Gymnasium contract of ``DrillString-v0`` on the distributed
string, its keywords, and its plant against the chain's own open-loop integrator."""

from __future__ import annotations

import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import drill_env
from drill_env.chain import chain_integrate_constant_torque
from drill_env.distributed import with_measured_depth
from drill_env.evaluation import ZeroAction, rollout
from drill_env.layout import X_BIT_SPEED
from drill_env.modes import probe_nodes

FIELD = drill_env.FIELD_ENV_ID
IDEAL = {
    "actuator_dead_time_s": 0.0,
    "actuator_lag_s": 0.0,
    "torque_rate_limit_nm_per_s": None,
    "telemetry_period_s": None,
    "sensor_period_s": 0.001,
}
MODES: dict[str, dict[str, Any]] = {
    "surface": {},
    "surface-residual": {"base_controller": "soft_speed"},
    "state": {"observation": "state"},
    "state-residual": {"observation": "state", "base_controller": "z_torque"},
}


@pytest.mark.parametrize("mode", sorted(MODES))
def test_gymnasium_and_sb3_checkers(mode: str) -> None:
    env = gym.make(FIELD, episode_s=5.0, **MODES[mode])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    sb3.check_env(gym.make(FIELD, episode_s=5.0, **MODES[mode]), warn=True)


@pytest.mark.parametrize(
    ("mode", "size"),
    [("surface", 6), ("surface-residual", 8), ("state", 2 * 103 - 1 + 4), ("state-residual", 211)],
)
def test_observation_sizes(mode: str, size: int) -> None:
    """Surface: speed, torque, reference, last torque, telemetry value and age (+ the base
    controller's torque and error); state: every node of the deepest string (+ the same)."""
    env = gym.make(FIELD, randomize=False, **MODES[mode])
    assert env.observation_space.shape == (size,)
    obs, info = env.reset(seed=0)
    assert obs.shape == (size,) and np.isfinite(obs).all()
    for key in ("telemetry_bit_speed_rad_s", "telemetry_age_s", "torque_command_nm"):
        assert key in info


def test_open_loop_plant_is_the_chain_integrator() -> None:
    """With an ideal actuator, no noise and a constant torque, the env's bit and top-drive
    speeds are those of the chain integrator of the same string at every plant step."""
    torque = 9_500.0
    env = gym.make(
        FIELD, randomize=False, wob_n=100e3, noise_std_rad_s=0.0, torque_noise_std_nm=0.0,
        telemetry_noise_std_rad_s=0.0, episode_s=20.0, control_dt_s=0.1, **IDEAL,
    )  # fmt: skip
    action = np.array([2.0 * torque / drill_env.options.FIELD_MAX_TORQUE_NM - 1.0], np.float32)

    class Constant:
        def predict(self, obs: Any, state: Any = None, episode_start: Any = None,
                    deterministic: bool = True) -> tuple[Any, Any]:  # fmt: skip
            return action, state

    trace = rollout(env, Constant(), seed=0)
    applied = float(trace.torque_nm[0])
    assert applied == pytest.approx(torque, rel=1e-6)
    states, modes = chain_integrate_constant_torque("field_2500m", applied, 100e3, 20.0)
    n = states.shape[1] // 2 + 1
    np.testing.assert_allclose(trace.bit_speed_rad_s, states[:-1, 2 * (n - 1)], atol=1e-6)
    np.testing.assert_allclose(trace.top_drive_speed_rad_s, states[:-1, 0], atol=1e-6)
    assert trace.bit_stuck.any() and not trace.bit_stuck.all()  # it sticks and slips


def test_records_are_the_probe_coordinates() -> None:
    """The records' 4-DOF columns are the chain state read at the probe nodes: speeds of the
    nodes, twists summed between them (their sum: the whole string's twist)."""
    env = gym.make(FIELD, randomize=False, noise_std_rad_s=0.0, episode_s=3.0, **IDEAL)
    env.reset(seed=0)
    env.step(np.array([0.0], np.float32))
    x = env.unwrapped.batch.x[0].copy()  # type: ignore[attr-defined]
    a, b, c, d = probe_nodes("field_2500m")
    env.step(np.array([0.0], np.float32))
    first = env.unwrapped.plant_samples().states[0]  # type: ignore[attr-defined]
    np.testing.assert_allclose(first[[0, 2, 4, 6]], x[[2 * a, 2 * b, 2 * c, 2 * d]])
    np.testing.assert_allclose(first[1] + first[3] + first[5], x[1 : 2 * d : 2].sum(), rtol=1e-12)
    assert first[X_BIT_SPEED] == x[2 * d]


@pytest.mark.parametrize("mode", ["surface-residual", "state"])
def test_vector_env_reproduces_single_envs(mode: str) -> None:
    """String i of the native vector env (randomised depths: strings of different lengths in
    one batch) is the single env reset with seed s + i, bit for bit, autoreset included."""
    kwargs = {**MODES[mode], "episode_s": 2.0, "control_dt_s": 0.1}
    venv = gym.make_vec(FIELD, num_envs=3, **kwargs)
    obs_v, _ = venv.reset(seed=40)
    singles = [gym.make(FIELD, **kwargs) for _ in range(3)]
    obs_s = [env.reset(seed=40 + i)[0] for i, env in enumerate(singles)]
    rng = np.random.default_rng(0)
    for _ in range(25):  # past the 20-decision episode: autoreset
        actions = rng.uniform(-1, 1, (3, 1)).astype(np.float32)
        obs_v, rew_v, term_v, trunc_v, _ = venv.step(actions)
        for i, env in enumerate(singles):
            if obs_s[i] is None:
                obs_s[i], _ = env.reset()
                np.testing.assert_array_equal(obs_v[i], obs_s[i])
                continue
            o, r, te, tr, _ = env.step(actions[i])
            np.testing.assert_array_equal(obs_v[i], o)
            assert rew_v[i] == r and trunc_v[i] == tr and term_v[i] == te
            obs_s[i] = None if (te or tr) else o
    depths = {e.unwrapped.batch.episodes[0].scenario.plant.measured_depth_m for e in singles}  # type: ignore[attr-defined]
    assert len(depths) == 3


def test_same_seed_same_trajectory_and_draws_in_range() -> None:
    env = gym.make(FIELD, episode_s=2.0)
    traces = [rollout(env, ZeroAction(), seed=5) for _ in range(2)]
    np.testing.assert_array_equal(traces[0].states, traces[1].states)
    np.testing.assert_array_equal(traces[0].observations, traces[1].observations)
    r = drill_env.scenarios.FieldRandomization()
    for seed in range(20):
        env.reset(seed=seed)
        scenario = env.unwrapped.batch.episodes[0].scenario  # type: ignore[attr-defined]
        plant, model = scenario.plant, scenario.controller_model
        assert r.measured_depth_range_m[0] <= plant.measured_depth_m <= r.measured_depth_range_m[1]
        assert r.mu_a_range[0] <= plant.mu_a <= r.mu_a_range[1]
        assert model.measured_depth_m == plant.measured_depth_m  # the geometry is known
        assert (model.mu_a, model.xi) == (0.8, 0.5)  # the friction is not


def test_measured_depth_keyword_and_options() -> None:
    env = gym.make(FIELD, randomize=False, measured_depth_m=3_000.0)
    env.reset(seed=0)
    plant = env.unwrapped.batch.episodes[0].scenario.plant  # type: ignore[attr-defined]
    assert plant.measured_depth_m == pytest.approx(3_000.0)
    env.reset(seed=0, options={"measured_depth_m": 1_500.0})
    plant = env.unwrapped.batch.episodes[0].scenario.plant  # type: ignore[attr-defined]
    assert plant.measured_depth_m == pytest.approx(1_500.0)
    with pytest.raises(ValueError, match=r"has \d+ nodes: allowed at most 123"):
        env.reset(seed=0, options={"measured_depth_m": 4_000.0})


@pytest.mark.parametrize(
    ("env_id", "kwargs", "error", "match"),
    [
        (FIELD, {"measured_depth_m": 100.0}, ValueError, r"measured_depth_m = 100.0 is out of range: allowed > BHA length"),
        (FIELD, {"parameters": "zribi2024"}, ValueError, r"parameters = 'zribi2024' is not a distributed string"),
        (FIELD, {"uncertainty": "condition1"}, TypeError, r"unrecognized keyword\(s\): uncertainty"),
        (FIELD, {"observation": "bit"}, ValueError, r"observation = 'bit' is not a known mode"),
        (FIELD, {"randomization": drill_env.Randomization()}, TypeError, r"randomization must be a FieldRandomization"),
        (FIELD, {"telemetry_delay_s": -1.0}, ValueError, r"telemetry_delay_s = -1.0 is out of range"),
        (FIELD, {"torque_rate_limit_nm_per_s": 0.0}, ValueError, r"torque_rate_limit_nm_per_s = 0.0 is out of range"),
        ("DrillString-v0", {"parameters": "field_2500m"}, ValueError, r"is a distributed string: use DrillStringField-v0"),
        ("DrillString-v0", {"measured_depth_m": 2000.0}, TypeError, r"unrecognized keyword\(s\): measured_depth_m"),
    ],
    ids=["shallow", "lumped-preset", "uncertainty", "observation", "randomization", "delay", "rate", "v0-distributed", "v0-depth"],
)  # fmt: skip
def test_bad_keywords(env_id: str, kwargs: dict[str, Any], error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        gym.make(env_id, **kwargs)


def test_a_deeper_string_has_more_nodes_and_a_longer_wave_travel() -> None:
    """The string's length sets its dynamics: at 5 km the bit answers a torque step at the
    top later than at 1.5 km (the torsional wave's travel time L / c)."""
    delays = []
    for depth in (1_500.0, 5_000.0):
        env = gym.make(
            FIELD, randomize=False, measured_depth_m=depth, noise_std_rad_s=0.0,
            episode_s=4.0, control_dt_s=0.001, wob_n=1.0, **IDEAL,
        )  # fmt: skip
        env.reset(seed=0)
        first = None
        for k in range(4_000):
            _, _, _, _, info = env.step(np.array([-0.9], np.float32))
            if first is None and info["bit_speed_rad_s"] > 1e-3:
                first = k * 1e-3
        assert first is not None
        delays.append(first)
        pipe = with_measured_depth("field_2500m", depth).pipe
        assert delays[-1] > 0.5 * pipe.length_m / pipe.wave_speed_m_s
    assert delays[1] > 2.0 * delays[0]


def test_elements_too_short_for_the_plant_step_are_refused() -> None:
    import dataclasses

    short = dataclasses.replace(drill_env.DISTRIBUTED_PRESETS["field_2500m"], element_length_m=2.0)
    with pytest.raises(
        ValueError, match=r"element_length_m = 2.0 is out of range for the plant step"
    ):
        gym.make(FIELD, parameters=short)
