"""A trained PPO agent as a policy with SB3's ``predict()``, and how it is saved and loaded.

A model is a folder of three files:

* ``model.zip``: the Stable-Baselines3 PPO model (network weights and optimiser state);
* ``obs_norm.npz``: the observation normalisation (``mean``, ``var``, ``clip_obs``,
  ``epsilon``; VecNormalize's statistics at the end of training);
* ``config.json``: ``name``, ``env_kwargs`` (the ``DrillString-v0`` keywords the policy needs:
  base controller, decision period, residual scale), ``observation_size``, the training
  configuration and its wall time.

:func:`load_policy` checks the three files against each other and against the environment
they describe, and returns a :class:`ResidualPolicy`. Torch and SB3 are imported only when a
model is loaded or saved.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

from drill_env.layout import observation_size

if TYPE_CHECKING:  # pragma: no cover
    from stable_baselines3 import PPO

__all__ = [
    "CONFIG_FILE",
    "DEFAULT_MODEL_DIR",
    "DEFAULT_MODEL_NAME",
    "MODEL_FILE",
    "NORM_FILE",
    "ResidualPolicy",
    "load_default_policy",
    "load_policy",
    "save_policy",
]

DEFAULT_MODEL_DIR: Final = Path(__file__).resolve().parent / "models"
"""Folder of the shipped models (``agents/models/``)."""
DEFAULT_MODEL_NAME: Final = "residual_ppo"
"""The shipped residual agent: ``DEFAULT_MODEL_DIR / DEFAULT_MODEL_NAME``."""
MODEL_FILE: Final = "model.zip"
NORM_FILE: Final = "obs_norm.npz"
CONFIG_FILE: Final = "config.json"
FORMAT_VERSION: Final = 1
_EXPECTED = f"a model folder with {MODEL_FILE}, {NORM_FILE} and {CONFIG_FILE}"


class ResidualPolicy:
    """A trained agent: observation normalisation, then the PPO policy network.

    ``predict`` follows SB3 (one observation ``(obs_size,)`` or a batch ``(n, obs_size)``;
    actions ``(1,)`` or ``(n, 1)`` in [-1, 1]). The deterministic action (the Gaussian's mean,
    clipped) is computed in NumPy from the network weights; a stochastic one goes through SB3.

    Attributes:
        name: The agent's name (``residual_ppo``, ``direct_ppo``, ...).
        env_kwargs: The ``DrillString-v0`` keywords the agent was trained with and needs:
            ``base_controller`` (``None`` for a from-scratch agent), ``control_dt_s``,
            ``residual_scale_nm``, ``min_torque_nm``, ``max_torque_nm``.
        metadata: The rest of ``config.json`` (training configuration, wall time, ...).
        model: The SB3 PPO model.
    """

    def __init__(
        self,
        model: PPO,
        obs_mean: npt.ArrayLike,
        obs_var: npt.ArrayLike,
        env_kwargs: dict[str, Any],
        name: str,
        clip_obs: float = 10.0,
        epsilon: float = 1e-8,
        metadata: dict[str, Any] | None = None,
    ) -> None:
        self.model = model
        self.name = name
        self.env_kwargs = dict(env_kwargs)
        self.metadata = dict(metadata or {})
        self.obs_mean = np.asarray(obs_mean, dtype=np.float64)
        self.obs_std = np.sqrt(np.asarray(obs_var, dtype=np.float64) + epsilon)
        self.clip_obs = float(clip_obs)
        self._layers = _numpy_actor(model)

    @property
    def observation_size(self) -> int:
        """Length of the observations the policy takes."""
        return int(self.obs_mean.shape[0])

    def normalize(self, observation: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """Observation(s) as the network sees them: standardised and clipped."""
        obs = np.asarray(observation, dtype=np.float64)
        z = np.clip((obs - self.obs_mean) / self.obs_std, -self.clip_obs, self.clip_obs)
        return z.astype(np.float32)

    def predict(
        self,
        observation: npt.ArrayLike,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[npt.NDArray[np.float32], Any]:
        """Action(s) in [-1, 1] for one observation or a batch; ``state`` is passed through."""
        obs = np.asarray(observation, dtype=np.float32)
        if obs.shape[-1] != self.observation_size or obs.ndim not in (1, 2):
            raise ValueError(
                f"{self.name} takes observations of shape ({self.observation_size},) or "
                f"(n, {self.observation_size}), got shape {obs.shape}"
            )
        z = self.normalize(obs)
        if not deterministic or self._layers is None:
            action, _ = self.model.predict(z, deterministic=deterministic)
            return np.asarray(action, dtype=np.float32), state
        h = z.astype(np.float64)
        for weight, bias, activation in self._layers:
            h = h @ weight.T + bias
            if activation == "tanh":
                h = np.tanh(h)
            elif activation == "relu":
                h = np.maximum(h, 0.0)
        return np.clip(h, -1.0, 1.0).astype(np.float32), state

    def __repr__(self) -> str:
        return f"ResidualPolicy(name={self.name!r}, env_kwargs={self.env_kwargs!r})"


def _numpy_actor(
    model: Any,
) -> list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], str]] | None:
    """The actor's layers (weight, bias, activation after) for a plain MLP policy, else None."""
    import torch as th

    policy = model.policy
    try:
        extractor = getattr(policy, "pi_features_extractor", policy.features_extractor)
        if type(extractor).__name__ != "FlattenExtractor":  # pragma: no cover
            return None  # custom extractors go through SB3
        modules = list(policy.mlp_extractor.policy_net) + [policy.action_net]
    except AttributeError:  # pragma: no cover - not an ActorCriticPolicy
        return None
    layers: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], str]] = []
    for module in modules:
        if isinstance(module, th.nn.Linear):
            layers.append(
                (
                    module.weight.detach().cpu().numpy().astype(np.float64),
                    module.bias.detach().cpu().numpy().astype(np.float64),
                    "",
                )
            )
        elif isinstance(module, (th.nn.Tanh, th.nn.ReLU)) and layers:
            w, b, _ = layers[-1]
            layers[-1] = (w, b, "tanh" if isinstance(module, th.nn.Tanh) else "relu")
        else:  # pragma: no cover - other architectures go through SB3
            return None
    if getattr(policy, "squash_output", False):  # pragma: no cover - gSDE with squashing
        return None
    return layers


