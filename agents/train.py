"""``drill-gym train``: PPO learns a residual torque on top of the proposed adaptive SMC.

One readable script in the CleanRL manner: the configuration (:class:`agents.config.TrainConfig`,
every field documented, every field a ``--flag``), one seeding block, the whole environment
stack in plain view, then PPO. Everything of a run goes to ``runs/{exp_name}__{seed}/``::

    config.json            the hyperparameters of the run
    progress*.csv, tb/     training statistics (SB3 logger; TensorBoard with ``--tensorboard``)
    validation.csv         validation IAE / RMSD / severity relative to the base controller
    checkpoints/           model and VecNormalize statistics every ``--checkpoint-every`` steps
    best/                  the best model on the validation scenarios
    model/                 the final model: model.zip, obs_norm.npz, config.json

Examples::

    drill-gym train                                  # the shipped agent's settings
    drill-gym train --total-timesteps 20000 --seed 3 # a short run
    drill-gym train --resume                         # continue from the last checkpoint
    drill-gym train --base-controller none --exp-name direct_ppo  # from scratch, no SMC
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import drill_env  # noqa: F401  (registers DrillString-v0)
from agents.config import TrainConfig, parse_config
from agents.policy import ResidualPolicy, save_policy
from drill_env import RewardWeights
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.limits import DEFAULT_TORQUE_LIMITS

__all__ = [
    "VALIDATION_SEED",
    "env_kwargs",
    "find_last_checkpoint",
    "main",
    "make_model",
    "make_training_env",
    "policy_env_kwargs",
    "train",
]

VALIDATION_SEED = 20_000
"""Validation scenario ``k`` is the training distribution drawn with reset seed
``VALIDATION_SEED + k`` (training uses ``seed + i`` and their spawned children; the held-out
set of ``drill-gym evaluate`` is a fixed list of scenarios)."""

CHECKPOINT_PREFIX = "rl_model"
RMSD_TARGET = 0.99
"""Model selection on validation: score = mean IAE ratio + 10 x the mean RMSD ratio's excess
over this (a 1 % margin below the base controller's RMSD)."""


def policy_env_kwargs(config: TrainConfig) -> dict[str, Any]:
    """The ``DrillString-v0`` keywords the trained policy needs at evaluation time."""
    base = None if config.base_controller.lower() == "none" else config.base_controller
    return {
        "base_controller": base,
        "control_dt_s": config.control_dt_s,
        "residual_scale_nm": config.residual_scale_nm,
        "min_torque_nm": DEFAULT_TORQUE_LIMITS.min_nm,
        "max_torque_nm": DEFAULT_TORQUE_LIMITS.max_nm,
    }


def env_kwargs(config: TrainConfig) -> dict[str, Any]:
    """The ``DrillString-v0`` keywords of training: randomised scenarios (the env's default
    ranges: WOB 60-200 kN with a 50 % chance of a step, V_ref 4-16 rad/s, Delta 0-0.75) and the
    reward weights of the configuration (the torque and residual penalties are terms of the
    env's reward, :mod:`drill_env.rewards`)."""
    kwargs = policy_env_kwargs(config)
    residual = kwargs["base_controller"] is not None
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


def find_last_checkpoint(run_dir: Path) -> tuple[Path, Path | None, int] | None:
    """The last checkpoint of a run: (model zip, VecNormalize pickle or None, timesteps)."""
    folder = run_dir / "checkpoints"
    best: tuple[Path, Path | None, int] | None = None
    for path in folder.glob(f"{CHECKPOINT_PREFIX}_*_steps.zip"):
        match = re.fullmatch(rf"{CHECKPOINT_PREFIX}_(\d+)_steps\.zip", path.name)
        if match is None:
            continue
        steps = int(match.group(1))
        norm = folder / f"{CHECKPOINT_PREFIX}_vecnormalize_{steps}_steps.pkl"
        if best is None or steps > best[2]:
            best = (path, norm if norm.is_file() else None, steps)
    return best


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


def _snapshot_policy(model: Any, venv: Any, config: TrainConfig) -> ResidualPolicy:
    """The live model and the current normalisation statistics as a :class:`ResidualPolicy`."""
    stats = _norm_stats(model, venv)
    return ResidualPolicy(
        model,
        stats["obs_mean"],
        stats["obs_var"],
        policy_env_kwargs(config),
        config.exp_name,
        clip_obs=stats["clip_obs"],
        epsilon=stats["epsilon"],
    )


def _save_final(
    model: Any, venv: Any, config: TrainConfig, folder: Path, extra: dict[str, Any]
) -> Path:
    return save_policy(
        model,
        folder,
        name=config.exp_name,
        env_kwargs=policy_env_kwargs(config),
        **_norm_stats(model, venv),
        metadata={"train_config": json.loads(config.to_json()), **extra},
    )


def _learning_rate(config: TrainConfig) -> Any:
    lr = config.learning_rate
    return (lambda progress: lr * progress) if config.anneal_lr else lr


def make_training_env(config: TrainConfig, vecnormalize_file: Path | None = None) -> Any:
    """The training environment: ``num_envs`` randomised strings in one native vector env,
    seen through SB3's API, with episode statistics and observation (and reward)
    normalisation; the statistics come from ``vecnormalize_file`` when given (resume)."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from agents.vec_env import GymnasiumVecEnv

    vector_env = gym.make_vec(
        "DrillString-v0",
        num_envs=config.num_envs,
        max_episode_steps=round(config.episode_s / config.control_dt_s),
        **env_kwargs(config),
    )
    venv: Any = VecMonitor(GymnasiumVecEnv(vector_env))
    if vecnormalize_file is not None:
        venv = VecNormalize.load(str(vecnormalize_file), venv)
        venv.training = True
        return venv
    return VecNormalize(
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

    model = PPO(
        "MlpPolicy",
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


def train(config: TrainConfig) -> Path:
    """Run one training (see the module docstring); returns the final model's folder."""
    import torch as th
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, TensorBoardOutputFormat
    from stable_baselines3.common.utils import set_random_seed

    run_dir = config.resolved_run_dir()
    run_dir.mkdir(parents=True, exist_ok=True)
    last = find_last_checkpoint(run_dir) if config.resume else None
    if config.resume and last is None:
        raise FileNotFoundError(
            f"--resume: no checkpoint in {str(run_dir / 'checkpoints')!r} "
            f"(expected {CHECKPOINT_PREFIX}_<steps>_steps.zip)"
        )
    start_steps = 0 if last is None else last[2]
    (run_dir / "config.json").write_text(config.to_json() + "\n")

    # ---- seeding: torch, numpy, random (SB3) and the environments' reset seeds
    th.set_num_threads(config.torch_threads)
    set_random_seed(config.seed + start_steps)

    # ---- environment: N strings in one native vector env -> SB3 API -> episode stats -> norm
    venv = make_training_env(config, None if last is None else last[1])

    # ---- agent: PPO with a zero-initialised residual, or the checkpoint to resume
    if last is None:
        model = make_model(config, venv)
    else:
        model = PPO.load(
            last[0],
            env=venv,
            device="cpu",
            custom_objects={"learning_rate": _learning_rate(config)},
        )
        model.set_random_seed(config.seed + start_steps)
    venv.seed(config.seed + start_steps)

    # ---- logging: CSV always, TensorBoard and stdout on request
    suffix = "" if start_steps == 0 else f"-resumed-at-{start_steps}"
    outputs: list[Any] = [CSVOutputFormat(str(run_dir / f"progress{suffix}.csv"))]
    if config.tensorboard:
        outputs.append(TensorBoardOutputFormat(str(run_dir / "tb" / f"run{suffix or '-0'}")))
    if config.verbose:
        from stable_baselines3.common.logger import HumanOutputFormat

        outputs.append(HumanOutputFormat(sys.stdout))
    model.set_logger(Logger(str(run_dir), outputs))

    # ---- callbacks: checkpoints and validation
    callbacks: list[BaseCallback] = []
    if config.checkpoint_every:
        callbacks.append(
            CheckpointCallback(
                save_freq=max(config.checkpoint_every // config.num_envs, 1),
                save_path=str(run_dir / "checkpoints"),
                name_prefix=CHECKPOINT_PREFIX,
                save_vecnormalize=True,
            )
        )
    validation: _Validation | None = None
    if config.validate_every:
        validation = _Validation(config, run_dir, BaseCallback)
        callbacks.append(validation.callback)

    t0 = time.perf_counter()
    model.learn(
        total_timesteps=max(config.total_timesteps - start_steps, 0),
        callback=CallbackList(callbacks),
        progress_bar=config.progress_bar,
        reset_num_timesteps=last is None,
    )
    wall_s = time.perf_counter() - t0
    if validation is not None:
        validation.run(model, venv)  # the final model competes too

    # ---- the final model: the best on validation (or the last one), with its statistics
    extra = {
        "run_timesteps": int(model.num_timesteps),
        "wall_time_s": round(wall_s, 1),
        "resumed_from": start_steps,
        "cpu_count": os.cpu_count(),
        "torch_threads": config.torch_threads,
    }
    out = config.resolved_save_dir()
    if validation is not None and validation.best_dir.is_dir():
        if out.resolve() != validation.best_dir.resolve():
            if out.exists():
                shutil.rmtree(out)
            shutil.copytree(validation.best_dir, out, ignore=shutil.ignore_patterns("score.json"))
        record = json.loads((out / "config.json").read_text())
        record["selected"] = "best on validation"
        record.update(extra)
        record["train_config"] = json.loads(config.to_json())
        (out / "config.json").write_text(json.dumps(record, indent=2) + "\n")
    else:
        _save_final(
            model,
            venv,
            config,
            out,
            {**extra, "timesteps": extra["run_timesteps"], "selected": "last"},
        )
    venv.close()
    return out


class _Validation:
    """Every ``validate_every`` decisions: roll out the validation scenarios with the current
    policy (deterministic), compare with the base controller on the same seeds, log the ratios
    and keep the best model in ``run_dir/best`` (lowest mean IAE ratio plus a penalty on a
    mean RMSD ratio above ``RMSD_TARGET``)."""

    def __init__(self, config: TrainConfig, run_dir: Path, base_callback: type) -> None:
        self.config = config
        self.best_dir = run_dir / "best"
        self.csv = run_dir / "validation.csv"
        kwargs = {
            **policy_env_kwargs(config),
            "randomize": True,
            "episode_s": config.episode_s,
            "noise_std_rad_s": config.noise_std_rad_s,
        }
        self.env = gym.make("DrillString-v0", max_episode_steps=-1, **kwargs)
        base = kwargs["base_controller"] or "proposed"
        base_env = gym.make(
            "DrillString-v0", max_episode_steps=-1, **{**kwargs, "base_controller": base}
        )
        self.seeds = [VALIDATION_SEED + k for k in range(config.validation_episodes)]
        self.reference = [episode_metrics(rollout(base_env, ZeroAction(), s)) for s in self.seeds]
        self.best = math.inf
        score_file = self.best_dir / "score.json"
        if score_file.is_file():
            self.best = float(json.loads(score_file.read_text())["score"])
        self.next_at = 0
        if not self.csv.exists():
            self.csv.write_text("timesteps,iae_ratio,rmsd_ratio,severity_ratio,score\n")
        outer = self

        class _Callback(base_callback):
            def _on_training_start(self) -> None:
                outer.next_at = (
                    self.num_timesteps // config.validate_every + 1
                ) * config.validate_every

            def _on_step(self) -> bool:
                if self.num_timesteps >= outer.next_at:
                    outer.next_at += config.validate_every
                    outer.run(self.model, self.model.get_env())
                return True

        self.callback = _Callback()

    def run(self, model: Any, venv: Any) -> float:
        policy = _snapshot_policy(model, venv, self.config)
        metrics = [episode_metrics(rollout(self.env, policy, s)) for s in self.seeds]
        iae = np.mean([m["iae"] for m in metrics]) / np.mean([m["iae"] for m in self.reference])
        rmsd = np.mean([m["rmsd_nm"] for m in metrics]) / np.mean(
            [m["rmsd_nm"] for m in self.reference]
        )
        sev = np.mean([m["stick_slip_severity"] for m in metrics]) / np.mean(
            [m["stick_slip_severity"] for m in self.reference]
        )
        score = float(iae + 10.0 * max(rmsd - RMSD_TARGET, 0.0))
        steps = int(model.num_timesteps)
        model.logger.record("validation/iae_ratio", float(iae))
        model.logger.record("validation/rmsd_ratio", float(rmsd))
        model.logger.record("validation/severity_ratio", float(sev))
        with self.csv.open("a") as f:
            f.write(f"{steps},{iae:.5f},{rmsd:.5f},{sev:.5f},{score:.5f}\n")
        if score < self.best:
            self.best = score
            _save_final(
                model,
                venv,
                self.config,
                self.best_dir,
                {"validation_score": score, "timesteps": steps},
            )
            (self.best_dir / "score.json").write_text(
                json.dumps({"score": score, "timesteps": steps})
            )
        return score


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym train [--field value ...]``; ``--help`` lists every field."""
    config = parse_config(argv, prog="drill-gym train", description=__doc__ or "")
    out = train(config)
    record = json.loads((out / "config.json").read_text())
    print(
        f"model saved to {out}: {record.get('selected')}, at {record.get('timesteps')} of "
        f"{record.get('run_timesteps')} decisions; {record.get('wall_time_s')} s of training"
    )
    return 0
