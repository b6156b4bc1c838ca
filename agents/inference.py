"""The policy network of a model folder in NumPy: architecture, normalisation, frame stacking.

What a trained agent computes, independent of how its arrays are stored
(:mod:`agents.model_format` reads and writes them): the observation is standardised by
:class:`ObsNorm`, optionally stacked with the previous ones (:func:`stack_frames`), and fed to
the Gaussian MLP (:class:`GaussianMlp`) described by a :class:`PolicySpec`. NumPy only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final, Literal, get_args

import numpy as np
import numpy.typing as npt

from drill_env.validation import shown

__all__ = [
    "ACTIVATIONS",
    "NOISE_TYPES",
    "Activation",
    "GaussianMlp",
    "Noise",
    "ObsNorm",
    "PolicySpec",
    "stack_frames",
]

Activation = Literal["tanh", "relu"]
"""Activation function of the hidden layers."""
Noise = Literal["diagonal", "state_dependent"]
"""Exploration noise of the Gaussian: a log-std per action (``log_std`` of shape
``(action_size,)``), or gSDE (``log_std`` of shape ``(last hidden size, action_size)``)."""
ACTIVATIONS: Final[tuple[str, ...]] = get_args(Activation)
NOISE_TYPES: Final[tuple[str, ...]] = get_args(Noise)


@dataclass(frozen=True)
class PolicySpec:
    """The architecture of a Gaussian MLP policy (``config.json``, field ``policy``).

    The action mean is ``W_k act(... act(W_0 z + b_0) ...) + b_k``, clipped to
    ``[action_low, action_high]``; ``z`` is the normalised network input: the observation, or
    with ``frame_stack = k > 1`` the last ``k`` observations concatenated, oldest first
    (:func:`stack_frames`), ``observation_size * k`` numbers. The limits a file may declare
    are checked when it is read (:mod:`agents.model_format`); here only consistency.

    Attributes:
        observation_size: Length of the observation.
        hidden_sizes: Sizes of the hidden layers.
        activation: ``"tanh"`` or ``"relu"``, after every hidden layer.
        action_size: Length of the action.
        action_low: Lower clipping bound per action entry.
        action_high: Upper clipping bound per action entry.
        noise: ``"diagonal"`` or ``"state_dependent"`` (:data:`NOISE_TYPES`).
        frame_stack: Observations in the network input (>= 1).
    """

    observation_size: int
    hidden_sizes: tuple[int, ...]
    activation: str = "tanh"
    action_size: int = 1
    action_low: tuple[float, ...] = (-1.0,)
    action_high: tuple[float, ...] = (1.0,)
    noise: str = "diagonal"
    frame_stack: int = 1

    def __post_init__(self) -> None:
        sizes = (self.observation_size, *self.hidden_sizes, self.action_size, self.frame_stack)
        if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in sizes):
            raise ValueError(f"PolicySpec: sizes must be integers >= 1, got {shown(self)}")
        if self.activation not in ACTIVATIONS or self.noise not in NOISE_TYPES:
            raise ValueError(
                f"PolicySpec: activation {shown(self.activation)} or noise {shown(self.noise)} unknown: "
                f"allowed {list(ACTIVATIONS)} and {list(NOISE_TYPES)}"
            )
        bounds = (self.action_low, self.action_high)
        if any(len(b) != self.action_size for b in bounds) or not all(
            math.isfinite(a) and math.isfinite(b) and a < b for a, b in zip(*bounds, strict=True)
        ):
            raise ValueError(
                f"PolicySpec: action_low {self.action_low} must be below action_high "
                f"{self.action_high}, finite, {self.action_size} entries each"
            )
        if self.noise == "state_dependent" and not self.hidden_sizes:
            raise ValueError("PolicySpec: state-dependent noise needs at least one hidden layer")

    @property
    def input_size(self) -> int:
        """Length of the network input: ``observation_size * frame_stack`` (also the length
        of the normalisation statistics)."""
        return self.observation_size * self.frame_stack

    def layer_sizes(self) -> list[int]:
        """Input, hidden and output sizes."""
        return [self.input_size, *self.hidden_sizes, self.action_size]

    def weight_shapes(self) -> dict[str, tuple[int, ...]]:
        """The network's arrays and their shapes.

        ``hidden.{i}.weight`` ``(out, in)`` and ``hidden.{i}.bias`` ``(out,)`` per hidden
        layer, ``action.weight``, ``action.bias``, and ``log_std``: ``(action_size,)``, or
        ``(last hidden size, action_size)`` for state-dependent noise.
        """
        sizes = self.layer_sizes()
        shapes: dict[str, tuple[int, ...]] = {}
        for i in range(len(self.hidden_sizes)):
            shapes[f"hidden.{i}.weight"] = (sizes[i + 1], sizes[i])
            shapes[f"hidden.{i}.bias"] = (sizes[i + 1],)
        shapes["action.weight"] = (self.action_size, sizes[-2])
        shapes["action.bias"] = (self.action_size,)
        if self.noise == "diagonal":
            shapes["log_std"] = (self.action_size,)
        else:
            shapes["log_std"] = (sizes[-2], self.action_size)
        return shapes

    def to_json(self) -> dict[str, Any]:
        """The ``policy`` field of config.json (``frame_stack`` only when above 1)."""
        out: dict[str, Any] = {
            "type": "gaussian_mlp",
            "hidden_sizes": list(self.hidden_sizes),
            "activation": self.activation,
            "action_size": self.action_size,
            "action_low": [float(x) for x in self.action_low],
            "action_high": [float(x) for x in self.action_high],
            "noise": self.noise,
        }
        if self.frame_stack != 1:
            out["frame_stack"] = self.frame_stack
        return out


@dataclass(frozen=True)
class ObsNorm:
    """Observation normalisation ``clip((obs - mean) / sqrt(var + epsilon), +-clip_obs)``.

    Attributes:
        mean: Running mean, shape ``(input_size,)``.
        var: Running variance (>= 0), same shape.
        clip_obs: Clipping bound of the normalised observation (> 0).
        epsilon: Added to the variance (>= 0; ``var + epsilon > 0``).
    """

    mean: npt.NDArray[np.float64]
    var: npt.NDArray[np.float64]
    clip_obs: float = 10.0
    epsilon: float = 1e-8

    @classmethod
    def identity(cls, size: int) -> ObsNorm:
        """No normalisation (mean 0, variance 1, no clipping in practice)."""
        return cls(np.zeros(size), np.ones(size), 1e6, 0.0)

    @staticmethod
    def shapes(size: int) -> dict[str, tuple[int, ...]]:
        """The stored arrays and their shapes."""
        return {"mean": (size,), "var": (size,), "clip_obs": (), "epsilon": ()}

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, npt.NDArray[np.float64]]) -> ObsNorm:
        """From the arrays of :meth:`shapes`."""
        return cls(
            arrays["mean"], arrays["var"], float(arrays["clip_obs"]), float(arrays["epsilon"])
        )

    def arrays(self) -> dict[str, npt.NDArray[np.float64]]:
        """The stored arrays (float64)."""
        return {
            "mean": np.asarray(self.mean, np.float64),
            "var": np.asarray(self.var, np.float64),
            "clip_obs": np.asarray(self.clip_obs, np.float64),
            "epsilon": np.asarray(self.epsilon, np.float64),
        }


def stack_frames(
    history: npt.ArrayLike | None,
    observation: npt.ArrayLike,
    episode_start: npt.ArrayLike | None,
    frame_stack: int,
) -> npt.NDArray[np.float32]:
    """The network input after one more observation: the last ``frame_stack`` observations
    concatenated, oldest first, zeros for the instants before the episode's start.

    This is Stable-Baselines3's ``VecFrameStack`` on a vector of observations (the history
    shifted left by one observation, the rows that start an episode cleared, the new
    observation written at the end), so a policy trained behind that wrapper sees at inference
    exactly what it saw in training.

    Args:
        history: The previous input, shape ``(n, m * frame_stack)``; ``None`` at the start.
        observation: The new observations, shape ``(n, m)``.
        episode_start: Per row, whether the observation is the first of an episode (its
            history is then cleared), shape ``(n,)``; ``None``: no row starts.
        frame_stack: Observations kept, ``k >= 1``.

    Returns:
        The new input, float32, shape ``(n, m * frame_stack)``.

    Raises:
        ValueError: ``history`` or ``episode_start`` of another shape.
    """
    obs = np.asarray(observation, dtype=np.float32)
    n, m = obs.shape
    width = m * frame_stack
    if history is None:
        stacked = np.zeros((n, width), dtype=np.float32)
    else:
        stacked = np.array(history, dtype=np.float32)
        if stacked.shape != (n, width):
            raise ValueError(
                f"state has shape {stacked.shape}: expected ({n}, {width}), the history of "
                f"{frame_stack} observations of {m} (pass None at the start of an episode)"
            )
    stacked = np.roll(stacked, -m, axis=1)
    if episode_start is not None:
        start = np.asarray(episode_start, dtype=bool).reshape(-1)
        if start.shape != (n,):
            raise ValueError(f"episode_start has {start.size} entries: expected {n}")
        stacked[start] = 0.0
    stacked[:, width - m :] = obs
    return stacked


class GaussianMlp:
    """The actor of a Gaussian MLP policy in NumPy (float64 arithmetic).

    Args:
        spec: The architecture.
        weights: The arrays of :meth:`PolicySpec.weight_shapes` (any float dtype; stored as
            float64).

    Raises:
        ValueError: A missing, extra, misshapen or non-finite array.
    """

    def __init__(self, spec: PolicySpec, weights: Mapping[str, npt.ArrayLike]) -> None:
        shapes = spec.weight_shapes()
        extra = sorted(set(weights) - set(shapes))
        missing = [k for k in shapes if k not in weights]
        if extra or missing:
            raise ValueError(
                f"policy weights: missing {missing}, unexpected {extra}; expected {list(shapes)}"
            )
        self.spec = spec
        self.weights: dict[str, npt.NDArray[np.float64]] = {}
        for name, shape in shapes.items():
            array = np.asarray(weights[name], dtype=np.float64)
            if array.shape != shape or not np.all(np.isfinite(array)):
                raise ValueError(
                    f"policy weights: {name} has shape {array.shape}, expected {shape}, and must "
                    "be finite"
                )
            self.weights[name] = array
        n = len(spec.hidden_sizes)
        self._layers = [
            (self.weights[f"hidden.{i}.weight"], self.weights[f"hidden.{i}.bias"]) for i in range(n)
        ]
        self._low = np.asarray(spec.action_low, np.float64)
        self._high = np.asarray(spec.action_high, np.float64)

    def latent(self, z: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Output of the last hidden layer, shape ``(n, last hidden size)``."""
        h = z
        for weight, bias in self._layers:
            h = h @ weight.T + bias
            h = np.tanh(h) if self.spec.activation == "tanh" else np.maximum(h, 0.0)
        return h

    def mean_action(self, latent: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The Gaussian's mean (unclipped), shape ``(n, action_size)``."""
        return latent @ self.weights["action.weight"].T + self.weights["action.bias"]

    def action_std(self, latent: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Standard deviation of the action noise, shape ``(n, action_size)``: ``exp(log_std)``,
        or for state-dependent noise ``sqrt(latent^2 @ exp(log_std)^2)`` (the marginal of
        gSDE with a fresh noise matrix at every call)."""
        std = np.exp(self.weights["log_std"])
        if self.spec.noise == "diagonal":
            return np.broadcast_to(std, (latent.shape[0], self.spec.action_size))
        return np.sqrt((latent * latent) @ (std * std))

    def clip(self, action: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Clip to the action bounds."""
        return np.clip(action, self._low, self._high)
