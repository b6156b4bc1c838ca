"""``drill-gym sweep-train``: multi-seed training and hyperparameter search of the residual
agent on Ray Tune (the ``[rl]`` and ``[scale]`` extras).

Every trial is one ordinary training run (:func:`agents.train.train`) with its own run
folder, ``OUT/runs/TRIAL__seedS/`` (TensorBoard logs, ``validation.csv``, checkpoints in the
project's pickle-free format, ``best/`` and ``model/``). Each validation of a run (every
``validate_every`` decisions and at the end; the ratios of the validation scenarios to the
base controller) is reported to Tune: ``iae_ratio``, ``rmsd_ratio``, ``severity_ratio``,
``score`` and ``timesteps``. Tune's scheduler stops trials early on the validation IAE ratio
(``--scheduler asha``, the default: asynchronous successive halving over the validations,
reduction factor 2; ``median``: the median stopping rule; ``none``), never before a trial's
``--grace-period`` validations (default 2). A run without validations (``validate_every``
0, as in the field agent's recipe) reports once, at its end: the validation of its final
model on the same scenarios (:func:`final_validation`).

The trials:

* ``--seeds 1 2 3`` and ``--grid NAME=V1,V2`` (any field of ``drill-gym train``, repeatable):
  every combination (Tune's grid search);
* ``--sample NAME=KIND:LOW:HIGH`` (``uniform``, ``loguniform``, ``int``) or
  ``NAME=choice:A,B``: drawn ``--samples`` times per grid point at random, or by Optuna's
  TPE sampler with ``--sampler optuna`` (Tune's ``OptunaSearch``; one seed, no ``--grid``).

The fixed settings of every trial are the defaults of ``drill-gym train`` for the env of
``--env`` (``DrillString-v0`` by default; ``DrillStringField-v0`` takes the field agent's
defaults, :data:`agents.config.ENV_DEFAULTS`) with a small budget (:data:`SWEEP_DEFAULTS`;
``--train-budget`` keeps the budget of ``drill-gym train`` instead), changed with
``--set NAME=VALUE``.

After the sweep: ``OUT/trials.csv`` and ``OUT/trials.md``, one row per trial (seed,
hyperparameters, the best and the last validation, whether it was stopped early, and the
held-out ratios); the best trial (lowest validation IAE ratio over its validations) is
exported in the project's model format to ``OUT/best_model/`` (its ``model/``, the best on its
validation, or its ``best/`` when the trial was stopped early) and scored on the held-out
scenarios of ``drill-gym evaluate`` for its env against its base controller (``--heldout
best``, the default; ``all`` scores every trial's model, ``none`` none). ``OUT/summary.json`` has it all.

Trials run one CPU each, ``--workers`` at a time on a local Ray cluster (or on the cluster of
``--address``; then ``OUT`` must be on a file system every node shares, since each trial
writes its run folder where it runs).

An interrupted sweep (a killed command, a lost node) is finished by the same command with
``--resume --trust-pickle OUT/tune``: Tune's experiment in ``OUT/tune`` is restored
(``OUT/sweep.json`` must hold the same spec), its finished trials are kept, and every other
trial continues its run folder from the last checkpoint (a run whose final model is written only
reports it again). Tune keeps its state as pickle files, which restoring unpickles: the
command refuses unless ``--trust-pickle`` names that folder (resume only a sweep you ran).
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import math
import shutil
import sys
import time
import typing
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import gymnasium as gym

from agents import train as training
from agents.checkpoints import find_last_checkpoint
from agents.config import TrainConfig
from agents.policy import is_model_folder, load_policy
from agents.train import planned_timesteps, train, validation_scenarios, validation_score
from baselines.registry import REFERENCE_CONTROLLER
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.files import write_text
from drill_env.validation import printable, shown
from experiments.arguments import SEED_HIGH, ArgumentParser, names_type, output_folder
from experiments.evaluate import (
    FIELD_HELD_OUT,
    HELD_OUT,
    evaluate,
    held_out_set,
    summarize,
)
from experiments.field import ENV_IDS, FIELD_ENV, PAPER_ENV, is_field, run_label
from experiments.paths import output_path
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import ADDRESS_VARIABLE, Backend, ray_session
from experiments.tables import Column, markdown_table, write_csv, write_json

__all__ = [
    "METRIC",
    "SWEEP_DEFAULTS",
    "SweepSpec",
    "SweepTrainSpec",
    "final_validation",
    "main",
    "parse_grid",
    "parse_sample",
    "run_study",
    "run_training_sweep",
    "train_trial",
]

METRIC: Final = "iae_ratio"
"""The metric Tune's scheduler and the choice of the best trial use (minimised): the mean
validation IAE relative to the base controller's."""

