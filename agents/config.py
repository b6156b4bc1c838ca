"""The training configuration of the residual PPO agent, CleanRL style: one flat dataclass,
a docstring under every field (the help of ``drill-gym train``'s options).

The defaults are the shipped ``DrillString-v0`` agent's settings (``agents/models/residual_ppo``).
Another env has its own defaults in :data:`ENV_DEFAULTS` (the shipped field agent's,
``agents/models/field_agent``): :meth:`TrainConfig.for_env` and the command line apply them to
every field the caller does not set; ``TrainConfig(...)`` itself takes every value as given.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import json
import math
import os
import re
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from drill_env.ids import COUPLED_ENV_ID as _COUPLED_ENV_ID
from drill_env.ids import ENV_ID
from drill_env.ids import FIELD_ENV_ID as _FIELD_ENV_ID
from drill_env.rewards import FIELD_REWARD_WEIGHTS, RewardWeights
from drill_env.validation import printable, shown

__all__ = [
    "ENV_DEFAULTS",
    "ENV_IDS",
    "COUPLED_ENV_ID",
    "FIELD_ENV_ID",
    "MAX_EPOCHS",
    "MAX_FRAME_STACK",
    "MAX_TORCH_THREADS",
    "MAX_VALIDATION_EPISODES",
    "PAPER_ENV_ID",
    "RESUME_CHANGES",
    "TRAINING_RANGE_NAMES",
    "TrainConfig",
    "field_docs",
    "plain_text",
    "resume_conflicts",
    "resumed_config",
]


PAPER_ENV_ID: Final = ENV_ID
"""The paper's 4-DOF string: the env of the dataclass defaults."""
FIELD_ENV_ID: Final = _FIELD_ENV_ID
"""The distributed field string with surface sensors, telemetry and a rig's top drive."""
COUPLED_ENV_ID: Final = _COUPLED_ENV_ID
"""The 4-DOF string on the regenerative bit: two actions (top-drive torque and applied force)."""
ENV_IDS: Final = (PAPER_ENV_ID, FIELD_ENV_ID, COUPLED_ENV_ID)
"""The envs ``drill-gym train`` trains on (``--env-id``)."""
TRAINING_RANGE_NAMES: Final = ("env", "wide")
"""The named scenario ranges of training on the field string (``--training-ranges``)."""
MAX_FRAME_STACK: Final = 256
"""Most past observations a policy may stack (``--frame-stack``)."""
MAX_VALIDATION_EPISODES: Final = 10_000
"""Most validation scenarios of a run (``--validation-episodes``): each is a whole episode of
the policy and of the base controller at every validation."""
MAX_EPOCHS: Final = 1_000
"""Most passes over each rollout (``--n-epochs``)."""
MAX_TORCH_THREADS: Final = max(256, os.cpu_count() or 1)
"""Most threads of torch (``--torch-threads``): 256, or the machine's CPU count if larger
(torch starts them all; tens of thousands crash the process)."""
RESUME_CHANGES: Final = (
    "total_timesteps",
    "torch_threads",
    "progress_bar",
    "verbose",
    "tensorboard",
    "run_dir",
    "save_dir",
    "resume",
    "overwrite",
    "trust_pickle",
)
"""The settings a resumed run may take from the caller instead of its ``config.json``: how
far it goes, with how many threads, what it prints and logs, and where its files are. Every
other setting is the run's own (:func:`resumed_config`)."""

_PAPER_REWARD: Final = RewardWeights()
"""The env's reward weights on ``DrillString-v0``: the defaults of the ``reward_*`` settings."""


