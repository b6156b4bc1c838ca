"""Training of the residual PPO agent: PPO learns a residual torque on top of the proposed
adaptive SMC (the ``drill-gym train`` command line is :mod:`experiments.train`).

One readable script in the CleanRL manner: the configuration (:class:`agents.config.TrainConfig`,
every field documented, every field a ``--flag``), one seeding block, the whole environment
stack in plain view, then PPO. Everything of a run goes to ``runs/{exp_name}__{seed}/``::

    config.json            the hyperparameters of the run
    progress*.csv, tb/     training statistics (SB3 logger) and, in tb/, the validation ratios
    validation.csv         validation IAE / RMSD / severity relative to the base controller
    checkpoints/steps_N/   policy, value network, optimizer state and normalisation
                           statistics (no pickle) every ``--checkpoint-every`` decisions and
                           at the end; ``--resume`` continues from the last one
    best/                  the best model on the validation scenarios
    model/                 the final model: config.json, policy.safetensors, obs_norm.safetensors

PPO trains in whole rollouts of ``n_steps * num_envs`` decisions, so ``--total-timesteps`` is
rounded up to a whole number of rollouts (the start line says so). An existing run folder is
refused unless ``--resume`` continues it or ``--overwrite`` clears it. One line per rollout
(decisions, decisions per second, mean episode return) and one per validation are printed.

Examples::

    drill-gym train                                  # the shipped agent's settings
    drill-gym train --total-timesteps 20000 --seed 3 # a short run (32,000 decisions)
    drill-gym train --resume --total-timesteps 4000000  # continue from the last checkpoint
    drill-gym train --base-controller none --exp-name direct_ppo  # from scratch, no SMC
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import shlex
import shutil
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final, NamedTuple

import gymnasium as gym
import numpy as np

import drill_env  # noqa: F401  (registers DrillString-v0)
from agents.checkpoints import (
    CHECKPOINT_DIR,
    PREFIX,
    Checkpoint,
    find_last_checkpoint,
    load_checkpoint,
    save_checkpoint,
)
from agents.config import COUPLED_ENV_ID, FIELD_ENV_ID, TrainConfig, resumed_config
from agents.model_format import read_json
from agents.policy import PICKLE_RISK, ResidualPolicy, is_model_folder, load_policy, policy_from_sb3
from baselines import controller_names
from baselines.registry import REFERENCE_CONTROLLER
from drill_env import RewardWeights
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.files import write_text
from drill_env.limits import DEFAULT_TORQUE_LIMITS
from drill_env.metrics import interquartile_mean
from drill_env.options import FIELD_MAX_TORQUE_NM, FieldEnvConfig
from drill_env.scenarios import RPM, FieldRandomization
from drill_env.validation import printable, shown

__all__ = [
    "REFERENCE_CONTROLLER",
    "TRAINING_RANGES",
    "VALIDATION_COLUMNS",
    "VALIDATION_SEED",
    "ValidationScore",
    "env_kwargs",
    "find_last_checkpoint",
    "kept_validation",
    "make_model",
    "make_training_env",
    "planned_timesteps",
    "policy_env_kwargs",
    "recorded_settings",
    "resume_settings",
    "train",
    "validation_scenarios",
    "validation_score",
]

VALIDATION_SEED = 20_000
"""Validation scenario ``k`` is the training distribution drawn with reset seed
``VALIDATION_SEED + k`` (training uses ``seed + i`` and their spawned children; the held-out
set of ``drill-gym evaluate`` is a fixed list of scenarios)."""

RMSD_TARGET = 0.99
"""Model selection on validation: score = mean IAE ratio + 10 x the mean RMSD ratio's excess
over this (a 1 % margin below the base controller's RMSD), plus the severity term of
:func:`validation_score`."""


def validation_scenarios(config: TrainConfig) -> tuple[dict[str, Any], list[int]]:
    """The validation scenarios of a run: the keywords of ``config.env_id`` (the policy's, the
    training distribution, episode length and noise) and the reset seeds
    ``VALIDATION_SEED + k``, ``k < validation_episodes``."""
    kwargs = {
        **policy_env_kwargs(config),
        "randomize": True,
        "episode_s": config.episode_s,
    }
    if config.env_id != COUPLED_ENV_ID:
        kwargs["noise_std_rad_s"] = config.noise_std_rad_s
    return kwargs, [VALIDATION_SEED + k for k in range(config.validation_episodes)]


class ValidationScore(NamedTuple):
    """A policy's validation against its base controller on the same scenarios (lower is
    better throughout)."""

    iae_ratio: float
    """Mean IAE over the base controller's."""
    rmsd_ratio: float
    """Mean RMS torque over the base controller's."""
    severity_ratio: float
    """Mean stick-slip severity over the base controller's."""
    severity_iqm_ratio: float
    """Interquartile mean of the stick-slip severity over the base controller's: a ripple on
    the scenarios that do not stick, which the mean hides behind the ones that do. (Each
    ratio is 1 when both values are 0, infinite when only the base controller's is.)"""
    score: float
    """The selection score ``iae_ratio + 10 max(rmsd_ratio - RMSD_TARGET, 0) + severity_weight
    max(severity_iqm_ratio - 1, 0)``."""