SWEEP_DEFAULTS: Final[dict[str, Any]] = {
    "total_timesteps": 32_000,
    "num_envs": 8,
    "n_steps": 500,
    "batch_size": 500,
    "episode_s": 50.0,
    "validate_every": 8_000,
    "validation_episodes": 4,
    "checkpoint_every": 16_000,
}
"""Fixed settings of every trial unless ``--set`` changes them: a small budget (8 rollouts of
4,000 decisions, four validations that the scheduler acts on, about a minute per trial)."""

HELDOUT_KEYS: Final = (
    "heldout_iae_ratio",
    "heldout_rmsd_ratio",
    "heldout_severity_prone_ratio",
    "heldout_goal_met",
)
"""Columns of the held-out scores (ratios to the base controller; empty: not scored)."""
SPEC_FILE: Final = "sweep.json"
"""The spec of a sweep, in its output folder: what ``--resume`` checks the options against."""
TUNE_FOLDER: Final = "tune"
"""Tune's experiment folder in the output folder (what ``--resume`` restores)."""
SAMPLE_KINDS: Final = ("uniform", "loguniform", "int", "choice")
"""Distributions of ``--sample``."""
FIXED_FIELDS: Final = (
    "run_dir",
    "save_dir",
    "resume",
    "overwrite",
    "trust_pickle",
    "seed",
    "env_id",
)
"""Fields of the training configuration the sweep sets itself (``env_id`` by ``--env``)."""
BUDGET_FIELDS: Final = tuple(SWEEP_DEFAULTS)
"""The fields of :data:`SWEEP_DEFAULTS`: the budget that ``--train-budget`` leaves at the
defaults of ``drill-gym train``."""


def _fields() -> dict[str, Any]:
    """Field name -> type of :class:`agents.config.TrainConfig` that a sweep may set."""

    hints = typing.get_type_hints(TrainConfig)
    return {
        f.name: hints[f.name] for f in dataclasses.fields(TrainConfig) if f.name not in FIXED_FIELDS
    }


def _value(name: str, text: str, kind: Any) -> Any:
    """``text`` parsed as the field ``name`` of type ``kind``."""
    text = text.strip()
    try:
        if kind is bool:
            lowered = text.lower()
            if lowered not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError
            return lowered in ("true", "1", "yes")
        if kind is int:
            return int(text)
        if kind is float:
            value = float(text)
            if not math.isfinite(value):
                raise ValueError
            return value
        if typing.get_origin(kind) is list:
            return [int(v) for v in text.replace("x", " ").split()]
        return text
    except ValueError:
        raise ValueError(
            f"{name} = {shown(text)} is not a valid {getattr(kind, '__name__', kind)}"
        ) from None


def _field(text: str, option: str) -> tuple[str, str]:
    """``NAME=REST`` -> (field name, REST), the name checked (``-`` read as ``_``)."""
    if "=" not in text:
        raise ValueError(f"{option} {shown(text)}: expected NAME=VALUE")
    name, rest = text.split("=", 1)
    name = name.strip().replace("-", "_")
    fields = _fields()
    if name not in fields:
        raise ValueError(
            f"{option} {shown(text)}: unknown training setting {shown(name)}: allowed {', '.join(sorted(fields))}"
        )
    return name, rest


def parse_grid(text: str) -> tuple[str, list[Any]]:
    """``--grid NAME=V1,V2,...`` -> (field name, values)."""
    name, rest = _field(text, "--grid")
    parts = [p for p in rest.split(",") if p.strip()]
    if not parts:
        raise ValueError(f"--grid {shown(text)}: the grid of {name} is empty: give NAME=V1,V2,...")
    kind = _fields()[name]
    return name, [_value(name, p, kind) for p in parts]


def parse_sample(text: str) -> tuple[str, tuple[str, list[Any]]]:
    """``--sample NAME=KIND:LOW:HIGH`` or ``NAME=choice:A,B`` -> (field, (kind, arguments))."""
    name, rest = _field(text, "--sample")
    kind, _, args = rest.partition(":")
    kind = kind.strip()
    if kind not in SAMPLE_KINDS:
        raise ValueError(
            f"--sample {shown(text)}: unknown distribution {shown(kind)}: allowed {', '.join(SAMPLE_KINDS)}"
        )
    field_kind = _fields()[name]
    if kind == "choice":
        values = [_value(name, p, field_kind) for p in args.split(",") if p.strip()]
        if not values:
            raise ValueError(
                f"--sample {shown(text)}: choice needs one or more values: NAME=choice:A,B"
            )
        return name, (kind, values)
    ends = args.split(":")
    if len(ends) != 2:
        raise ValueError(f"--sample {shown(text)}: expected NAME={kind}:LOW:HIGH")
    number = int if kind == "int" else float
    low, high = (_value(name, e, number) for e in ends)
    if not low < high or (kind == "loguniform" and low <= 0):
        raise ValueError(
            f"--sample {shown(text)}: allowed LOW < HIGH{' and LOW > 0' if kind == 'loguniform' else ''}"
        )
    return name, (kind, [low, high])


