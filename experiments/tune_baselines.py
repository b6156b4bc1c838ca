"""``drill-gym tune``: tune the industry speed loops' factors with the agent's tuning budget,
on the agent's training scenarios, and select them by the agent's validation rule.

The residual agent (``drill-gym train``) learns from about 400,000 simulated seconds of
randomised training episodes and keeps the model with the best validation score
(:func:`agents.train.validation_score`: mean IAE ratio to the proposed SMC plus
``10 max(RMSD ratio - 0.99, 0)``, on the 16 validation scenarios of
:func:`agents.train.validation_scenarios`). This command gives the speed loops ``stiff_pi``,
``soft_speed`` and ``z_torque`` the same:

1. **Search** (:data:`SEARCH_SPACES`, log-spaced ranges of each loop's relative factors):
   round 0 is the default factors plus a Latin hypercube of ``--candidates - 1`` points over
   the whole space; round 1 a Latin hypercube of ``--refine`` points in a box around round 0's
   best, ``--zoom`` times the width of the space in every (log) factor. Every candidate runs
   the first ``--episodes`` training episodes of the agent: the env's default randomisation,
   episode ``n`` being episode ``n // 16`` of string ``n % 16`` of the agent's vector env,
   whose string ``i`` starts from reset seed ``seed + i`` (``seed = 1``) and then continues its
   own seed sequence. Its training score is the selection score against the proposed SMC on
   the same episodes.
2. **Validation**: the ``--top`` candidates of each loop with the best training scores, and
   the default factors for comparison, run the agent's validation scenarios and the ones after
   them, 32 in all (reset seeds 20000 + k, the same env keywords); the selected factors are those of the ``--top`` with
   the lowest validation score: the rule that selects the agent's model.

A candidate whose run diverges in any episode is out (score infinite). On
``DrillStringField-v0`` the scenarios are that env's own randomisation and defaults (surface
signals, mud-pulse telemetry, the actuator with its rate limit) with the same seeds, and the
reference is the proposed SMC on the same env (with its observer on the surface signals).

Outputs in ``--out`` (default ``results/tune/ENV``): the sweep runner's results database
``tune.sqlite`` (the three stages, rounds 0 and 1 and the validation; ``--resume`` continues
them), ``candidates.csv`` (every candidate: factors, training and validation ratios
and scores), ``tune.json`` (per loop: the selected and default factors, the gains they give on
the nominal string, their scores, the budget in simulated and wall seconds) and a table on
standard output. ``--write`` stores the selected factors in ``baselines/tuned_gains.json``
(or ``--gains-file``), the file the controllers ``stiff_pi_tuned``, ``soft_speed_tuned`` and
``z_torque_tuned`` read (entries of the other env are kept).
"""

from __future__ import annotations

import dataclasses
import math
import shlex
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import gymnasium as gym
import numpy as np

import baselines  # noqa: F401  (registers the built-in controllers)
import drill_env
from agents.config import TrainConfig
from agents.train import validation_scenarios, validation_score
from baselines.base import resolve_model
from baselines.registry import REFERENCE_CONTROLLER
from baselines.tuned import (
    KIND_ENVS,
    TUNABLE,
    TUNED_GAINS_FILE,
    TunedEntry,
    load_tuned_gains,
    parse_tuned_gains,
    tuned_gains_document,
)
from drill_env.control import make_controller
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.files import check_writable_target
from drill_env.validation import shown
from experiments.arguments import ArgumentParser, check_output_folder, names_type, output_folder
from experiments.results_db import Exactly, Fields, Flag, Number, Schema, Values
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import (
    Backend,
    RunnerSpec,
    SweepOutcome,
    Task,
    TaskResult,
    chunks,
    run_sweep,
)
from experiments.tables import Column, json_clean, markdown_table, write_csv, write_json

__all__ = [
    "ENVS",
    "NOMINAL_PRESETS",
    "REFERENCE",
    "SEARCH_SPACES",
    "CandidateStudy",
    "Factor",
    "Score",
    "TuneSettings",
    "TuneSpec",
    "candidates_task",
    "latin_hypercube",
    "main",
    "run_tune",
    "run_tuning",
    "score_of",
    "training_episodes",
    "tuning_env_kwargs",
    "validation_episodes",
]

