"""A trained agent as a policy with SB3's ``predict()`` in pure NumPy, and its model files.

A model folder holds three files that can be read without running any code
(:mod:`agents.model_format`, ``docs/model-files.md``):

* ``config.json``: ``name``, ``env_kwargs`` (the ``DrillString-v0`` keywords the policy needs:
  base controller, decision period, residual scale, torque limits; optionally ``env_id``,
  ``DrillStringField-v0`` for a model of the field string, with its ``observation``),
  ``observation_size``, the architecture (``policy``, with ``frame_stack`` for a policy that
  sees its last observations) and the training record;
* ``policy.safetensors``: the actor's weights, biases and log standard deviation;
* ``obs_norm.safetensors``: the observation normalisation (``mean``, ``var``, ``clip_obs``,
  ``epsilon``: VecNormalize's statistics at the end of training).

:func:`load_policy` checks the files against the schema, against each other and against the
environment they describe, and returns a :class:`ResidualPolicy`; neither torch nor
Stable-Baselines3 is imported. :func:`export_policy` converts a Stable-Baselines3 PPO model
(and its normalisation statistics) to this format; it needs torch. Folders of the previous
format (``.npz`` arrays) still load; an SB3 ``model.zip`` (the first format) is a pickle and
loads only when named with ``trust_pickle=True``.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

import drill_env  # noqa: F401  (registers the envs)
from agents.inference import GaussianMlp, ObsNorm, PolicySpec, stack_frames
from agents.legacy_format import LEGACY_NORM_FILE, LEGACY_WEIGHTS_FILE, read_npz
from agents.model_format import (
    CONFIG_FILE,
    DEFAULT_ENV_ID,
    FORMAT_VERSION,
    NORM_FILE,
    RECORD_FIELDS,
    WEIGHTS_FILE,
    ModelConfig,
    array_files,
    read_arrays,
    read_config,
    read_json,
    split_env_id,
    validate_env_kwargs,
    write_model_files,
)
from baselines import controller_names
from drill_env import COUPLED_ENV_ID
from drill_env.layout import observation_size
from drill_env.validation import shown as shown_value

if TYPE_CHECKING:  # pragma: no cover
    from stable_baselines3 import PPO

__all__ = [
    "CONFIG_FILE",
    "CONVERT_HINT",
    "DEFAULT_MODEL_DIR",
    "DEFAULT_MODEL_NAME",
    "LEGACY_MODEL_FILE",
    "NORM_FILE",
    "PICKLE_RISK",
    "WEIGHTS_FILE",
    "ResidualPolicy",
    "export_policy",
    "is_model_folder",
    "load_default_policy",
    "load_policy",
    "policy_from_sb3",
]

DEFAULT_MODEL_DIR: Final = Path(__file__).resolve().parent / "models"
"""Folder of the shipped models (``agents/models/``)."""
DEFAULT_MODEL_NAME: Final = "residual_ppo"
"""The shipped residual agent: ``DEFAULT_MODEL_DIR / DEFAULT_MODEL_NAME``."""
LEGACY_MODEL_FILE: Final = "model.zip"
"""A Stable-Baselines3 model (format 1): pickled Python objects, read only on opt-in."""
PICKLE_RISK: Final = (
    "loading it unpickles Python objects, which runs any code the file's author put in it"
)
CONVERT_HINT: Final = (
    "if you trust its source, name that file itself: load_policy(FILE, trust_pickle=True) "
    "(drill-gym evaluate FILE --trust-pickle), or convert it once to the safe format with "
    "'drill-gym convert FILE NEW_FOLDER --trust-pickle' (agents.convert.convert_model)"
)
_FILES: Final = (CONFIG_FILE, WEIGHTS_FILE, NORM_FILE)
_LEGACY_FILES: Final = (CONFIG_FILE, LEGACY_WEIGHTS_FILE, LEGACY_NORM_FILE)


class ResidualPolicy:
    """A trained agent: observation normalisation, then a Gaussian MLP, all in NumPy.

    ``predict`` follows SB3 (one observation ``(obs_size,)`` or a batch ``(n, obs_size)``;
    actions ``(1,)`` or ``(n, 1)`` clipped to the action bounds, [-1, 1]). A policy with
    ``spec.frame_stack = k > 1`` sees its last ``k`` observations: the history is the
    ``state`` of ``predict`` (as for SB3's recurrent policies: pass back the state it returned,
    ``None`` or ``episode_start=True`` at the start of an episode; ``rollout`` does), built by
    :func:`agents.inference.stack_frames` as SB3's ``VecFrameStack`` built it in training.
    The deterministic
    action is the Gaussian's mean, computed in float64 from the stored weights (the same
    arithmetic as SB3's forward pass, equal to float32 rounding). A stochastic action adds
    Gaussian noise drawn from the policy's own ``np.random.Generator`` (:meth:`seed`), not
    from torch's random generator as SB3 does, so samples differ from SB3's for one seed.

    Args:
        spec: The architecture.
        weights: The arrays of ``spec.weight_shapes()``.
        obs_norm: The observation normalisation.
        env_kwargs: The ``DrillString-v0`` keywords the agent needs.
        name: The agent's name.
        metadata: The training record (``train_config``, ``timesteps``, ...).
        rng: Generator of the stochastic actions (default: a fresh unseeded one).
        env_id: The env the agent is for (``DrillString-v0`` or ``DrillStringField-v0``).

    Attributes:
        name: The agent's name (``residual_ppo``, ``direct_ppo``, ...).
        env_kwargs: The ``DrillString-v0`` keywords the agent was trained with and needs:
            ``base_controller`` (``None`` for a from-scratch agent), ``control_dt_s``,
            ``residual_scale_nm``, ``min_torque_nm``, ``max_torque_nm``.
        metadata: The rest of ``config.json`` (``format``, ``observation_size``, ``policy``,
            the training configuration, wall time, ...).
        env_id: The env the agent is for: ``gym.make(policy.env_id, **scenario,
            **policy.env_kwargs)`` (``env_kwargs.env_id`` in config.json; ``DrillString-v0``
            when the file names none).
        spec: The architecture.
        obs_norm: The observation normalisation.
    """

    def __init__(
        self,
        spec: PolicySpec,
        weights: Mapping[str, npt.ArrayLike],
        obs_norm: ObsNorm,
        env_kwargs: Mapping[str, Any],
        name: str,
        metadata: Mapping[str, Any] | None = None,
        rng: np.random.Generator | None = None,
        env_id: str = DEFAULT_ENV_ID,
    ) -> None:
        if obs_norm.mean.shape != (spec.input_size,):
            raise ValueError(
                f"obs_norm has shape {obs_norm.mean.shape}: expected ({spec.input_size},)"
            )
        self.spec = spec
        self.network = GaussianMlp(spec, weights)
        self.obs_norm = obs_norm
        self.name = name
        self.env_id = env_id
        self.env_kwargs = dict(env_kwargs)
        self.metadata: dict[str, Any] = {
            "format": FORMAT_VERSION,  # the format of the files read (``save`` writes today's)
            **dict(metadata or {}),
            "observation_size": spec.observation_size,
            "policy": spec.to_json(),
        }
        self.obs_mean = np.asarray(obs_norm.mean, dtype=np.float64)  # (spec.input_size,)
        self.obs_std = np.sqrt(np.asarray(obs_norm.var, dtype=np.float64) + obs_norm.epsilon)
        self.clip_obs = float(obs_norm.clip_obs)
        self._rng = rng if rng is not None else np.random.default_rng()

    @property
    def observation_size(self) -> int:
        """Length of the observations the policy takes (one instant's)."""
        return self.spec.observation_size

    @property
    def frame_stack(self) -> int:
        """Observations the network sees at once (1: no memory)."""
        return self.spec.frame_stack

    @property
    def weights(self) -> dict[str, npt.NDArray[np.float64]]:
        """The network's arrays by name (``policy.safetensors``)."""
        return self.network.weights

    def seed(self, seed: int | None = None) -> None:
        """Reseed the generator of the stochastic actions."""
        self._rng = np.random.default_rng(seed)

    def normalize(self, observation: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """Network input(s) (the observation, or the stacked history of :meth:`predict`'s
        state) as the network sees them: standardised and clipped."""
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
        """Action(s) for one observation or a batch; ``state`` is passed through.

        Args:
            observation: Shape ``(observation_size,)`` or ``(n, observation_size)``.
            state: Without frame stacking returned unchanged (the policy has no memory); with
                it the history returned by the previous call, ``(n, input_size)`` float32
                (``None`` at the start).
            episode_start: Without frame stacking ignored; with it, per observation whether
                it starts an episode (its history is cleared), shape ``(n,)``.
            deterministic: The Gaussian's mean; else a sample from the policy's generator.

        Returns:
            The action(s), float32, shape ``(action_size,)`` or ``(n, action_size)``, and
            ``state`` (with frame stacking the new history).
        """
        obs = np.asarray(observation, dtype=np.float32)
        if obs.ndim not in (1, 2) or obs.shape[-1] != self.observation_size:
            raise ValueError(
                f"{self.name} takes observations of shape ({self.observation_size},) or "
                f"(n, {self.observation_size}), got shape {obs.shape}"
            )
        if self.frame_stack > 1:
            state = stack_frames(
                state, obs.reshape(-1, obs.shape[-1]), episode_start, self.frame_stack
            )
            z = self.normalize(state if obs.ndim == 2 else state[0]).astype(np.float64)
        else:
            z = self.normalize(obs).astype(np.float64)
        latent = self.network.latent(z)
        action = self.network.mean_action(latent)
        if not deterministic:
            std = self.network.action_std(latent)
            action = action + std * self._rng.standard_normal(action.shape)
        return self.network.clip(action).astype(np.float32), state

    def save(self, folder: str | Path) -> Path:
        """Write the model folder in the current format (``config.json``, ``policy.safetensors``,
        ``obs_norm.safetensors``)."""
        env_kwargs = dict(self.env_kwargs)
        if self.env_id != DEFAULT_ENV_ID:
            env_kwargs["env_id"] = self.env_id
        return write_model_files(
            Path(folder),
            name=self.name,
            env_kwargs=env_kwargs,
            spec=self.spec,
            weights={k: v.astype(np.float32) for k, v in self.weights.items()},
            obs_norm=self.obs_norm,
            record=self.metadata,
        )

    def __repr__(self) -> str:
        if self.env_id != DEFAULT_ENV_ID:
            return (
                f"ResidualPolicy(name={shown_value(self.name)}, env_id={shown_value(self.env_id)}, "
                f"env_kwargs={shown_value(self.env_kwargs)})"
            )
        return f"ResidualPolicy(name={self.name!r}, env_kwargs={self.env_kwargs!r})"


# -------------------------------------------------------------------------- from SB3 (torch)
def policy_from_sb3(
    model: PPO,
    *,
    name: str,
    env_kwargs: Mapping[str, Any],
    obs_mean: npt.ArrayLike | None = None,
    obs_var: npt.ArrayLike | None = None,
    clip_obs: float = 10.0,
    epsilon: float = 1e-8,
    metadata: Mapping[str, Any] | None = None,
    frame_stack: int = 1,
    env_id: str = DEFAULT_ENV_ID,
) -> ResidualPolicy:
    """Convert a Stable-Baselines3 PPO model (and VecNormalize statistics) to a
    :class:`ResidualPolicy`: the one conversion from SB3 to the portable format.

    The actor must be SB3's plain MLP (``FlattenExtractor``, Linear layers with one tanh or
    ReLU activation, no squashing); the weights are copied as float32. Without normalisation
    statistics the identity is stored (mean 0, variance 1, epsilon 0, no clipping). A model
    trained behind ``VecFrameStack(n_stack=k)`` (and then ``VecNormalize``) takes
    ``frame_stack=k``: its input is ``k`` observations of the env.

    Raises:
        ValueError: Another architecture (custom extractor, squashed output, ...), or an
            input that is not ``frame_stack`` whole observations.
    """
    import torch as th

    policy = model.policy
    size = int(model.observation_space.shape[0])  # type: ignore[index]
    if frame_stack < 1 or size % frame_stack:
        raise ValueError(
            f"frame_stack = {shown_value(frame_stack)}: the model takes {size} inputs, not a whole number "
            "of stacked observations"
        )
    where = f"cannot convert {type(policy).__name__} of {type(model).__name__}"
    extractor = getattr(
        policy, "pi_features_extractor", getattr(policy, "features_extractor", None)
    )
    if type(extractor).__name__ != "FlattenExtractor":
        raise ValueError(f"{where}: features extractor {type(extractor).__name__} is not supported")
    if getattr(policy, "squash_output", False):
        raise ValueError(f"{where}: squashed (tanh) outputs are not supported")
    if getattr(getattr(policy, "action_dist", None), "use_expln", False):
        raise ValueError(f"{where}: gSDE with use_expln is not supported")
    try:
        modules = list(policy.mlp_extractor.policy_net)
        action_net = policy.action_net
        log_std = policy.log_std
    except AttributeError as err:
        raise ValueError(f"{where}: not an actor-critic MLP policy ({err})") from None

    def array(t: th.Tensor) -> npt.NDArray[np.float32]:
        return t.detach().cpu().numpy().astype(np.float32)

    weights: dict[str, npt.NDArray[np.float32]] = {}
    hidden: list[int] = []
    activations: set[str] = set()
    expect_linear = True
    for module in modules:
        if expect_linear and isinstance(module, th.nn.Linear):
            i = len(hidden)
            weights[f"hidden.{i}.weight"] = array(module.weight)
            weights[f"hidden.{i}.bias"] = array(module.bias)
            hidden.append(int(module.out_features))
            expect_linear = False
        elif not expect_linear and isinstance(module, (th.nn.Tanh, th.nn.ReLU)):
            activations.add("tanh" if isinstance(module, th.nn.Tanh) else "relu")
            expect_linear = True
        else:
            raise ValueError(
                f"{where}: layer {shown_value(module)} is not supported in the policy network"
            )
    if not expect_linear or len(activations) > 1 or not isinstance(action_net, th.nn.Linear):
        raise ValueError(f"{where}: expected Linear layers each followed by one activation")
    weights["action.weight"] = array(action_net.weight)
    weights["action.bias"] = array(action_net.bias)
    use_sde = bool(getattr(policy, "use_sde", False))
    if use_sde:
        std = getattr(policy.action_dist, "get_std")(log_std)  # noqa: B009
        weights["log_std"] = np.log(array(std).astype(np.float64)).astype(np.float32)
    else:
        weights["log_std"] = array(log_std)
    space = model.action_space
    spec = PolicySpec(
        observation_size=size // frame_stack,
        hidden_sizes=tuple(hidden),
        activation=activations.pop() if activations else "tanh",
        action_size=int(action_net.out_features),
        action_low=tuple(float(x) for x in np.asarray(space.low).ravel()),  # type: ignore[attr-defined]
        action_high=tuple(float(x) for x in np.asarray(space.high).ravel()),  # type: ignore[attr-defined]
        noise="state_dependent" if use_sde else "diagonal",
        frame_stack=frame_stack,
    )
    if obs_mean is None:
        norm = ObsNorm.identity(size)
    else:
        var = np.ones(size) if obs_var is None else np.asarray(obs_var, dtype=np.float64)
        norm = ObsNorm(np.asarray(obs_mean, dtype=np.float64), var, float(clip_obs), float(epsilon))
    return ResidualPolicy(spec, weights, norm, env_kwargs, name, metadata, env_id=env_id)


def export_policy(
    model: PPO,
    folder: str | Path,
    *,
    name: str,
    env_kwargs: Mapping[str, Any],
    obs_mean: npt.ArrayLike | None = None,
    obs_var: npt.ArrayLike | None = None,
    clip_obs: float = 10.0,
    epsilon: float = 1e-8,
    metadata: Mapping[str, Any] | None = None,
    frame_stack: int = 1,
    env_id: str = DEFAULT_ENV_ID,
) -> Path:
    """Write an SB3 PPO model and its normalisation statistics as a portable model folder
    (:func:`policy_from_sb3`, then :meth:`ResidualPolicy.save`).

    Args:
        model: The PPO model.
        folder: The model folder (created; its three files are replaced).
        name: The agent's name.
        env_kwargs: The ``DrillString-v0`` keywords the policy needs.
        obs_mean: Observation mean (VecNormalize's ``obs_rms.mean``); None: no normalisation.
        obs_var: Observation variance.
        clip_obs: Clipping of the normalised observation.
        epsilon: Added to the variance.
        metadata: Training-record fields of config.json (``train_config``, ``timesteps``,
            ``selected``, ...; ``docs/model-files.md`` lists them).
        frame_stack: Observations stacked in the model's input (``VecFrameStack``).
        env_id: The env the policy is for.

    Returns:
        The folder.
    """
    policy = policy_from_sb3(
        model,
        name=name,
        env_kwargs=env_kwargs,
        obs_mean=obs_mean,
        obs_var=obs_var,
        clip_obs=clip_obs,
        epsilon=epsilon,
        metadata=metadata,
        frame_stack=frame_stack,
        env_id=env_id,
    )
    return policy.save(folder)


# ---------------------------------------------------------------------------------- loading
def is_model_folder(folder: Path) -> bool:
    """Whether ``folder`` has the files of a portable model (this format or the previous)."""
    return any(
        all((folder / name).is_file() for name in files) for files in (_FILES, _LEGACY_FILES)
    )


def _check_environment(config: ModelConfig, where: str, path: Path, base_controller: Any) -> None:
    """The config against ``DrillString-v0``: registered base controller, observation and
    action sizes."""

    if config.env_id == COUPLED_ENV_ID:
        _check_coupled(config, where)
        return
    found = config.env_kwargs.get("base_controller")
    if found is not None and found not in controller_names():
        raise ValueError(
            f"{where!r}: field env_kwargs.base_controller: the model was trained on base "
            f"controller {shown_value(found)}, which is not registered; expected one of "
            f"{controller_names()} or None"
        )
    if base_controller is not ... and found != base_controller:
        raise ValueError(
            f"{str(path)!r}: wrong base controller: expected a model trained on "
            f"{shown_value(base_controller)}, found one trained on {shown_value(found)}"
        )
    if config.env_id == DEFAULT_ENV_ID:
        expected = observation_size(found is not None)
        env = f"DrillString-v0 with base_controller={shown_value(found)}"
    else:
        expected = _observation_size(config.env_id, config.env_kwargs)
        shown = ", ".join(f"{k}={shown_value(v)}" for k, v in config.env_kwargs.items())
        env = f"{config.env_id} with {shown}"
    if config.spec.observation_size != expected:
        raise ValueError(
            f"{where!r}: field observation_size: wrong observation size: expected {expected} "
            f"({env}), found {config.spec.observation_size}"
        )
    if config.spec.action_size != 1:
        raise ValueError(
            f"{where!r}: field policy.action_size = {config.spec.action_size}: "
            f"{config.env_id} takes one action"
        )


def _check_coupled(config: ModelConfig, where: str) -> None:
    """A ``DrillStringCoupled-v0`` model: its observation and action sizes those of the env
    made with its keywords (which checks its torque loop too)."""
    import gymnasium as gym

    try:
        env = gym.make(config.env_id, **config.env_kwargs)
    except (ValueError, TypeError) as err:
        raise ValueError(f"{where!r}: field env_kwargs: {err}") from None
    sizes = (env.observation_space.shape[0], env.action_space.shape[0])  # type: ignore[index]
    env.close()
    found = (config.spec.observation_size, config.spec.action_size)
    if found != sizes:
        raise ValueError(
            f"{where!r}: fields observation_size, policy.action_size = {found}: expected "
            f"{sizes} ({config.env_id} with {config.env_kwargs})"
        )


def _observation_size(env_id: str, env_kwargs: Mapping[str, Any]) -> int:
    """Length of the observation of ``env_id`` made with ``env_kwargs`` (an env is made)."""
    import gymnasium as gym

    env = gym.make(env_id, **env_kwargs)
    try:
        return int(env.observation_space.shape[0])  # type: ignore[index]
    finally:
        env.close()


def load_policy(
    path: str | Path, base_controller: Any = ..., *, trust_pickle: bool = False
) -> ResidualPolicy:
    """Load a saved agent from its model folder (or a file in it).

    Reads ``config.json`` (checked against the schema), then ``obs_norm.safetensors`` and
    ``policy.safetensors`` (or the ``.npz`` files of a folder of the previous format, format
    2); imports neither torch nor Stable-Baselines3, unpickles nothing.

    Args:
        path: The model folder, or one of its files; or, with ``trust_pickle``, a
            Stable-Baselines3 ``.zip`` file (the earlier format, with the ``config.json`` and
            ``obs_norm.npz`` written beside it).
        base_controller: When given, the base controller the caller expects (``None`` for a
            from-scratch agent); a model trained on another one is an error.
        trust_pickle: Load the Stable-Baselines3 ``.zip`` that ``path`` names. It is a
            pickle: loading it runs any code its author put in it. Only for files you made
            yourself or got from a source you trust; needs torch and SB3. It covers that file
            only: a folder holding a ``model.zip`` is refused.

    Raises:
        FileNotFoundError: The path or one of the files does not exist.
        ValueError: A file is corrupt or breaks the schema, the files disagree with each
            other or with the environment (observation size, unknown or unexpected base
            controller), or the model is a pickle that ``trust_pickle`` does not cover; one
            line naming the file and what is wrong.
    """
    path = Path(path)
    expected = f"a model folder with {', '.join(_FILES)}"
    if not path.exists():
        raise FileNotFoundError(f"no model at {str(path)!r}: expected {expected}")
    if path.is_file() and path.suffix == ".zip":
        if not trust_pickle:
            raise ValueError(
                f"{str(path)!r} is a Stable-Baselines3 model (a pickle): {PICKLE_RISK}; "
                f"{CONVERT_HINT}"
            )
        return _load_sb3(path, base_controller)
    folder = path if path.is_dir() else path.parent
    if path.is_file() and path.name not in (*_FILES, *_LEGACY_FILES):
        raise ValueError(f"{str(path)!r} is not a model file: expected {expected}")
    zip_file = folder / LEGACY_MODEL_FILE
    if zip_file.is_file() and not is_model_folder(folder):
        raise ValueError(
            f"{str(zip_file)!r} is a Stable-Baselines3 model (a pickle): {PICKLE_RISK}; "
            f"{CONVERT_HINT}"
        )
    if not (folder / CONFIG_FILE).is_file():
        missing = [name for name in _FILES if not (folder / name).is_file()]
        raise FileNotFoundError(
            f"incomplete model in {str(folder)!r}: expected {expected}; missing "
            f"{', '.join(missing)}"
        )
    config = read_config(folder)
    missing = [name for name in array_files(config.format) if not (folder / name).is_file()]
    if missing:
        raise FileNotFoundError(
            f"incomplete model in {str(folder)!r}: its config.json is of format "
            f"{config.format}, which needs {', '.join(array_files(config.format))}; missing "
            f"{', '.join(missing)}"
        )
    _check_environment(config, str(folder / CONFIG_FILE), path, base_controller)
    norm, weights = read_arrays(folder, config)
    return ResidualPolicy(
        config.spec,
        weights,
        norm,
        config.env_kwargs,
        config.name,
        config.record,
        env_id=config.env_id,
    )


def _load_sb3(zip_file: Path, base_controller: Any) -> ResidualPolicy:
    """The Stable-Baselines3 ``zip_file`` (exactly that file) with the ``config.json``
    (format 1) and ``obs_norm.npz`` beside it, converted by :func:`policy_from_sb3`
    (unpickles: opt-in)."""
    import zipfile

    folder = zip_file.parent
    config_file, norm_file = folder / CONFIG_FILE, folder / LEGACY_NORM_FILE
    for needed in (config_file, norm_file):
        if not needed.is_file():
            raise FileNotFoundError(
                f"incomplete model in {str(folder)!r}: a Stable-Baselines3 {zip_file.name} needs "
                f"{CONFIG_FILE} and {LEGACY_NORM_FILE} beside it; missing {needed.name}"
            )
    record = read_json(config_file)
    env_id, env_kwargs = split_env_id(
        validate_env_kwargs(record.get("env_kwargs"), str(config_file))
    )
    if env_id != DEFAULT_ENV_ID:
        raise ValueError(
            f"{str(config_file)!r}: field env_kwargs.env_id = {shown_value(env_id)}: a Stable-Baselines3 "
            f"model.zip is always for {DEFAULT_ENV_ID}"
        )
    name = record.get("name", folder.name)
    if not isinstance(name, str) or not name or not name.isprintable() or len(name) > 100:
        raise ValueError(
            f"{str(config_file)!r}: field name = {shown_value(name)}: expected a printable string of 1 to "
            "100 characters"
        )
    found = env_kwargs["base_controller"]
    size = observation_size(found is not None)
    spec_stub = PolicySpec(observation_size=size, hidden_sizes=())
    stub = ModelConfig(name, env_kwargs, spec_stub)
    _check_environment(stub, str(config_file), zip_file, base_controller)
    stats = read_npz(norm_file, ObsNorm.shapes(size), "observation normalisation statistics")
    if not zipfile.is_zipfile(zip_file):
        raise ValueError(
            f"{str(zip_file)!r} is not a valid Stable-Baselines3 model: expected a zip archive, "
            "found something else (corrupt or truncated file?)"
        )
    from stable_baselines3 import PPO

    try:
        model = PPO.load(zip_file, device="cpu")
    except Exception as err:  # SB3 raises many types on a bad archive
        raise ValueError(
            f"{str(zip_file)!r} is not a valid Stable-Baselines3 PPO model: "
            f"{type(err).__name__}: {' '.join(str(err).split())[:200]}"
        ) from None
    if model.observation_space.shape != (size,):
        raise ValueError(
            f"{str(zip_file)!r}: wrong observation size: expected {size} "
            f"(DrillString-v0 with base_controller={shown_value(found)}), found a model taking "
            f"{model.observation_space.shape}"
        )
    metadata = {k: v for k, v in record.items() if k in RECORD_FIELDS}
    return policy_from_sb3(
        model,
        name=name,
        env_kwargs=env_kwargs,
        obs_mean=stats["mean"],
        obs_var=stats["var"],
        clip_obs=float(stats["clip_obs"]),
        epsilon=float(stats["epsilon"]),
        metadata=metadata,
    )


def load_default_policy() -> ResidualPolicy | None:
    """The shipped residual agent (``agents/models/residual_ppo``), or None when absent."""
    folder = DEFAULT_MODEL_DIR / DEFAULT_MODEL_NAME
    if not is_model_folder(folder):
        return None
    return load_policy(folder)