@dataclasses.dataclass(frozen=True)
class SweepSpec:
    """What a training sweep runs.

    Attributes:
        seeds: Training seeds (a grid axis).
        grid: Field -> values (grid axes).
        samples: Field -> (distribution, arguments) drawn per trial.
        num_samples: Draws per grid point (Tune's ``num_samples``).
        sampler: ``random`` or ``optuna``.
        scheduler: ``asha``, ``median`` or ``none``.
        settings: Fixed training settings (``SWEEP_DEFAULTS`` and ``--set``).
        grace_period: Validations every trial reports before the scheduler may stop it.
        env_id: The env of every trial; the settings not given take its training defaults
            (:meth:`agents.config.TrainConfig.for_env`).
    """

    seeds: tuple[int, ...]
    grid: Mapping[str, Sequence[Any]]
    samples: Mapping[str, tuple[str, Sequence[Any]]]
    num_samples: int
    sampler: str
    scheduler: str
    settings: Mapping[str, Any]
    grace_period: int = 2
    env_id: str = PAPER_ENV

    def __post_init__(self) -> None:
        if not self.seeds:
            raise ValueError("--seeds is empty: give one or more seeds")
        if self.grace_period < 1:
            raise ValueError(f"--grace-period {self.grace_period} is out of range: allowed >= 1")
        if self.num_samples < 1:
            raise ValueError(f"--samples {self.num_samples} is out of range: allowed >= 1")
        if self.sampler == "optuna":
            if not self.samples:
                raise ValueError("--sampler optuna needs one or more --sample NAME=KIND:LOW:HIGH")
            if self.grid or len(self.seeds) > 1:
                raise ValueError(
                    "--sampler optuna searches --sample settings with one seed: leave out --grid "
                    "and give one --seeds value (or use the random sampler over the grid)"
                )
        clash = set(self.grid) & set(self.samples) | (
            set(self.settings) & (set(self.grid) | set(self.samples))
        )
        if clash:
            raise ValueError(f"{sorted(clash)[0]} is set more than once (--grid, --sample, --set)")
        list(self.corner_configs())  # every value checked before anything starts

    def trials(self) -> int:
        """Number of trials."""
        grid = len(self.seeds) * math.prod(len(v) for v in self.grid.values())
        return grid * self.num_samples

    def corner_configs(self) -> Iterator[Any]:
        """Training configurations at every grid value and at the ends of every sample range
        (building them validates the values)."""

        def build(**values: Any) -> Any:
            return TrainConfig.for_env(
                self.env_id, **{**self.settings, "seed": self.seeds[0], **values}
            )

        yield build()
        for seed in self.seeds:
            yield build(seed=seed)
        for name, values in self.grid.items():
            for v in values:
                yield build(**{name: v})
        for name, (_, args) in self.samples.items():
            for v in args:
                yield build(**{name: v})

    def validations(self) -> int:
        """Validations each trial reports (the last one after the final rollout)."""

        config = TrainConfig.for_env(self.env_id, **{**self.settings, "seed": self.seeds[0]})
        if not config.validate_every:
            return 1
        return (planned_timesteps(config) - 1) // config.validate_every + 1


def _space(spec: SweepSpec) -> dict[str, Any]:
    """Tune's search space of the trials."""
    from ray import tune

    def sample(kind: str, args: Sequence[Any]) -> Any:
        if kind == "choice":
            return tune.choice(list(args))
        if kind == "int":
            return tune.randint(int(args[0]), int(args[1]) + 1)
        return (tune.loguniform if kind == "loguniform" else tune.uniform)(args[0], args[1])

    space: dict[str, Any] = {
        name: sample(kind, args) for name, (kind, args) in spec.samples.items()
    }
    if spec.sampler != "optuna":
        space["seed"] = tune.grid_search(list(spec.seeds))
        space.update({name: tune.grid_search(list(v)) for name, v in spec.grid.items()})
    return space


@contextlib.contextmanager
def _report_validations() -> Iterator[None]:
    """While training: every validation of :mod:`agents.train` is also reported to Tune (its
    ratios as the run's ``validation.csv`` records them)."""
    from ray import tune

    original = training._Validation.run

    def run(self: Any, model: Any, venv: Any) -> float:
        score = original(self, model, venv)
        tune.report(_validations(self.csv)[-1])
        return score

    training._Validation.run = run  # type: ignore[method-assign]
    try:
        yield
    finally:
        training._Validation.run = original  # type: ignore[method-assign]


