"""A residual agent on ``DrillStringCoupled-v0``: the training settings of the env
(``agents.config.ENV_DEFAULTS``), its training env through the SB3 adapter, and its model
files (the coupled env's keywords, two actions) saved, loaded and checked."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import drill_env
from agents import load_policy
from agents.config import COUPLED_ENV_ID, TrainConfig
from agents.inference import ObsNorm, PolicySpec
from agents.policy import ResidualPolicy
from agents.train import coupled_mean_reward, env_kwargs, policy_env_kwargs
from drill_env.coupled_env import DrillStringCoupledEnv

KWARGS = {
    "torque_loop": "stiff_pi",
    "control_dt_s": 0.1,
    "residual_torque_nm": 5_000.0,
    "max_torque_nm": 50_000.0,
}


def _policy(action_size: int = 2, kwargs: dict[str, object] = KWARGS) -> ResidualPolicy:
    spec = PolicySpec(
        observation_size=8,
        hidden_sizes=(8,),
        action_size=action_size,
        action_low=(-1.0,) * action_size,
        action_high=(1.0,) * action_size,
    )
    rng = np.random.default_rng(0)
    weights = {k: 0.1 * rng.standard_normal(shape) for k, shape in spec.weight_shapes().items()}
    return ResidualPolicy(
        spec, weights, ObsNorm.identity(8), dict(kwargs), "coupled_agent", env_id=COUPLED_ENV_ID
    )


def test_the_env_defaults_make_the_training_env() -> None:
    config = TrainConfig.for_env(COUPLED_ENV_ID)
    assert config.base_controller == "stiff_pi" and config.env_id == drill_env.COUPLED_ENV_ID
    assert policy_env_kwargs(config) == KWARGS
    kwargs = env_kwargs(config)
    assert kwargs["randomize"] is True and "noise_std_rad_s" not in kwargs
    env = DrillStringCoupledEnv(**kwargs)
    assert env.action_space.shape == (2,)


def test_sb3_adapter_steps_the_vector_env() -> None:
    pytest.importorskip("stable_baselines3")
    from agents.train import make_training_env

    config = TrainConfig.for_env(COUPLED_ENV_ID, num_envs=2, episode_s=0.3)
    venv = make_training_env(config)
    obs = venv.reset()
    assert obs.shape == (2, 8)
    for _ in range(4):  # the episode ends after 3 decisions; the adapter resets those strings
        obs, rewards, dones, infos = venv.step(np.zeros((2, 2), dtype=np.float32))
        assert np.all(np.isfinite(obs)) and rewards.shape == (2,)
    venv.close()


def test_model_files_round_trip_and_are_checked(tmp_path: Path) -> None:
    policy = _policy()
    policy.save(tmp_path / "m")
    loaded = load_policy(tmp_path / "m")
    assert loaded.env_id == COUPLED_ENV_ID and loaded.env_kwargs == {**KWARGS}
    env = drill_env.coupled_env.DrillStringCoupledEnv(**loaded.env_kwargs, episode_s=0.2)
    expected = coupled_mean_reward(env, policy, [0])  # float32 weights in the files
    assert coupled_mean_reward(env, loaded, [0]) == pytest.approx(expected, rel=1e-6)
    with pytest.raises(ValueError, match="action_size = \\(8, 1\\): expected \\(8, 2\\)"):
        _policy(action_size=1).save(tmp_path / "one")
        load_policy(tmp_path / "one")
    bad = json.loads((tmp_path / "m" / "config.json").read_text())
    bad["env_kwargs"]["torque_loop"] = "warp"
    (tmp_path / "m" / "config.json").write_text(json.dumps(bad))
    with pytest.raises(ValueError, match="env_kwargs.torque_loop = 'warp' is not a known"):
        load_policy(tmp_path / "m")


def test_the_shipped_coupled_agent_loads_for_its_env() -> None:
    from agents import DEFAULT_MODEL_DIR

    policy = load_policy(DEFAULT_MODEL_DIR / "coupled_agent")
    assert policy.env_id == COUPLED_ENV_ID and policy.env_kwargs == KWARGS
    env = DrillStringCoupledEnv(**policy.env_kwargs, episode_s=0.5)
    obs, _ = env.reset(seed=0)
    action, _ = policy.predict(obs, deterministic=True)
    assert action.shape == (2,) and np.all(np.abs(action) <= 1)


@pytest.mark.slow
def test_the_shipped_coupled_agent_beats_its_base_loops_on_the_reward() -> None:
    """The shipping rule of docs/reports/coupled.md: more reward per decision than its base
    loops alone on randomised episodes it was neither trained nor validated on."""
    from agents import DEFAULT_MODEL_DIR

    policy = load_policy(DEFAULT_MODEL_DIR / "coupled_agent")
    env = DrillStringCoupledEnv(**policy.env_kwargs)
    seeds = [30_000 + k for k in range(24)]  # the report's 24 held-out episodes
    assert coupled_mean_reward(env, policy, seeds) > coupled_mean_reward(env, None, seeds)