ENVS: Final = (drill_env.ENV_ID, drill_env.FIELD_ENV_ID)
"""The envs a search runs on."""
REFERENCE: Final = REFERENCE_CONTROLLER[drill_env.ENV_ID]
"""The controller every score is relative to (the agent's base controller)."""
NOMINAL_PRESETS: Final = {drill_env.ENV_ID: "zribi2024", drill_env.FIELD_ENV_ID: "field_2500m"}
"""The nominal string of each env, on which the derived gains are reported."""
RESULTS_FILE: Final = "tune.sqlite"
"""The results database of the three stages in ``--out``."""
METRICS: Final = ("iae", "rmsd_nm", "stick_slip_severity")
"""The episode metrics a record keeps (with ``diverged``)."""


@dataclass(frozen=True)
class Factor:
    """One searched factor: a field of the loop's gains dataclass and its range.

    Attributes:
        name: The field (``impedance_factor``).
        low: Lowest value searched (> 0).
        high: Highest value searched (> ``low``).
        log: Sample ``log(value)`` uniformly (``False``: ``value``).
    """

    name: str
    low: float
    high: float
    log: bool = True

    def to_unit(self, value: float) -> float:
        """``value`` mapped to [0, 1] over the range (log-scaled when ``log``)."""
        if self.log:
            return (math.log(value) - math.log(self.low)) / (
                math.log(self.high) - math.log(self.low)
            )
        return (value - self.low) / (self.high - self.low)

    def from_unit(self, u: float) -> float:
        """The value at ``u`` in [0, 1] of the range, rounded to 4 significant digits."""
        if self.log:
            value = math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        else:
            value = self.low + u * (self.high - self.low)
        return float(f"{min(max(value, self.low), self.high):.4g}")


SEARCH_SPACES: Final[dict[str, tuple[Factor, ...]]] = {
    "stiff_pi": (
        Factor("bandwidth_factor", 0.2, 200.0),
        Factor("damping_ratio", 0.25, 4.0),
    ),
    "soft_speed": (
        Factor("impedance_factor", 0.5, 8.0),
        Factor("frequency_factor", 0.1, 4.0),
    ),
    "z_torque": (
        Factor("impedance_factor", 0.25, 16.0),
        Factor("mean_periods", 0.05, 10.0),
        Factor("bandwidth_factor", 0.2, 100.0),
        Factor("damping_ratio", 0.25, 2.0),
    ),
}
"""The factors searched per loop and their ranges (all log-spaced). ``soft_speed``'s
``inertia_compensation`` stays on: with the constant references of the training scenarios it
never acts. The gains dataclasses define the factors (docs/industry-controllers.md)."""