def final_validation(config: TrainConfig, model: Path) -> dict[str, float]:
    """The validation of a run's final model, for a run without validations
    (``validate_every`` 0): the ratios to the base controller on the run's validation
    scenarios (:func:`agents.train.validation_scenarios`, :func:`agents.train.validation_score`)
    and the decisions the run took."""
    policy = load_policy(model)
    kwargs, seeds = validation_scenarios(config)
    base = kwargs["base_controller"] or REFERENCE_CONTROLLER[config.env_id]
    env = gym.make(config.env_id, max_episode_steps=-1, **kwargs)
    base_env = gym.make(config.env_id, max_episode_steps=-1, **{**kwargs, "base_controller": base})
    try:
        metrics = [episode_metrics(rollout(env, policy, s)) for s in seeds]
        reference = [episode_metrics(rollout(base_env, ZeroAction(), s)) for s in seeds]
    finally:
        env.close()
        base_env.close()
    result = validation_score(metrics, reference, config.validation_severity_weight)
    steps = policy.metadata.get("run_timesteps", policy.metadata.get("timesteps", 0))
    return {"timesteps": int(steps), **result._asdict()}


def train_trial(config: dict[str, Any]) -> None:
    """One trial (run in a Tune worker): a training run with the trial's settings in its own
    run folder ``config["runs_dir"]/TRIAL__seedS``, its validations reported to Tune (a run
    without validations reports the validation of its final model once, at the end). A run
    folder that holds checkpoints (a sweep resumed with ``--resume``) continues from the last
    one; one that holds its final model reports it again without training."""
    from ray import tune

    settings = dict(config["settings"])
    keys = ("settings", "runs_dir", "seed", "env_id")
    chosen = {k: v for k, v in config.items() if k not in keys}
    seed = int(config["seed"] if "seed" in config else settings.pop("seed"))
    settings.pop("seed", None)
    trial = tune.get_context().get_trial_id()
    run_dir = output_path(config["runs_dir"], f"{trial}__seed{seed}")
    train_config = TrainConfig.for_env(
        config.get("env_id", PAPER_ENV),
        **{**settings, **chosen, "seed": seed, "run_dir": str(run_dir)},
    )
    model = train_config.resolved_save_dir()
    finished = is_model_folder(model) and _same_run(run_dir, train_config)
    if not finished and find_last_checkpoint(run_dir) is not None:
        train_config = dataclasses.replace(train_config, resume=True)
    if train_config.validate_every:
        if finished:  # every validation of the finished run, as it reported them
            for report in _validations(run_dir / "validation.csv"):
                tune.report(report)
            return
        with _report_validations():
            train(train_config, progress=False)
        return
    if not finished:
        train(train_config, progress=False)
    tune.report(final_validation(train_config, model))


def _same_run(run_dir: Path, config: TrainConfig) -> bool:
    """Whether ``run_dir/config.json`` holds the settings of ``config`` (``resume`` aside)."""
    try:
        stored = json.loads((run_dir / "config.json").read_text())
    except (OSError, ValueError):
        return False
    current = json.loads(dataclasses.replace(config, resume=False).to_json())
    return isinstance(stored, dict) and {**stored, "resume": False} == current


def _validations(csv_file: Path) -> list[dict[str, Any]]:
    """The validations of a run as its ``validation.csv`` records them (Tune's reports): the
    decisions and each ratio and the score, by column (a run of an earlier version has no
    ``severity_iqm_ratio``)."""
    reports = []
    with csv_file.open(newline="") as f:
        for line, row in enumerate(csv.DictReader(f), start=2):
            try:
                reports.append(
                    {k: int(v) if k == "timesteps" else float(v) for k, v in row.items() if v}
                )
            except (TypeError, ValueError):
                raise ValueError(
                    f"{str(csv_file)!r}: line {line} is not a validation record: "
                    f"{printable(','.join(map(str, row.values())))}"
                ) from None
    return reports


def _scheduler(spec: SweepSpec) -> Any:
    if spec.scheduler == "none":
        return None
    from ray.tune.schedulers import ASHAScheduler, MedianStoppingRule

    if spec.scheduler == "median":
        return MedianStoppingRule(
            time_attr="training_iteration",
            grace_period=spec.grace_period,
            min_samples_required=2,
        )
    last = spec.validations() + 1  # above the last report: a trial that ends is not stopped
    return ASHAScheduler(
        time_attr="training_iteration",
        max_t=last,
        grace_period=min(spec.grace_period, last),  # longer than the run: never stopped
        reduction_factor=2,
    )


def _spec_record(spec: SweepSpec) -> dict[str, Any]:
    """The spec of a sweep as ``OUT/sweep.json`` records it (what ``--resume`` compares)."""
    return json.loads(json.dumps(dataclasses.asdict(spec), default=list))


