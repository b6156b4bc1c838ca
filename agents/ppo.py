"""Stable-Baselines3's PPO with a leaner rollout collection.

At every step of a rollout SB3's ``ActorCriticPolicy.forward`` calls a dozen ``nn.Module``
wrappers and builds a ``torch.distributions.Normal`` (with its argument checks) to draw 16
actions from two small MLPs: about two thirds of the policy's time during collection is that
Python, not arithmetic. :class:`LeanPPO` collects with the same torch operations on the same
tensors in the same order (``F.linear``, the activation, one ``normal_`` draw, the Gaussian
log-density as ``Normal.log_prob`` writes it), so the rollout buffer, the random stream and the
trained weights are SB3's bit for bit (``tests/test_agents.py`` trains both side by side). The
updates are SB3's own. A policy this module does not know layer by layer (another feature
extractor, another distribution, state-dependent exploration, squashed or image observations)
is collected by SB3's ``collect_rollouts`` unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Final

import numpy as np
import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3 import PPO
from stable_baselines3.common.buffers import RolloutBuffer
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import FlattenExtractor, MlpExtractor
from stable_baselines3.common.utils import obs_as_tensor
from stable_baselines3.common.vec_env import VecEnv

__all__ = ["LeanPPO", "policy_step"]

Tensor = th.Tensor
PolicyStep = Callable[[Tensor], tuple[Tensor, Tensor, Tensor]]
"""Observations -> (actions, values, log-probabilities), as ``ActorCriticPolicy.forward``."""

_ACTIVATIONS: Final[dict[type[th.nn.Module], Callable[[Tensor], Tensor]]] = {
    th.nn.Tanh: th.tanh,  # nn.Tanh.forward is torch.tanh
    th.nn.ReLU: th.relu,  # nn.ReLU(inplace=False).forward is F.relu, i.e. torch.relu
}
_LOG_SQRT_2PI: Final = math.log(math.sqrt(2 * math.pi))
"""The constant of ``torch.distributions.Normal.log_prob``, computed as it computes it."""


def _layers(network: th.nn.Module) -> list[Callable[[Tensor], Tensor]] | None:
    """The functions of a ``Sequential`` of ``Linear`` and tanh/ReLU layers bound to the
    layers' parameter tensors (the optimizer and ``load_state_dict`` update them in place);
    None for any other module."""
    modules = list(network) if type(network) is th.nn.Sequential else [network]
    layers: list[Callable[[Tensor], Tensor]] = []
    for module in modules:
        if type(module) is th.nn.Linear:
            layers.append(_linear(module.weight, module.bias))
        elif type(module) in _ACTIVATIONS:
            layers.append(_ACTIVATIONS[type(module)])
        else:
            return None
    return layers


def _linear(weight: Tensor, bias: Tensor | None) -> Callable[[Tensor], Tensor]:
    """``nn.Linear.forward`` on these parameter tensors."""
    return lambda x: F.linear(x, weight, bias)


def _run(layers: list[Callable[[Tensor], Tensor]], x: Tensor) -> Tensor:
    for layer in layers:
        x = layer(x)
    return x


def policy_step(policy: Any) -> PolicyStep | None:
    """``policy.forward(obs)`` (stochastic actions) as the same torch operations without the
    module calls and the distribution object, for the policy's parameters as they are now (the
    Gaussian's spread is read once: build a new step after each update), or None when ``policy`` is not SB3's plain MLP
    actor-critic on flat observations with a diagonal Gaussian (no state-dependent noise, no
    squashing): then only ``policy.forward`` itself is SB3's answer."""
    if not (
        type(policy) is ActorCriticPolicy
        and type(policy.action_dist) is DiagGaussianDistribution
        and not policy.use_sde
        and not policy.squash_output
        and policy.share_features_extractor
        and type(policy.features_extractor) is FlattenExtractor
        and type(policy.mlp_extractor) is MlpExtractor
        and type(policy.observation_space) is spaces.Box
        and len(policy.observation_space.shape) == 1
        and type(policy.action_space) is spaces.Box
    ):
        return None
    actor = _layers(policy.mlp_extractor.policy_net)
    critic = _layers(policy.mlp_extractor.value_net)
    action_net = _layers(policy.action_net)
    value_net = _layers(policy.value_net)
    if actor is None or critic is None or action_net is None or value_net is None:
        return None
    actor += action_net
    critic += value_net
    action_shape = (-1, *policy.action_space.shape)
    with th.no_grad():  # the Gaussian's per-action constants until the next update
        # DiagGaussianDistribution.proba_distribution: std = ones_like(mean) * log_std.exp(),
        # the same numbers in every row; Normal.log_prob's 2 * scale**2 and scale.log()
        std = policy.log_std.exp()
        two_var = 2 * std**2
        log_std = std.log()

    def step(obs: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        features = obs.float()  # preprocess_obs of a flat Box; Flatten of (n, d) is itself
        mean = _run(actor, features)
        values = _run(critic, features)
        # Normal.rsample (one normal_ draw of the batch's shape), then Normal.log_prob
        actions = mean + th.empty(mean.shape, dtype=mean.dtype).normal_() * std
        log_prob = -((actions - mean) ** 2) / two_var - log_std - _LOG_SQRT_2PI
        return actions.reshape(action_shape), values, log_prob.sum(dim=1)

    return step


class LeanPPO(PPO):
    """SB3's ``PPO``; its rollouts are collected through :func:`policy_step` when the policy
    allows it (the same transitions, random draws and buffer, bit for bit)."""

    def collect_rollouts(
        self,
        env: VecEnv,
        callback: BaseCallback,
        rollout_buffer: RolloutBuffer,
        n_rollout_steps: int,
    ) -> bool:
        step = policy_step(self.policy)
        if step is None or self._last_obs is None or isinstance(self._last_obs, dict):
            return super().collect_rollouts(env, callback, rollout_buffer, n_rollout_steps)
        # SB3's loop (stable_baselines3.common.on_policy_algorithm), with the policy step above
        self.policy.set_training_mode(False)
        n_steps = 0
        rollout_buffer.reset()
        callback.on_rollout_start()
        assert isinstance(self.action_space, spaces.Box)
        low, high = self.action_space.low, self.action_space.high
        while n_steps < n_rollout_steps:
            with th.no_grad():
                obs_tensor = obs_as_tensor(self._last_obs, self.device)  # type: ignore[arg-type]
                assert isinstance(obs_tensor, th.Tensor)  # a flat Box (policy_step)
                actions_tensor, values, log_probs = step(obs_tensor)
            actions = actions_tensor.cpu().numpy()
            clipped_actions = np.clip(actions, low, high)  # the Gaussian is unbounded
            new_obs, rewards, dones, infos = env.step(clipped_actions)
            self.num_timesteps += env.num_envs
            callback.update_locals(locals())
            if not callback.on_step():
                return False
            self._update_info_buffer(infos, dones)
            n_steps += 1
            for idx in np.flatnonzero(dones):  # a timeout bootstraps with the value function
                info = infos[idx]
                if info.get("terminal_observation") is not None and info.get(
                    "TimeLimit.truncated", False
                ):
                    terminal_obs = self.policy.obs_to_tensor(info["terminal_observation"])[0]
                    with th.no_grad():
                        terminal_value = self.policy.predict_values(terminal_obs)[0]
                    rewards[idx] += self.gamma * terminal_value
            rollout_buffer.add(
                self._last_obs,  # type: ignore[arg-type]
                actions,
                rewards,
                self._last_episode_starts,  # type: ignore[arg-type]
                values,
                log_probs,
            )
            self._last_obs = new_obs  # type: ignore[assignment]
            self._last_episode_starts = dones
        with th.no_grad():
            values = self.policy.predict_values(obs_as_tensor(new_obs, self.device))  # type: ignore[arg-type]
        rollout_buffer.compute_returns_and_advantage(last_values=values, dones=dones)
        callback.update_locals(locals())
        callback.on_rollout_end()
        return True