ENV_DEFAULTS: Final[dict[str, dict[str, Any]]] = {
    PAPER_ENV_ID: {},
    FIELD_ENV_ID: {
        "exp_name": "field_agent",
        "base_controller": "z_torque_tuned",
        "observation": "surface",
        "training_ranges": "wide",
        "frame_stack": 1,
        "control_dt_s": 0.2,
        "residual_scale_nm": 10_000.0,
        "noise_std_rad_s": 0.05,
        **{  # the env's default reward weights, where they differ from the paper string's
            f"reward_{weight.name}": getattr(FIELD_REWARD_WEIGHTS, weight.name)
            for weight in dataclasses.fields(RewardWeights)
            if getattr(FIELD_REWARD_WEIGHTS, weight.name) != getattr(_PAPER_REWARD, weight.name)
        },
        "n_steps": 500,
        "batch_size": 1000,
        "gamma": 0.99,
        "total_timesteps": 600_000,
        "validate_every": 200_000,
        "validation_episodes": 32,
        "validation_severity_weight": 1.0,
        "checkpoint_every": 200_000,
    },
    COUPLED_ENV_ID: {
        "exp_name": "coupled_agent",
        "base_controller": "stiff_pi",
        "control_dt_s": 0.1,
        "residual_scale_nm": 5_000.0,
        "episode_s": 30.0,
        "noise_std_rad_s": 0.0,
        "num_envs": 8,
        "n_steps": 300,
        "batch_size": 600,
        "gamma": 0.99,
        "total_timesteps": 200_000,
        "validate_every": 50_000,
        "validation_episodes": 8,
        "checkpoint_every": 50_000,
    },
}
"""Per-env training defaults: for each env id, the fields whose default differs from the
dataclass's (``DrillString-v0``'s), and ``frame_stack`` named for the field string (1: frame
stacking of 16 or 48 observations did not train better, docs/reports/field-agent.md). The field
string's are the shipped field agent's: a residual on ``z_torque_tuned`` trained on the wide
ranges for 600,000 decisions, with a tracking weight of 3 (a ripple of the bit speed costs more
against the torque terms), the dataclass's seed and exploration noise, and of the models
validated at 200,000, 400,000 and 600,000 decisions the one with the best score with the
severity term (a ripple of the bit speed on the scenarios that do not stick, which the mean IAE
does not see). Applied by :meth:`TrainConfig.for_env` and the command line to the fields the
caller did not set. On ``DrillStringCoupled-v0`` the base controller is the env's
``torque_loop`` (a registered compiled law), ``residual_scale_nm`` its ``residual_torque_nm``;
the second action is a residual on the fixed applied force (the env's ``residual_force_n``); the
reward is the env's own (``CoupledRewardWeights``: the
``reward_*`` settings do not apply) and there is no measurement noise."""