def _check_resume(
    out: Path, recorded: Mapping[str, Any], resume: bool, trust_pickle: Path | None = None
) -> None:
    """Refuse ``--resume`` without a resumable sweep of the same spec in ``out`` or without
    ``trust_pickle`` naming its Tune folder (whose state files are pickles), and a new sweep in
    a folder that already holds one."""
    from ray import tune

    spec_file = out / SPEC_FILE
    tune_folder = out / TUNE_FOLDER
    if trust_pickle is not None and not resume:
        raise ValueError(
            "--trust-pickle names the Tune folder --resume restores: it needs --resume"
        )
    if not resume:
        if spec_file.exists() or (out / TUNE_FOLDER).exists():
            raise ValueError(
                f"--out {str(out)!r} already holds a sweep: pass --resume to finish it, or "
                "choose another --out"
            )
        return
    if not spec_file.is_file() or not tune.Tuner.can_restore(str(out / TUNE_FOLDER)):
        raise ValueError(
            f"--resume: no sweep to resume in {str(out)!r} (expected {SPEC_FILE} and "
            f"{TUNE_FOLDER}/ written by drill-gym sweep-train): check --out, or leave out --resume"
        )
    try:
        before = json.loads(spec_file.read_text())
    except (OSError, ValueError):
        before = None
    if before != recorded:
        changed = (
            sorted(k for k in recorded if before.get(k) != recorded[k])
            if isinstance(before, dict)
            else ["the spec file"]
        )
        raise ValueError(
            f"--resume: the sweep in {str(out)!r} was started with other settings "
            f"({', '.join(changed) or 'the spec file'} differ): give the same options as before"
        )
    if trust_pickle is None or Path(trust_pickle).resolve() != tune_folder.resolve():
        raise ValueError(
            f"--resume restores Tune's state in {str(tune_folder)!r}, pickle files that can run "
            f"any code: pass --trust-pickle {str(tune_folder)!r} to say you trust them (a sweep "
            "you ran yourself)"
        )


def _trial_row(result: Any, spec: SweepSpec, runs_dir: Path) -> dict[str, Any]:
    """One row of the summary table from a Tune result (the validations as the run's
    ``validation.csv`` records them, which a resumed trial continues; without one, as reported
    to Tune)."""
    config = result.config
    seed = int(config.get("seed", spec.seeds[0]))
    history = result.metrics_dataframe
    records = [] if history is None else history.to_dict("records")
    trial = str(result.metrics.get("trial_id", "")) if result.metrics else ""
    folder = next(runs_dir.glob(f"{trial}__seed{seed}"), None) if trial else None
    if folder is not None and (folder / "validation.csv").is_file():
        records = _validations(folder / "validation.csv")
    row: dict[str, Any] = {"trial": trial, "seed": seed}
    for name in (*spec.grid, *spec.samples):
        row[name] = config.get(name)
    valid = [r for r in records if r.get(METRIC) is not None and math.isfinite(r[METRIC])]
    best = min(valid, key=lambda r: r[METRIC]) if valid else None
    last = valid[-1] if valid else None
    # the run's own choice (best/), else its last model
    kept = (training.kept_validation(folder) if folder is not None else None) or last
    row.update(
        {
            "validations": len(valid),
            "timesteps": None if last is None else int(last["timesteps"]),
            "best_iae_ratio": None if best is None else float(best[METRIC]),
            "best_at_timesteps": None if best is None else int(best["timesteps"]),
            "last_iae_ratio": None if last is None else float(last[METRIC]),
            "last_rmsd_ratio": None if last is None else float(last["rmsd_ratio"]),
            "kept_score": None if kept is None else kept.get("score"),
            "kept_at_timesteps": None if kept is None else kept["timesteps"],
            "stopped_early": bool(len(valid) < spec.validations()),
            "error": None if result.error is None else _error_line(result.error),
            "run_dir": None if folder is None else str(folder),
            **dict.fromkeys(HELDOUT_KEYS),
        }
    )
    return row


