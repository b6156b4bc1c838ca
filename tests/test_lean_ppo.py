"""agents.ppo.LeanPPO collects rollouts as Stable-Baselines3's PPO does, bit for bit: the same
actions, values, log-probabilities, random draws and trained weights (the reference is SB3's own
``collect_rollouts`` on an identically built model)."""

from __future__ import annotations

import dataclasses
import types
from typing import Any

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
th = pytest.importorskip("torch")

from stable_baselines3 import PPO  # noqa: E402

from agents.config import COUPLED_ENV_ID, FIELD_ENV_ID, TrainConfig  # noqa: E402
from agents.ppo import LeanPPO, policy_step  # noqa: E402
from agents.train import make_model, make_training_env  # noqa: E402


def _config(**changes: Any) -> TrainConfig:
    """Two rollouts of 2 strings x 64 decisions on 5 s episodes: timeouts inside a rollout."""
    values: dict[str, Any] = {
        "num_envs": 2,
        "n_steps": 64,
        "batch_size": 32,
        "n_epochs": 2,
        "episode_s": 5.0,
        "verbose": 0,
        "seed": 7,
    }
    values.update(changes)
    env_id = values.pop("env_id", TrainConfig.env_id)
    return dataclasses.replace(TrainConfig.for_env(env_id), **values)


def _trained(config: TrainConfig, collect_with_sb3: bool) -> tuple[Any, Any]:
    """A model of ``make_model`` after two rollouts and their updates; with
    ``collect_with_sb3`` its rollouts are collected by SB3's ``PPO.collect_rollouts``."""
    venv = make_training_env(config)
    model = make_model(config, venv)
    if collect_with_sb3:
        model.collect_rollouts = types.MethodType(PPO.collect_rollouts, model)
    venv.seed(config.seed)
    model.learn(total_timesteps=2 * config.n_steps * config.num_envs)
    return model, venv


def _assert_same_training(config: TrainConfig) -> None:
    lean, lean_env = _trained(config, collect_with_sb3=False)
    sb3, sb3_env = _trained(config, collect_with_sb3=True)
    for name, value in sb3.policy.state_dict().items():
        assert th.equal(lean.policy.state_dict()[name], value), name
    for field in ("observations", "actions", "rewards", "values", "log_probs", "returns"):
        np.testing.assert_array_equal(
            getattr(lean.rollout_buffer, field), getattr(sb3.rollout_buffer, field), field
        )
    np.testing.assert_array_equal(lean_env.obs_rms.mean, sb3_env.obs_rms.mean)
    assert lean.num_timesteps == sb3.num_timesteps
    assert [e["r"] for e in lean.ep_info_buffer] == [e["r"] for e in sb3.ep_info_buffer]
    assert len(lean.ep_info_buffer) > 0  # episodes ended inside the rollouts
    lean_env.close()
    sb3_env.close()


@pytest.mark.parametrize(
    "changes",
    [
        {},
        {"net_arch": [16, 24, 8], "frame_stack": 2, "base_controller": "none"},
        {"env_id": COUPLED_ENV_ID},
    ],
    ids=["default-recipe", "three-layers-stacked-direct", "coupled-two-actions"],
)
def test_lean_collection_trains_the_same_weights_as_sb3(changes: dict[str, Any]) -> None:
    config = _config(**changes)
    assert policy_step(make_model(config, make_training_env(config)).policy) is not None
    _assert_same_training(config)


@pytest.mark.slow
def test_lean_collection_on_the_field_string_trains_the_same_weights_as_sb3() -> None:
    _assert_same_training(_config(env_id=FIELD_ENV_ID, n_steps=16, batch_size=16))


def test_policy_step_is_the_policy_forward_with_the_same_draws() -> None:
    """ReLU layers, an action of two dimensions: the same actions, values and
    log-probabilities as ``ActorCriticPolicy.forward`` after the same seed."""
    from gymnasium import spaces

    observation = spaces.Box(-5.0, 5.0, (7,), np.float32)
    action = spaces.Box(-1.0, 1.0, (2,), np.float32)
    model = PPO(
        "MlpPolicy",
        _space_env(observation, action),
        policy_kwargs={"net_arch": [8, 8], "activation_fn": th.nn.ReLU, "log_std_init": -0.3},
        device="cpu",
        seed=1,
    )
    step = policy_step(model.policy)
    assert step is not None
    obs = th.as_tensor(np.random.default_rng(0).normal(size=(5, 7)), dtype=th.float32)
    with th.no_grad():
        th.manual_seed(3)
        expected = model.policy(obs)
        th.manual_seed(3)
        got = step(obs)
    for want, have in zip(expected, got, strict=True):
        assert want.shape == have.shape and th.equal(want, have)


def _space_env(observation: Any, action: Any) -> Any:
    """A do-nothing Gymnasium env with these spaces (PPO needs one to be built)."""
    import gymnasium as gym

    class Spaces(gym.Env[Any, Any]):
        observation_space = observation
        action_space = action

        def reset(self, *, seed: int | None = None, options: Any = None) -> Any:
            return observation.sample(), {}

        def step(self, a: Any) -> Any:
            return observation.sample(), 0.0, False, False, {}

    return Spaces()


@pytest.mark.parametrize("kind", ["gsde", "squashed"])
def test_policies_it_does_not_know_are_collected_by_sb3(kind: str) -> None:
    """State-dependent exploration and squashed actions have no lean step: SB3 collects."""
    from gymnasium import spaces

    observation = spaces.Box(-5.0, 5.0, (3,), np.float32)
    action = spaces.Box(-1.0, 1.0, (1,), np.float32)
    kwargs: dict[str, Any] = {"use_sde": True}
    if kind == "squashed":
        kwargs["policy_kwargs"] = {"squash_output": True}
    model = LeanPPO("MlpPolicy", _space_env(observation, action), device="cpu", **kwargs)
    assert policy_step(model.policy) is None
    model.learn(total_timesteps=64, progress_bar=False)  # through SB3's collect_rollouts
    assert model.num_timesteps >= 64