def validation_score(
    metrics: Sequence[Mapping[str, Any]],
    reference: Sequence[Mapping[str, Any]],
    severity_weight: float = 0.0,
) -> ValidationScore:
    """The validation ratios and selection score of episode metrics against the base
    controller's on the same scenarios (:class:`ValidationScore`); ``severity_weight``
    (``TrainConfig.validation_severity_weight``) prices a severity IQM above the base
    controller's, 0 leaves it out."""

    def ratio(key: str, statistic: Any = np.mean) -> float:
        policy, base = (float(statistic([m[key] for m in ms])) for ms in (metrics, reference))
        return policy / base if base > 0 else (1.0 if policy == 0 else math.inf)

    iae, rmsd, sev = ratio("iae"), ratio("rmsd_nm"), ratio("stick_slip_severity")
    sev_iqm = ratio("stick_slip_severity", interquartile_mean)
    score = iae + 10.0 * max(rmsd - RMSD_TARGET, 0.0)
    if severity_weight:
        score += severity_weight * max(sev_iqm - 1.0, 0.0)
    return ValidationScore(iae, rmsd, sev, sev_iqm, float(score))


VALIDATION_COLUMNS: Final = {
    False: ("timesteps", *ValidationScore._fields),
    True: ("timesteps", "mean_reward", "base_mean_reward", "score"),
}
"""The columns of a run's ``validation.csv``: by whether the env is ``DrillStringCoupled-v0``
(a mean reward, the env's own) or not (the ratios of :class:`ValidationScore`)."""


def policy_env_kwargs(config: TrainConfig) -> dict[str, Any]:
    """The keywords of ``config.env_id`` the trained policy needs at evaluation time: base
    controller, decision period, residual scale, the env's torque limits and, on
    ``DrillStringField-v0``, the observation mode (``env_id`` itself is kept apart)."""
    base = None if config.base_controller.lower() == "none" else config.base_controller
    if config.env_id == COUPLED_ENV_ID:
        return {
            "torque_loop": base or "none",
            "control_dt_s": config.control_dt_s,
            "residual_torque_nm": config.residual_scale_nm,
            "max_torque_nm": DEFAULT_TORQUE_LIMITS.max_nm,
        }
    field = config.env_id == FIELD_ENV_ID
    kwargs: dict[str, Any] = {
        "base_controller": base,
        "control_dt_s": config.control_dt_s,
        "residual_scale_nm": config.residual_scale_nm,
        "min_torque_nm": DEFAULT_TORQUE_LIMITS.min_nm,
        "max_torque_nm": FIELD_MAX_TORQUE_NM if field else DEFAULT_TORQUE_LIMITS.max_nm,
    }
    if field:
        kwargs["observation"] = config.observation or FieldEnvConfig.observation
    return kwargs


TRAINING_RANGES: Final[dict[str, FieldRandomization | None]] = {
    "env": None,
    "wide": FieldRandomization(
        wob_range_n=(50e3, 230e3),
        reference_range_rad_s=(25 * RPM, 160 * RPM),
        measured_depth_range_m=(800.0, 5_500.0),
        mu_a_range=(0.6, 1.15),
        mu_0_ratio_range=(0.42, 0.8),
        xi_range=(0.3, 1.3),
        mud_damping_factor_range=(0.3, 2.0),
    ),
}
"""The scenario ranges of ``--training-ranges`` on ``DrillStringField-v0`` (``None``: the env's
own randomisation). ``wide`` contains the env's ranges and reaches further toward stick-slip
(heavier, slower, longer and shorter strings, stickier bits, less mud damping), where a
residual on a well-tuned loop has something to correct."""


def env_kwargs(config: TrainConfig) -> dict[str, Any]:
    """The keywords of training on ``config.env_id``: randomised scenarios (the env's default
    ranges; ``DrillString-v0``: WOB 60-200 kN with a 50 % chance of a step, V_ref 4-16 rad/s,
    Delta 0-0.75; ``DrillStringField-v0``: docs/specification.md section 18) and the reward
    weights of the configuration (the torque and residual penalties are terms of the env's
    reward, :mod:`drill_env.rewards`)."""
    kwargs = policy_env_kwargs(config)
    if config.env_id == COUPLED_ENV_ID:  # the env's own reward (CoupledRewardWeights)
        return {**kwargs, "randomize": True, "episode_s": config.episode_s}
    residual = kwargs["base_controller"] is not None
    ranges = TRAINING_RANGES[config.training_ranges]
    if ranges is not None:
        kwargs["randomization"] = ranges
    return {
        **kwargs,
        "randomize": True,
        "episode_s": config.episode_s,
        "noise_std_rad_s": config.noise_std_rad_s,
        "reward_weights": RewardWeights(
            tracking=config.reward_tracking,
            chattering=config.reward_chattering,
            stuck=config.reward_stuck,
            chattering_scale_nm=config.reward_chattering_scale_nm,
            torque=config.reward_torque,
            # Without a base controller there is no residual: the whole torque is the agent's.
            residual=config.reward_residual if residual else 0.0,
        ),
    }