def _error_line(error: BaseException | str) -> str:
    """The line of a trial's error that names it: the last non-empty line of its text (Ray's
    text starts with the worker's address and ends with the exception), made printable."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return printable(lines[-1] if lines else type(error).__name__, 200)


def failed_trials_line(rows: Sequence[Mapping[str, Any]], out: Path) -> str | None:
    """The line that reports the trials of ``rows`` that ended with an error and where their
    errors are, or None when none did."""
    failed = [row for row in rows if row.get("error")]
    if not failed:
        return None
    count = f"all {len(rows)}" if len(failed) == len(rows) else f"{len(failed)} of {len(rows)}"
    return (
        f"{count} trial(s) failed: their errors are in the column error of "
        f"{printable(out / 'trials.csv')} and in full in "
        f"{printable(out / TUNE_FOLDER)}/TRIAL/error.txt (first: {failed[0]['error']})"
    )


def _model_folder(run_dir: Path) -> Path | None:
    """The model of a run: ``model/`` (the best on validation) or, for a run stopped early,
    ``best/``."""

    for name in ("model", "best"):
        if is_model_folder(run_dir / name):
            return run_dir / name
    return None


def _heldout(model: Path, scenario_ids: Sequence[str] | None) -> dict[str, Any]:
    """Held-out ratios of the model to its base controller on the held-out set of its env
    (:mod:`experiments.evaluate`; on the field string the base controller with the agent's
    observation mode)."""

    agent = load_policy(model)
    field = is_field(agent.env_id)
    fallback = REFERENCE_CONTROLLER[FIELD_ENV if field else PAPER_ENV]
    base = agent.env_kwargs.get("base_controller") or fallback
    observation = agent.env_kwargs.get("observation", "surface") if field else None
    held_out = held_out_set(agent.env_id)
    scenarios = [s for s in held_out if scenario_ids is None or s.id in scenario_ids]
    rows, _ = evaluate(
        [agent],
        [base],
        scenarios,
        env_id=agent.env_id,
        observations=[observation] if observation else ["surface"],
    )
    label = run_label({"controller": base, "observation": observation})
    agent_label = run_label({"controller": agent.name, "observation": observation})
    goal = summarize(rows, label, agents=[agent_label])["goal"][agent_label]
    return {
        "heldout_iae_ratio": goal["iae_ratio"],
        "heldout_rmsd_ratio": goal["rmsd_ratio"],
        "heldout_severity_prone_ratio": goal["severity_prone_ratio"],
        "heldout_goal_met": goal["met"],
    }


def run_training_sweep(
    spec: SweepSpec,
    out: Path,
    backend: Backend,
    heldout: str = "best",
    heldout_scenarios: Sequence[str] | None = None,
    progress: bool = True,
    resume: bool = False,
    trust_pickle: Path | None = None,
) -> dict[str, Any]:
    """Run the trials on Ray Tune, then write the summary table and export the best model.

    Args:
        resume: Continue the interrupted sweep in ``out`` (Tune's experiment ``out/tune``,
            the same spec): its finished trials are kept, the others continue from their
            last checkpoint.
        trust_pickle: With ``resume``: ``out/tune``, named to trust the pickled state of Tune
            that restoring reads.

    Returns:
        The summary (as ``OUT/summary.json``): the trial rows, the best trial, the files.

    Raises:
        ValueError: ``resume`` without a sweep in ``out`` or with another spec; a sweep
            already in ``out`` without ``resume``.
    """
    from ray import tune

    out = out.resolve()
    runs_dir = out / "runs"
    spec_file = out / SPEC_FILE
    recorded = _spec_record(spec)
    _check_resume(out, recorded, resume, trust_pickle)
    runs_dir.mkdir(parents=True, exist_ok=True)
    spec_file.write_text(json.dumps(recorded, indent=2) + "\n")
    started = time.perf_counter()
    search = None
    if spec.sampler == "optuna":
        from ray.tune.search.optuna import OptunaSearch

        search = OptunaSearch(metric=METRIC, mode="min", seed=spec.seeds[0])
    settings = {**spec.settings}
    if spec.sampler == "optuna":
        settings["seed"] = spec.seeds[0]
    with ray_session(backend):
        tuner = (
            tune.Tuner.restore(
                str(out / TUNE_FOLDER),
                tune.with_resources(train_trial, {"cpu": 1}),
                resume_errored=True,
            )
            if resume
            else _new_tuner(spec, settings, runs_dir, search, backend, out, progress)
        )
        grid = tuner.fit()
        rows = [_trial_row(grid[i], spec, runs_dir) for i in range(len(grid))]
    scored = [r for r in rows if r["best_iae_ratio"] is not None and r["run_dir"]]
    best = min(scored, key=lambda r: r["best_iae_ratio"]) if scored else None
    summary: dict[str, Any] = {"trials": rows, "best": None, "metric": METRIC}
    if best is not None:
        model = _model_folder(Path(best["run_dir"]))
        if model is not None:
            policy = load_policy(model)
            policy.metadata["source"] = (
                f"drill-gym sweep-train: trial {best['trial']} (lowest validation {METRIC}), {model}"
            )
            target = out / "best_model"
            if target.exists():
                shutil.rmtree(target)
            summary["best"] = {"trial": best["trial"], "model": str(policy.save(target))}
    for row in rows:
        evaluate_it = heldout == "all" or (heldout == "best" and best is not None and row is best)
        model = _model_folder(Path(row["run_dir"])) if row["run_dir"] else None
        if evaluate_it and model is not None:
            row.update(_heldout(model, heldout_scenarios))
    keys = list(dict.fromkeys(k for row in rows for k in row))
    for row in rows:
        for key in keys:
            row.setdefault(key, None)
    summary["files"] = [
        str(write_csv(rows, out / "trials.csv", keys)),
        str(_write_markdown(rows, spec, out / "trials.md")),
    ]
    summary["wall_time_s"] = round(time.perf_counter() - started, 1)
    write_json(summary, out / "summary.json", indent=2)
    return summary


def _new_tuner(
    spec: SweepSpec,
    settings: Mapping[str, Any],
    runs_dir: Path,
    search: Any,
    backend: Backend,
    out: Path,
    progress: bool,
) -> Any:
    """Tune's tuner of a new sweep (experiment ``out/tune``)."""
    from ray import tune

    return tune.Tuner(
        tune.with_resources(train_trial, {"cpu": 1}),
        param_space={
            **_space(spec),
            "settings": settings,
            "runs_dir": str(runs_dir),
            "env_id": spec.env_id,
        },
        tune_config=tune.TuneConfig(
            metric=METRIC,
            mode="min",
            scheduler=_scheduler(spec),
            search_alg=search,
            num_samples=spec.num_samples,
            max_concurrent_trials=backend.workers,
        ),
        run_config=tune.RunConfig(
            name=TUNE_FOLDER, storage_path=str(out), verbose=1 if progress else 0
        ),
    )