def latin_hypercube(count: int, dims: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` points of a Latin hypercube in [0, 1]^dims, shape (count, dims): each axis cut
    into ``count`` equal strata, one point per stratum, strata paired at random."""
    out = np.empty((count, dims))
    for d in range(dims):
        out[:, d] = (rng.permutation(count) + rng.random(count)) / count
    return out


def default_factors(loop: str) -> dict[str, float]:
    """The default values of the searched factors of ``loop``."""
    defaults = TUNABLE[loop]()
    return {f.name: float(getattr(defaults, f.name)) for f in SEARCH_SPACES[loop]}


# --------------------------------------------------------------------------- scenarios
def tuning_env_kwargs(env_id: str, config: TrainConfig | None = None) -> dict[str, Any]:
    """The env keywords of every run of the search (without ``base_controller``).

    ``DrillString-v0``: those of the agent's validation scenarios
    (:func:`agents.train.validation_scenarios`: the training distribution, 100 s, 0.1 rad/s
    noise, the agent's decision period and torque limits), which are the training env's
    keywords but the reward weights (no metric depends on them). ``DrillStringField-v0``: the
    env's own defaults with its randomisation and the agent's episode length.
    """
    config = config or TrainConfig()
    if env_id == drill_env.FIELD_ENV_ID:
        return {"randomize": True, "episode_s": float(config.episode_s)}
    if env_id != drill_env.ENV_ID:
        raise ValueError(f"env = {shown(env_id)} is not valid: allowed {', '.join(ENVS)}")
    kwargs, _ = validation_scenarios(config)
    return {k: v for k, v in kwargs.items() if k != "base_controller"}


def training_episodes(count: int, config: TrainConfig | None = None) -> list[tuple[int, int]]:
    """The first ``count`` training episodes of the agent as ``(reset seed, index)`` pairs:
    episode ``n`` is the episode ``n // num_envs`` of string ``n % num_envs``, which starts
    from reset seed ``seed + n % num_envs`` and continues that string's seed sequence
    (``index`` unseeded resets after the seeded one)."""
    config = config or TrainConfig()
    return [(config.seed + n % config.num_envs, n // config.num_envs) for n in range(count)]


VALIDATION_EPISODES: Final = 32
"""Validation scenarios of the search: the agent's (seeds 20000 + k, 16 by default) and the
ones after them, up to this many, so that five candidates per loop are told apart."""


def validation_episodes(config: TrainConfig | None = None) -> list[tuple[int, int]]:
    """The validation scenarios of the search as ``(reset seed, 0)`` pairs: the agent's
    (seeds 20000 + k) extended to at least :data:`VALIDATION_EPISODES`."""
    config = config or TrainConfig()
    count = max(config.validation_episodes, VALIDATION_EPISODES)
    _, seeds = validation_scenarios(dataclasses.replace(config, validation_episodes=count))
    return [(s, 0) for s in seeds]


def _run_episodes(
    env: gym.Env[Any, Any], episodes: Sequence[tuple[int, int]]
) -> tuple[list[dict[str, Any]], float]:
    """The metrics of ``episodes`` (in their order) under the env's base controller, and the
    simulated seconds. Each seed's sequence is run from its seeded reset up to the highest
    index asked for."""
    wanted: dict[int, set[int]] = {}
    for seed, index in episodes:
        wanted.setdefault(int(seed), set()).add(int(index))
    found: dict[tuple[int, int], dict[str, Any]] = {}
    simulated = 0.0
    for seed, indices in wanted.items():
        for index in range(max(indices) + 1):
            trace = rollout(env, ZeroAction(), seed if index == 0 else None)
            simulated += trace.duration_s
            if index in indices:
                found[(seed, index)] = episode_metrics(trace)
    return [found[(int(s), int(i))] for s, i in episodes], simulated


def candidates_task(
    env_id: str,
    env_kwargs: Mapping[str, Any],
    episodes: Sequence[Sequence[int]],
    candidates: Sequence[tuple[str, str, Mapping[str, float]]],
) -> TaskResult:
    """Run each candidate ``(key, controller, factors)`` as the base controller (zero
    residual) of ``gym.make(env_id, **env_kwargs)`` on ``episodes``; one record per key: the
    controller, its factors, the metrics per episode (``iae``, ``rmsd_nm``,
    ``stick_slip_severity``, ``diverged``), the simulated and the wall seconds."""
    pairs = [(int(s), int(i)) for s, i in episodes]
    records: dict[str, dict[str, Any]] = {}
    for key, controller, factors in candidates:
        started = time.perf_counter()
        env = gym.make(
            env_id,
            max_episode_steps=-1,
            base_controller=make_controller(controller, **dict(factors)),
            **dict(env_kwargs),
        )
        try:
            metrics, simulated = _run_episodes(env, pairs)
        finally:
            env.close()
        records[key] = {
            "controller": controller,
            "factors": dict(factors),
            **{k: [m[k] for m in metrics] for k in METRICS},
            "diverged": [bool(m["diverged"]) for m in metrics],
            "simulated_s": simulated,
            "wall_s": time.perf_counter() - started,
        }
    return TaskResult(records)


@dataclass(frozen=True)
class CandidateStudy:
    """Candidates on a set of episodes, on the sweep runner: an item is one candidate, a task
    ``task_candidates`` of them (:func:`candidates_task`).

    Attributes:
        name: Name of the sweep.
        env_id: The env.
        env_kwargs: Its keywords (without ``base_controller``).
        episodes: ``(reset seed, index)`` pairs (:func:`training_episodes`).
        candidates: ``(key, controller, factors)``, keys unique.
        task_candidates: Candidates per task (does not change the numbers).
    """

    name: str
    env_id: str
    env_kwargs: Mapping[str, Any]
    episodes: tuple[tuple[int, int], ...]
    candidates: tuple[tuple[str, str, Mapping[str, float]], ...]
    task_candidates: int = 1

    def __post_init__(self) -> None:
        keys = [c[0] for c in self.candidates]
        if len(set(keys)) != len(keys):
            raise ValueError(f"sweep {shown(self.name)}: candidate keys are not unique")
        if not self.episodes:
            raise ValueError(f"sweep {shown(self.name)}: episodes = [] is empty")

    def spec(self) -> dict[str, Any]:
        """Everything the records depend on."""
        return {
            "env_id": self.env_id,
            "env_kwargs": json_clean({k: _jsonable(v) for k, v in self.env_kwargs.items()}),
            "episodes": [list(e) for e in self.episodes],
            "candidates": [[k, c, dict(f)] for k, c, f in self.candidates],
        }

    def items(self) -> list[str]:
        """One item per candidate."""
        return [c[0] for c in self.candidates]

    def record_schema(self, item: str) -> Schema:
        """A candidate's record: its controller and factors (this study's), the metrics and
        whether it diverged on each episode, the simulated and the wall seconds."""
        _, controller, factors = next(c for c in self.candidates if c[0] == item)
        episodes = len(self.episodes)
        return Fields(
            {
                "controller": Exactly(controller),
                "factors": Exactly(dict(factors)),
                **{k: Values(Number(), episodes) for k in METRICS},
                "diverged": Values(Flag(), episodes),
                "simulated_s": Number(nullable=False, low=0.0),
                "wall_s": Number(nullable=False, low=0.0),
            }
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """``task_candidates`` missing candidates per task."""
        wanted = set(missing)
        chosen = [c for c in self.candidates if c[0] in wanted]
        return [
            Task(
                key="/".join(c[0] for c in block),
                function=candidates_task,
                kwargs={
                    "env_id": self.env_id,
                    "env_kwargs": dict(self.env_kwargs),
                    "episodes": [list(e) for e in self.episodes],
                    "candidates": [(k, c, dict(f)) for k, c, f in block],
                },
                items=tuple(c[0] for c in block),
            )
            for block in chunks(chosen, self.task_candidates)
        ]


def _jsonable(value: Any) -> Any:
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    return repr(value)


# ----------------------------------------------------------------------------- scoring
@dataclass(frozen=True)
class Score:
    """A candidate's ratios to the reference on the same episodes and its selection score.

    Attributes:
        iae_ratio, rmsd_ratio, severity_ratio: Ratios of the means over the episodes.
        score: ``iae_ratio + 10 max(rmsd_ratio - 0.99, 0)``; infinite when not ``feasible``.
        feasible: No episode diverged and every metric is finite.
    """

    iae_ratio: float
    rmsd_ratio: float
    severity_ratio: float
    score: float
    feasible: bool

    def as_dict(self, prefix: str) -> dict[str, Any]:
        """The fields as ``{prefix}_iae_ratio`` and so on (non-finite as ``None``)."""
        return {
            f"{prefix}_{k}": (v if math.isfinite(v) else None)
            for k, v in (
                ("iae_ratio", self.iae_ratio),
                ("rmsd_ratio", self.rmsd_ratio),
                ("severity_ratio", self.severity_ratio),
                ("score", self.score),
            )
        }


def _metrics(record: Mapping[str, Any]) -> list[dict[str, float]]:
    values = [record[k] for k in METRICS]
    return [
        {k: math.nan if v is None else float(v) for k, v in zip(METRICS, row, strict=True)}
        for row in zip(*values, strict=True)
    ]


def score_of(record: Mapping[str, Any], reference: Mapping[str, Any]) -> Score:
    """The selection score of a candidate's record against the reference's record on the same
    episodes: :func:`agents.train.validation_score`, the rule that selects the agent's model;
    a candidate with a diverged episode or a non-finite metric is not feasible."""
    metrics, base = _metrics(record), _metrics(reference)
    result = validation_score(metrics, base)
    finite = all(math.isfinite(m[k]) for m in metrics for k in METRICS)
    feasible = finite and not any(record["diverged"]) and math.isfinite(result.score)
    return Score(
        result.iae_ratio,
        result.rmsd_ratio,
        result.severity_ratio,
        result.score if feasible else math.inf,
        feasible,
    )


# ------------------------------------------------------------------------------ search
@dataclass(frozen=True)
class TuneSpec:
    """Settings of ``drill-gym tune`` (each field is the option of the same name): the search
    (see the module docstring) and where its outputs go."""

    env_id: str = field(
        default=drill_env.ENV_ID,
        metadata=option(parse=names_type(lambda: ENVS, "env"), metavar="ENV", flag="--env"),
    )
    """the environment"""
    loops: tuple[str, ...] = field(
        default=tuple(SEARCH_SPACES),
        metadata=option(parse=names_type(lambda: tuple(SEARCH_SPACES), "loop"), metavar="NAME"),
    )
    """the loops to tune"""
    candidates: int = field(default=32, metadata=option(low=1, high=100_000))
    """candidates per loop in round 0, the default factors included"""
    refine: int = field(default=16, metadata=option(low=0, high=100_000))
    """candidates per loop in round 1, around round 0's best (0: no round 1)"""
    zoom: float = field(default=0.25, metadata=option(low=0.0, high=1.0, open_low=True))
    """width of round 1's box as a share of each factor's whole (log) range"""
    episodes: int = field(default=32, metadata=option(low=1, high=100_000))
    """training episodes per candidate"""
    top: int = field(default=4, metadata=option(low=1, high=100_000))
    """candidates per loop validated, by training score"""
    search_seed: int = field(default=0, metadata=option(low=0, high=2**31 - 1))
    """seed of the Latin hypercubes"""
    out: Path | None = field(
        default=None,
        metadata=option(parse=output_folder, metavar="DIR", default_text="results/tune/ENV"),
    )
    """output folder"""
    write: bool = False
    """store the selected factors in the tuned gains file (--gains-file)"""
    gains_file: Path = field(
        default=TUNED_GAINS_FILE,
        metadata=option(metavar="FILE", default_text="baselines/tuned_gains.json"),
    )
    """the tuned gains file --write updates"""
    no_progress: bool = False
    """no progress bars"""

    def __post_init__(self) -> None:
        object.__setattr__(self, "loops", tuple(dict.fromkeys(self.loops)))  # each loop once
        if self.env_id not in ENVS:
            raise ValueError(f"--env: {shown(self.env_id)} is not valid: allowed {', '.join(ENVS)}")
        if not self.loops:
            raise ValueError(f"--loops: empty: allowed one or more of {', '.join(SEARCH_SPACES)}")
        for loop in self.loops:
            if loop not in SEARCH_SPACES:
                raise ValueError(
                    f"--loops: unknown loop {shown(loop)}: allowed {', '.join(SEARCH_SPACES)}"
                )
        for name, low in (("candidates", 1), ("refine", 0), ("episodes", 1), ("top", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(
                    f"--{name}: {shown(value)} is out of range: allowed an integer >= {low}"
                )
        if self.top > self.candidates + self.refine:
            raise ValueError(
                f"--top: {self.top} is out of range: allowed at most --candidates + --refine = "
                f"{self.candidates + self.refine}"
            )
        if not (isinstance(self.zoom, (int, float)) and 0 < self.zoom <= 1):
            raise ValueError(f"--zoom: {shown(self.zoom)} is out of range: allowed (0, 1]")

    @property
    def folder(self) -> Path:
        """The output folder: ``out``, else ``results/tune/ENV``."""
        folder = self.out if self.out is not None else Path("results") / "tune" / self.env_id
        try:
            return check_output_folder(folder)
        except ValueError as err:
            raise ValueError(f"argument --out: {err}") from None


TuneSettings = TuneSpec
"""Deprecated name of :class:`TuneSpec`."""


def _round0(settings: TuneSpec, loop: str) -> list[tuple[str, str, dict[str, float]]]:
    space = SEARCH_SPACES[loop]
    rng = np.random.default_rng([settings.search_seed, list(SEARCH_SPACES).index(loop), 0])
    points = latin_hypercube(settings.candidates - 1, len(space), rng)
    out = [(f"{loop}/r0/c000", loop, default_factors(loop))]
    for n, u in enumerate(points, 1):
        factors = {f.name: f.from_unit(float(x)) for f, x in zip(space, u, strict=True)}
        out.append((f"{loop}/r0/c{n:03d}", loop, factors))
    return out


def _round1(
    settings: TuneSpec, loop: str, best: Mapping[str, float]
) -> list[tuple[str, str, dict[str, float]]]:
    space = SEARCH_SPACES[loop]
    rng = np.random.default_rng([settings.search_seed, list(SEARCH_SPACES).index(loop), 1])
    points = latin_hypercube(settings.refine, len(space), rng)
    half = settings.zoom / 2
    out = []
    for n, u in enumerate(points):
        factors = {}
        for f, x in zip(space, u, strict=True):
            centre = f.to_unit(float(best[f.name]))
            low, high = max(0.0, centre - half), min(1.0, centre + half)
            factors[f.name] = f.from_unit(low + float(x) * (high - low))
        out.append((f"{loop}/r1/c{n:03d}", loop, factors))
    return out


@dataclass
class LoopResult:
    """What the search found for one loop.

    Attributes:
        loop: Its name.
        rows: One row per candidate (key, round, factors, training and validation scores).
        selected: The key of the selected candidate (``None``: no validated one is feasible).
        default: The key of the default factors.
    """

    loop: str
    rows: list[dict[str, Any]] = field(default_factory=list)
    selected: str | None = None
    default: str = ""

    def row(self, key: str) -> dict[str, Any]:
        """The row of ``key``."""
        return next(r for r in self.rows if r["key"] == key)


@dataclass
class TuneResult:
    """A finished search.

    Attributes:
        settings: Its settings.
        loops: Per loop, in the order of ``settings.loops``.
        simulated_s: Simulated seconds of every run made for it (all rounds and the
            validation, the reference included, also those read back from results files).
        compute_s: Wall seconds those runs took (as recorded with each candidate).
        wall_s: Wall seconds of this command's search (runs read back cost nothing).
    """

    settings: TuneSpec
    loops: list[LoopResult]
    simulated_s: float
    compute_s: float
    wall_s: float
    per_loop_simulated_s: dict[str, float] = field(default_factory=dict)


def _study(
    name: str,
    settings: TuneSpec,
    episodes: Sequence[tuple[int, int]],
    candidates: Sequence[tuple[str, str, dict[str, float]]],
    task_candidates: int,
) -> CandidateStudy:
    return CandidateStudy(
        name=name,
        env_id=settings.env_id,
        env_kwargs=tuning_env_kwargs(settings.env_id),
        episodes=tuple(episodes),
        candidates=tuple(candidates),
        task_candidates=task_candidates,
    )


def run_tuning(
    settings: TuneSpec,
    backend: Backend | None = None,
    out: Path | None = None,
    results: Path | None = None,
    resume: bool = False,
    progress: bool = True,
    overwrite: bool = False,
    task_candidates: int = 1,
) -> TuneResult:
    """Search, validate and select (see the module docstring).

    Args:
        settings: The search.
        backend: Where the runs go (default serial).
        out: Folder of the results database ``tune.sqlite`` of the three stages (``None``:
            none written, unless ``results``).
        results: The results database of the three stages; wins over ``out``.
        resume: Keep what the results database already holds of these stages.
        progress: Progress bars on standard error.
        overwrite: Delete the rows of these stages from the results database first.
        task_candidates: Candidates per task of the sweep runner (does not change the numbers).
    """
    started = time.perf_counter()
    train = training_episodes(settings.episodes)
    Candidate = tuple[str, str, dict[str, float]]
    reference: Candidate = (f"{REFERENCE}/reference", REFERENCE, {})
    outcomes: list[SweepOutcome] = []

    def sweep(stage: str, episodes: Any, candidates: Any) -> SweepOutcome:
        study = _study(f"tune-{stage}", settings, episodes, candidates, task_candidates)
        path = results if results is not None else None if out is None else out / RESULTS_FILE
        outcome = run_sweep(study, backend, path, resume, progress, overwrite=overwrite)
        outcomes.append(outcome)
        return outcome

    rounds = {loop: _round0(settings, loop) for loop in settings.loops}
    first = sweep(
        "round0", train, [reference, *(c for loop in settings.loops for c in rounds[loop])]
    )
    records = dict(first.records)
    base_train = records[reference[0]]
    training = {k: score_of(r, base_train) for k, r in records.items() if k != reference[0]}
    if settings.refine:
        refined = []
        for loop in settings.loops:
            best = min(rounds[loop], key=lambda c: (training[c[0]].score, c[0]))
            refined += _round1(settings, loop, best[2])
        second = sweep("round1", train, refined)
        records.update(second.records)
        training.update({k: score_of(r, base_train) for k, r in second.records.items()})
        for c in refined:
            rounds[str(c[1])].append(c)
    validated: dict[str, list[str]] = {}
    to_validate: list[Candidate] = [(f"{REFERENCE}/validation", REFERENCE, {})]
    for loop in settings.loops:
        ranked = sorted(rounds[loop], key=lambda c: (training[c[0]].score, c[0]))
        top = [c for c in ranked[: settings.top] if training[c[0]].feasible]
        validated[loop] = [c[0] for c in top]
        default = rounds[loop][0]
        extra = [] if default in top else [default]
        to_validate += [(f"{k}/validation", lp, f) for k, lp, f in [*top, *extra]]
    third = sweep("validation", validation_episodes(), to_validate)
    base_val = third.records[f"{REFERENCE}/validation"]
    validation = {
        k.removesuffix("/validation"): score_of(r, base_val)
        for k, r in third.records.items()
        if not k.startswith(f"{REFERENCE}/")
    }
    loops: list[LoopResult] = []
    for loop in settings.loops:
        result = LoopResult(loop=loop, default=rounds[loop][0][0])
        for key, _, factors in rounds[loop]:
            row: dict[str, Any] = {
                "loop": loop,
                "key": key,
                "round": int(key.split("/")[1][1:]),
                **{f"factor_{k}": v for k, v in factors.items()},
                **training[key].as_dict("training"),
                "validated": key in validated[loop],
            }
            if key in validation:
                row.update(validation[key].as_dict("validation"))
            result.rows.append(row)
        eligible = [k for k in validated[loop] if validation[k].feasible]
        if eligible:
            result.selected = min(eligible, key=lambda k: (validation[k].score, training[k].score))
        loops.append(result)
    all_records = [r for o in outcomes for r in o.records.values()]
    per_loop = {
        loop: sum(
            float(r["simulated_s"]) for o in outcomes for r in o.records.values()
            if r["controller"] == loop
        )
        for loop in settings.loops
    }  # fmt: skip
    return TuneResult(
        settings=settings,
        loops=loops,
        simulated_s=sum(float(r["simulated_s"]) for r in all_records),
        compute_s=sum(float(r["wall_s"]) for r in all_records),
        wall_s=time.perf_counter() - started,
        per_loop_simulated_s=per_loop,
    )


def factors_of(row: Mapping[str, Any]) -> dict[str, float]:
    """The factors of a candidate row."""
    return {k.removeprefix("factor_"): float(v) for k, v in row.items() if k.startswith("factor_")}


def derived_gains(loop: str, factors: Mapping[str, float], env_id: str) -> dict[str, float]:
    """``kp``, ``ki``, ``z``, ``tau_mean_s`` (and ``j_ff``) the factors give on the env's
    nominal string (:data:`NOMINAL_PRESETS`)."""
    tuning = make_controller(loop, **dict(factors)).tuning(  # type: ignore[attr-defined]
        resolve_model(NOMINAL_PRESETS[env_id])
    )
    return {k: float(getattr(tuning, k)) for k in ("kp", "ki", "j_ff", "z", "tau_mean_s")}


# ---------------------------------------------------------------------------- reporting
SUMMARY_COLUMNS: Final = (
    Column("label", "loop", align="left"),
    Column("factors", "factors", align="left"),
    Column("training_score", "training score", "{:.3f}"),
    Column("validation_iae_ratio", "val. IAE ratio", "{:.3f}"),
    Column("validation_rmsd_ratio", "val. RMSD ratio", "{:.3f}"),
    Column("validation_severity_ratio", "val. severity ratio", "{:.3f}"),
    Column("validation_score", "val. score", "{:.3f}"),
)


def _factor_text(factors: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {v:.4g}" for k, v in factors.items())


def summary(result: TuneResult) -> dict[str, Any]:
    """The summary written to ``tune.json``: per loop the default and the selected factors,
    their gains on the nominal string and their scores; the budget."""
    env_id = result.settings.env_id
    loops: dict[str, Any] = {}
    for lr in result.loops:
        entry: dict[str, Any] = {}
        for label, key in (("default", lr.default), ("selected", lr.selected)):
            if key is None:
                entry[label] = None
                continue
            row = lr.row(key)
            factors = factors_of(row)
            entry[label] = {
                "key": key,
                "factors": factors,
                "gains": derived_gains(lr.loop, factors, env_id),
                **{k: v for k, v in row.items() if k.startswith(("training_", "validation_"))},
            }
        entry["simulated_s"] = result.per_loop_simulated_s.get(lr.loop, 0.0)
        entry["candidates"] = len(lr.rows)
        loops[lr.loop] = entry
    s = result.settings
    return {
        "env_id": env_id,
        "settings": {
            "loops": list(s.loops),
            "candidates": s.candidates,
            "refine": s.refine,
            "zoom": s.zoom,
            "episodes": s.episodes,
            "top": s.top,
            "search_seed": s.search_seed,
            "search_spaces": {
                loop: [
                    [f.name, f.low, f.high, "log" if f.log else "linear"]
                    for f in SEARCH_SPACES[loop]
                ]
                for loop in s.loops
            },
            "training_episodes": [list(e) for e in training_episodes(s.episodes)],
            "validation_seeds": [e[0] for e in validation_episodes()],
            "env_kwargs": {k: _jsonable(v) for k, v in tuning_env_kwargs(env_id).items()},
        },
        "loops": loops,
        "budget": {
            "simulated_s": result.simulated_s,
            "compute_s": result.compute_s,
            "wall_s": result.wall_s,
        },
    }


def summary_rows(result: TuneResult) -> list[dict[str, Any]]:
    """Rows of the table printed at the end: default and selected factors per loop."""
    rows = []
    for lr in result.loops:
        for label, key in (("default", lr.default), ("tuned", lr.selected)):
            if key is None:
                rows.append({"label": f"{lr.loop} ({label})", "factors": "none feasible"})
                continue
            row = lr.row(key)
            rows.append(
                {**row, "label": f"{lr.loop} ({label})", "factors": _factor_text(factors_of(row))}
            )
    return rows


def write_gains(result: TuneResult, path: Path, command: str) -> tuple[Path, list[str]]:
    """Store the selected factors of ``result`` in the tuned-gains file ``path`` (entries of
    other loops and of the other plant kind are kept); returns the path and the loops
    written.

    Raises:
        ValueError: the existing file is malformed (it is left as it is).
    """
    entries: dict[str, dict[str, TunedEntry]] = {}
    if path.is_file():
        entries = {k: dict(v) for k, v in load_tuned_gains(path).items()}
    kind = next(k for k, e in KIND_ENVS.items() if e == result.settings.env_id)
    written = []
    for lr in result.loops:
        if lr.selected is None:
            continue
        row, default = lr.row(lr.selected), lr.row(lr.default)
        defaults = TUNABLE[lr.loop]()
        gains = type(defaults)(**factors_of(row))
        entries.setdefault(lr.loop, {})[kind] = TunedEntry(
            gains=gains,
            env_id=result.settings.env_id,
            validation_score=row.get("validation_score"),
            default_validation_score=default.get("validation_score"),
            command=command,
        )
        written.append(lr.loop)
    document = tuned_gains_document(
        entries,
        about="Relative factors of the industry speed loops selected by drill-gym tune "
        "(experiments/tune_baselines.py, docs/reports/tuned-baselines.md); read by the controllers "
        "stiff_pi_tuned, soft_speed_tuned and z_torque_tuned. One entry per plant kind: "
        "DrillStringParameters (tuned on DrillString-v0) and DistributedStringParameters "
        "(tuned on DrillStringField-v0).",
    )
    parse_tuned_gains(document, path.name)  # what is written must load
    write_json(document, path)
    return path, written


# ---------------------------------------------------------------------------- command line
DESCRIPTION: Final = """\
Tune the factors of the speed loops with the residual agent's budget, scenarios and selection
rule: two rounds of Latin hypercubes on the agent's first --episodes training episodes, then
the --top candidates on 32 validation scenarios. Writes tune.sqlite (--resume continues it),
candidates.csv and tune.json into --out; --write stores the selected factors in the tuned
gains file. Ranges, budget and times: docs/reports/tuned-baselines.md.

example: drill-gym tune --loops soft_speed --candidates 8 --refine 0 --episodes 4 --top 2
"""


def _parser() -> ArgumentParser:
    return spec_parser("drill-gym tune", DESCRIPTION, TuneSpec, RunnerSpec)


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym tune``; returns the exit code (see ``--help``)."""
    argv = list(argv) if argv is not None else None
    args = _parser().parse_args(argv)
    spec = spec_from_args(TuneSpec, args)
    given = argv if argv is not None else sys.argv[1:]
    return run_tune(
        spec, spec_from_args(RunnerSpec, args), shlex.join(["drill-gym", "tune", *given])
    )


def run_tune(spec: TuneSpec, runner: RunnerSpec, command: str) -> int:
    """Search, print and write what ``spec`` asks for on ``runner``; ``command`` is the
    command line recorded in the tuned gains file. Returns the exit code."""
    if spec.write:  # a link, a folder or a malformed file fails now, not after the search
        check_writable_target(spec.gains_file)
        if spec.gains_file.is_file():
            load_tuned_gains(spec.gains_file)
    out = spec.folder
    backend = runner.backend()
    result = run_tuning(
        spec,
        backend,
        out=out,
        results=runner.results,
        resume=runner.resume,
        progress=not spec.no_progress,
        overwrite=runner.overwrite,
        task_candidates=runner.task_size or 1,
    )
    rows = [row for lr in result.loops for row in lr.rows]
    keys = list(dict.fromkeys(k for row in rows for k in row))
    written = [write_csv(rows, out / "candidates.csv", keys)]
    written.append(write_json(summary(result), out / "tune.json"))
    print(markdown_table(summary_rows(result), SUMMARY_COLUMNS))
    for lr in result.loops:
        if lr.selected is None:
            print(f"{lr.loop}: no validated candidate is feasible: nothing selected")
            continue
        gains = derived_gains(lr.loop, factors_of(lr.row(lr.selected)), spec.env_id)
        print(
            f"{lr.loop}: selected {lr.selected}; on {NOMINAL_PRESETS[spec.env_id]}: "
            + ", ".join(f"{k} {v:.4g}" for k, v in gains.items())
        )
    print(
        f"tune on {spec.env_id} ({backend.describe()}): {result.simulated_s:,.0f} simulated s "
        f"({', '.join(f'{k} {v:,.0f}' for k, v in result.per_loop_simulated_s.items())}), "
        f"{result.compute_s:.1f} s of runs, {result.wall_s:.1f} s wall; wrote "
        + ", ".join(str(w) for w in written)
    )
    if spec.write:
        path, loops = write_gains(result, spec.gains_file, command)
        print(f"wrote the factors of {', '.join(loops) or 'no loop'} to {path}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