def _norm_stats(model: Any, venv: Any) -> dict[str, Any]:
    """The observation normalisation in use: mean, var, clip_obs, epsilon (identity if none)."""
    from stable_baselines3.common.vec_env import VecNormalize

    size = model.observation_space.shape[0]
    if isinstance(venv, VecNormalize) and venv.norm_obs:
        rms: Any = venv.obs_rms  # one RunningMeanStd (Box observations)
        return {
            "obs_mean": rms.mean.copy(),
            "obs_var": rms.var.copy(),
            "clip_obs": float(venv.clip_obs),
            "epsilon": float(venv.epsilon),
        }
    return {"obs_mean": np.zeros(size), "obs_var": np.ones(size), "clip_obs": 1e6, "epsilon": 0.0}


def _learning_rate(config: TrainConfig) -> Any:
    lr = config.learning_rate
    return (lambda progress: lr * progress) if config.anneal_lr else lr


def make_training_env(config: TrainConfig, vecnormalize_file: Path | None = None) -> Any:
    """The training environment: ``num_envs`` randomised strings of ``config.env_id`` in one
    native vector env, seen through SB3's API, with episode statistics, the last
    ``frame_stack`` observations stacked (``VecFrameStack``, when above 1) and observation
    (and reward) normalisation of the stacked vector. ``vecnormalize_file``: an older run's
    pickled VecNormalize statistics (resumed only as named by ``--trust-pickle``; checkpoints of this
    version are loaded by :func:`agents.checkpoints.load_checkpoint`)."""
    from stable_baselines3.common.vec_env import VecFrameStack, VecMonitor, VecNormalize

    from agents.vec_env import GymnasiumVecEnv, LeanVecNormalize

    vector_env = gym.make_vec(
        config.env_id,
        num_envs=config.num_envs,
        max_episode_steps=round(config.episode_s / config.control_dt_s),
        **env_kwargs(config),
    )
    venv: Any = VecMonitor(GymnasiumVecEnv(vector_env))
    if config.frame_stack > 1:
        venv = VecFrameStack(venv, n_stack=config.frame_stack)
    if vecnormalize_file is not None:
        venv = VecNormalize.load(str(vecnormalize_file), venv)
        venv.training = True
        return venv
    return LeanVecNormalize(  # VecNormalize's numbers with fewer Python operations per step
        venv,
        norm_obs=config.norm_obs,
        norm_reward=config.norm_reward,
        gamma=config.gamma,
        clip_obs=10.0,
    )


def make_model(config: TrainConfig, venv: Any) -> Any:
    """A new PPO agent for ``venv`` (separate tanh MLPs for policy and value); with
    ``zero_init_action`` its action mean is exactly 0 for every observation."""
    import torch as th
    from stable_baselines3 import PPO

    from agents.ppo import LeanActorCriticPolicy

    model = PPO(
        LeanActorCriticPolicy,  # SB3's MlpPolicy with fewer Python operations, same numbers
        venv,
        learning_rate=_learning_rate(config),
        n_steps=config.n_steps,
        batch_size=config.batch_size,
        n_epochs=config.n_epochs,
        gamma=config.gamma,
        gae_lambda=config.gae_lambda,
        clip_range=config.clip_range,
        ent_coef=config.ent_coef,
        vf_coef=config.vf_coef,
        max_grad_norm=config.max_grad_norm,
        target_kl=config.target_kl or None,
        use_sde=config.use_sde,
        sde_sample_freq=config.sde_sample_freq,
        policy_kwargs={
            "net_arch": {"pi": list(config.net_arch), "vf": list(config.net_arch)},
            "activation_fn": th.nn.Tanh,
            "log_std_init": config.log_std_init,
        },
        seed=config.seed,
        device="cpu",
        verbose=config.verbose,
    )
    if config.zero_init_action:
        # The residual starts at exactly zero: the untrained agent is the base controller.
        with th.no_grad():
            for parameter in model.policy.action_net.parameters():
                parameter.zero_()
    return model


def planned_timesteps(config: TrainConfig) -> int:
    """``total_timesteps`` rounded up to whole rollouts of ``n_steps * num_envs`` decisions
    (PPO collects whole rollouts; the learning rate anneals over this many)."""
    rollout = config.n_steps * config.num_envs
    return math.ceil(config.total_timesteps / rollout) * rollout


