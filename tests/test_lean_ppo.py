"""agents.ppo.LeanActorCriticPolicy computes what Stable-Baselines3's ``MlpPolicy`` computes,
bit for bit: the same actions, values, log-probabilities, random draws, gradients and trained
weights (the reference is SB3's own ``forward`` and ``evaluate_actions`` on the same policy)."""

from __future__ import annotations

import dataclasses
import types
from typing import Any

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
th = pytest.importorskip("torch")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.policies import ActorCriticPolicy  # noqa: E402

from agents.config import COUPLED_ENV_ID, FIELD_ENV_ID, TrainConfig  # noqa: E402
from agents.ppo import LeanActorCriticPolicy  # noqa: E402
from agents.train import make_model, make_training_env  # noqa: E402


def _with_sb3_methods(policy: Any) -> Any:
    """``policy`` answering with SB3's own ``forward`` and ``evaluate_actions``."""
    policy.forward = types.MethodType(ActorCriticPolicy.forward, policy)
    policy.evaluate_actions = types.MethodType(ActorCriticPolicy.evaluate_actions, policy)
    return policy


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


def _trained(config: TrainConfig, sb3_methods: bool) -> tuple[Any, Any]:
    """A model of ``make_model`` after two rollouts and their updates; with ``sb3_methods``
    its policy answers with SB3's own methods."""
    venv = make_training_env(config)
    model = make_model(config, venv)
    assert isinstance(model.policy, LeanActorCriticPolicy)
    assert model.policy._networks() is not None  # the lean path is the one tested
    if sb3_methods:
        _with_sb3_methods(model.policy)
    venv.seed(config.seed)
    model.learn(total_timesteps=2 * config.n_steps * config.num_envs)
    return model, venv


def _assert_same_training(config: TrainConfig) -> None:
    lean, lean_env = _trained(config, sb3_methods=False)
    sb3, sb3_env = _trained(config, sb3_methods=True)
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
def test_lean_policy_trains_the_same_weights_as_sb3(changes: dict[str, Any]) -> None:
    _assert_same_training(_config(**changes))


@pytest.mark.slow
def test_lean_policy_on_the_field_string_trains_the_same_weights_as_sb3() -> None:
    _assert_same_training(_config(env_id=FIELD_ENV_ID, n_steps=16, batch_size=16))


def test_forward_and_evaluate_actions_are_sb3s_with_the_same_draws_and_gradients() -> None:
    """ReLU layers, an action of two dimensions: the same actions, values and
    log-probabilities as SB3's ``forward`` after the same seed (stochastic and deterministic),
    and the same values, log-probabilities, entropies and gradients from ``evaluate_actions``."""
    from gymnasium import spaces

    observation = spaces.Box(-5.0, 5.0, (7,), np.float32)
    action = spaces.Box(-1.0, 1.0, (2,), np.float32)
    policies = [
        PPO(
            LeanActorCriticPolicy,
            _space_env(observation, action),
            policy_kwargs={"net_arch": [8, 8], "activation_fn": th.nn.ReLU, "log_std_init": -0.3},
            device="cpu",
            seed=1,
        ).policy
        for _ in range(2)
    ]
    lean, sb3 = policies[0], _with_sb3_methods(policies[1])
    rng = np.random.default_rng(0)
    obs = th.as_tensor(rng.normal(size=(5, 7)), dtype=th.float32)
    actions = th.as_tensor(rng.normal(size=(5, 2)), dtype=th.float32)
    with th.no_grad():
        for deterministic in (False, True):
            th.manual_seed(3)
            expected = sb3(obs, deterministic=deterministic)
            th.manual_seed(3)
            got = lean(obs, deterministic=deterministic)
            for want, have in zip(expected, got, strict=True):
                assert want.shape == have.shape and th.equal(want, have)
    outputs = []
    for policy in (sb3, lean):
        values, log_prob, entropy = policy.evaluate_actions(obs, actions)
        (log_prob.exp().mean() + values.square().mean() - 0.1 * entropy.mean()).backward()
        outputs.append([values, log_prob, entropy] + [p.grad for p in policy.parameters()])
    for want, have in zip(*outputs, strict=True):
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


@pytest.mark.parametrize("kind", ["gsde", "squashed", "image-shaped"])
def test_policies_it_does_not_know_layer_by_layer_take_sb3s_methods(kind: str) -> None:
    """State-dependent exploration, squashed actions, observations that are not flat: SB3's
    own ``forward`` and ``evaluate_actions`` answer, and PPO trains."""
    from gymnasium import spaces

    shape = (3, 4) if kind == "image-shaped" else (3,)
    observation = spaces.Box(-5.0, 5.0, shape, np.float32)
    action = spaces.Box(-1.0, 1.0, (1,), np.float32)
    kwargs: dict[str, Any] = {"use_sde": kind != "image-shaped"}
    if kind == "squashed":
        kwargs["policy_kwargs"] = {"squash_output": True}
    model = PPO(
        LeanActorCriticPolicy,
        _space_env(observation, action),
        device="cpu",
        n_steps=32,
        batch_size=32,
        **kwargs,
    )
    assert model.policy._networks() is None
    model.learn(total_timesteps=64)
    assert model.num_timesteps >= 64


def test_a_copy_of_the_policy_computes_with_its_own_parameters() -> None:
    """The networks the policy binds at its first forward pass are not shared by a deep copy
    or a pickled one: each answers with its own weights, as SB3's methods do."""
    import copy
    import pickle

    from gymnasium import spaces

    observation = spaces.Box(-5.0, 5.0, (4,), np.float32)
    action = spaces.Box(-1.0, 1.0, (1,), np.float32)
    policy = PPO(LeanActorCriticPolicy, _space_env(observation, action), device="cpu").policy
    obs = th.as_tensor(np.ones((3, 4)), dtype=th.float32)
    with th.no_grad():
        policy(obs)  # binds the networks
        for twin in (copy.deepcopy(policy), pickle.loads(pickle.dumps(policy))):
            twin.action_net.bias.fill_(0.5)
            twin.value_net.bias.fill_(-2.0)
            th.manual_seed(0)
            got = twin(obs)
            th.manual_seed(0)
            expected = ActorCriticPolicy.forward(twin, obs)
            for want, have in zip(expected, got, strict=True):
                assert th.equal(want, have)
            assert not th.equal(policy(obs, deterministic=True)[0], twin(obs, True)[0])