@dataclass
class TrainConfig:
    """Every setting of one training run of ``drill-gym train``."""

    # ---------------------------------------------------------------- experiment
    exp_name: str = "residual_ppo"
    """Name of the run; the run folder is ``runs/{exp_name}__{seed}`` unless ``run_dir`` is set."""
    seed: int = 1
    """Seed of everything: the network initialisation, PPO's sampling and the training
    scenarios (string ``i`` of the vector env starts from reset seed ``seed + i``)."""
    total_timesteps: int = 3_000_000
    """Agent decisions to train for, summed over the parallel environments, rounded up to
    whole rollouts of ``n_steps * num_envs`` (3 M: 188 rollouts of 16,000)."""
    num_envs: int = 16
    """Drill strings simulated in parallel (one native vector env, one compiled call per step)."""
    torch_threads: int = 1
    """Threads of torch for the network updates (1 leaves the other core to the simulation
    and to other work; the tiny network gains nothing from more)."""
    run_dir: str = ""
    """Folder of the run: TensorBoard logs, progress.csv, checkpoints and the final model.
    Empty: ``runs/{exp_name}__{seed}``."""
    save_dir: str = ""
    """Where the final model goes (config.json, policy.safetensors, obs_norm.safetensors). Empty:
    ``{run_dir}/model``."""
    checkpoint_every: int = 500_000
    """Save a checkpoint (policy, value network, optimizer state and normalisation statistics,
    no pickle) at the first rollout end after every this many decisions; the last one is
    always saved at the end of the run. 0: only the last one."""
    resume: bool = False
    """Continue the run in ``run_dir`` with its own settings: from its last checkpoint up to
    ``total_timesteps``, with the settings the run recorded in its ``config.json``. On the
    command line the options left out take the recorded values, and an option given with a
    value that differs from the recorded one is an error naming it. Only ``total_timesteps``,
    ``torch_threads``, ``progress_bar``, ``verbose``, ``tensorboard``, ``save_dir`` and
    ``trust_pickle`` may change (the run folder is found from ``run_dir``, or from
    ``exp_name`` and ``seed``): ``drill-gym train --resume --out RUN --total-timesteps N``."""
    overwrite: bool = False
    """Delete an existing run folder of ``drill-gym train`` first. Without it (or ``resume``)
    a run folder that already holds files is refused."""
    trust_pickle: tuple[str, ...] = ()
    """The pickled checkpoint files of an older version that ``resume`` may read, each named:
    ``checkpoints/rl_model_N_steps.zip`` and, when the run has one,
    ``checkpoints/rl_model_vecnormalize_N_steps.pkl`` of the checkpoint being resumed.
    Unpickling runs any code the file's author put in it: name only files you wrote yourself.
    The trust covers exactly the files named, for this command only: it is never read back
    from a configuration file."""
    tensorboard: bool = True
    """Write TensorBoard logs (training statistics and validation ratios) to
    ``{run_dir}/tb``."""
    progress_bar: bool = False
    """Show SB3's progress bar (needs the packages tqdm and rich, part of the rl extra).
    Without it one line per rollout and per validation is printed."""
    verbose: int = 0
    """SB3 verbosity: 0 silent, 1 prints SB3's training statistics after each rollout."""
    validate_every: int = 100_000
    """Run the validation scenarios every this many decisions (with the policy acting when the
    count is reached, before that rollout's update) and on the final model, log mean IAE, RMSD
    and stick-slip severity relative to the base controller, and keep the best model (the
    lowest score, :func:`agents.train.validation_score`); 0 disables validation (the final
    model is then the last one)."""
    validation_episodes: int = 16
    """Validation scenarios (drawn from the training distribution with fixed seeds that the
    held-out set of ``drill-gym evaluate`` does not use)."""
    validation_severity_weight: float = 0.0
    """Weight of the stick-slip ripple in the model selection: the validation score adds this
    times the excess over 1 of the ratio of the interquartile means of the stick-slip severity
    (the policy's over the base controller's on the validation scenarios), a ripple that the
    mean hides behind the scenarios that stick. 0: mean IAE and RMSD only."""

    # ----------------------------------------------------------------- environment
    env_id: str = PAPER_ENV_ID
    """The env to train on: ``DrillString-v0`` (the paper's 4-DOF string) or
    ``DrillStringField-v0`` (the field string: surface signals, mud-pulse telemetry, a rig's top
    drive). On the command line the settings not given then take that env's defaults."""
    observation: str = ""
    """Observation mode of ``DrillStringField-v0`` (``surface``: what a rig measures;
    ``estimate``: that plus the base controller's observer estimate of the bit speed and the
    bit-rock torque, computed from the same signals; ``state``: every node measured); empty:
    the env's own default. ``DrillString-v0`` models take the empty value."""
    training_ranges: str = "env"
    """Scenario ranges of the training episodes on ``DrillStringField-v0``: ``env`` (the env's
    randomisation, docs/specification.md section 18) or ``wide`` (those ranges widened toward
    stick-slip: WOB to 230 kN, down to 25 rpm, 0.8-5.5 km, static friction to 1.15, ``mu_0 /
    mu_a`` from 0.42, Stribeck rate to 1.3 s/rad, mud damping from x0.3;
    ``agents.train.TRAINING_RANGES``). Validation always draws from the env's ranges.
    ``DrillString-v0`` takes ``env``."""
    frame_stack: int = 1
    """The policy sees its last this many observations, oldest first (zeros before the start
    of an episode, the history reset at every reset): memory for a partially observed string.
    1: the current observation only."""
    base_controller: str = "proposed"
    """Base controller under the residual (a registered name); ``none`` trains a from-scratch
    policy that sets the whole top-drive torque."""
    control_dt_s: float = 0.1
    """Decision period of the agent, s (the base controller still runs at every 1 ms step)."""
    residual_scale_nm: float = 20_000.0
    """Residual torque per unit action, N m: ``u = clip(u_base + residual_scale_nm * a)``."""
    episode_s: float = 100.0
    """Training episode length, s (the start-up transient and one mid-episode WOB step)."""
    noise_std_rad_s: float = 0.1
    """Measurement noise on the speeds during training, rad/s."""
    reward_tracking: float = _PAPER_REWARD.tracking
    """Weight of the relative tracking error ``min(|V_ref - w_bit| / V_ref, 1)``."""
    reward_chattering: float = _PAPER_REWARD.chattering
    """Weight of the torque variation within a decision period."""
    reward_chattering_scale_nm: float = _PAPER_REWARD.chattering_scale_nm
    """Torque variation within one decision period that saturates the chattering term, N m
    (the noisy base controller alone varies by about 20 kN m per 0.1 s)."""
    reward_stuck: float = _PAPER_REWARD.stuck
    """Weight of the share of time with the bit stuck (0: the tracking term already counts a
    stuck bit as a full error; an extra weight made the agent prefer spinning the bit far
    above a low reference to ever sticking)."""
    reward_torque: float = _PAPER_REWARD.torque
    """Weight of the env's torque term ``mean(u^2) / max_torque^2`` per decision (the paper's
    RMSD measure, from every plant step), subtracted from the reward: it keeps the agent's
    gain in IAE from costing torque."""
    reward_residual: float = _PAPER_REWARD.residual
    """Weight of the env's residual term ``mean((u - u_base)^2) / residual_scale_nm^2`` per
    decision (the torque the residual adds, after the torque limits), subtracted from the
    reward: it pulls the added torque toward 0 (a weight of 0.5 halved the agent's gain in
    IAE; the torque term controls the RMSD directly). Residual mode only (ignored with
    ``base_controller none``)."""

    # ------------------------------------------------------------------------- PPO
    learning_rate: float = 3e-4
    """Adam step size (annealed linearly to 0 when ``anneal_lr``)."""
    anneal_lr: bool = True
    """Decay the learning rate linearly to 0 over ``total_timesteps``."""
    n_steps: int = 1000
    """Decisions per environment per rollout (the rollout has ``n_steps * num_envs``). One
    whole episode (100 s / 0.1 s): the strings of the vector env run in lockstep, so a shorter
    rollout would show each update only one phase of the episode (start-up, or steady
    drilling), and the policy would swing between them."""
    batch_size: int = 1000
    """Minibatch size of the updates."""
    n_epochs: int = 10
    """Passes over each rollout."""
    gamma: float = 0.995
    """Discount per decision (0.995 at 0.1 s: a horizon of about 20 s)."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    clip_range: float = 0.2
    """PPO clipping of the probability ratio."""
    ent_coef: float = 0.0
    """Entropy bonus."""
    vf_coef: float = 0.5
    """Weight of the value loss."""
    max_grad_norm: float = 0.5
    """Gradient clipping by global norm."""
    target_kl: float = 0.0
    """Stop an update early when the approximate KL exceeds this; 0 disables."""
    net_arch: list[int] = field(default_factory=lambda: [64, 64])
    """Hidden layers of the policy and of the value network (separate networks, tanh)."""
    log_std_init: float = -1.0
    """Initial log standard deviation of the Gaussian policy (exploration noise); with
    ``use_sde`` the log scale of the state-dependent noise weights."""
    use_sde: bool = False
    """Generalised state-dependent exploration (gSDE): the noise is a random linear function
    of the policy's last hidden layer, held for ``sde_sample_freq`` steps, so exploration tries
    whole feedback laws instead of white noise (which a slow string mode averages away)."""
    sde_sample_freq: int = -1
    """Draw new gSDE noise weights every this many decisions; -1: once per rollout."""
    zero_init_action: bool = True
    """Start the action mean at exactly 0 (zero weights and bias of the last policy layer):
    the untrained residual agent is then the base controller."""
    norm_obs: bool = True
    """Normalise observations with running statistics (saved with the model)."""
    norm_reward: bool = True
    """Scale rewards by the running standard deviation of the return (training only)."""

    # -------------------------------------------------------------------- helpers
    def resolved_run_dir(self) -> Path:
        """The run folder."""
        return Path(self.run_dir or f"runs/{self.exp_name}__{self.seed}")

    def resolved_save_dir(self) -> Path:
        """The folder of the final model."""
        return Path(self.save_dir) if self.save_dir else self.resolved_run_dir() / "model"

    @classmethod
    def for_env(cls, env_id: str = PAPER_ENV_ID, **values: Any) -> TrainConfig:
        """A config for ``env_id``: ``values`` as given, every other field the env's default
        (:data:`ENV_DEFAULTS`, else the dataclass default).

        Raises:
            ValueError: an unknown env id or a value out of range.
            TypeError: an unknown field.
        """
        if env_id not in ENV_DEFAULTS:
            raise ValueError(
                f"{_option('env_id')} = {shown(env_id)} is not valid: allowed {', '.join(ENV_IDS)}"
            )
        return cls._checked({**ENV_DEFAULTS[env_id], **values, "env_id": env_id})

    def to_json(self) -> str:
        """The settings as JSON (every field)."""
        return json.dumps(dataclasses.asdict(self), indent=2)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> TrainConfig:
        """A config from a dict (as written by :meth:`to_json`); unknown keys are an error.

        A recorded ``trust_pickle`` (``false`` in the records of earlier versions, the files
        named in later ones) is read as no trust: a file never grants it, only the caller
        (``TrainConfig(trust_pickle=...)``, ``--trust-pickle FILE``)."""
        return cls._checked({k: v for k, v in values.items() if k != "trust_pickle"})

    @classmethod
    def _checked(cls, values: dict[str, Any]) -> TrainConfig:
        """``cls(**values)`` after refusing unknown keys."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - names, key=str)
        if unknown:
            raise TypeError(
                f"unrecognized config key(s): {', '.join(printable(k) for k in unknown)}; "
                f"valid: {', '.join(sorted(names))}"
            )
        return cls(**values)

    def __post_init__(self) -> None:
        for name in ("total_timesteps", "num_envs", "n_steps", "batch_size"):
            _check_int(name, getattr(self, name), 1)
        _check_int("n_epochs", self.n_epochs, 1, MAX_EPOCHS)
        _check_int("validation_episodes", self.validation_episodes, 1, MAX_VALIDATION_EPISODES)
        _check_int("torch_threads", self.torch_threads, 1, MAX_TORCH_THREADS)
        for name in ("checkpoint_every", "validate_every"):
            _check_int(name, getattr(self, name), 0)
        _check_int("seed", self.seed, 0, 2**32 - 1)
        _check_int("sde_sample_freq", self.sde_sample_freq, -1)
        if self.verbose not in (0, 1, 2) or isinstance(self.verbose, bool):
            raise ValueError(
                f"{_option('verbose')} = {shown(self.verbose)} is not valid: allowed 0, 1, 2"
            )
        _check_number("gamma", self.gamma, 0.0, 1.0, open_low=True)
        _check_number("gae_lambda", self.gae_lambda, 0.0, 1.0)
        _check_number("learning_rate", self.learning_rate, 0.0, 1.0, open_low=True)
        _check_number("clip_range", self.clip_range, 0.0, 10.0, open_low=True)
        _check_number("max_grad_norm", self.max_grad_norm, 0.0, 1e6, open_low=True)
        for name in ("ent_coef", "vf_coef", "target_kl"):
            _check_number(name, getattr(self, name), 0.0, 1e6)
        _check_number("log_std_init", self.log_std_init, -20.0, 5.0)
        _check_number("validation_severity_weight", self.validation_severity_weight, 0.0, 1e6)
        for name in (
            "reward_tracking",
            "reward_chattering",
            "reward_stuck",
            "reward_torque",
            "reward_residual",
        ):
            _check_number(name, getattr(self, name), 0.0, 1e6)
        _check_number("reward_chattering_scale_nm", self.reward_chattering_scale_nm, 0, 1e9, True)
        _check_number("residual_scale_nm", self.residual_scale_nm, 0.0, 1e6)
        _check_number("control_dt_s", self.control_dt_s, 0.0, 10.0, open_low=True)
        _check_number("episode_s", self.episode_s, 0.0, 1e5, open_low=True)
        _check_number("noise_std_rad_s", self.noise_std_rad_s, 0.0, 10.0)
        _check_int("frame_stack", self.frame_stack, 1, MAX_FRAME_STACK)
        if self.env_id not in ENV_IDS:
            raise ValueError(
                f"{_option('env_id')} = {shown(self.env_id)} is not valid: allowed {', '.join(ENV_IDS)}"
            )
        if self.env_id == PAPER_ENV_ID and self.observation:
            raise ValueError(
                f"{_option('observation')} = {shown(self.observation)} is not valid with "
                f"{_option('env_id')} {PAPER_ENV_ID}: allowed empty (the observation is set "
                f"on {FIELD_ENV_ID} only)"
            )
        if self.training_ranges not in TRAINING_RANGE_NAMES:
            raise ValueError(
                f"{_option('training_ranges')} = {shown(self.training_ranges)} is not valid: allowed "
                f"{', '.join(TRAINING_RANGE_NAMES)}"
            )
        if self.env_id == PAPER_ENV_ID and self.training_ranges != "env":
            raise ValueError(
                f"{_option('training_ranges')} = {shown(self.training_ranges)} is not valid with "
                f"{_option('env_id')} {PAPER_ENV_ID}: allowed env (the ranges are set on "
                f"{FIELD_ENV_ID} only)"
            )
        if self.observation not in ("", "state", "surface", "estimate"):
            raise ValueError(
                f"{_option('observation')} = {shown(self.observation)} is not valid: allowed "
                "surface, estimate, state or empty (the env's default)"
            )
        if not self.net_arch or any(
            isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 1024
            for n in self.net_arch
        ):
            raise ValueError(
                f"{_option('net_arch')} = {shown(self.net_arch)} is out of range: allowed 1 to 8 "
                "layer sizes, each an integer in [1, 1024]"
            )
        if len(self.net_arch) > 8:
            raise ValueError(
                f"{_option('net_arch')} = {shown(self.net_arch)}: allowed at most 8 layers"
            )
        if (
            not self.exp_name
            or not self.exp_name.replace("-", "_").replace(".", "_").isidentifier()
        ):
            raise ValueError(
                f"{_option('exp_name')} = {shown(self.exp_name)} is not valid: allowed letters, "
                "digits, '_', '-' and '.'"
            )
        if self.resume and self.overwrite:
            raise ValueError("--resume and --overwrite exclude each other: choose one")
        self.trust_pickle = _trusted_files(self.trust_pickle)
        if self.trust_pickle and not self.resume:
            raise ValueError(
                f"{_option('trust_pickle')} names pickled checkpoints to resume from: it needs "
                f"{_option('resume')}"
            )


