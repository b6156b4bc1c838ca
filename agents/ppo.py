"""The policy PPO trains: Stable-Baselines3's ``MlpPolicy`` with leaner forward passes.

At every step of a rollout SB3's ``ActorCriticPolicy.forward`` calls a dozen ``nn.Module``
wrappers and builds a ``torch.distributions.Normal`` (with its argument checks) to draw the
actions of two small MLPs, and every minibatch of the update does the same in
``evaluate_actions``: most of that time is Python, not arithmetic.
:class:`LeanActorCriticPolicy` runs the same torch operations on the same tensors in the same
order (``F.linear``, the activation, one ``normal_`` draw, the Gaussian's log-density and
entropy as ``Normal`` writes them), so the actions, values, random stream, gradients and
trained weights are SB3's bit for bit (``tests/test_lean_ppo.py`` trains both side by side).
A configuration it does not know layer by layer (another feature extractor or distribution,
state-dependent exploration, squashed or non-flat observations) takes SB3's own methods.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, Final

import torch as th
import torch.nn.functional as F
from gymnasium import spaces
from stable_baselines3.common.distributions import DiagGaussianDistribution
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import FlattenExtractor, MlpExtractor

__all__ = ["LeanActorCriticPolicy"]

Tensor = th.Tensor
Layer = Callable[[Tensor], Tensor]

_ACTIVATIONS: Final[dict[type[th.nn.Module], Layer]] = {
    th.nn.Tanh: th.tanh,  # nn.Tanh.forward is torch.tanh
    th.nn.ReLU: th.relu,  # nn.ReLU(inplace=False).forward is F.relu, i.e. torch.relu
}
_LOG_SQRT_2PI: Final = math.log(math.sqrt(2 * math.pi))
"""The constant of ``torch.distributions.Normal.log_prob``, computed as it computes it."""
_ENTROPY_CONSTANT: Final = 0.5 + 0.5 * math.log(2 * math.pi)
"""The constant of ``torch.distributions.Normal.entropy``, computed as it computes it."""


def _linear(weight: Tensor, bias: Tensor | None) -> Layer:
    """``nn.Linear.forward`` on these parameter tensors."""
    return lambda x: F.linear(x, weight, bias)


def _layers(network: th.nn.Module) -> list[Layer] | None:
    """The functions of a ``Sequential`` of ``Linear`` and tanh/ReLU layers (or of one
    ``Linear``) bound to the layers' parameter tensors, which the optimizer and
    ``load_state_dict`` update in place; None for any other module."""
    modules = list(network) if type(network) is th.nn.Sequential else [network]
    layers: list[Layer] = []
    for module in modules:
        if type(module) is th.nn.Linear:
            layers.append(_linear(module.weight, module.bias))
        elif type(module) in _ACTIVATIONS:
            layers.append(_ACTIVATIONS[type(module)])
        else:
            return None
    return layers


def _log_prob(actions: Tensor, loc: Tensor, scale: Tensor) -> Tensor:
    """``Normal(loc, scale).log_prob(actions)`` summed over the action (SB3's
    ``sum_independent_dims``), written as torch writes it."""
    log_prob = -((actions - loc) ** 2) / (2 * scale**2) - scale.log() - _LOG_SQRT_2PI
    return log_prob.sum(dim=1)


def _run(layers: list[Layer], x: Tensor) -> Tensor:
    for layer in layers:
        x = layer(x)
    return x


class _Networks:
    """The four networks of a plain MLP actor-critic as lists of functions."""

    def __init__(
        self, actor: list[Layer], critic: list[Layer], action: list[Layer], value: list[Layer]
    ) -> None:
        self.actor, self.critic, self.action, self.value = actor, critic, action, value

    def latents(self, obs: Tensor) -> tuple[Tensor, Tensor]:
        """``MlpExtractor.forward`` after ``extract_features`` of a flat Box (``float()``,
        and a flatten of a (batch, size) tensor is itself)."""
        features = obs.float()
        return _run(self.actor, features), _run(self.critic, features)


class LeanActorCriticPolicy(ActorCriticPolicy):
    """SB3's ``MlpPolicy`` (``ActorCriticPolicy``, same constructor); ``forward`` and
    ``evaluate_actions`` skip the module calls and the distribution object when the policy is
    the plain MLP with a diagonal Gaussian on flat observations (the same numbers). The layers
    are read at the first forward pass: replace none of them afterwards."""

    def _networks(self) -> _Networks | None:
        """The networks as functions of their parameter tensors, built at the first call (a
        copy of the policy builds its own: see ``__getstate__``), or None when this policy is
        not the plain case (then SB3's methods answer)."""
        if "_lean_networks" not in self.__dict__:
            self.__dict__["_lean_networks"] = self._build_networks()
        networks: _Networks | None = self.__dict__["_lean_networks"]
        return networks

    def __getstate__(self) -> dict[str, Any]:
        """Without the built networks (functions bound to this object's tensors): what
        ``pickle``, ``copy.copy`` and ``copy.deepcopy`` take of the policy."""
        state = dict(self.__dict__)
        state.pop("_lean_networks", None)
        return state

    def _build_networks(self) -> _Networks | None:
        if not (
            type(self.action_dist) is DiagGaussianDistribution
            and not self.use_sde
            and not self.squash_output
            and self.share_features_extractor
            and type(self.features_extractor) is FlattenExtractor
            and type(self.mlp_extractor) is MlpExtractor
            and type(self.observation_space) is spaces.Box
            and len(self.observation_space.shape) == 1
        ):
            return None
        parts = (
            _layers(self.mlp_extractor.policy_net),
            _layers(self.mlp_extractor.value_net),
            _layers(self.action_net),
            _layers(self.value_net),
        )
        if any(part is None for part in parts):
            return None
        return _Networks(*parts)  # type: ignore[arg-type]

    def forward(self, obs: Any, deterministic: bool = False) -> tuple[Tensor, Tensor, Tensor]:
        """Actions, values and log-probabilities of ``obs`` (``ActorCriticPolicy.forward``)."""
        networks = self._networks()
        if networks is None or not isinstance(obs, th.Tensor):
            return super().forward(obs, deterministic)
        latent_pi, latent_vf = networks.latents(obs)
        values = _run(networks.value, latent_vf)
        mean = _run(networks.action, latent_pi)
        # DiagGaussianDistribution.proba_distribution, Normal.rsample (one normal_ draw of
        # the batch's shape) or its mean
        std = th.ones_like(mean) * self.log_std.exp()
        if deterministic:
            actions = mean
        else:
            actions = mean + th.empty(mean.shape, dtype=mean.dtype).normal_() * std
        log_prob = _log_prob(actions, mean, std)
        actions = actions.reshape((-1, *self.action_space.shape))  # type: ignore[misc]
        return actions, values, log_prob

    def evaluate_actions(self, obs: Any, actions: Tensor) -> tuple[Tensor, Tensor, Tensor | None]:
        """Values, log-probabilities of ``actions`` and entropies
        (``ActorCriticPolicy.evaluate_actions``: the same graph, the same gradients)."""
        networks = self._networks()
        if networks is None or not isinstance(obs, th.Tensor):
            return super().evaluate_actions(obs, actions)
        latent_pi, latent_vf = networks.latents(obs)
        mean = _run(networks.action, latent_pi)
        std = th.ones_like(mean) * self.log_std.exp()
        loc, scale = th.broadcast_tensors(mean, std)  # Normal(mean, std)
        log_prob = _log_prob(actions, loc, scale)
        values = _run(networks.value, latent_vf)
        entropy = _ENTROPY_CONSTANT + th.log(scale)
        return values, log_prob, entropy.sum(dim=1)