def _write_markdown(rows: Sequence[Mapping[str, Any]], spec: SweepSpec, path: Path) -> Path:
    columns = [Column("trial", "trial", align="left"), Column("seed", "seed")]
    columns += [Column(n, n, "{}") for n in (*spec.grid, *spec.samples)]
    columns += [
        Column("validations", "validations"),
        Column("timesteps", "decisions", "{:,}"),
        Column("best_iae_ratio", "best val. IAE ratio", "{:.3f}"),
        Column("last_iae_ratio", "last val. IAE ratio", "{:.3f}"),
        Column("last_rmsd_ratio", "last val. RMSD ratio", "{:.3f}"),
        Column("kept_at_timesteps", "model kept at", "{:,}"),
        Column("stopped_early", "stopped early", "{}"),
        Column("heldout_iae_ratio", "held-out IAE ratio", "{:.3f}"),
        Column("heldout_rmsd_ratio", "held-out RMSD ratio", "{:.3f}"),
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, markdown_table(rows, columns) + "\n")
    return path


# ---------------------------------------------------------------------------- command line
def _heldout_ids() -> list[str]:
    return [s.id for s in (*HELD_OUT, *FIELD_HELD_OUT)]


@dataclasses.dataclass(frozen=True)
class SweepTrainSpec:
    """Settings of ``drill-gym sweep-train``; its options are generated from these fields
    (each field is the option of the same name)."""

    seeds: tuple[int, ...] = dataclasses.field(
        default=(1,), metadata=option(low=0, high=SEED_HIGH, metavar="S")
    )
    """training seeds, a trial each"""
    num_samples: int = dataclasses.field(
        default=1, metadata=option(low=1, high=10_000, flag="--samples")
    )
    """--sample draws per grid point"""
    sampler: str = dataclasses.field(
        default="random", metadata=option(choices=("random", "optuna"))
    )
    """how --sample settings are drawn (optuna: TPE)"""
    scheduler: str = dataclasses.field(
        default="asha", metadata=option(choices=("asha", "median", "none"))
    )
    """early stopping of weak trials"""
    grace_period: int = dataclasses.field(default=2, metadata=option(low=1, high=10_000))
    """validations before a trial may be stopped"""
    settings: tuple[str, ...] = dataclasses.field(
        default=(),
        metadata=option(
            flag="--set",
            metavar="NAME=VALUE",
            default_text=", ".join(f"{k}={v}" for k, v in SWEEP_DEFAULTS.items()),
        ),
    )
    """fixed training settings of every trial (others as drill-gym train)"""
    env_id: str = dataclasses.field(
        default=PAPER_ENV, metadata=option(choices=ENV_IDS, flag="--env")
    )
    """the env of every trial"""
    train_budget: bool = False
    """keep drill-gym train's budget for the env instead of the small one of --set"""
    heldout: str = dataclasses.field(
        default="best", metadata=option(choices=("best", "all", "none"))
    )
    """score the best trial's model, every trial's or none on the held-out scenarios"""
    heldout_scenarios: tuple[str, ...] = dataclasses.field(
        default=(),
        metadata=option(
            parse=names_type(_heldout_ids, "scenario"), metavar="ID", default_text="all"
        ),
    )
    """only these held-out scenarios"""
    workers: int = dataclasses.field(default=2, metadata=option(low=1, high=4096))
    """trials at a time, a CPU each"""
    address: str | None = dataclasses.field(
        default=None,
        metadata=option(metavar="ADDR", default_text=f"${ADDRESS_VARIABLE}, else a local one"),
    )
    """join the Ray cluster at ADDR"""
    out: Path = dataclasses.field(
        default=Path("results/sweep-train"), metadata=option(parse=output_folder, metavar="DIR")
    )
    """output folder"""
    no_progress: bool = False
    """no Tune progress output"""
    resume: bool = False
    """finish the interrupted sweep in --out, same options"""
    trust_pickle: Path | None = dataclasses.field(default=None, metadata=option(metavar="OUT/tune"))
    """with --resume: Tune's state folder, named to trust its pickles (they run any code)"""
    grid: tuple[str, ...] | None = dataclasses.field(
        default=None, metadata=option(repeat=True, metavar="NAME=V1,V2")
    )
    """a training setting's values: every combination a trial"""
    sample: tuple[str, ...] | None = dataclasses.field(
        default=None, metadata=option(repeat=True, metavar="NAME=KIND:LOW:HIGH")
    )
    """a training setting drawn per trial, KIND uniform, loguniform or int (or choice:A,B)"""

    def __post_init__(self) -> None:
        self.sweep_spec()  # every value checked before anything starts

    def sweep_spec(self) -> SweepSpec:
        """The trials these settings ask for.

        Raises:
            ValueError: a setting that does not parse or does not fit (naming its option).
        """
        try:
            grid = dict(parse_grid(g) for g in self.grid or ())
            samples = dict(parse_sample(s) for s in self.sample or ())
            fields = _fields()
            explicit: dict[str, Any] = {}
            for text in self.settings:
                name, value = _field(text, "--set")
                explicit[name] = _value(name, value, fields[name])
            budget = {} if self.train_budget else SWEEP_DEFAULTS
            settings = {k: v for k, v in budget.items() if k not in (*grid, *samples)}
            settings.update(explicit)
            if self.heldout_scenarios:
                allowed = [s.id for s in held_out_set(self.env_id)]
                wrong = [i for i in self.heldout_scenarios if i not in allowed]
                if wrong:
                    raise ValueError(
                        f"--heldout-scenarios {', '.join(wrong)}: not a held-out scenario of "
                        f"{self.env_id}: allowed {allowed[0]} to {allowed[-1]}"
                    )
            return SweepSpec(
                seeds=tuple(dict.fromkeys(self.seeds)),
                grid=grid,
                samples=samples,
                num_samples=self.num_samples,
                sampler=self.sampler,
                scheduler=self.scheduler,
                settings=settings,
                grace_period=self.grace_period,
                env_id=self.env_id,
            )
        except TypeError as err:
            raise ValueError(str(err)) from None