def _option(name: str) -> str:
    """A field as the command line spells it."""
    return "--" + name.replace("_", "-")


def resume_conflicts(recorded: TrainConfig, given: dict[str, Any]) -> list[str]:
    """The settings of ``given`` (name -> value) that a resumed run may not change
    (:data:`RESUME_CHANGES`) and whose value differs from the ``recorded`` one."""
    return [
        name
        for name, value in given.items()
        if name not in RESUME_CHANGES and value != getattr(recorded, name)
    ]


def resumed_config(recorded: dict[str, Any], given: dict[str, Any], source: str) -> TrainConfig:
    """The settings of a resumed run: those ``recorded`` in its ``config.json`` (``source``,
    for messages), with the ``given`` values of :data:`RESUME_CHANGES` and ``resume`` on.

    Raises:
        ValueError: a ``given`` setting outside :data:`RESUME_CHANGES` that differs from the
            recorded value (naming its option and both values), or a record that is not the
            settings of a run.
    """
    try:
        stored = TrainConfig.from_dict(dict(recorded))
    except (TypeError, ValueError) as err:
        raise ValueError(
            f"--resume: {source} does not hold the settings of a run: {printable(err, 300)}"
        ) from None
    conflicts = resume_conflicts(stored, given)
    if conflicts:
        name = conflicts[0]
        more = f" (and {', '.join(_option(n) for n in conflicts[1:])})" if conflicts[1:] else ""
        raise ValueError(
            f"--resume: {_option(name)} = {shown(given[name])} differs from the run's "
            f"{shown(getattr(stored, name))} ({source}){more}: a resumed run keeps its "
            "settings; leave the option out (only "
            f"{', '.join(_option(n) for n in RESUME_CHANGES if n not in ('resume', 'overwrite'))}"
            " may change)"
        )
    changes = {k: v for k, v in given.items() if k in RESUME_CHANGES}
    return dataclasses.replace(stored, **{**changes, "resume": True, "overwrite": False})


