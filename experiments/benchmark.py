"""``drill-gym benchmark [POLICY ...]``: any controller or agent scored on fixed, versioned
scenario suites, with interquartile means, stratified-bootstrap intervals and performance
profiles.

A *suite* is data: one JSON file ``experiments/suites/NAME-vVERSION.json`` listing its env, its
reference controller, the episode length, the noise and every scenario with its reset seeds
(:func:`load_suite` reads and checks it). A shipped suite is never edited: a change is a new
file with the next version, and ``tests/test_benchmark.py`` pins the SHA-256 of each shipped
file's content (:func:`content_hash`). The shipped suites:

* ``heldout-v1``: the held-out set of ``DrillString-v0`` (h01-h20, :data:`experiments.heldout.HELD_OUT`);
* ``corners-v1``: its corner set (c01-c16, :data:`experiments.heldout.CORNERS`);
* ``field-v1``: the held-out set of ``DrillStringField-v0`` (f01-f16,
  :data:`experiments.heldout.FIELD_HELD_OUT`);
* ``deep-v1``: deep strings on ``DrillStringField-v0`` (the distributed presets at 4-6 km).
* ``outside-v1``: ``DrillStringField-v0`` outside the shipped field agent's training ranges
  (``agents.train.TRAINING_RANGES['wide']``), one way or more per scenario.

Each scenario runs with five reset seeds (they drive the noise; the first one is the seed of
``drill-gym evaluate``). Every run goes through the one scoring path
(:func:`experiments.field.run_on` and :func:`drill_env.evaluation.episode_metrics`): a
controller as the env's ``base_controller`` with a zero residual, an agent with its own env
keywords. On the field suites a speed loop runs on the rig's surface signals (the suite's
``observation``); the paper's sliding-mode controllers need the whole state
(:func:`experiments.field.observations_of`) and are labelled ``(state)``.

The scorecard, per suite and metric (:data:`METRICS`: IAE, stick-slip severity over the
stick-slip-prone scenarios, RMS torque deviation, chattering; all lower is better):

* the interquartile mean (IQM: the mean of the middle 50 % of the runs) over every scenario
  and seed, and its 95 % stratified-bootstrap confidence interval (percentile method; the
  scenarios are the strata, a scenario's seeds are resampled with replacement within it:
  :func:`iqm_interval`, ``scipy.stats.bootstrap``);
* a normalised score, ``(IQM_ref - IQM) / (IQM_ref - IQM_best)``: 0 for the suite's reference
  controller, 1 for the best entry of the table (its interval is the IQM's, mapped the same
  way; none when no entry beats the reference);
* performance profiles: the fraction of runs at or below each value of the metric, one curve
  per entry (``profiles.png``).

A learned method may be given as several models, one per training seed: a folder whose
subfolders each hold one (``drill-gym sweep-train``'s ``OUT/runs/*/model``, or ``OUT``
itself), or ``NAME=FOLDER`` repeated under one ``NAME`` (:func:`make_entry`,
:func:`merge_entries`). Its IQM is then over every training seed, scenario and reset seed, and
its interval resamples, within each scenario, the training seeds and then each drawn seed's
reset seeds (a two-level stratified bootstrap), so it covers the spread between training
seeds; the scorecard says how many training seeds each entry has and gives each seed's own
IQM. The interval of an entry of one model says how much the IQM moves with the noise seeds
only, nothing of how much a retrained agent would differ.

Outputs (``--out``, default ``results/benchmark``): ``scorecard.md``, ``scorecard.csv`` (one
row per suite, entry and metric), ``runs.csv`` (one row per run) and ``profiles.png``; with a
method of several training seeds ``runs.csv`` has a ``training_seed`` column and
``scorecard.csv`` a ``training_seeds`` column (:data:`SEED_KEYS`).

The runs go through the sweep runner (:class:`BenchmarkStudy`, :mod:`experiments.sweep`): an
item is one run (suite, entry, training seed, scenario, reset seed), serially by default, on
Ray with ``--workers N``; with ``--results`` (or on Ray, ``--resume``) each run is a row of the
SQLite results database ``OUT/benchmark.sqlite``, keyed by the suites' content hashes and the
entries (a model by the SHA-256 of its weights), and ``--resume`` runs only those missing. The
scorecard is computed from the runs' records, so a resumed benchmark writes the same one.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import math
import re
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

import baselines  # noqa: F401  (registers the built-in controllers a suite may name)
from agents.policy import is_model_folder, load_policy
from drill_env.control import controller_names
from drill_env.distributed import DISTRIBUTED_PRESETS
from drill_env.evaluation import Policy, ZeroAction, episode_metrics, termination_note
from drill_env.files import write_text
from drill_env.metrics import METRIC_KEYS, interquartile_mean
from drill_env.scenarios import WobProfile
from drill_env.validation import shown
from experiments.arguments import SEED_HIGH, ArgumentParser, one_line, output_folder
from experiments.controllers import (
    CONTROLLERS_OPTION_HELP,
    controller_type,
    is_user_controller,
    refuse_on_ray,
    resolve_controller_name,
)
from experiments.evaluate import shipped_models
from experiments.field import (
    CONTROLLER_MODELS,
    ENV_IDS,
    FieldCase,
    FieldCondition,
    is_field,
    observations_of,
    run_label,
    run_on,
)
from experiments.heldout import HeldOutScenario, held_out_scenario
from experiments.paths import output_file
from experiments.plots import METRIC_LABELS, save_figure
from experiments.results_db import Fields, Flag, Number, Schema, Text, exactly
from experiments.spec_cli import option, spec_from_args, spec_options
from experiments.sweep import (
    Backend,
    RunnerSpec,
    SweepOutcome,
    Task,
    TaskResult,
    agent_fingerprint,
    check_task_size,
    chunks,
    run_sweep,
)
from experiments.tables import json_clean, write_csv

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

    from agents.policy import ResidualPolicy

__all__ = [
    "CONFIDENCE",
    "DEFAULT_RESAMPLES",
    "METRICS",
    "MIN_SEEDS",
    "PRONE_ONLY",
    "SUITE_DIR",
    "SEED_KEYS",
    "SUITE_FORMAT",
    "BenchmarkOptions",
    "BenchmarkSpec",
    "BenchmarkStudy",
    "Entry",
    "Suite",
    "SuiteScenario",
    "content_hash",
    "csv_columns",
    "iqm",
    "iqm_interval",
    "load_suite",
    "main",
    "make_entry",
    "merge_entries",
    "normalised_score",
    "profiles_figure",
    "run_benchmark",
    "run_suite",
    "score_suite",
    "scorecard_markdown",
    "seed_folders",
    "shipped_suites",
    "training_seed",
    "training_seed_table",
]

SUITE_DIR: Final = Path(__file__).resolve().with_name("suites")
"""Folder of the shipped suites, one ``NAME-vVERSION.json`` each."""
SUITE_FORMAT: Final = 1
"""Layout version of a suite file (its ``format``)."""
MIN_SEEDS: Final = 2
"""Fewest reset seeds of a scenario: the stratified bootstrap resamples a scenario's seeds."""
METRICS: Final = ("iae", "stick_slip_severity", "rmsd_nm", "chattering_nm_per_s")
"""The scorecard's metrics (keys of :data:`drill_env.metrics.METRIC_KEYS`), lower is better."""
PRONE_ONLY: Final = frozenset({"stick_slip_severity"})
"""Metrics scored over the stick-slip-prone scenarios only."""
CONFIDENCE: Final = 0.95
"""Confidence level of the intervals."""
DEFAULT_RESAMPLES: Final = 2000
"""Bootstrap resamples of each interval."""
IDLE_DECISION_S: Final = 1.0
"""Decision period of a controller's run (its residual is zero; the controller itself runs at
every plant step, and the noise samples do not depend on the decision period)."""