def _snapshot(
    model: Any, venv: Any, config: TrainConfig, metadata: dict[str, Any] | None = None
) -> ResidualPolicy:
    """The live model and the current normalisation statistics as a portable policy."""
    return policy_from_sb3(
        model,
        name=config.exp_name,
        env_kwargs=policy_env_kwargs(config),
        **_norm_stats(model, venv),
        metadata=metadata,
        frame_stack=config.frame_stack,
        env_id=config.env_id,
    )


def _record(config: TrainConfig, extra: dict[str, Any]) -> dict[str, Any]:
    return {"train_config": json.loads(config.to_json()), **extra}


def _is_run_folder(run_dir: Path) -> bool:
    """Whether ``run_dir`` has the config.json that ``drill-gym train`` writes (read bounded
    and strict: a FIFO or a huge file there is not one)."""
    config_file = run_dir / "config.json"
    if config_file.is_symlink():
        return False
    try:
        record = read_json(config_file)
    except (OSError, ValueError):
        return False
    return {"exp_name", "total_timesteps", "n_steps"} <= set(record)


def recorded_settings(run_dir: Path) -> dict[str, Any] | None:
    """The settings a run recorded in ``run_dir/config.json`` (read bounded and strict), or
    None when it has none.

    Raises:
        ValueError: The file is there but is not a JSON object (naming the file).
    """
    config_file = run_dir / "config.json"
    if not os.path.lexists(config_file):
        return None
    if config_file.is_symlink() or not config_file.is_file():
        raise ValueError(
            f"--resume: {shown(str(config_file), 300)} is not a regular file: expected the "
            "settings drill-gym train recorded"
        )
    return read_json(config_file)


def resume_settings(config: TrainConfig, run_dir: Path) -> TrainConfig:
    """``config`` for resuming the run in ``run_dir``, checked against the settings the run
    recorded (:func:`agents.config.resumed_config`: only :data:`agents.config.RESUME_CHANGES`
    may differ).

    Raises:
        ValueError: A setting that differs from the recorded one, or no ``config.json``.
    """
    recorded = recorded_settings(run_dir)
    source = shown(str(run_dir / "config.json"), 300)
    if recorded is None:
        raise ValueError(
            f"--resume: {source} is missing: a run is resumed with the settings it recorded "
            "there (a run folder of drill-gym train has it)"
        )
    given = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    return resumed_config(recorded, given, source)


RUN_SUBFOLDERS: Final = (CHECKPOINT_DIR, "best", "model", "tb")
"""Folders of a run folder that ``drill-gym train`` writes into."""
MAX_LINK_SCAN: Final = 100_000
"""Most entries of a run folder examined for links before resuming."""


def _refuse_links(run_dir: Path) -> None:
    """Refuse to resume in ``run_dir`` when it, or a folder train writes into, holds a
    symbolic link: writing its files (config.json, progress CSVs, checkpoints) would follow
    it to a file that is not the run's."""
    if run_dir.is_symlink():
        return  # the user named the link itself: its target is the run folder
    seen = 0
    for folder in (run_dir, *(run_dir / name for name in RUN_SUBFOLDERS)):
        if folder != run_dir and (folder.is_symlink() or not folder.is_dir()):
            if folder.is_symlink():
                raise ValueError(
                    f"--resume: {str(folder)!r} is a symbolic link: drill-gym train writes only "
                    "into folders of its own run; remove the link or start a new run"
                )
            continue
        with os.scandir(folder) as entries:
            for entry in entries:
                seen += 1
                if seen > MAX_LINK_SCAN:
                    raise ValueError(
                        f"--resume: {str(run_dir)!r} holds more than {MAX_LINK_SCAN} files: not "
                        "a run folder of drill-gym train"
                    )
                if entry.is_symlink():
                    raise ValueError(
                        f"--resume: {str(Path(entry.path))!r} is a symbolic link: drill-gym "
                        "train writes only files of its own run (a link could send them to "
                        "another file); remove the link or start a new run"
                    )


MAX_ROLLOUT_DECISIONS: Final = 10_000_000
"""Most decisions of one rollout (``n_steps * num_envs``): SB3's rollout buffer holds each
decision's observation, action, reward, value and log-probability (about 1 GB at this size
for the 11 observations of DrillString-v0)."""
MAX_TOTAL_TIMESTEPS: Final = 10**12
"""Most decisions of one run (about 300,000 times the shipped agent's 3 M)."""