DESCRIPTION: Final = """\
Multi-seed training and hyperparameter search on Ray Tune: each trial a drill-gym train run
in OUT/runs/TRIAL__seedS, stopped early when weak on its validation IAE ratio. Writes
trials.csv/.md, best_model/ with its held-out scores and summary.json. Needs rl and scale.

example:
  drill-gym sweep-train --sampler optuna --samples 8 \\
      --sample learning_rate=loguniform:1e-5:1e-3 --sample ent_coef=uniform:0:0.01
"""


def _parser() -> ArgumentParser:
    return spec_parser("drill-gym sweep-train", DESCRIPTION, SweepTrainSpec)


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym sweep-train``; returns the exit code."""
    args = _parser().parse_args(list(argv) if argv is not None else None)
    return run_study(spec_from_args(SweepTrainSpec, args))


def run_study(options: SweepTrainSpec) -> int:
    """Run the training sweep ``options`` asks for and print its table; returns the exit code."""
    spec = options.sweep_spec()
    _check_resume(options.out.resolve(), _spec_record(spec), options.resume, options.trust_pickle)
    backend = Backend(workers=options.workers, use_ray=True, address=options.address)
    print(
        f"sweep-train: {spec.trials()} trials ({len(spec.seeds)} seeds"
        + "".join(f" x {len(v)} {k}" for k, v in spec.grid.items())
        + (f" x {spec.num_samples} {spec.sampler} samples" if spec.num_samples > 1 else "")
        + f"), {spec.validations()} validations each, scheduler {spec.scheduler}, on "
        f"{backend.describe()}; env {spec.env_id}",
        flush=True,
    )
    summary = run_training_sweep(
        spec,
        options.out,
        backend,
        heldout=options.heldout,
        heldout_scenarios=list(options.heldout_scenarios) or None,
        progress=not options.no_progress,
        resume=options.resume,
        trust_pickle=options.trust_pickle,
    )
    print((options.out / "trials.md").read_text())
    best = summary["best"]
    print(
        (
            f"best trial {best['trial']}: model exported to {printable(best['model'])}; "
            if best
            else "no trial reported a validation; "
        )
        + f"summary in {printable(options.out / 'summary.json')} ({summary['wall_time_s']} s)"
    )
    rows = summary["trials"]
    failed = failed_trials_line(rows, options.out)
    if failed is not None:
        print(f"drill-gym sweep-train: {failed}", file=sys.stderr)
        if all(row.get("error") for row in rows):
            return 1  # nothing trained: not a success, though the tables are written
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