SCORE_KEYS: Final = (
    "suite", "suite_sha256", "env_id", "entry", "metric", "prone_only", "runs", "missing",
    "diverged", "iqm", "ci_low", "ci_high", "score", "score_low", "score_high", "reference",
    "best",
)  # fmt: skip
"""Columns of ``scorecard.csv``."""
RUN_KEYS: Final = (
    "suite", "entry", "scenario", "seed", "prone", *METRIC_KEYS, "diverged", "note",
)  # fmt: skip
"""Columns of ``runs.csv``."""

SEED_KEYS: Final = {"training_seed": "entry", "training_seeds": "entry"}
"""Columns of ``runs.csv`` (the run's training seed) and ``scorecard.csv`` (an entry's number
of training seeds) written only when a method has several training seeds, and the column
each follows."""


def csv_columns(keys: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> list[str]:
    """``keys`` (:data:`RUN_KEYS` or :data:`SCORE_KEYS`) with the columns of
    :data:`SEED_KEYS` that some row of ``rows`` has, each after the column it follows."""
    out = list(keys)
    for key, after in SEED_KEYS.items():
        if key not in out and any(key in r for r in rows):
            out.insert(out.index(after) + 1, key)
    return out


_NAME: Final = re.compile(r"[a-z][a-z0-9_]*")
_FILE_NAME: Final = re.compile(r"([a-z][a-z0-9_]*)-v([1-9][0-9]*)\.json")
_NAMED_FOLDER: Final = re.compile(r"([a-z][a-z0-9_]*)=(.+)", re.DOTALL)
"""``NAME=FOLDER``: a model folder, or a folder of training seeds, under a name of its own."""


# ---------------------------------------------------------------------------------- suites
@dataclass(frozen=True)
class SuiteScenario:
    """One scenario of a suite and its reset seeds.

    Attributes:
        held: The scenario (its ``seed`` is the first of ``seeds``).
        seeds: Reset seeds of its runs (at least :data:`MIN_SEEDS`, distinct).
    """

    held: HeldOutScenario
    seeds: tuple[int, ...]

    @property
    def id(self) -> str:
        """The scenario's id."""
        return self.held.id

    @property
    def prone(self) -> bool:
        """Whether it is stick-slip prone (:attr:`HeldOutScenario.prone`)."""
        return self.held.prone


@dataclass(frozen=True)
class Suite:
    """A fixed, versioned scenario suite (read from its JSON file by :func:`load_suite`).

    Attributes:
        name: Its name (lower case).
        version: Its version (>= 1).
        env_id: The env of every run.
        description: What it holds, in words.
        reference: The registered controller whose score is 0.
        observation: On the field string, the observation mode of the controllers that can run
            on it (``None`` on ``DrillString-v0``).
        episode_s: Length of every run, s.
        noise_std_rad_s: Measurement noise on the speeds, rad/s.
        controller_model: On the field string, what the controllers know of it (``nominal`` or
            ``exact``; ``None`` on ``DrillString-v0``).
        scenarios: The scenarios.
        sha256: :func:`content_hash` of the file's content.
        source: The file it was read from.
    """

    name: str
    version: int
    env_id: str
    description: str
    reference: str
    observation: str | None
    episode_s: float
    noise_std_rad_s: float
    controller_model: str | None
    scenarios: tuple[SuiteScenario, ...]
    sha256: str
    source: str

    @property
    def label(self) -> str:
        """``NAME-vVERSION``."""
        return f"{self.name}-v{self.version}"

    @property
    def runs(self) -> int:
        """Runs of one entry: every scenario with every seed."""
        return sum(len(s.seeds) for s in self.scenarios)

    def env_kwargs(self, scenario: SuiteScenario) -> dict[str, Any]:
        """The env keywords of a run of ``scenario`` (its plant, profiles and noise)."""
        return {**scenario.held.scenario.keywords(), "episode_s": self.episode_s}


def content_hash(data: Any) -> str:
    """SHA-256 of ``data`` (a suite file's parsed JSON) in canonical form (sorted keys, no
    white space): the same for any layout of the same content."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


class _Reader:
    """Typed access to one JSON object of a suite file; every error names the file and field."""

    def __init__(self, data: Any, where: str, keys: Sequence[str]) -> None:
        if not isinstance(data, dict):
            raise ValueError(f"{where}: expected a JSON object, got {type(data).__name__}")
        unknown = sorted(set(data) - set(keys))
        missing = [k for k in keys if k not in data]
        if unknown or missing:
            parts = ([f"unknown field(s) {', '.join(unknown)}"] if unknown else []) + (
                [f"missing field(s) {', '.join(missing)}"] if missing else []
            )
            raise ValueError(f"{where}: {'; '.join(parts)}: expected {', '.join(keys)}")
        self.data, self.where = data, where

    def fail(self, key: str, allowed: str) -> ValueError:
        return ValueError(f"{self.where}: field {key} = {shown(self.data[key])}: allowed {allowed}")

    def text(self, key: str, pattern: re.Pattern[str] | None = None) -> str:
        value = self.data[key]
        if not isinstance(value, str) or not value or (pattern and not pattern.fullmatch(value)):
            raise self.fail(
                key, "a non-empty string" + (f" matching {pattern.pattern}" if pattern else "")
            )
        return value

    def number(self, key: str, low: float, high: float, *, optional: bool = False) -> float | None:
        value = self.data[key]
        if value is None and optional:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(
                key, f"a number in [{low:g}, {high:g}]" + (" or null" if optional else "")
            )
        if not (math.isfinite(value) and low <= value <= high):
            raise self.fail(key, f"[{low:g}, {high:g}]")
        return float(value)

    def real(self, key: str, low: float, high: float) -> float:
        value = self.number(key, low, high)
        assert value is not None
        return value

    def choice(self, key: str, allowed: Sequence[Any]) -> Any:
        if self.data[key] not in allowed:
            raise self.fail(key, ", ".join("null" if a is None else str(a) for a in allowed))
        return self.data[key]


_SUITE_KEYS: Final = (
    "format", "name", "version", "env_id", "description", "reference", "observation",
    "episode_s", "noise_std_rad_s", "controller_model", "scenarios",
)  # fmt: skip
_PAPER_KEYS: Final = (
    "id", "condition", "uncertainty", "reference_speed_rad_s", "wob_n", "wob_step_time_s",
    "wob_final_n", "seeds",
)  # fmt: skip
_FIELD_KEYS: Final = (
    "id", "parameters", "measured_depth_m", "reference_rpm", "wob_n", "wob_step_time_s",
    "wob_final_n", "friction", "seeds",
)  # fmt: skip
_FRICTION_KEYS: Final = ("name", "mu_a", "mu_0_ratio", "xi", "mud_damping_factor")


def _seeds(r: _Reader) -> tuple[int, ...]:
    seeds = r.data["seeds"]
    ok = (
        isinstance(seeds, list)
        and len(seeds) >= MIN_SEEDS
        and all(
            isinstance(s, int) and not isinstance(s, bool) and 0 <= s <= SEED_HIGH for s in seeds
        )
        and len(set(seeds)) == len(seeds)
    )
    if not ok:
        raise r.fail(
            "seeds",
            f"a list of at least {MIN_SEEDS} distinct integers in [0, {SEED_HIGH}] (the "
            "stratified bootstrap resamples a scenario's seeds)",
        )
    return tuple(seeds)


def _wob(r: _Reader) -> tuple[float, float | None, float | None]:
    wob = r.real("wob_n", 1.0, 1e7)
    step = r.number("wob_step_time_s", 0.0, 1e5, optional=True)
    final = r.number("wob_final_n", 1.0, 1e7, optional=True)
    if (step is None) != (final is None):
        raise r.fail("wob_step_time_s", "a number together with wob_final_n, or both null")
    return wob, step, final


def _paper_scenario(r: _Reader, noise: float) -> SuiteScenario:
    seeds = _seeds(r)
    wob, step, final = _wob(r)
    deltas = r.data["uncertainty"]
    if not (
        isinstance(deltas, list)
        and len(deltas) == 3
        and all(isinstance(d, (int, float)) and not isinstance(d, bool) for d in deltas)
    ):
        raise r.fail("uncertainty", "a list of three numbers (Delta1, Delta2, Delta3)")
    held = held_out_scenario(
        r.text("id"),
        seeds[0],
        r.real("reference_speed_rad_s", 0.0, 1e3),
        wob / 1e3,
        (float(deltas[0]), float(deltas[1]), float(deltas[2])),
        None if step is None or final is None else (step, final / 1e3),
    )
    scenario = replace(held.scenario, noise_std_rad_s=noise)
    return SuiteScenario(replace(held, condition=r.text("condition"), scenario=scenario), seeds)


def _field_scenario(r: _Reader, noise: float, controller_model: str) -> SuiteScenario:
    seeds = _seeds(r)
    wob, step, final = _wob(r)
    f = _Reader(r.data["friction"], f"{r.where}.friction", _FRICTION_KEYS)
    condition = FieldCondition(
        f.text("name"),
        f.real("mu_a", 0.0, 10.0),
        f.real("mu_0_ratio", 0.0, 1.0),
        f.real("xi", 0.0, 100.0),
        f.real("mud_damping_factor", 0.0, 100.0),
    )
    case = FieldCase(
        r.text("id"),
        r.choice("parameters", sorted(DISTRIBUTED_PRESETS)),
        r.real("measured_depth_m", 1.0, 20_000.0),
        WobProfile(wob, step, final),
        r.real("reference_rpm", 0.0, 1e4),
        condition,
        seeds[0],
    )
    scenario = case.scenario(noise, controller_model)
    return SuiteScenario(HeldOutScenario(case.id, seeds[0], condition.name, scenario, case), seeds)


def parse_suite(data: Any, where: str) -> Suite:
    """A :class:`Suite` from the parsed JSON ``data`` of the file ``where``.

    Raises:
        ValueError: one line naming the file and the field that is missing, unknown or out of
            range (a scenario's physics is checked by the env's own validation).
    """
    r = _Reader(data, where, _SUITE_KEYS)
    if r.data["format"] != SUITE_FORMAT:
        raise r.fail("format", str(SUITE_FORMAT))
    version = r.data["version"]
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise r.fail("version", "an integer >= 1")
    env_id = r.choice("env_id", ENV_IDS)
    on_field = is_field(env_id)
    reference = r.text("reference")
    if reference not in controller_names():  # a file never names code to import and run
        raise r.fail(
            "reference",
            f"a registered controller name: {', '.join(controller_names())} (a suite file "
            "cannot name MODULE:CLASS or PATH.py:CLASS)",
        )
    observation = r.choice("observation", ("state", "surface") if on_field else (None,))
    controller_model = r.choice("controller_model", CONTROLLER_MODELS if on_field else (None,))
    episode_s = r.real("episode_s", 1.0, 1e5)
    if episode_s != round(episode_s):  # every decision period of controllers and agents fits
        raise r.fail("episode_s", "a whole number of seconds in [1, 100000]")
    noise = r.real("noise_std_rad_s", 0.0, 10.0)
    items = r.data["scenarios"]
    if not isinstance(items, list) or not items:
        raise r.fail("scenarios", "a non-empty list of scenarios")
    scenarios: list[SuiteScenario] = []
    for k, item in enumerate(items):
        s = _Reader(item, f"{where}: scenarios[{k}]", _FIELD_KEYS if on_field else _PAPER_KEYS)
        try:
            scenario = (
                _field_scenario(s, noise, str(controller_model))
                if on_field
                else _paper_scenario(s, noise)
            )
        except ValueError as err:
            message = str(err)
            raise ValueError(
                message if message.startswith(where) else f"{s.where}: {message}"
            ) from None
        scenarios.append(scenario)
    ids = [s.id for s in scenarios]
    twice = sorted({i for i in ids if ids.count(i) > 1})
    if twice:
        raise ValueError(f"{where}: scenario id(s) {', '.join(twice)} appear more than once")
    return Suite(
        r.text("name", _NAME),
        version,
        env_id,
        r.text("description"),
        reference,
        observation,
        episode_s,
        noise,
        controller_model,
        tuple(scenarios),
        content_hash(data),
        where,
    )


def shipped_suites() -> list[str]:
    """Labels of the shipped suites (``heldout-v1``, ...), every version, by name then
    version."""
    found = [_FILE_NAME.fullmatch(p.name) for p in SUITE_DIR.glob("*.json")]
    pairs = sorted((m.group(1), int(m.group(2))) for m in found if m)
    return [f"{name}-v{version}" for name, version in pairs]


def _latest(name: str) -> str | None:
    versions = [label for label in shipped_suites() if label.rsplit("-v", 1)[0] == name]
    return max(versions, key=lambda label: int(label.rsplit("-v", 1)[1]), default=None)


def load_suite(suite: str | Path) -> Suite:
    """Read and check a suite: a shipped one by label (``heldout-v1``) or name (``heldout``:
    its latest version), or a JSON file of the same layout.

    Raises:
        ValueError: for an unknown suite, a file that is not JSON, breaks the layout, or whose
            name ``NAME-vVERSION.json`` disagrees with its ``name`` and ``version``.
        OSError: for a file that cannot be read.
    """
    text = str(suite)
    if text.endswith(".json") or "/" in text:
        path = Path(text)
        if not path.is_file():
            raise ValueError(f"suite {shown(text)}: no such file")
    else:
        label = text if text in shipped_suites() else _latest(text)
        if label is None:
            names = sorted({s.rsplit("-v", 1)[0] for s in shipped_suites()})
            raise ValueError(
                f"unknown suite {shown(text)}: allowed {', '.join(names + shipped_suites())}, or a "
                "suite file (.json)"
            )
        path = SUITE_DIR / f"{label}.json"
    where = str(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise ValueError(f"{where}: not JSON: {err}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{where}: not UTF-8 text") from None
    loaded = parse_suite(data, where)
    named = _FILE_NAME.fullmatch(path.name)
    if named and (named.group(1), int(named.group(2))) != (loaded.name, loaded.version):
        raise ValueError(
            f"{where}: the file name says {named.group(1)}-v{named.group(2)}, its content "
            f"{loaded.label}: a changed suite is a new file with a new version"
        )
    return loaded


# --------------------------------------------------------------------------------- entries
@dataclass(frozen=True)
class Entry:
    """One line of the scorecard: a registered controller or a learned method.

    Attributes:
        name: The controller's registered name or the agent's name.
        agent: The agent (``None`` for a controller); of a method trained with several seeds,
            the model of its first training seed.
        source: What the user named (a controller's name or spec, a model folder).
        training_seeds: Of a method given as several models (one per training seed), every
            ``(training seed, model)`` by seed; empty for a controller or a single model.
    """

    name: str
    agent: ResidualPolicy | None = None
    source: str = ""
    training_seeds: tuple[tuple[int, ResidualPolicy], ...] = ()

    @property
    def seed_count(self) -> int:
        """Training seeds of the entry (1 for a single model, 0 for a controller)."""
        return len(self.training_seeds) or int(self.agent is not None)

    def run(self, suite: Suite) -> tuple[str, Policy, dict[str, Any]] | None:
        """``(label, policy, env keywords)`` of this entry's runs on ``suite`` (the
        scenario's keywords are added per run), or ``None`` when it does not run there (an
        agent made for another env). Of a method with several training seeds: its first
        model's (:meth:`runs` gives them all)."""
        on_field = is_field(suite.env_id)
        if self.agent is None:
            kwargs: dict[str, Any] = {
                "base_controller": self.name,
                "control_dt_s": IDLE_DECISION_S,
            }
            observation = None
            if on_field:
                observation = observations_of(self.name, (str(suite.observation),))[0]
                kwargs["observation"] = observation
            label = run_label({"controller": self.name, "observation": observation})
            return label, ZeroAction(), kwargs
        return _agent_run(self.name, self.agent, suite)

    def runs(self, suite: Suite) -> list[tuple[int | None, str, Policy, dict[str, Any]]]:
        """``(training seed, label, policy, env keywords)`` of every model of this entry on
        ``suite``: one with seed ``None`` for a controller or a single model, one per training
        seed for a method given with several; empty when it does not run there."""
        if not self.training_seeds:
            job = self.run(suite)
            return [] if job is None else [(None, *job)]
        out: list[tuple[int | None, str, Policy, dict[str, Any]]] = []
        for seed, agent in self.training_seeds:
            job = _agent_run(self.name, agent, suite)
            if job is not None:
                out.append((seed, *job))
        return out


def _agent_run(
    name: str, agent: ResidualPolicy, suite: Suite
) -> tuple[str, Policy, dict[str, Any]] | None:
    """``(label, agent, its env keywords)`` of an agent's runs on ``suite``, or ``None`` when
    it is made for another env."""
    if agent.env_id != suite.env_id:
        return None
    own = dict(agent.env_kwargs)
    observation = own.get("observation", "surface") if is_field(suite.env_id) else None
    return run_label({"controller": name, "observation": observation}), agent, own


def training_seed(agent: ResidualPolicy, where: str) -> int:
    """The training seed of a model (``train_config.seed`` of its ``config.json``).

    Raises:
        ValueError: naming ``where`` when the model records none.
    """
    config = agent.metadata.get("train_config")
    seed = config.get("seed") if isinstance(config, Mapping) else None
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise ValueError(
            f"{where}: the model records no training seed (train_config.seed of its "
            "config.json): a method with several training seeds needs one per model"
        )
    return seed


def seed_folders(folder: Path) -> list[Path]:
    """The model folders of the training seeds of one method under ``folder``: those of
    ``folder/runs`` when it exists (a ``drill-gym sweep-train`` output folder, whose
    ``best_model/`` is a copy of one of them), else the subfolders of ``folder`` that are model
    folders or hold one as ``model/`` (run folders of ``drill-gym train``); by name."""
    for parent in (folder / "runs", folder):
        if not parent.is_dir():
            continue
        found = []
        for child in sorted(p for p in parent.iterdir() if p.is_dir()):
            if is_model_folder(child):
                found.append(child)
            elif is_model_folder(child / "model"):
                found.append(child / "model")
        if found:
            return found
    return []


def _combine(name: str, models: Sequence[tuple[ResidualPolicy, str]], source: str) -> Entry:
    """One entry named ``name`` of ``models`` (``(model, where it was read)``, one per
    training seed); a single model is an entry of one model.

    Raises:
        ValueError: naming the models that disagree on their env or repeat a training seed.
    """
    if len(models) == 1:
        return Entry(name, models[0][0], source)
    first, first_where = models[0]
    seen: dict[int, tuple[ResidualPolicy, str]] = {}
    for agent, where in models:
        if (agent.env_id, agent.env_kwargs) != (first.env_id, first.env_kwargs):
            raise ValueError(
                f"{name}: {where} is made for {agent.env_id} with {agent.env_kwargs}, "
                f"{first_where} for {first.env_id} with {first.env_kwargs}: the training seeds "
                "of one method share their env and its keywords"
            )
        seed = training_seed(agent, where)
        if seed in seen:
            raise ValueError(
                f"{name}: training seed {seed} appears twice ({seen[seed][1]} and {where}): "
                "give each training seed once"
            )
        seen[seed] = agent, where
    seeds = tuple((k, seen[k][0]) for k in sorted(seen))
    return Entry(name, seeds[0][1], source, seeds)


def make_entry(text: str) -> Entry:
    """An :class:`Entry` from what the user typed: a registered controller name,
    ``MODULE:CLASS`` or ``PATH.py:CLASS`` (:func:`experiments.controllers.load_controller`),
    a model folder (:func:`agents.policy.load_policy`), or a folder of model folders, one
    per training seed (:func:`seed_folders`; a ``drill-gym sweep-train`` output). Any folder
    may be given as ``NAME=FOLDER``: the entry is named ``NAME`` (lower case, digits,
    underscores), and entries of the same ``NAME`` are one method
    (:func:`merge_entries`).

    Raises:
        ValueError: naming ``text`` and what it could have been.
        FileNotFoundError: for an incomplete model folder.
    """

    named = _NAMED_FOLDER.fullmatch(text)
    name, folder = (named.group(1), named.group(2)) if named else (None, text)
    path = Path(folder)
    if named or (text not in controller_names() and ":" not in text and path.exists()):
        if not path.is_dir() or is_model_folder(path):
            agent = load_policy(path)
            return Entry(name or agent.name, agent, text)
        found = seed_folders(path)
        if not found:
            load_policy(path)  # the error of an incomplete model folder
        entry = _combine(name or text, [(load_policy(f), str(f)) for f in found], text)
        if name is None:  # named after its models
            names = sorted({agent.name for _, agent in entry.training_seeds} or {entry.name})
            if len(names) > 1:
                raise ValueError(
                    f"{shown(text)}: its models are named {', '.join(names)}: give the method a "
                    "name as NAME=FOLDER"
                )
            entry = replace(entry, name=names[0])
        return entry
    try:
        return Entry(resolve_controller_name(text), None, text)
    except ValueError as err:
        if ":" in text:
            raise
        raise ValueError(f"{err}; or a model folder (no such folder {shown(text)})") from None


def merge_entries(entries: Sequence[Entry]) -> list[Entry]:
    """``entries`` with those given as ``NAME=FOLDER`` under one ``NAME`` made one method
    whose training seeds are all of theirs (in the place of the first).

    Raises:
        ValueError: when the merged models disagree on their env or repeat a training seed.
    """
    out: list[Entry] = []
    groups: dict[str, list[Entry]] = {}
    place: dict[str, int] = {}
    for entry in entries:
        named = _NAMED_FOLDER.fullmatch(entry.source)
        if named is None or entry.agent is None:
            out.append(entry)
            continue
        if entry.name not in groups:
            groups[entry.name], place[entry.name] = [], len(out)
            out.append(entry)
        groups[entry.name].append(entry)
    for name, group in groups.items():
        if len(group) > 1:
            models = [
                (agent, e.source)
                for e in group
                for agent in [a for _, a in e.training_seeds] or ([e.agent] if e.agent else [])
            ]
            out[place[name]] = _combine(name, models, " ".join(e.source for e in group))
    return out


def _default_entries() -> list[str]:
    return [*controller_names(), *(str(p) for p in shipped_models())]


# --------------------------------------------------------------------------------- running
def run_suite(
    suite: Suite, entries: Sequence[Entry], progress: bool = False
) -> list[dict[str, Any]]:
    """Every run of every entry on ``suite``: one row per (entry, scenario, seed) with the
    suite, the label, the scenario, the seed, ``prone`` and the metrics of
    :data:`drill_env.metrics.METRIC_KEYS`; a method with several training seeds has one row
    per (training seed, scenario, seed), with its ``training_seed``. Entries that do not run
    on the suite's env are left out. (The :class:`BenchmarkStudy` of ``suite`` run serially in
    this process, no results database.)"""
    study = BenchmarkStudy((suite,), tuple(entries))
    if not study.runs():
        return []
    return study.rows(run_sweep(study, Backend(), progress=progress))


@dataclass(frozen=True)
class BenchmarkRun:
    """One episode of the benchmark: an entry's model (or controller) on one scenario of a
    suite with one reset seed.

    Attributes:
        suite: The suite.
        label: The entry's label on the suite (with the observation mode on the field string).
        trained: The model's training seed (``None``: a controller or a method of one model).
        policy: The policy (:class:`ZeroAction` for a controller).
        kwargs: Its env keywords (the scenario's are added).
        scenario: The scenario.
        seed: The reset seed.
        user: Whether it is a user's controller class (its failures name the run).
    """

    suite: Suite
    label: str
    trained: int | None
    policy: Any
    kwargs: Mapping[str, Any]
    scenario: SuiteScenario
    seed: int
    user: bool = False

    @property
    def item(self) -> str:
        """The item key of the run."""
        seed = "" if self.trained is None else f"training_seed={self.trained}/"
        return f"{self.suite.label}/{self.label}/{seed}{self.scenario.id}/seed={self.seed}"

    def head(self) -> dict[str, Any]:
        """The run's row without its metrics."""
        return {
            "suite": self.suite.label,
            "entry": self.label,
            **({} if self.trained is None else {"training_seed": self.trained}),
            "scenario": self.scenario.id,
            "seed": self.seed,
            "prone": self.scenario.prone,
        }


def run_once(run: BenchmarkRun) -> dict[str, Any]:
    """The row of one run: its head, the metrics of :func:`episode_metrics` and a ``note``
    (empty, or why the run ended early: a controller's NaN or infinite torque,
    :func:`drill_env.evaluation.termination_note`); on the field string, for a controller
    that cannot be made for the string (its tuning or model has no solution there), metrics
    ``None`` and the reason in ``note``."""
    suite, scenario = run.suite, run.scenario
    try:
        trace = run_on(
            suite.env_id, {**suite.env_kwargs(scenario), **run.kwargs}, run.policy, run.seed
        )
    except ValueError as err:
        if not is_field(suite.env_id):
            raise
        return {**run.head(), **dict.fromkeys(METRIC_KEYS), "note": one_line(str(err))}
    except Exception as err:
        if not run.user:
            raise
        raise ValueError(
            f"{run.label} failed on {suite.label} {scenario.id} seed {run.seed}: "
            f"{type(err).__name__}: {err}"
        ) from err
    return {**run.head(), **episode_metrics(trace), "note": one_line(termination_note(trace))}


def benchmark_runs_task(runs: Sequence[BenchmarkRun]) -> TaskResult:
    """Runs of the benchmark (:func:`run_once`), records by :attr:`BenchmarkRun.item`."""
    return TaskResult({run.item: run_once(run) for run in runs})


BENCHMARK_TASK_RUNS: Final = 5
"""Default runs per benchmark task (a scenario's five reset seeds)."""


def entry_fingerprint(entry: Entry) -> dict[str, Any]:
    """What identifies an entry in the benchmark's settings: a controller's name and what the
    user typed; a learned method's name and each model's :func:`agent_fingerprint` with its
    training seed."""
    if entry.agent is None:
        return {"controller": entry.name, "source": entry.source}
    models = [(None, entry.agent)] if not entry.training_seeds else list(entry.training_seeds)
    return {
        "method": entry.name,
        "models": [{"training_seed": k, **(agent_fingerprint(a) or {})} for k, a in models],
    }


@dataclass(frozen=True)
class BenchmarkStudy:
    """The benchmark on the sweep runner: an item is one run (:class:`BenchmarkRun`: suite,
    entry, training seed, scenario, reset seed), a task ``task_runs`` of them; the scorecard
    is computed from the records (:func:`score_suite`), so a resumed benchmark gives the same
    scorecard."""

    suites: tuple[Suite, ...]
    entries: tuple[Entry, ...] = field(compare=False)
    task_runs: int = BENCHMARK_TASK_RUNS
    name: str = "benchmark"

    def __post_init__(self) -> None:
        check_task_size("task_runs", self.task_runs)

    @functools.cached_property
    def _runs(self) -> list[BenchmarkRun]:
        out = []
        for suite in self.suites:
            for entry in self.entries:
                user = entry.agent is None and is_user_controller(entry.name)
                for trained, label, policy, kwargs in entry.runs(suite):
                    for scenario in suite.scenarios:
                        for seed in scenario.seeds:
                            out.append(
                                BenchmarkRun(
                                    suite, label, trained, policy, kwargs, scenario, seed, user
                                )
                            )
        return out

    def runs(self) -> list[BenchmarkRun]:
        """Every run, in the order of ``runs.csv``: by suite, entry, training seed, scenario
        and reset seed."""
        return list(self._runs)

    @functools.cached_property
    def _run_of_item(self) -> dict[str, BenchmarkRun]:
        return {r.item: r for r in self._runs}

    def spec(self) -> dict[str, Any]:
        """The suites (label and content hash) and the entries (:func:`entry_fingerprint`)."""
        return {
            "suites": [[s.label, s.sha256] for s in self.suites],
            "entries": [entry_fingerprint(e) for e in self.entries],
            "idle_decision_s": IDLE_DECISION_S,
        }

    def items(self) -> list[str]:
        """One item per run."""
        return [r.item for r in self._runs]

    def record_schema(self, item: str) -> Schema:
        """A run's row: its head as this study's, the metrics (numbers, ``None``: not defined
        or not run), ``diverged`` when it ran, and the note."""
        return Fields(
            {
                **exactly(self._run_of_item[item].head()),
                **{key: Number() for key in METRIC_KEYS},
                "note": Text(),
            },
            optional={"diverged": Flag()},
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """``task_runs`` missing runs per task."""
        wanted = set(missing)
        runs = [r for r in self._runs if r.item in wanted]
        return [
            Task(
                key=block[0].item if len(block) == 1 else f"{block[0].item}+{len(block) - 1}",
                function=benchmark_runs_task,
                kwargs={"runs": block},
                items=tuple(r.item for r in block),
            )
            for block in chunks(runs, self.task_runs)
        ]

    def rows(self, outcome: SweepOutcome) -> list[dict[str, Any]]:
        """The run rows in order, as read back from JSON (a metric without a value:
        ``None``)."""
        return [dict(outcome.records[item]) for item in self.items()]


# ------------------------------------------------------------------------------ statistics
def iqm(values: Any) -> float:
    """Interquartile mean of ``values`` (any shape, flattened):
    :func:`drill_env.metrics.interquartile_mean`, rliable's estimator."""
    return float(interquartile_mean(values))


def _iqm_of_strata(*strata: Any, axis: int = -1) -> Any:
    return interquartile_mean(np.concatenate(strata, axis=axis), axis=axis)


def iqm_interval(
    strata: Sequence[Any],
    resamples: int = DEFAULT_RESAMPLES,
    seed: int | Sequence[int] = 0,
    confidence: float = CONFIDENCE,
) -> tuple[float, float, float]:
    """The IQM over every value of ``strata`` and its stratified-bootstrap interval.

    Args:
        strata: One array per scenario: 1-D, its runs' values (one per reset seed, at least
            two); or 2-D, shape ``(training seeds, reset seeds)``, the runs of a method
            trained with several seeds (at least two reset seeds).
        resamples: Bootstrap resamples.
        seed: Seed of the resampling generator.
        confidence: Confidence level.

    Returns:
        ``(iqm, low, high)``: each resample draws every scenario's runs with replacement from
        that scenario's own runs (the scenarios are fixed, as in rliable), and the interval is
        the percentile interval of the resampled IQMs (``scipy.stats.bootstrap``). With
        several training seeds in a scenario the draw has two levels
        (:func:`_two_level_bootstrap`): its training seeds with replacement, then each drawn
        seed's reset seeds with replacement; with one training seed everywhere it is the
        draw of the reset seeds above.

    Raises:
        ValueError: for no strata, a stratum with fewer than two reset seeds, or one of more
            than two dimensions.
    """
    from scipy.stats import bootstrap

    arrays = [np.asarray(s, dtype=float) for s in strata]
    if any(a.ndim > 2 for a in arrays):
        raise ValueError("a stratum is 1-D (reset seeds) or 2-D (training x reset seeds)")
    grids = [a.reshape(1, -1) if a.ndim < 2 else a for a in arrays]
    if not grids or any(g.shape[0] < 1 or g.shape[1] < MIN_SEEDS for g in grids):
        raise ValueError(f"every stratum needs at least {MIN_SEEDS} values")
    if any(g.shape[0] > 1 for g in grids):
        return _two_level_bootstrap(grids, resamples, seed, confidence)
    data = tuple(a.ravel() for a in arrays)
    point = iqm(np.concatenate(data))
    if all(np.ptp(d) == 0.0 for d in data):  # nothing to resample: the interval is the point
        return point, point, point
    result = bootstrap(
        data,
        _iqm_of_strata,
        n_resamples=int(resamples),
        confidence_level=confidence,
        method="percentile",
        paired=False,
        vectorized=True,
        rng=np.random.default_rng(seed),
    )
    ci = result.confidence_interval
    return point, float(ci.low), float(ci.high)


def _two_level_bootstrap(
    grids: Sequence[npt.NDArray[np.float64]],
    resamples: int,
    seed: int | Sequence[int],
    confidence: float,
) -> tuple[float, float, float]:
    """The IQM of every value of ``grids`` (one ``(training seeds, reset seeds)`` array per
    scenario) and its percentile interval under a stratified two-level bootstrap: per
    resample and scenario, its training seeds drawn with replacement (independently in every
    scenario, as rliable resamples the runs of each task), then each drawn seed's reset seeds
    with replacement; the IQM of the pooled draw."""
    point = iqm(np.concatenate([g.ravel() for g in grids]))
    if all(np.ptp(g) == 0.0 for g in grids):
        return point, point, point
    rng = np.random.default_rng(seed)
    n = int(resamples)
    drawn = []
    for grid in grids:
        trained, reset = grid.shape
        rows = rng.integers(trained, size=(n, trained))
        columns = rng.integers(reset, size=(n, trained, reset))
        drawn.append(grid[rows[:, :, None], columns].reshape(n, trained * reset))
    stats = interquartile_mean(np.concatenate(drawn, axis=1), axis=1)
    tail = 50.0 * (1.0 - confidence)
    low, high = np.percentile(stats, [tail, 100.0 - tail])
    return point, float(low), float(high)


def normalised_score(value: float, reference: float, best: float) -> float:
    """``(reference - value) / (reference - best)`` for a lower-is-better metric: 0 at the
    reference, 1 at the best; NaN when the best is not below the reference."""
    if not (math.isfinite(reference) and math.isfinite(best) and best < reference):
        return math.nan
    return (reference - value) / (reference - best)


def _stratum(runs: Sequence[Mapping[str, Any]], metric: str, where: str) -> Any:
    """The values of ``metric`` in one scenario's ``runs`` of one entry: 1-D (one per reset
    seed), or of a method with several training seeds 2-D, ``(training seeds, reset seeds)``
    (NaN for a run without a value)."""

    def value(r: Mapping[str, Any]) -> float:
        return math.nan if r[metric] is None else float(r[metric])

    if not any("training_seed" in r for r in runs):
        return np.array([value(r) for r in runs])
    by_seed: dict[Any, list[float]] = {}
    for r in runs:
        by_seed.setdefault(r.get("training_seed"), []).append(value(r))
    if len({len(v) for v in by_seed.values()}) > 1:
        raise ValueError(f"{where}: the training seeds have different numbers of runs")
    return np.array([by_seed[k] for k in sorted(by_seed, key=_seed_order)])


def _seed_order(seed: Any) -> tuple[int, str]:
    """Sort key of training seeds: by number (read from CSV they are text)."""
    try:
        return int(seed), ""
    except (TypeError, ValueError):
        return 0, str(seed)


def score_suite(
    suite: Suite,
    rows: Sequence[Mapping[str, Any]],
    resamples: int = DEFAULT_RESAMPLES,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """The scorecard rows of ``suite``: one per (entry, metric of :data:`METRICS`) with the
    number of runs, the IQM and its interval, the normalised score and its interval, the
    reference's and the best entry's labels; of a method whose runs carry a
    ``training_seed``, also ``training_seeds`` (their number), its interval resampling them
    (:func:`iqm_interval`). An entry with a diverged run (its metrics cover only the steps
    before the end) is never the best and has no score.

    Raises:
        ValueError: when the suite's reference controller has no runs in ``rows``.
    """
    mine = [r for r in rows if r["suite"] == suite.label]
    labels = list(dict.fromkeys(r["entry"] for r in mine))
    reference = run_label(
        {
            "controller": suite.reference,
            "observation": (
                observations_of(suite.reference, (str(suite.observation),))[0]
                if is_field(suite.env_id)
                else None
            ),
        }
    )
    if reference not in labels:
        raise ValueError(
            f"suite {suite.label}: its reference controller {shown(reference)} was not run"
        )
    prone_ids = {s.id for s in suite.scenarios if s.prone}
    stats: dict[tuple[str, str], tuple[float, float, float]] = {}
    counts: dict[tuple[str, str], dict[str, int]] = {}
    for m_index, metric in enumerate(METRICS):
        for e_index, label in enumerate(labels):
            strata = []
            diverged = 0
            for scenario in suite.scenarios:
                if metric in PRONE_ONLY and scenario.id not in prone_ids:
                    continue
                runs = [r for r in mine if r["entry"] == label and r["scenario"] == scenario.id]
                diverged += sum(bool(r.get("diverged")) for r in runs)
                strata.append(_stratum(runs, metric, f"{suite.label} {label} {scenario.id}"))
            counts[(label, metric)] = {
                "runs": sum(s.size for s in strata),
                "missing": sum(int((~np.isfinite(s)).sum()) for s in strata),
                "diverged": diverged,
            }
            if not strata or counts[(label, metric)]["missing"]:
                # a run without a value (a controller that could not run there): no IQM
                stats[(label, metric)] = (math.nan, math.nan, math.nan)
                continue
            stats[(label, metric)] = iqm_interval(strata, resamples, (seed, m_index, e_index))
    trained = {
        label: len({r["training_seed"] for r in mine if r["entry"] == label})
        for label in labels
        if any("training_seed" in r for r in mine if r["entry"] == label)
    }
    out: list[dict[str, Any]] = []
    for metric in METRICS:
        finite = {  # the best entry: of those with a value whose runs all ran to their end
            lb: stats[(lb, metric)][0]
            for lb in labels
            if math.isfinite(stats[(lb, metric)][0]) and not counts[(lb, metric)]["diverged"]
        }
        best = min(finite, key=lambda lb: finite[lb]) if finite else None
        ref_value = stats[(reference, metric)][0]
        best_value = finite[best] if best is not None else math.nan
        for label in labels:
            point, low, high = stats[(label, metric)]
            score = normalised_score(point, ref_value, best_value)
            # the score falls as the metric rises: the IQM's high end is the score's low end
            score_low = normalised_score(high, ref_value, best_value)
            score_high = normalised_score(low, ref_value, best_value)
            if counts[(label, metric)]["diverged"]:  # cut-short runs: never scored as good
                score = score_low = score_high = math.nan
            out.append(
                {
                    "suite": suite.label,
                    "suite_sha256": suite.sha256,
                    "env_id": suite.env_id,
                    "entry": label,
                    **({"training_seeds": trained[label]} if label in trained else {}),
                    "metric": metric,
                    "prone_only": metric in PRONE_ONLY,
                    **counts[(label, metric)],
                    "iqm": point,
                    "ci_low": low,
                    "ci_high": high,
                    "score": score,
                    "score_low": score_low,
                    "score_high": score_high,
                    "reference": reference,
                    "best": best,
                }
            )
    return out


# ------------------------------------------------------------------------------- reporting
def metric_title(metric: str) -> str:
    """The scorecard's heading of ``metric`` (the figures' label, :data:`METRIC_LABELS`)."""
    label = METRIC_LABELS[metric]
    return f"{label}, prone scenarios" if metric in PRONE_ONLY else label


def _number(value: float, metric: str) -> str:
    if not math.isfinite(value):
        return "n/a"
    if metric in ("rmsd_nm", "chattering_nm_per_s"):
        return f"{value:,.0f}"
    if metric == "iae":
        return f"{value:.1f}"
    return f"{value:.3f}"


def _interval(row: Mapping[str, Any], keys: tuple[str, str, str], metric: str | None) -> str:
    point, low, high = (float(row[k]) for k in keys)
    if not math.isfinite(point):
        return "n/a"
    if metric is None:
        return f"{point:.2f} [{low:.2f}, {high:.2f}]"
    return f"{_number(point, metric)} [{_number(low, metric)}, {_number(high, metric)}]"


def suite_table(suite: Suite, scores: Sequence[Mapping[str, Any]]) -> str:
    """The markdown table of ``suite``: one line per entry (by IQM of the first metric, those
    with a diverged run after every other), each metric's IQM [95 % interval] and normalised
    score [interval]."""
    mine = [s for s in scores if s["suite"] == suite.label]
    by = {(s["entry"], s["metric"]): s for s in mine}
    labels = list(dict.fromkeys(s["entry"] for s in mine))
    first = METRICS[0]
    labels.sort(
        key=lambda lb: (
            bool(by[(lb, first)]["diverged"]),
            not math.isfinite(by[(lb, first)]["iqm"]),
            by[(lb, first)]["iqm"],
        )
    )
    head = "| entry | " + " | ".join(f"{metric_title(m)} | score" for m in METRICS) + " |"
    lines = [head, "|---|" + "---:|---:|" * len(METRICS)]
    for label in labels:
        cells = []
        for m in METRICS:
            row = by[(label, m)]
            cells.append(_interval(row, ("iqm", "ci_low", "ci_high"), m))
            cells.append(_interval(row, ("score", "score_low", "score_high"), None))
        seeds = by[(label, first)].get("training_seeds")
        name = f"{label}, {seeds} training seeds" if seeds else label
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    notes = [
        f"{label}: {by[(label, first)]['missing']} runs without a value, "
        f"{by[(label, first)]['diverged']} diverged"
        for label in labels
        if by[(label, first)]["missing"] or by[(label, first)]["diverged"]
    ]
    if notes:
        lines += ["", "Runs that could not be scored or diverged: " + "; ".join(notes) + "."]
    return "\n".join(lines)


def training_seed_table(suite: Suite, rows: Sequence[Mapping[str, Any]]) -> str:
    """Of every method of ``rows`` with several training seeds on ``suite``: one line per
    training seed with its own IQM of each metric (over the scenarios and reset seeds) and
    its rank by the first metric's (1: lowest); empty when there is none."""
    mine = [r for r in rows if r["suite"] == suite.label and "training_seed" in r]
    if not mine:
        return ""
    prone_ids = {s.id for s in suite.scenarios if s.prone}
    first = METRICS[0]
    head = "| entry | training seed | rank | " + " | ".join(metric_title(m) for m in METRICS)
    lines = [head + " |", "|---|---:|---:|" + "---:|" * len(METRICS)]
    for label in dict.fromkeys(r["entry"] for r in mine):
        values: dict[Any, dict[str, float]] = {}
        for k in sorted({r["training_seed"] for r in mine if r["entry"] == label}, key=_seed_order):
            runs = [r for r in mine if r["entry"] == label and r["training_seed"] == k]
            values[k] = {}
            for m in METRICS:
                got = [
                    math.nan if r[m] is None else float(r[m])
                    for r in runs
                    if m not in PRONE_ONLY or r["scenario"] in prone_ids
                ]
                values[k][m] = iqm(got) if got and all(map(math.isfinite, got)) else math.nan
        ranked = sorted(
            values, key=lambda k: (not math.isfinite(values[k][first]), values[k][first])
        )
        for k in values:
            cells = " | ".join(_number(values[k][m], m) for m in METRICS)
            lines.append(f"| {label} | {k} | {ranked.index(k) + 1} | {cells} |")
    return "\n".join(lines)


def scorecard_markdown(
    suites: Sequence[Suite],
    scores: Sequence[Mapping[str, Any]],
    entries: Sequence[Entry],
    resamples: int,
    seed: int,
    command: str = "",
    wall_s: float | None = None,
    rows: Sequence[Mapping[str, Any]] = (),
) -> str:
    """The scorecard as markdown: how it was made, then one table per suite (and, with the
    runs ``rows``, one per suite of the training seeds of the methods that have several:
    :func:`training_seed_table`)."""
    lines = ["# Benchmark scorecard", ""]
    if command:
        lines += [f"Command: `{command}`" + (f" ({wall_s:.0f} s wall)" if wall_s else ""), ""]
    lines += [
        "Each cell: the interquartile mean (IQM, the mean of the middle 50 % of the runs) over "
        "every scenario and seed, and its 95 % stratified-bootstrap confidence interval "
        f"(percentile method, {resamples} resamples, bootstrap seed {seed}; each scenario's "
        "seeds are resampled within it). Lower is better for every metric. The severity is "
        "taken over the stick-slip-prone scenarios only. Score: (IQM of the reference "
        "controller - IQM) / (IQM of the reference - IQM of the best entry): 0 is the "
        "reference, 1 the best entry of the table; n/a when no entry beats the reference.",
        "",
    ]
    agents = [e for e in entries if e.agent is not None and not e.training_seeds]
    if agents:
        lines += [
            "Learned agents ("
            + ", ".join(e.name for e in agents)
            + ") are one trained model each (one training seed): their intervals cover the "
            "noise seeds of the runs, not the spread between training seeds.",
            "",
        ]
    methods = [e for e in entries if e.training_seeds]
    if methods:
        lines += [
            "Scored over training seeds: "
            + ", ".join(
                f"{e.name} ({e.seed_count} training seeds: "
                f"{', '.join(str(k) for k, _ in e.training_seeds)})"
                for e in methods
            )
            + ". Their IQM pools every training seed, scenario and reset seed; their interval "
            "resamples, within each scenario, the training seeds and then each drawn seed's "
            "reset seeds, so it covers the spread between training seeds. The table under a "
            "suite gives each training seed's own IQM.",
            "",
        ]
    for suite in suites:
        prone = sum(s.prone for s in suite.scenarios)
        seeds = sorted({len(s.seeds) for s in suite.scenarios})
        lines += [
            f"## {suite.label}: {suite.env_id}, reference `{suite.reference}`",
            "",
            f"{suite.description} {len(suite.scenarios)} scenarios ({prone} prone) x "
            f"{'/'.join(map(str, seeds))} seeds; suite file SHA-256 `{suite.sha256[:16]}...`.",
            "",
            suite_table(suite, scores),
            "",
        ]
        per_seed = training_seed_table(suite, rows)
        if per_seed:
            lines += [per_seed, ""]
    return "\n".join(lines)


def profiles_figure(suites: Sequence[Suite], rows: Sequence[Mapping[str, Any]]) -> Figure:
    """Performance profiles: per suite (rows of panels) and metric (columns), the fraction of
    an entry's runs whose value is at or below each x (the severity over the prone scenarios);
    one curve per entry."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    n_rows, n_cols = len(suites), len(METRICS)
    fig = Figure(figsize=(4.0 * n_cols + 2.6, 2.9 * n_rows), layout="constrained")
    axes = fig.subplots(n_rows, n_cols, squeeze=False)
    colors = [f"C{k}" for k in range(10)]
    styles = ["-", "--", ":", "-."]
    for i, suite in enumerate(suites):
        mine = [r for r in rows if r["suite"] == suite.label]
        prone_ids = {s.id for s in suite.scenarios if s.prone}
        labels = list(dict.fromkeys(r["entry"] for r in mine))
        for j, metric in enumerate(METRICS):
            ax = axes[i][j]
            for k, label in enumerate(labels):
                values = np.sort(
                    [
                        float(r[metric])
                        for r in mine
                        if r["entry"] == label
                        and r[metric] is not None
                        and math.isfinite(float(r[metric]))
                        and (metric not in PRONE_ONLY or r["scenario"] in prone_ids)
                    ]
                )
                if values.size == 0:
                    continue
                fraction = np.arange(0, values.size + 1) / values.size
                ax.step(
                    np.concatenate([values[:1], values]), fraction, where="post", color=colors[k % 10],
                    linestyle=styles[(k // 10) % 4], label=label, linewidth=1.2,
                )  # fmt: skip
            finite = [r[metric] for r in mine if r[metric] is not None]
            spread = [float(v) for v in finite if math.isfinite(float(v))]
            if spread and min(spread) > 0 and max(spread) > 20 * min(spread):
                ax.set_xscale("log")  # values over more than a decade
                ax.xaxis.set_minor_formatter(NullFormatter())  # labels at the decades only
            ax.set_xlabel(metric_title(metric), fontsize=8)
            ax.set_ylim(0.0, 1.02)
            ax.tick_params(labelsize=7)
            if j == 0:
                ax.set_ylabel(f"{suite.label}\nfraction of runs <= x", fontsize=8)
            if j == n_cols - 1:
                ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False)
    fig.suptitle(
        "Performance profiles: the share of each entry's runs at or below a value (further "
        "left and higher is better)",
        fontsize=9,
    )
    return fig


# ----------------------------------------------------------------------------- command line
@dataclass(frozen=True)
class BenchmarkOptions:
    """The options of ``drill-gym benchmark`` (each field is the option of the same name)."""

    controllers: tuple[str, ...] = field(
        default=(), metadata=option(parse=controller_type, metavar="NAME", default_text="none")
    )
    """controllers to score too (as POLICY): registered names, MODULE:CLASS or PATH.py:CLASS"""
    suites: tuple[str, ...] = field(
        default=(), metadata=option(metavar="SUITE", default_text="every shipped suite, latest")
    )
    """suites by name (its latest version), by NAME-vVERSION, or suite files (.json)"""
    out: Path = field(
        default=Path("results/benchmark"), metadata=option(parse=output_folder, metavar="DIR")
    )
    """output folder"""
    resamples: int = field(default=DEFAULT_RESAMPLES, metadata=option(low=100, high=100_000))
    """bootstrap resamples of each confidence interval"""
    seed: int = field(default=0, metadata=option(low=0, high=SEED_HIGH))
    """seed of the bootstrap resampling (the runs' seeds are the suites')"""
    no_plots: bool = False
    """write no figure"""
    no_progress: bool = False
    """no progress bar"""


@dataclass(frozen=True)
class BenchmarkSpec(BenchmarkOptions):
    """Settings of ``drill-gym benchmark``: what to score (the POLICY arguments) and the
    options."""

    policies: tuple[str, ...] = ()
    """what to score (empty: every registered controller and every model in agents/models/);
    the controllers of ``controllers`` are scored too"""

    def suite_names(self) -> list[str]:
        """The suites named, each once (default: the latest version of every shipped one)."""
        names = self.suites or sorted({label.rsplit("-v", 1)[0] for label in shipped_suites()})
        return list(dict.fromkeys(names))

    def entry_names(self) -> list[str]:
        """What to score, each once (default: every controller and shipped model)."""
        return list(dict.fromkeys([*self.policies, *self.controllers] or _default_entries()))


DESCRIPTION: Final = """\
Score controllers and agents on fixed, versioned scenario suites: per suite and metric, the
interquartile mean over every scenario and seed with its 95 % stratified-bootstrap interval, a
score from 0 (the suite's reference) to 1 (the best entry), performance profiles. Suites:
heldout-v1, corners-v1 (DrillString-v0), field-v1, deep-v1, outside-v1 (DrillStringField-v0).
Writes scorecard.md/.csv, runs.csv, profiles.png to --out. More: docs/reports/benchmark.md.

examples:
  drill-gym benchmark                                  # every shipped controller and agent
  drill-gym benchmark proposed agents/models/residual_ppo --suites heldout corners
  drill-gym benchmark examples/custom_controller.py:SpeedPI --suites heldout-v1
  drill-gym benchmark field_x10=results/sweep-train --suites field deep   # training seeds
"""


def _parser() -> ArgumentParser:
    parser = ArgumentParser(prog="drill-gym benchmark", description=DESCRIPTION)
    parser.add_argument(
        "policies",
        nargs="*",
        metavar="POLICY",
        help="what to score: controllers ("
        + CONTROLLERS_OPTION_HELP
        + "), model folders, folders of model folders (one method, its training seeds), "
        "NAME=FOLDER; default: every controller and shipped model, and each suite's reference",
    )
    spec_options(parser, BenchmarkOptions)
    spec_options(parser, RunnerSpec)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym benchmark``: run, score and write; returns the exit code (see ``--help``)."""
    argv = list(argv) if argv is not None else None
    args = _parser().parse_args(argv)
    spec = spec_from_args(BenchmarkSpec, args)
    runner = spec_from_args(RunnerSpec, args)
    given = argv if argv is not None else sys.argv[1:]
    return run_benchmark(spec, ("drill-gym benchmark " + " ".join(given)).strip(), runner)


def _policy_error(option: str, message: str) -> None:
    raise ValueError(f"POLICY: {message}")


def run_benchmark(
    spec: BenchmarkSpec, command: str = "drill-gym benchmark", runner: RunnerSpec | None = None
) -> int:
    """Run, score and write what ``spec`` asks for on the runner ``runner`` (default:
    serially, no results database; ``command``: the command line written in the scorecard);
    returns the exit code."""
    runner = runner or RunnerSpec()
    if importlib.util.find_spec("scipy") is None:  # before minutes of runs, not after
        raise ValueError(
            "needs the package 'scipy' for the bootstrap, which is not installed (the bench "
            "extra has it: pip install -e '.[bench]')"
        )
    start = time.perf_counter()
    suites: list[Suite] = []
    for text in spec.suite_names():
        try:
            suites.append(load_suite(text))
        except ValueError as err:
            raise ValueError(f"--suites: {err}") from None
    labels = [s.label for s in suites]
    if len(set(labels)) != len(labels):
        raise ValueError(f"--suites: the same suite twice: {', '.join(labels)}")
    entries: list[Entry] = []
    for text in spec.entry_names():
        try:
            entries.append(make_entry(text))
        except ValueError as err:
            raise ValueError(f"POLICY: {err}") from None
    try:
        entries = merge_entries(entries)
    except ValueError as err:
        raise ValueError(f"POLICY: {err}") from None
    names = {e.name for e in entries}
    for suite in suites:
        if suite.reference not in names:
            entries.insert(0, make_entry(suite.reference))
            names.add(suite.reference)
    taken = [e.name for e in entries]
    twice = sorted({n for n in taken if taken.count(n) > 1})
    if twice:
        raise ValueError(f"POLICY: two entries are named {', '.join(twice)}")
    refuse_on_ray(
        _policy_error, runner.backend().distributed, [e.name for e in entries if not e.agent]
    )
    study = BenchmarkStudy(
        tuple(suites), tuple(entries), task_runs=runner.task_size or BENCHMARK_TASK_RUNS
    )
    outcome = runner.run(study, spec.out / "benchmark.sqlite", progress=not spec.no_progress)
    rows = study.rows(outcome)
    scores: list[dict[str, Any]] = []
    for suite in suites:
        suite_rows = [r for r in rows if r["suite"] == suite.label]
        scores += score_suite(suite, suite_rows, spec.resamples, spec.seed)
    wall = time.perf_counter() - start
    out = spec.out
    out.mkdir(parents=True, exist_ok=True)
    text = scorecard_markdown(
        suites, scores, entries, spec.resamples, spec.seed, command, wall, rows
    )
    written = [
        write_text(output_file(out, "scorecard.md"), text + "\n"),
        write_csv(
            json_clean(scores), output_file(out, "scorecard.csv"), csv_columns(SCORE_KEYS, scores)
        ),
        write_csv(rows, output_file(out, "runs.csv"), csv_columns(RUN_KEYS, rows)),
    ]
    if not spec.no_plots:
        figure = profiles_figure(suites, rows)
        written.append(save_figure(figure, output_file(out, "profiles.png")))
    for suite in suites:
        print(f"{suite.label} ({suite.env_id}, reference {suite.reference}):")
        print(suite_table(suite, scores))
        print()
    print(
        f"{len(rows)} runs on {len(suites)} suites in {wall:.1f} s; wrote "
        f"{', '.join(p.name for p in written)} to {out}/"
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