def save_policy(
    model: PPO,
    directory: str | Path,
    *,
    name: str,
    env_kwargs: dict[str, Any],
    obs_mean: npt.ArrayLike | None = None,
    obs_var: npt.ArrayLike | None = None,
    clip_obs: float = 10.0,
    epsilon: float = 1e-8,
    metadata: dict[str, Any] | None = None,
) -> Path:
    """Write ``model.zip``, ``obs_norm.npz`` and ``config.json`` into ``directory``.

    Without normalisation statistics the identity is stored (mean 0, variance 1, epsilon 0,
    no clipping).

    Returns:
        The folder.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    size = int(model.observation_space.shape[0])  # type: ignore[index]
    mean = np.zeros(size) if obs_mean is None else np.asarray(obs_mean, dtype=np.float64)
    var = np.ones(size) if obs_var is None else np.asarray(obs_var, dtype=np.float64)
    if obs_mean is None:
        clip_obs, epsilon = 1e6, 0.0
    model.save(out / MODEL_FILE)
    np.savez(out / NORM_FILE, mean=mean, var=var, clip_obs=clip_obs, epsilon=epsilon)
    record = {
        "format": FORMAT_VERSION,
        "name": name,
        "env_kwargs": env_kwargs,
        "observation_size": size,
        **(metadata or {}),
    }
    (out / CONFIG_FILE).write_text(json.dumps(record, indent=2) + "\n")
    return out


def _model_files(path: Path) -> tuple[Path, Path, Path]:
    if not path.exists():
        raise FileNotFoundError(
            f"no model at {str(path)!r}: expected {_EXPECTED}, or its {MODEL_FILE}"
        )
    folder = path if path.is_dir() else path.parent
    model = path if path.is_file() else folder / MODEL_FILE
    files = (model, folder / NORM_FILE, folder / CONFIG_FILE)
    missing = [f.name for f in files if not f.is_file()]
    if missing:
        raise FileNotFoundError(
            f"incomplete model in {str(folder)!r}: expected {_EXPECTED}; missing {', '.join(missing)}"
        )
    return files


def load_policy(path: str | Path, base_controller: Any = ...) -> ResidualPolicy:
    """Load a saved agent (a model folder, or the ``model.zip`` in one).

    Args:
        path: The model folder (``model.zip``, ``obs_norm.npz``, ``config.json``) or its zip.
        base_controller: When given, the base controller the caller expects (``None`` for a
            from-scratch agent); a model trained on another one is an error.

    Raises:
        FileNotFoundError: The path or one of the three files does not exist.
        ValueError: A file is corrupt, or the files disagree with each other or with the
            environment (observation size, unknown or unexpected base controller); the message
            says what was expected and what was found.
    """
    model_file, norm_file, config_file = _model_files(Path(path))
    try:
        record = json.loads(config_file.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{str(config_file)!r} is not valid JSON: {err}") from None
    if not isinstance(record, dict) or not isinstance(record.get("env_kwargs"), dict):
        raise ValueError(
            f"{str(config_file)!r}: expected a JSON object with 'name' and 'env_kwargs', "
            f"found {type(record).__name__} with keys {sorted(record) if isinstance(record, dict) else []}"
        )
    env_kwargs: dict[str, Any] = dict(record["env_kwargs"])
    found = env_kwargs.get("base_controller")
    from baselines import controller_names

    if found is not None and found not in controller_names():
        raise ValueError(
            f"{str(config_file)!r}: the model was trained on base controller {found!r}, which is "
            f"not registered; expected one of {controller_names()} or None"
        )
    if base_controller is not ... and found != base_controller:
        raise ValueError(
            f"{str(path)!r}: wrong base controller: expected a model trained on "
            f"{base_controller!r}, found one trained on {found!r}"
        )
    expected_size = observation_size(found is not None)
    try:
        with np.load(norm_file) as stats:
            mean, var = np.asarray(stats["mean"]), np.asarray(stats["var"])
            clip_obs, epsilon = float(stats["clip_obs"]), float(stats["epsilon"])
    except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as err:
        raise ValueError(
            f"{str(norm_file)!r} is not valid normalisation statistics (an .npz with mean, var, "
            f"clip_obs, epsilon): {err}"
        ) from None
    if mean.shape != (expected_size,) or var.shape != (expected_size,):
        raise ValueError(
            f"{str(norm_file)!r}: wrong observation size: expected {expected_size} "
            f"(base_controller={found!r}), found statistics of shape {mean.shape}"
        )
    if not zipfile.is_zipfile(model_file):
        raise ValueError(
            f"{str(model_file)!r} is not a valid Stable-Baselines3 model: expected a zip archive, "
            "found something else (corrupt or truncated file?)"
        )
    from stable_baselines3 import PPO

    try:
        model = PPO.load(model_file, device="cpu")
    except Exception as err:  # SB3 raises many types on a bad archive
        raise ValueError(
            f"{str(model_file)!r} is not a valid Stable-Baselines3 PPO model: "
            f"{type(err).__name__}: {err}"
        ) from None
    model_size = model.observation_space.shape
    if model_size != (expected_size,):
        raise ValueError(
            f"{str(model_file)!r}: wrong observation size: expected {expected_size} "
            f"(DrillString-v0 with base_controller={found!r}), found a model taking {model_size}"
        )
    metadata = {k: v for k, v in record.items() if k not in ("name", "env_kwargs")}
    return ResidualPolicy(
        model,
        mean,
        var,
        env_kwargs,
        name=str(record.get("name", model_file.parent.name)),
        clip_obs=clip_obs,
        epsilon=epsilon,
        metadata=metadata,
    )


def load_default_policy() -> ResidualPolicy | None:
    """The shipped residual agent (``agents/models/residual_ppo``), or None when absent."""
    folder = DEFAULT_MODEL_DIR / DEFAULT_MODEL_NAME
    if not (folder / MODEL_FILE).is_file():
        return None
    return load_policy(folder)