def _check_settings(config: TrainConfig) -> None:
    """User errors that need no training: sizes, base controller, progress bar packages."""
    import importlib.util

    decisions = config.n_steps * config.num_envs
    if decisions > MAX_ROLLOUT_DECISIONS:
        raise ValueError(
            f"--n-steps {config.n_steps} x --num-envs {config.num_envs} = {decisions} decisions "
            f"per rollout is out of range: allowed at most {MAX_ROLLOUT_DECISIONS:,} (SB3 keeps "
            "the whole rollout in memory)"
        )
    if config.total_timesteps > MAX_TOTAL_TIMESTEPS:
        raise ValueError(
            f"--total-timesteps = {shown(config.total_timesteps)} is out of range: allowed at "
            f"most {MAX_TOTAL_TIMESTEPS:.0e}"
        )
    names = controller_names()
    if config.base_controller.lower() != "none" and config.base_controller not in names:
        raise ValueError(
            f"--base-controller = {shown(config.base_controller)} is not registered: allowed "
            f"{', '.join(names)} or none"
        )
    if config.progress_bar:
        missing = [n for n in ("tqdm", "rich") if importlib.util.find_spec(n) is None]
        if missing:
            raise ValueError(
                f"--progress-bar needs the package(s) {', '.join(missing)} (part of the rl "
                "extra: pip install rich): install them or leave --progress-bar off (the "
                "default; one line per rollout is printed instead)"
            )


def _check_save_dir(config: TrainConfig) -> None:
    """Refuse a ``--save-dir`` whose files are not a model's: the final model's three files
    would replace a user's files of the same names."""
    if not config.save_dir:
        return  # {run_dir}/model: a folder of the run
    folder = Path(config.save_dir)
    if folder.is_symlink() or (os.path.lexists(folder) and not folder.is_dir()):
        raise ValueError(
            f"--save-dir {str(folder)!r} exists and is not a folder: expected a new folder, an "
            "empty one or a model folder"
        )
    if folder.is_dir() and any(folder.iterdir()) and not is_model_folder(folder):
        raise ValueError(
            f"--save-dir {str(folder)!r} holds other files: expected a new folder, an empty one "
            "or a model folder (nothing was written)"
        )


def _prepare_run_dir(config: TrainConfig, run_dir: Path) -> Checkpoint | None:
    """The checkpoint to resume (``--resume``), after refusing a run folder that already
    holds files unless ``--resume`` or ``--overwrite`` (which deletes it) is given."""

    if config.resume:
        if run_dir.is_dir():
            _refuse_links(run_dir)
        last = find_last_checkpoint(run_dir)
        if last is None:
            raise FileNotFoundError(
                f"--resume: no checkpoint in {str(run_dir / CHECKPOINT_DIR)!r} (expected "
                f"folders {PREFIX}<decisions>/ written by drill-gym train); check --run-dir, "
                "--exp-name and --seed, or start a new run without --resume"
            )
        return _trusted(config, last)
    if run_dir.exists() and not run_dir.is_dir():
        raise ValueError(f"--run-dir {str(run_dir)!r} is a file: expected a folder")
    if run_dir.is_dir() and any(run_dir.iterdir()):
        if not config.overwrite:
            raise ValueError(
                f"run folder {str(run_dir)!r} already holds files (an earlier or failed run): "
                "pass --resume to continue it, --overwrite to delete it and start again, or "
                "choose another --exp-name, --seed or --run-dir"
            )
        if not _is_run_folder(run_dir):
            raise ValueError(
                f"--overwrite: {str(run_dir)!r} does not look like a run folder of drill-gym "
                "train (no config.json with its settings), so it is not deleted: delete it "
                "yourself or choose another --run-dir"
            )
        shutil.rmtree(run_dir)
    return None


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except (OSError, ValueError):
        return False


def _trusted(config: TrainConfig, last: Checkpoint) -> Checkpoint:
    """``last`` to resume from: a checkpoint folder as it is; an old pickled checkpoint only
    when ``--trust-pickle`` names exactly its files (the checkpoint and its VecNormalize
    statistics), and then read through the names the user gave."""

    named = [Path(name) for name in config.trust_pickle]
    needed = last.pickles
    option = "--trust-pickle " + " ".join(shlex.quote(str(p)) for p in needed)
    if not needed:
        if named:
            raise ValueError(
                f"--trust-pickle names {', '.join(repr(str(n)) for n in named)}, but the last "
                f"checkpoint {str(last.path)!r} is a checkpoint folder, read without pickle: "
                "nothing to trust; leave --trust-pickle out"
            )
        return last
    for name in named:
        if not name.is_file():
            raise ValueError(f"--trust-pickle {str(name)!r}: no such file")
    missing = [p for p in needed if not any(_same_file(p, n) for n in named)]
    if missing:
        raise ValueError(
            f"--resume: the last checkpoint {str(last.path)!r} is a pickled Stable-Baselines3 "
            f"checkpoint of an older version: {PICKLE_RISK}; pass --trust-pickle only if you "
            f"wrote it yourself, naming its files: {option}"
        )
    extra = [n for n in named if not any(_same_file(n, p) for p in needed)]
    if extra:
        raise ValueError(
            f"--trust-pickle names {', '.join(repr(str(n)) for n in extra)}, which --resume "
            f"does not read: it reads only the last checkpoint's files, {option}"
        )
    path = next(n for n in named if _same_file(n, last.path))
    norm = None
    if last.legacy_norm is not None:
        norm = next(n for n in named if _same_file(n, last.legacy_norm))
    return Checkpoint(path, last.steps, norm, pickled=True)


