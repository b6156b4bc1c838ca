"""The training configuration of the residual PPO agent, CleanRL style: one flat dataclass,
a docstring under every field, parsed from the command line by :func:`parse_config`.

The defaults are the shipped agent's settings (``agents/models/residual_ppo``).
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import json
import textwrap
import typing
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["TrainConfig", "field_docs", "parse_config"]


@dataclass
class TrainConfig:
    """Every setting of one training run of ``drill-gym train``."""

    # ---------------------------------------------------------------- experiment
    exp_name: str = "residual_ppo"
    """Name of the run; the run folder is ``runs/{exp_name}__{seed}`` unless ``run_dir`` is set."""
    seed: int = 1
    """Seed of everything: the network initialisation, PPO's sampling and the training
    scenarios (string ``i`` of the vector env starts from reset seed ``seed + i``)."""
    total_timesteps: int = 2_000_000
    """Agent decisions to train for, summed over the parallel environments (2 M: about 5 min
    on 2 busy cores)."""
    num_envs: int = 16
    """Drill strings simulated in parallel (one native vector env, one compiled call per step)."""
    torch_threads: int = 1
    """Threads of torch for the network updates (1 leaves the other core to the simulation
    and to other work; the tiny network gains nothing from more)."""
    run_dir: str = ""
    """Folder of the run: TensorBoard logs, progress.csv, checkpoints and the final model.
    Empty: ``runs/{exp_name}__{seed}``."""
    save_dir: str = ""
    """Where the final model goes (model.zip, obs_norm.npz, config.json). Empty:
    ``{run_dir}/model``."""
    checkpoint_every: int = 100_000
    """Save a checkpoint (model and normalisation statistics) every this many decisions;
    0 disables checkpoints."""
    resume: bool = False
    """Continue the run in ``run_dir`` from its last checkpoint up to ``total_timesteps``."""
    tensorboard: bool = True
    """Write TensorBoard logs to ``{run_dir}/tb``."""
    progress_bar: bool = True
    """Show SB3's progress bar (tqdm + rich)."""
    verbose: int = 0
    """SB3 verbosity: 0 silent, 1 prints the training statistics after each rollout."""
    validate_every: int = 100_000
    """Run the validation scenarios every this many decisions, log mean IAE, RMSD and
    stick-slip severity relative to the base controller, and keep the best model;
    0 disables validation (the final model is then the last one)."""
    validation_episodes: int = 16
    """Validation scenarios (drawn from the training distribution with fixed seeds that the
    held-out set of ``drill-gym evaluate`` does not use)."""

    # ----------------------------------------------------------------- environment
    base_controller: str = "proposed"
    """Base controller under the residual (a registered name); ``none`` trains a from-scratch
    policy that sets the whole top-drive torque."""
    control_dt_s: float = 0.1
    """Decision period of the agent, s (the base controller still runs at every 1 ms step)."""
    residual_scale_nm: float = 10_000.0
    """Residual torque per unit action, N m: ``u = clip(u_base + residual_scale_nm * a)``."""
    episode_s: float = 100.0
    """Training episode length, s (the start-up transient and one mid-episode WOB step)."""
    noise_std_rad_s: float = 0.1
    """Measurement noise on the speeds during training, rad/s."""
    reward_tracking: float = 1.0
    """Weight of the relative tracking error ``min(|V_ref - w_bit| / V_ref, 1)``."""
    reward_chattering: float = 0.1
    """Weight of the torque variation within a decision period."""
    reward_chattering_scale_nm: float = 50_000.0
    """Torque variation within one decision period that saturates the chattering term, N m
    (the noisy base controller alone varies by about 20 kN m per 0.1 s)."""
    reward_stuck: float = 0.0
    """Weight of the share of time with the bit stuck (0: the tracking term already counts a
    stuck bit as a full error; an extra weight made the agent prefer spinning the bit far
    above a low reference to ever sticking)."""
    reward_torque: float = 0.0
    """Weight of the env's torque term ``mean(u^2) / max_torque^2`` per decision (the paper's
    RMSD measure, from every plant step), subtracted from the reward."""
    reward_residual: float = 0.5
    """Weight of the env's residual term ``mean((u - u_base)^2) / residual_scale_nm^2`` per
    decision (the torque the residual adds, after the torque limits), subtracted from the
    reward: it trades some of the IAE gain for a lower torque (RMSD). Residual mode only
    (ignored with ``base_controller none``)."""

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

    def to_json(self) -> str:
        """The settings as JSON (every field)."""
        return json.dumps(dataclasses.asdict(self), indent=2)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> TrainConfig:
        """A config from a dict (as written by :meth:`to_json`); unknown keys are an error."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - names)
        if unknown:
            raise TypeError(
                f"unrecognized config key(s): {', '.join(unknown)}; valid: {', '.join(sorted(names))}"
            )
        return cls(**values)

    def __post_init__(self) -> None:
        positive = ("total_timesteps", "num_envs", "torch_threads", "n_steps", "batch_size")
        for name in positive + ("n_epochs", "validation_episodes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} = {value!r} is out of range: allowed an integer >= 1")
        for name in ("checkpoint_every", "validate_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} = {value!r} is out of range: allowed an integer >= 0")
        if not 0.0 < self.gamma <= 1.0:
            raise ValueError(f"gamma = {self.gamma!r} is out of range: allowed (0, 1]")
        if not 0.0 <= self.gae_lambda <= 1.0:
            raise ValueError(f"gae_lambda = {self.gae_lambda!r} is out of range: allowed [0, 1]")
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate = {self.learning_rate!r} is out of range: allowed > 0")
        if not self.net_arch or any(n < 1 for n in self.net_arch):
            raise ValueError(f"net_arch = {self.net_arch!r}: allowed a list of sizes >= 1")


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


def _parse_bool(text: str) -> bool:
    lowered = text.strip().lower()
    if lowered in ("1", "true", "yes", "on"):
        return True
    if lowered in ("0", "false", "no", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected true or false, got {text!r}")


def parse_config(
    argv: Sequence[str] | None, prog: str = "drill-gym train", description: str = ""
) -> TrainConfig:
    """A :class:`TrainConfig` from command-line arguments ``--field value`` (``--flag`` alone
    sets a boolean to true, ``--no-flag`` to false; ``--net-arch 64 64`` for lists)."""
    parser = argparse.ArgumentParser(
        prog=prog, description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    docs = field_docs()
    hints = typing.get_type_hints(TrainConfig)
    defaults = TrainConfig()
    for f in dataclasses.fields(TrainConfig):
        flag = "--" + f.name.replace("_", "-")
        default = getattr(defaults, f.name)
        help_text = f"{docs.get(f.name, '')} (default: {default})".replace("%", "%%")
        hint = hints[f.name]
        if hint is bool:
            parser.add_argument(
                flag,
                dest=f.name,
                nargs="?",
                const=True,
                default=default,
                type=_parse_bool,
                help=help_text,
            )
            parser.add_argument(
                "--no-" + f.name.replace("_", "-"),
                dest=f.name,
                action="store_false",
                help=argparse.SUPPRESS,
            )
        elif typing.get_origin(hint) is list:
            parser.add_argument(
                flag, dest=f.name, nargs="+", type=int, default=default, help=help_text
            )
        else:
            parser.add_argument(flag, dest=f.name, type=hint, default=default, help=help_text)
    args = parser.parse_args(list(argv) if argv is not None else None)
    return TrainConfig(**vars(args))