def _check_int(name: str, value: Any, low: int, high: int | None = None) -> None:
    ok = not isinstance(value, bool) and isinstance(value, int) and value >= low
    if ok and (high is None or value <= high):
        return
    allowed = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high}]"
    raise ValueError(f"{_option(name)} = {shown(value)} is out of range: allowed {allowed}")


MAX_TRUSTED_FILES: Final = 2
"""Most files ``--trust-pickle`` names: an old checkpoint and its VecNormalize statistics."""


def _trusted_files(value: Any) -> tuple[str, ...]:
    """``value`` as the tuple of file names ``trust_pickle`` holds (a sequence of 1 to
    :data:`MAX_TRUSTED_FILES` non-empty paths, or empty)."""
    option = _option("trust_pickle")
    if isinstance(value, bool):
        raise ValueError(
            f"{option} = {shown(value)} is not valid: name the pickled checkpoint files you trust "
            f"({option} FILE [FILE]); a switch would cover files you did not name"
        )
    if isinstance(value, (str, bytes, os.PathLike)) or not isinstance(value, (list, tuple)):
        raise ValueError(f"{option} = {shown(value)} is not valid: expected a list of file names")
    if len(value) > MAX_TRUSTED_FILES:
        raise ValueError(
            f"{option} names {len(value)} files: allowed at most {MAX_TRUSTED_FILES} (an old "
            "checkpoint rl_model_N_steps.zip and its rl_model_vecnormalize_N_steps.pkl)"
        )
    names = tuple(os.fspath(v) if isinstance(v, os.PathLike) else v for v in value)
    for name in names:
        if not isinstance(name, str) or not name or "\x00" in name or len(name) > 4096:
            raise ValueError(f"{option} = {shown(name)} is not valid: expected a file name")
    return names