def _start_line(config: TrainConfig, total: int, last: Checkpoint | None) -> str:
    rollout = config.n_steps * config.num_envs
    shape = f"{config.n_steps:,} steps x {config.num_envs} envs"
    if total != config.total_timesteps:
        plan = (
            f"training {total:,} decisions: --total-timesteps {config.total_timesteps:,} rounded "
            f"up to whole rollouts of {rollout:,} ({shape})"
        )
    else:
        plan = f"training {total:,} decisions: {total // rollout} rollouts of {rollout:,} ({shape})"
    if last is None:
        return plan
    more = max(total - last.steps, 0)
    where = printable(str(last.path), 300)
    return f"resuming from {where} at {last.steps:,} decisions ({more:,} more); {plan}"


def _save_checkpoint(model: Any, venv: Any, config: TrainConfig, run_dir: Path) -> Path:
    """A checkpoint folder ``checkpoints/steps_N`` (:mod:`agents.checkpoints`)."""

    steps = int(model.num_timesteps)
    folder = run_dir / CHECKPOINT_DIR / f"{PREFIX}{steps}"
    folder.parent.mkdir(parents=True, exist_ok=True)
    policy = {
        "name": config.exp_name,
        "env_kwargs": policy_env_kwargs(config),
        **_norm_stats(model, venv),
        "metadata": _record(config, {"timesteps": steps, "selected": "checkpoint"}),
        "frame_stack": config.frame_stack,
        "env_id": config.env_id,
    }
    return save_checkpoint(model, venv, folder, policy=policy)


def train(config: TrainConfig, progress: bool = True) -> Path:
    """Run one training (see the module docstring); returns the final model's folder.

    Args:
        config: The settings of the run.
        progress: Print one line per rollout and per validation (and SB3's progress bar with
            ``config.progress_bar``); ``False`` prints only the start line.

    Raises:
        ValueError: A setting the run cannot use (an unregistered base controller, an
            existing run folder without ``resume`` or ``overwrite``, a pickled checkpoint
            without ``trust_pickle``, a corrupt checkpoint, a resumed run whose settings
            differ from those it recorded beyond :data:`agents.config.RESUME_CHANGES`); one
            line naming the option.
        FileNotFoundError: ``resume`` without a checkpoint.
    """
    run_dir = config.resolved_run_dir()
    _check_settings(config)
    _check_save_dir(config)
    last = _prepare_run_dir(config, run_dir)
    if config.resume:
        config = resume_settings(config, run_dir)
    start_steps = 0 if last is None else last.steps
    total = planned_timesteps(config)
    print(_start_line(config, total, last), flush=True)

    import torch as th
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat
    from stable_baselines3.common.utils import set_random_seed

    run_dir.mkdir(parents=True, exist_ok=True)

    # ---- seeding: torch, numpy, random (SB3) and the environments' reset seeds
    th.set_num_threads(config.torch_threads)
    set_random_seed(config.seed + start_steps)

    # ---- environment: N strings in one native vector env -> SB3 API -> episode stats -> norm
    legacy_norm = last.legacy_norm if last is not None and last.legacy else None
    venv = make_training_env(config, legacy_norm)

    # ---- agent: PPO with a zero-initialised residual, or the checkpoint to resume
    if last is None:
        model = make_model(config, venv)
    elif last.legacy:  # an older run's pickled SB3 checkpoint, the file --trust-pickle names
        model = PPO.load(
            last.path,
            env=venv,
            device="cpu",
            custom_objects={"learning_rate": _learning_rate(config)},
        )
        model.set_random_seed(config.seed + start_steps)
    else:
        model = make_model(config, venv)
        load_checkpoint(model, venv, last.path)
        model.set_random_seed(config.seed + start_steps)
    venv.seed(config.seed + start_steps)
    write_text(run_dir / "config.json", config.to_json() + "\n")  # once the agent is built

    # ---- logging: CSV always, TensorBoard and stdout on request
    suffix = "" if start_steps == 0 else f"-resumed-at-{start_steps}"
    outputs: list[Any] = [CSVOutputFormat(str(run_dir / f"progress{suffix}.csv"))]
    if config.tensorboard:
        outputs.append(TensorBoardOutputFormat(str(run_dir / "tb" / f"run{suffix or '-0'}")))
    if config.verbose:
        from stable_baselines3.common.logger import HumanOutputFormat

        outputs.append(HumanOutputFormat(sys.stdout))
    model.set_logger(Logger(str(run_dir), outputs))

    # ---- callbacks: checkpoints at rollout boundaries, validation, one line per rollout
    validation = _Validation(config, run_dir, progress) if config.validate_every else None
    callback = _run_callback(
        BaseCallback, config, run_dir, total, start_steps, validation, progress
    )

    t0 = time.perf_counter()
    model.learn(
        total_timesteps=max(total - start_steps, 0),
        callback=callback,
        progress_bar=config.progress_bar and progress,
        reset_num_timesteps=last is None,
    )
    wall_s = time.perf_counter() - t0
    if validation is not None:
        validation.run(model, venv)  # the final model competes too
    if callback.last_checkpoint != model.num_timesteps:
        _save_checkpoint(model, venv, config, run_dir)  # always one at the end

    # ---- the final model: the best on validation (or the last one), with its statistics
    extra = {
        "run_timesteps": int(model.num_timesteps),
        "wall_time_s": round(wall_s, 1),
        "resumed_from": start_steps,
        "cpu_count": os.cpu_count(),
        "torch_threads": config.torch_threads,
    }
    if validation is not None and is_model_folder(validation.best_dir):
        final = load_policy(validation.best_dir)
        final.metadata.update({"selected": "best on validation", **extra})
        final.metadata["train_config"] = json.loads(config.to_json())
    else:
        record = {**extra, "timesteps": extra["run_timesteps"], "selected": "last"}
        final = _snapshot(model, venv, config, _record(config, record))
    out = final.save(config.resolved_save_dir())
    model.logger.close()
    venv.close()
    return out


def _run_callback(
    base: type,
    config: TrainConfig,
    run_dir: Path,
    total: int,
    start_steps: int,
    validation: _Validation | None,
    progress: bool = True,
) -> Any:
    """The SB3 callback of a run: a checkpoint at the first rollout boundary after every
    ``checkpoint_every`` decisions (after the update, so that resuming continues from a
    whole rollout), the validation every ``validate_every`` decisions, and one printed line
    per rollout (unless ``progress`` is off or SB3's progress bar shows it)."""
    every = config.checkpoint_every

    class _RunCallback(base):
        def __init__(self) -> None:
            super().__init__()
            self.last_checkpoint = start_steps
            self.next_checkpoint: float = math.inf
            self.t0 = time.perf_counter()

        def _on_training_start(self) -> None:
            steps = self.num_timesteps
            self.t0 = time.perf_counter()
            if every:
                self.next_checkpoint = (steps // every + 1) * every
            if validation is not None:
                validation.next_at = (steps // config.validate_every + 1) * config.validate_every

        def _on_rollout_start(self) -> None:
            if self.num_timesteps >= self.next_checkpoint:
                _save_checkpoint(self.model, self.model.get_env(), config, run_dir)
                self.last_checkpoint = self.num_timesteps
                while self.next_checkpoint <= self.num_timesteps:
                    self.next_checkpoint += every

        def _on_step(self) -> bool:
            # the model at the end of the run is validated after its last update, once
            if validation is not None and validation.next_at <= self.num_timesteps < total:
                validation.next_at += config.validate_every
                validation.run(self.model, self.model.get_env())
            return True

        def _on_rollout_end(self) -> None:
            if config.progress_bar or not progress:
                return
            from stable_baselines3.common.utils import safe_mean

            steps = self.num_timesteps
            rate = (steps - start_steps) / max(time.perf_counter() - self.t0, 1e-9)
            episodes = self.model.ep_info_buffer
            ret = (
                f", mean episode return {safe_mean([e['r'] for e in episodes]):.2f}"
                if episodes
                else ""
            )
            print(f"{config.exp_name}: {steps:,}/{total:,} decisions, {rate:,.0f} decisions/s{ret}")
            sys.stdout.flush()

    return _RunCallback()


def coupled_mean_reward(env: Any, policy: Any, seeds: Sequence[int]) -> float:
    """Mean reward per decision of ``policy`` (deterministic; None: zero action, the base
    loops alone) on ``DrillStringCoupled-v0`` episodes reset with ``seeds``."""
    total, count = 0.0, 0
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            if policy is None:
                action = np.zeros(env.action_space.shape, dtype=np.float32)
            else:
                action, _ = policy.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(action)
            total += float(reward)
            count += 1
            done = terminated or truncated
    return total / max(count, 1)


def kept_validation(run_dir: Path) -> dict[str, Any] | None:
    """The validation whose model a run kept in ``best/`` (``best/score.json``): its selection
    score and the decisions it was taken at (``None`` in the files of earlier versions); ``None``
    when the run kept none (the final model is then the last one).

    Raises:
        ValueError: a score that is not a number, decisions that are not a whole number >= 0
            (the message names the file and the field).
    """
    score_file = Path(run_dir) / "best" / "score.json"
    if not score_file.is_file():
        return None
    record = read_json(score_file)
    score, steps = record.get("score"), record.get("timesteps")
    if isinstance(score, bool) or not isinstance(score, (int, float)):
        raise ValueError(f"{str(score_file)!r}: field score = {shown(score)}: expected a number")
    if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 0):
        raise ValueError(
            f"{str(score_file)!r}: field timesteps = {shown(steps)}: expected an integer >= 0"
        )
    return {"score": float(score), "timesteps": steps}


class _Validation:
    """Every ``validate_every`` decisions: roll out the validation scenarios with the current
    policy (deterministic), compare with the base controller on the same seeds, log the ratios
    (validation.csv, TensorBoard, one printed line) and keep the best model in ``run_dir/best``
    (lowest mean IAE ratio plus a penalty on a mean RMSD ratio above ``RMSD_TARGET``)."""

    def __init__(self, config: TrainConfig, run_dir: Path, progress: bool = True) -> None:
        self.config = config
        self.progress = progress
        self.best_dir = run_dir / "best"
        self.csv = run_dir / "validation.csv"
        kwargs, self.seeds = validation_scenarios(config)
        self.coupled = config.env_id == COUPLED_ENV_ID
        self.env = gym.make(config.env_id, max_episode_steps=-1, **kwargs)
        if self.coupled:
            self.reference_return = coupled_mean_reward(self.env, None, self.seeds)
        else:
            base = kwargs["base_controller"] or REFERENCE_CONTROLLER[config.env_id]
            base_env = gym.make(
                config.env_id, max_episode_steps=-1, **{**kwargs, "base_controller": base}
            )
            self.reference = [
                episode_metrics(rollout(base_env, ZeroAction(), s)) for s in self.seeds
            ]
        kept = kept_validation(run_dir)
        self.best = math.inf if kept is None else kept["score"]
        self.next_at = 0
        if self.csv.exists():  # a resumed run goes on with its own columns
            with self.csv.open() as f:
                self.columns = f.readline().rstrip("\n").split(",")
        else:
            self.columns = list(VALIDATION_COLUMNS[self.coupled])
            write_text(self.csv, ",".join(self.columns) + "\n")

    def _write(self, model: Any, values: dict[str, float], steps: int) -> None:
        """One validation's ``values`` (keyed by column) to TensorBoard (at once, at ``steps``,
        under ``validation/``) and as a line of ``validation.csv``."""
        from stable_baselines3.common.logger import TensorBoardOutputFormat

        logged = {f"validation/{k}": v for k, v in values.items()}
        for output in model.logger.output_formats:
            if isinstance(output, TensorBoardOutputFormat):
                output.write(logged, {k: () for k in logged}, step=steps)
        row = {"timesteps": str(steps), **{k: f"{v:.5f}" for k, v in values.items()}}
        with self.csv.open("a") as f:
            f.write(",".join(row.get(c, "") for c in self.columns) + "\n")

    def _keep_if_best(self, policy: ResidualPolicy, score: float, steps: int) -> bool:
        """Save ``policy`` to ``best/`` with its score when ``score`` is the lowest so far;
        returns whether it was."""
        if not score < self.best:
            return False
        self.best = score
        policy.metadata.update(
            _record(self.config, {"validation_score": score, "timesteps": steps})
        )
        policy.save(self.best_dir)
        write_text(self.best_dir / "score.json", json.dumps({"score": score, "timesteps": steps}))
        return True

    def run(self, model: Any, venv: Any) -> float:
        policy = _snapshot(model, venv, self.config)
        steps = int(model.num_timesteps)
        if self.coupled:
            return self._run_coupled(model, policy, steps)
        metrics = [episode_metrics(rollout(self.env, policy, s)) for s in self.seeds]
        result = validation_score(metrics, self.reference, self.config.validation_severity_weight)
        self._write(model, result._asdict(), steps)
        best = self._keep_if_best(policy, result.score, steps)
        if not self.progress:
            return result.score
        print(
            f"validation at {steps:,} decisions: IAE ratio {result.iae_ratio:.3f}, RMSD ratio "
            f"{result.rmsd_ratio:.3f}, severity ratio {result.severity_ratio:.3f} (IQM "
            f"{result.severity_iqm_ratio:.3f}), score {result.score:.3f}"
            + (" (best so far, saved to best/)" if best else ""),
            flush=True,
        )
        return result.score

    def _run_coupled(self, model: Any, policy: ResidualPolicy, steps: int) -> float:
        """Validation on ``DrillStringCoupled-v0``: the mean reward per decision against the
        base loops' on the same seeds; score ``base - agent`` (lower is better)."""
        mean = coupled_mean_reward(self.env, policy, self.seeds)
        score = self.reference_return - mean
        values = {"mean_reward": mean, "base_mean_reward": self.reference_return, "score": score}
        self._write(model, values, steps)
        best = self._keep_if_best(policy, score, steps)
        if self.progress:
            print(
                f"validation at {steps:,} decisions: mean reward {mean:.4f} (base loops "
                f"{self.reference_return:.4f}), score {score:.4f}"
                + (" (best so far, saved to best/)" if best else ""),
                flush=True,
            )
        return score