def _check_number(name: str, value: Any, low: float, high: float, open_low: bool = False) -> None:
    ok = (
        not isinstance(value, bool)
        and isinstance(value, (int, float))
        and math.isfinite(value if isinstance(value, float) else 0.0)
        and (value > low if open_low else value >= low)
        and value <= high
    )
    if not ok:
        bracket = "(" if open_low else "["
        raise ValueError(
            f"{_option(name)} = {shown(value)} is out of range: allowed {bracket}{low:g}, {high:g}]"
        )


def field_docs(cls: type = TrainConfig) -> dict[str, str]:
    """The docstring under each field of the dataclass ``cls`` (read from its source)."""
    tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    body = tree.body[0].body  # type: ignore[attr-defined]
    docs: dict[str, str] = {}
    for node, after in zip(body, body[1:], strict=False):
        if (
            isinstance(node, ast.AnnAssign)
            and isinstance(node.target, ast.Name)
            and isinstance(after, ast.Expr)
            and isinstance(after.value, ast.Constant)
            and isinstance(after.value.value, str)
        ):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs


def plain_text(text: str, fields: Sequence[str] = ()) -> str:
    """``text`` without Sphinx/reST markup, for ``--help``: roles such as ``:class:`x``` become
    ``x``, double and single backticks are dropped, ``::`` before a literal block becomes
    ``:``, and the names in ``fields`` become their ``--options``."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", text)
    known = set(fields)

    def literal(match: re.Match[str]) -> str:
        inner = match.group(1)
        return _option(inner) if inner in known else inner

    text = re.sub(r"``([^`]+)``", literal, text)
    text = re.sub(r"`([^`]+)`", literal, text)
    text = text.replace("`", "'")
    return re.sub(r"::(\s*\n)", r":\1", text)
