"""``drill-gym realism``: every controller judged on what it could really see and do.

The study starts from the **ideal** level (``drill_env.options.realism_keywords("ideal")``: the
whole state measured at every 1 ms plant step, an ideal actuator) and moves ONE factor at a
time toward and beyond the field's defaults (``realism_keywords("field")``,
docs/specification.md sections 18 and 19):

* ``observation``: the full state; surface signals at 1 kHz without noise; surface signals at
  100 Hz with the field's noise (base: ideal);
* ``telemetry_period``: none, 0.05, 1, 5, 10, 20 s, no delay (base: surface);
* ``telemetry_delay``: 0, 1, 5, 10, 20 s at a 5 s period, mud pulse (base: surface);
* ``telemetry_delay_fast``: 0, 0.05, 0.2, 0.5, 1, 2 s at a 0.05 s period (base: surface);
* ``dead_time``: 0, 10, 20, 50, 100, 200 ms (base: ideal);
* ``lag``: 0, 10, 20, 50, 100, 200 ms (base: ideal);
* ``rate_limit``: none, 1e6, 3e5, 1e5, 3e4, 1e4 N m/s (base: ideal).

"surface" is the field's measurement channel without telemetry (top-drive speed and surface
torque sampled at 100 Hz, 250 N m of torque noise, 0.1 rad/s on any telemetry value) with an
ideal actuator: the sliding-mode controllers then run their state observer
(docs/observer.md). The full **field** level is one more row. Each setting runs a fixed set of
six held-out scenarios per env (:data:`SCENARIOS`), every controller, through the one scoring
path (``experiments.field.run_on``: ``gym.make``, ``drill_env.evaluation.rollout``,
``episode_metrics``) with a zero residual. A controller **breaks** at a setting
(:func:`broken`) when its mean IAE over the scenarios exceeds :data:`IAE_RATIO` times its own
ideal mean IAE, or its mean stick-slip severity exceeds :data:`SEVERITY_LIMIT` where its ideal
one did not, or its drive spends a share of the run at a torque limit more than
:data:`LIMIT_RISE` above its ideal share, or a run diverges where none did at ideal; its
**break point** on a factor is the first value of the factor at which it breaks
(:func:`break_points`).

The runs go through the sweep runner (:mod:`experiments.sweep`): serially in this process by
default, on Ray with ``--workers``; settings that coincide (no telemetry and the surface
setting, a dead time of 0 and the ideal level, ...) are run once.

Beside the break points the study gives what they meet (:func:`loop_numbers`): the phase,
dead-time and lag margins of the speed loops (:func:`loop_margins` of ``stiff_pi`` and
``soft_speed`` on the impedance the string presents to the top drive,
:func:`chain_impedance`) and the memory of the sliding-mode controllers' observer on surface
signals. docs/reports/realism.md reports the study run with its defaults.

Outputs (``--out``, default ``results/realism``): ``realism.csv`` and ``realism.json`` (one
row per env, factor value and controller: the means over the scenarios and the mean severity
over the prone ones, :data:`PRONE`), ``runs.csv`` (one row
per run), ``breakpoints.csv`` and ``breakpoints.json``, ``summary.json`` and
``figures/realism_<factor>.png``; markdown tables on standard output.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NamedTuple

import numpy as np
import numpy.typing as npt

import baselines  # noqa: F401  (registers the built-in controllers, in their order)
from baselines.observer import ObserverGains, design_observer
from drill_env.control import controller_names, make_controller
from drill_env.distributed import Chain, chain_from_parameters
from drill_env.evaluation import ZeroAction, episode_metrics
from drill_env.metrics import STICK_SLIP_SEVERITY
from drill_env.options import REALISM_KEYWORDS, EnvConfig, FieldEnvConfig, realism_keywords
from drill_env.parameters import PLANT_DT_S, PRESETS
from drill_env.validation import shown as shown_value
from experiments.arguments import BASE_SEED_HIGH, ArgumentParser, names_type, output_folder
from experiments.evaluate import FIELD_HELD_OUT, HELD_OUT, HeldOutScenario
from experiments.field import ENV_IDS, FIELD_ENV, PAPER_ENV, run_on
from experiments.paths import output_file
from experiments.plots import realism_figure, save_figure
from experiments.results_db import Fields, Flag, Number, Schema
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import RunnerSpec, Task, TaskResult, item_tasks, run_sweep
from experiments.tables import Column, markdown_table, write_csv, write_json

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "CONTROL_DT_S",
    "EPISODE_S",
    "FACTORS",
    "FIELD",
    "IAE_RATIO",
    "IDEAL",
    "LIMIT_BAND",
    "LIMIT_RISE",
    "MEAN_KEYS",
    "PRONE",
    "SCENARIOS",
    "SEVERITY_LIMIT",
    "SPEED_LOOPS",
    "SURFACE",
    "Factor",
    "LoopMargins",
    "RealismSpec",
    "RealismStudy",
    "Setting",
    "Step",
    "break_points",
    "broken",
    "chain_impedance",
    "factor_settings",
    "loop_margins",
    "loop_numbers",
    "main",
    "mean_rows",
    "run_realism",
    "run_study",
    "study_settings",
]

IAE_RATIO: Final = 1.5
"""A controller breaks when its mean IAE exceeds this many times its own ideal mean IAE."""
SEVERITY_LIMIT: Final = STICK_SLIP_SEVERITY
"""A controller breaks when its mean stick-slip severity exceeds this where the ideal one did
not (the stick-slip threshold of the maps, docs/specification.md section 14)."""
LIMIT_RISE: Final = 0.1
"""A controller breaks when the share of the run its drive spends at a torque limit exceeds the
ideal share by more than this: a torque limit cycle (the drive banging between its limits),
or a drive that cannot hold the load."""
LIMIT_BAND: Final = 1e-3
"""The applied torque counts as at a limit within this fraction of the torque range of it."""
EPISODE_S: Final = 100.0
"""Length of every run, s (the held-out sets' own length)."""
CONTROL_DT_S: Final = 1.0
"""Decision period of the runs, s. The controllers act at every 1 ms plant step inside the
env and the residual is zero, so the decision period changes none of the plant-rate samples
the metrics read (the noise is drawn in the same blocks, ``tests/test_realism.py`` checks it);
a longer one only saves Python calls."""
TASK_RUNS: Final = 6
"""Default runs per task of the sweep runner (one controller on one setting's scenarios)."""

SCENARIOS: Final[dict[str, tuple[str, ...]]] = {
    # h01: 4 rad/s, 60 kN, nominal (prone: low speed); h03: 5 rad/s, 90 kN, condition2 (prone,
    # a wrong model); h07: 7 rad/s, 130 kN, condition1; h12: 10 rad/s, 185 kN, nominal (prone:
    # high WOB); h14: the paper's point, 12 rad/s, 97 kN, nominal; h16: 13 rad/s, 80 -> 130 kN
    # at 50 s, condition1.
    PAPER_ENV: ("h01", "h03", "h07", "h12", "h14", "h16"),
    # f01: 1.2 km, 60 kN, 50 rpm (prone); f03: 2.5 km, 100 kN, 100 rpm; f05: 3 km, 80 -> 140 kN,
    # 120 rpm, smooth; f07: 4.5 km, 140 kN, 70 rpm, mild (prone); f08: 2 km, 200 -> 90 kN,
    # 140 rpm, sticky (prone); f16: 2.5 km, 80 kN, 180 rpm (outside the drawn speeds). All on
    # field_2500m, where every controller can be built.
    FIELD_ENV: ("f01", "f03", "f05", "f07", "f08", "f16"),
}
"""The held-out scenarios of each env the study runs (``experiments.evaluate.HELD_OUT`` and
``FIELD_HELD_OUT``): three stick-slip-prone and three ordinary ones on each."""

PRONE: Final[dict[str, tuple[str, ...]]] = {
    PAPER_ENV: ("h01", "h03", "h12"),
    FIELD_ENV: ("f01", "f07", "f08"),
}
"""The stick-slip-prone scenarios among :data:`SCENARIOS` (low speed, a wrong model, high WOB;
short and slow, long and mild, sticky): the mean severity over those of a setting's scenarios
is its ``prone_severity``."""

MEAN_KEYS: Final = (
    "iae",
    "stick_slip_severity",
    "stuck_fraction",
    "torque_at_limit",
    "chattering_nm_per_s",
)
"""Metrics averaged over a setting's scenarios (docs/specification.md section 4, and the share
of the run with the drive at a torque limit, :func:`run_one`)."""

IDEAL: Final[dict[str, Any]] = realism_keywords("ideal")
"""The ideal level: the whole state at every plant step, an ideal actuator."""
FIELD: Final[dict[str, Any]] = realism_keywords("field")
"""The field level: the defaults of ``DrillStringField-v0``."""
_CHANNEL: Final = ("sensor_period_s", "torque_noise_std_nm", "telemetry_noise_std_rad_s")
SURFACE: Final[dict[str, Any]] = {
    **IDEAL,
    "observation": "surface",
    **{k: FIELD[k] for k in _CHANNEL},
}
"""The field's measurement channel without telemetry, with an ideal actuator: the base of the
telemetry factors (``realism_keywords("surface_only")`` with the ideal actuator)."""


class Step(NamedTuple):
    """One value of a factor.

    Attributes:
        value: The value as the tables show it (a number in the factor's unit, ``None`` for
            "none", or a name).
        label: Its label in tables and figures.
        changes: The keywords it changes from the factor's base.
    """

    value: float | str | None
    label: str
    changes: Mapping[str, Any]


@dataclass(frozen=True)
class Factor:
    """One factor of realism, moved on its own from its base.

    Attributes:
        name: Short name (``--factors``, the files).
        title: What it is (the figures' axis).
        unit: The unit of its values (``""``: none).
        base: The keywords of its base (:data:`IDEAL` or :data:`SURFACE` plus a period).
        base_name: A word for the base (``ideal``, ``surface``, ``surface, telemetry 5 s``).
        keywords: The realism keywords it moves.
        steps: Its values in order, the first being the base itself.
    """

    name: str
    title: str
    unit: str
    base: Mapping[str, Any]
    base_name: str
    keywords: tuple[str, ...]
    steps: tuple[Step, ...]


def _seconds_factor(
    name: str, title: str, keyword: str, values_s: Sequence[float | None], base: Mapping[str, Any],
    base_name: str, unit: str = "s",
) -> Factor:  # fmt: skip
    scale = 1e3 if unit == "ms" else 1.0
    steps = tuple(
        Step(
            None if v is None else float(v) * scale,
            "none" if v is None else f"{float(v) * scale:g}",
            {keyword: v},
        )
        for v in values_s
    )
    return Factor(name, title, unit, dict(base), base_name, (keyword,), steps)


FACTORS: Final[tuple[Factor, ...]] = (
    Factor(
        "observation",
        "what the controller measures",
        "",
        IDEAL,
        "ideal",
        ("observation", *_CHANNEL),
        (
            Step("state", "full state", {}),
            Step("surface_exact", "surface, 1 kHz, exact", {"observation": "surface"}),
            Step(
                "surface",
                "surface, 100 Hz, noisy",
                {"observation": "surface", **{k: FIELD[k] for k in _CHANNEL}},
            ),
        ),
    ),
    _seconds_factor(
        "telemetry_period",
        "telemetry period, no delay",
        "telemetry_period_s",
        (None, 0.05, 1.0, 5.0, 10.0, 20.0),
        SURFACE,
        "surface",
    ),
    _seconds_factor(
        "telemetry_delay",
        "telemetry delay, a value every 5 s",
        "telemetry_delay_s",
        (0.0, 1.0, 5.0, 10.0, 20.0),
        {**SURFACE, "telemetry_period_s": 5.0},
        "surface, telemetry every 5 s",
    ),
    _seconds_factor(
        "telemetry_delay_fast",
        "telemetry delay, a value every 0.05 s",
        "telemetry_delay_s",
        (0.0, 0.05, 0.2, 0.5, 1.0, 2.0),
        {**SURFACE, "telemetry_period_s": 0.05},
        "surface, telemetry every 0.05 s",
    ),
    _seconds_factor(
        "dead_time",
        "actuator dead time",
        "actuator_dead_time_s",
        (0.0, 0.01, 0.02, 0.05, 0.1, 0.2),
        IDEAL,
        "ideal",
        unit="ms",
    ),
    _seconds_factor(
        "lag",
        "actuator lag (first-order time constant)",
        "actuator_lag_s",
        (0.0, 0.01, 0.02, 0.05, 0.1, 0.2),
        IDEAL,
        "ideal",
        unit="ms",
    ),
    Factor(
        "rate_limit",
        "torque rate limit",
        "N m/s",
        IDEAL,
        "ideal",
        ("torque_rate_limit_nm_per_s",),
        tuple(
            Step(
                r,
                "none" if r is None else f"{r:.0e}".replace("e+0", "e"),
                {"torque_rate_limit_nm_per_s": r},
            )
            for r in (None, 1e6, 3e5, 1e5, 3e4, 1e4)
        ),  # fmt: skip
    ),
)
"""The factors, in the order of the tables."""

FACTOR_NAMES: Final = tuple(f.name for f in FACTORS)


@dataclass(frozen=True)
class Setting:
    """One setting of the study: a factor at one of its values (or the ideal or field level).

    Attributes:
        factor: The factor's name (``ideal`` and ``field`` for the two levels).
        index: The value's position in the factor (0 for the levels).
        value: The value (:attr:`Step.value`).
        label: Its label.
        keywords: Every realism keyword (``drill_env.options.REALISM_KEYWORDS``) of the runs.
    """

    factor: str
    index: int
    value: float | str | None
    label: str
    keywords: Mapping[str, Any]

    @property
    def key(self) -> str:
        """The realism keywords that differ from the ideal level, as text (``ideal`` for
        none): settings with the same keywords share their runs."""
        changed = [f"{k}={shown_value(self.keywords[k])}" for k in REALISM_KEYWORDS if
                   self.keywords[k] != IDEAL[k]]  # fmt: skip
        return ",".join(changed) or "ideal"


def factor_settings(factor: Factor) -> list[Setting]:
    """The settings of ``factor``, one per value, each its base with the value's changes."""
    return [
        Setting(factor.name, k, step.value, step.label, {**factor.base, **step.changes})
        for k, step in enumerate(factor.steps)
    ]


def study_settings(factors: Sequence[str] = FACTOR_NAMES) -> list[Setting]:
    """The ideal level, every setting of each of ``factors`` (in :data:`FACTORS` order) and
    the field level.

    Raises:
        ValueError: for an unknown factor name.
    """
    for name in factors:
        if name not in FACTOR_NAMES:
            raise ValueError(
                f"factor {shown_value(name)} is not known: allowed {', '.join(FACTOR_NAMES)}"
            )
    settings = [Setting("ideal", 0, "ideal", "ideal", dict(IDEAL))]
    for factor in FACTORS:
        if factor.name in factors:
            settings += factor_settings(factor)
    settings.append(Setting("field", 0, "field", "field", dict(FIELD)))
    return settings


# ------------------------------------------------------------------------------ the runs
def _scenario(env_id: str, scenario_id: str) -> HeldOutScenario:
    for held_out in FIELD_HELD_OUT if env_id == FIELD_ENV else HELD_OUT:
        if held_out.id == scenario_id:
            return held_out
    raise ValueError(f"scenario {shown_value(scenario_id)} is not a held-out scenario of {env_id}")


def run_one(
    env_id: str,
    scenario: str,
    controller: str,
    keywords: Mapping[str, Any],
    episode_s: float = EPISODE_S,
    seed_offset: int = 0,
) -> dict[str, Any]:
    """One run: ``controller`` as base controller with a zero residual on the held-out
    ``scenario`` of ``env_id`` with the realism ``keywords``; its metrics
    (``drill_env.evaluation.episode_metrics``) and ``torque_at_limit``, the share of the run's
    plant steps with the applied torque at one of the drive's limits (within
    :data:`LIMIT_BAND` of the torque range of it).

    Args:
        env_id: ``DrillString-v0`` or ``DrillStringField-v0``.
        scenario: A held-out scenario id of that env (``h14``, ``f03``).
        controller: A registered controller name.
        keywords: The realism keywords of the run.
        episode_s: Length of the run, s (a multiple of :data:`CONTROL_DT_S`).
        seed_offset: Added to the scenario's own reset seed.
    """
    held_out = _scenario(env_id, scenario)
    kwargs = {
        **held_out.env_kwargs(),
        **keywords,
        "episode_s": float(episode_s),
        "control_dt_s": CONTROL_DT_S,
        "base_controller": controller,
    }
    trace = run_on(env_id, kwargs, ZeroAction(), held_out.seed + seed_offset)
    metrics = episode_metrics(trace)
    config = FieldEnvConfig if env_id == FIELD_ENV else EnvConfig
    defaults = {f.name: f.default for f in fields(config)}
    low, high = (float(kwargs.get(k, defaults[k])) for k in ("min_torque_nm", "max_torque_nm"))
    band = LIMIT_BAND * (high - low)
    u = trace.torque_nm
    metrics["torque_at_limit"] = float(np.mean((u <= low + band) | (u >= high - band)))
    return metrics


def run_task(runs: Sequence[Mapping[str, Any]]) -> TaskResult:
    """A task of the sweep runner: each of ``runs`` (the item key and :func:`run_one`'s
    arguments) run in turn."""
    records = {
        str(r["item"]): run_one(
            r["env_id"],
            r["scenario"],
            r["controller"],
            r["keywords"],
            r["episode_s"],
            r["seed_offset"],
        )  # fmt: skip
        for r in runs
    }
    return TaskResult(records)


@dataclass(frozen=True)
class RealismStudy:
    """The study on the sweep runner: one item per distinct (env, realism keywords,
    controller, scenario).

    Attributes:
        envs: The env ids.
        controllers: Registered controller names.
        settings: The settings (those with equal keywords share their runs).
        scenarios: The scenario ids of each env.
        episode_s: Length of every run, s.
        seed_offset: Added to every scenario's own reset seed.
        task_runs: Runs per task.
    """

    envs: tuple[str, ...]
    controllers: tuple[str, ...]
    settings: tuple[Setting, ...]
    scenarios: Mapping[str, tuple[str, ...]]
    episode_s: float = EPISODE_S
    seed_offset: int = 0
    task_runs: int = TASK_RUNS

    @property
    def name(self) -> str:
        """The sweep's name."""
        return "realism"

    def keywords(self) -> dict[str, Mapping[str, Any]]:
        """The distinct realism keywords, by setting key, in order of first use."""
        return {s.key: s.keywords for s in self.settings}

    def runs(self) -> Iterator[dict[str, Any]]:
        """Every distinct run, in the order of the tables."""
        for env_id in self.envs:
            for key, keywords in self.keywords().items():
                for controller in self.controllers:
                    for scenario in self.scenarios[env_id]:
                        yield {
                            "item": f"{env_id}|{key}|{controller}|{scenario}",
                            "env_id": env_id,
                            "scenario": scenario,
                            "controller": controller,
                            "keywords": dict(keywords),
                            "episode_s": self.episode_s,
                            "seed_offset": self.seed_offset,
                        }

    def spec(self) -> dict[str, Any]:
        """Everything the results depend on."""
        return {
            "envs": list(self.envs),
            "controllers": list(self.controllers),
            "keywords": {k: dict(v) for k, v in self.keywords().items()},
            "scenarios": {e: list(self.scenarios[e]) for e in self.envs},
            "episode_s": self.episode_s,
            "seed_offset": self.seed_offset,
            "control_dt_s": CONTROL_DT_S,
        }

    def items(self) -> list[str]:
        """Every item key."""
        return [r["item"] for r in self.runs()]

    def record_schema(self, item: str) -> Schema:
        """A run's metrics: numbers (``None``: not defined) and ``diverged``."""
        return Fields(
            {"diverged": Flag(), "torque_at_limit": Number(low=0.0, high=1.0)}, rest=Number()
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """The missing runs in tasks of :attr:`task_runs`."""
        wanted = set(missing)
        runs = [r for r in self.runs() if r["item"] in wanted]
        return item_tasks("realism", run_task, "runs", runs, self.task_runs)


def _mean(values: Sequence[Any]) -> float:
    clean = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(clean)) if clean else math.nan


def mean_rows(
    study: RealismStudy, records: Mapping[str, Mapping[str, Any]]
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The study's tables from its run records.

    Returns:
        One row per (env, setting, controller) with the means of :data:`MEAN_KEYS` over the
        scenarios, ``prone_severity`` (the mean severity over those of :data:`PRONE`; NaN
        for none) and the number of diverged runs; and one row per run.
    """
    means: list[dict[str, Any]] = []
    runs: list[dict[str, Any]] = []
    for env_id in study.envs:
        for setting in study.settings:
            head = {
                "env": env_id,
                "factor": setting.factor,
                "index": setting.index,
                "value": setting.value,
                "label": setting.label,
            }
            for controller in study.controllers:
                mine = [
                    records[f"{env_id}|{setting.key}|{controller}|{s}"]
                    for s in study.scenarios[env_id]
                ]
                for scenario, r in zip(study.scenarios[env_id], mine, strict=True):
                    runs.append(
                        {**head, "controller": controller, "scenario": scenario,
                         **{k: r[k] for k in (*MEAN_KEYS, "diverged")}}
                    )  # fmt: skip
                row = {**head, "controller": controller}
                row.update({k: _mean([r[k] for r in mine]) for k in MEAN_KEYS})
                row["prone_severity"] = _mean(
                    [
                        r["stick_slip_severity"]
                        for s, r in zip(study.scenarios[env_id], mine, strict=True)
                        if s in PRONE[env_id]
                    ]
                )
                row["diverged"] = sum(bool(r["diverged"]) for r in mine)
                row["runs"] = len(mine)
                means.append(row)
    return means, runs


# ------------------------------------------------------------------------- break points
def broken(row: Mapping[str, Any], ideal: Mapping[str, Any]) -> str:
    """Why a controller breaks at the setting of ``row`` against its ``ideal`` row (both with
    the means of :data:`MEAN_KEYS` and ``diverged``); ``""`` when it does not.

    It breaks when a run diverges where none did at ideal (``diverged``), when its mean IAE
    exceeds :data:`IAE_RATIO` times the ideal one (``IAE x2.1``), when its mean severity
    exceeds :data:`SEVERITY_LIMIT` where the ideal one did not (``severity 0.73``), or when
    its drive spends a share of the run at a torque limit more than :data:`LIMIT_RISE` above
    the ideal share (``at limit 0.69``).
    """
    if row["diverged"] and not ideal["diverged"]:
        return "diverged"
    iae, iae0 = float(row["iae"]), float(ideal["iae"])
    if math.isfinite(iae) and math.isfinite(iae0) and iae > IAE_RATIO * iae0:
        return f"IAE x{iae / iae0:.1f}"
    sev, sev0 = float(row["stick_slip_severity"]), float(ideal["stick_slip_severity"])
    if math.isfinite(sev) and sev > SEVERITY_LIMIT and not sev0 > SEVERITY_LIMIT:
        return f"severity {sev:.2f}"
    at, at0 = float(row.get("torque_at_limit", 0.0)), float(ideal.get("torque_at_limit", 0.0))
    if math.isfinite(at) and math.isfinite(at0) and at > at0 + LIMIT_RISE:
        return f"at limit {at:.2f}"
    return ""


def break_points(means: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The break point of every controller on every factor of the ``means`` rows
    (:func:`mean_rows`), and whether it breaks at the field level.

    Returns:
        One row per (env, controller, factor): ``value`` and ``label`` of the first value of
        the factor at which it breaks (:func:`broken`; ``None`` and ``"-"`` when it holds at
        every value), the ``reason``, its means there and at ideal (``iae``, ``iae_ideal``,
        ``severity``, ``severity_ideal``). The ``field`` factor has the field level as its one
        value.

    Raises:
        ValueError: when a controller has no ideal row.
    """
    ideal = {(r["env"], r["controller"]): r for r in means if r["factor"] == "ideal"}
    rows: list[dict[str, Any]] = []
    groups = dict.fromkeys((r["env"], r["controller"], r["factor"]) for r in means)
    for env_id, controller, factor in groups:
        if factor == "ideal":
            continue
        reference = ideal.get((env_id, controller))
        if reference is None:
            raise ValueError(f"no ideal row of {controller} on {env_id}: cannot find break points")
        steps = sorted(
            (r for r in means if (r["env"], r["controller"], r["factor"]) ==
             (env_id, controller, factor)),
            key=lambda r: int(r["index"]),
        )  # fmt: skip
        hit = next(((r, why) for r in steps if (why := broken(r, reference))), None)
        where = hit[0] if hit else None
        rows.append(
            {
                "env": env_id,
                "controller": controller,
                "factor": factor,
                "value": None if where is None else where["value"],
                "label": "-" if where is None else where["label"],
                "index": None if where is None else where["index"],
                "reason": "" if hit is None else hit[1],
                "iae": None if where is None else where["iae"],
                "iae_ideal": reference["iae"],
                "severity": None if where is None else where["stick_slip_severity"],
                "severity_ideal": reference["stick_slip_severity"],
            }
        )
    return rows


# ------------------------------------------------------------- what the breaks meet
class LoopMargins(NamedTuple):
    """The margins of a speed loop ``u = (kp + ki / s) (w_ref - w)`` on the top drive.

    Attributes:
        crossover_rad_s: The highest frequency where the open loop's gain is 1, rad/s.
        phase_margin_deg: Its phase margin there, degrees.
        dead_time_margin_s: The smallest dead time that makes the loop unstable, s (the
            smallest phase margin over the gain crossings divided by their frequency).
        lag_margin_s: The smallest first-order lag that takes every phase margin to zero,
            s (``inf``: none up to 10 s).
    """

    crossover_rad_s: float
    phase_margin_deg: float
    dead_time_margin_s: float
    lag_margin_s: float


def chain_impedance(chain: Chain, omega_rad_s: npt.ArrayLike) -> npt.NDArray[np.complex128]:
    """The impedance the string presents to its top drive's torque, N m s/rad: torque over
    top-drive speed at each frequency, the top drive's own inertia and bearing damping
    included, the bit sliding (the friction, the one nonlinearity, left out).

    Args:
        chain: The linear chain (``drill_env.distributed.chain_from_parameters``).
        omega_rad_s: Frequencies, rad/s (> 0), any shape.

    Returns:
        The complex impedance at each frequency, the shape of ``omega_rad_s``.
    """
    w = np.asarray(omega_rad_s, dtype=np.float64)
    jw = 1j * w
    inertia, ground = chain.node_inertia_kg_m2, chain.node_damping_nm_s_rad
    z = jw * inertia[-1] + ground[-1]
    for e in range(len(chain.element_stiffness_nm_rad) - 1, -1, -1):
        spring = chain.element_stiffness_nm_rad[e] / jw + chain.element_damping_nm_s_rad[e]
        z = jw * inertia[e] + ground[e] + 1.0 / (1.0 / spring + 1.0 / z)
    result: npt.NDArray[np.complex128] = z
    return result


def loop_margins(
    kp: float, ki: float, impedance: Callable[[npt.NDArray[np.float64]], Any]
) -> LoopMargins:
    """The margins of the PI speed loop ``kp + ki / s`` on a top drive whose load has the
    ``impedance`` (torque over speed, a function of the frequency in rad/s; for example
    :func:`chain_impedance`), on a grid of 20,000 frequencies from 0.01 to 10,000 rad/s.

    Args:
        kp: Proportional gain, N m s/rad (> 0).
        ki: Integral gain, N m/rad (>= 0).
        impedance: The load's impedance at an array of frequencies, N m s/rad.

    Returns:
        The :class:`LoopMargins`.
    """
    w = np.logspace(-2, 4, 20_000)
    base = (kp + ki / (1j * w)) / np.asarray(impedance(w))

    def margins(
        loop: npt.NDArray[np.complex128],
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
        gain = np.abs(loop)
        cross = np.flatnonzero((gain[:-1] >= 1.0) & (gain[1:] < 1.0))
        return cross, np.mod(np.pi + np.angle(loop[cross]), 2.0 * np.pi)

    cross, pm = margins(base)
    if cross.size == 0:
        return LoopMargins(math.nan, math.nan, math.inf, math.inf)
    delay = float(np.min(pm / w[cross]))

    def stable(lag_s: float) -> bool:
        c, m = margins(base / (1.0 + 1j * w * lag_s))
        return bool(c.size and np.all((m > 1e-9) & (m < np.pi)))

    lag = math.inf
    if not stable(10.0):
        low, high = 0.0, 10.0
        for _ in range(60):
            mid = 0.5 * (low + high)
            low, high = (mid, high) if stable(mid) else (low, mid)
        lag = high
    return LoopMargins(float(w[cross[-1]]), float(np.degrees(pm[-1])), delay, lag)


SPEED_LOOPS: Final = ("stiff_pi", "soft_speed")
"""The speed loops whose margins :func:`loop_numbers` gives (``z_torque``'s inner loop has the
gains of ``stiff_pi``)."""


def loop_numbers(
    envs: Sequence[str] = ENV_IDS, loops: Sequence[str] = SPEED_LOOPS
) -> list[dict[str, Any]]:
    """What the break points are measured against, per env and speed loop: the loop's margins
    (:func:`loop_margins` of its ``kp``, ``ki``) on the env's nominal string (``zribi2024``;
    ``field_2500m`` at 2,500 m) with the bit sliding, and the memory of the sliding-mode
    controllers' observer on the surface setting (:data:`SURFACE`): the slowest time constant
    of its one-step transition ``F``, s (the same in every row of an env)."""

    rows = []
    for env_id in envs:
        config = FieldEnvConfig(**SURFACE) if env_id == FIELD_ENV else EnvConfig(**SURFACE)
        model = config.string() if isinstance(config, FieldEnvConfig) else PRESETS["zribi2024"]
        impedance = functools.partial(chain_impedance, chain_from_parameters(model))
        design = design_observer(model, config.measurement_channel(), ObserverGains())
        slowest = float(np.max(np.abs(np.linalg.eigvals(design.F))))
        for loop in loops:
            tuning = make_controller(loop).tuning(model)  # type: ignore[attr-defined]
            rows.append(
                {
                    "env": env_id,
                    "loop": loop,
                    "kp": tuning.kp,
                    "ki": tuning.ki,
                    **loop_margins(tuning.kp, tuning.ki, impedance)._asdict(),
                    "observer_memory_s": -PLANT_DT_S / math.log(slowest),
                }
            )
    return rows


# ------------------------------------------------------------------------------ outputs
def means_table(means: Sequence[Mapping[str, Any]], env_id: str) -> str:
    """Mean IAE, severity, severity on the prone scenarios and stuck fraction of every
    controller at every setting of ``env_id`` (markdown)."""
    mine = [r for r in means if r["env"] == env_id]
    controllers = list(dict.fromkeys(r["controller"] for r in mine))
    by = {(r["factor"], r["index"], r["controller"]): r for r in mine}
    lines: list[dict[str, Any]] = []
    for factor, index, label in dict.fromkeys((r["factor"], r["index"], r["label"]) for r in mine):
        line: dict[str, Any] = {"setting": f"{factor}: {label}" if factor != label else factor}
        for c in controllers:
            r = by[(factor, index, c)]
            cell = (
                f"{r['iae']:.0f} / {r['stick_slip_severity']:.2f} / "
                f"{r['prone_severity']:.2f} / {r['stuck_fraction']:.2f}"
            )
            line[c] = cell + (f" ({r['diverged']} div.)" if r["diverged"] else "")
        lines.append(line)
    columns = [Column("setting", "setting", align="left")] + [Column(c, c) for c in controllers]
    return markdown_table(lines, columns)


def breaks_table(breaks: Sequence[Mapping[str, Any]], env_id: str) -> str:
    """The break point of each controller on each factor of ``env_id`` (markdown)."""
    mine = [r for r in breaks if r["env"] == env_id]
    factors = list(dict.fromkeys(r["factor"] for r in mine))
    lines: list[dict[str, Any]] = []
    for c in dict.fromkeys(r["controller"] for r in mine):
        line: dict[str, Any] = {"controller": c}
        for r in mine:
            if r["controller"] == c:
                text = "breaks" if r["factor"] == "field" else str(r["label"])
                line[r["factor"]] = f"{text} ({r['reason']})" if r["reason"] else "-"
        lines.append(line)
    units = {f.name: f.unit for f in FACTORS}
    columns = [Column("controller", "controller", align="left")] + [
        Column(f, f"{f} ({units[f]})" if units.get(f) else f, align="left") for f in factors
    ]
    return markdown_table(lines, columns)


def loops_table(loops: Sequence[Mapping[str, Any]]) -> str:
    """:func:`loop_numbers` as a markdown table."""
    columns = [
        Column("env", "env", align="left"),
        Column("loop", "speed loop", align="left"),
        Column("kp", "kp (N m s/rad)", "{:.0f}"),
        Column("ki", "ki (N m/rad)", "{:.0f}"),
        Column("crossover_rad_s", "crossover (rad/s)", "{:.2f}"),
        Column("phase_margin_deg", "phase margin (deg)", "{:.1f}"),
        Column("dead_time_margin_s", "dead-time margin (ms)", "{:.1f}"),
        Column("lag_margin_s", "lag margin (ms)", "{:.0f}"),
        Column("observer_memory_s", "observer memory (s)", "{:.2f}"),
    ]
    shown = [
        {
            **r,
            "dead_time_margin_s": 1e3 * r["dead_time_margin_s"],
            "lag_margin_s": 1e3 * r["lag_margin_s"],
        }
        for r in loops
    ]
    return markdown_table(shown, columns)


def realism_figures(
    means: Sequence[Mapping[str, Any]], breaks: Sequence[Mapping[str, Any]] = ()
) -> Iterator[tuple[str, Figure]]:
    """One figure per factor of the ``means`` rows: IAE, severity and stuck fraction against
    the factor's value, one line per controller, one row of panels per env, each break point
    (:func:`break_points`) ringed (file name, figure)."""

    factors = {f.name: f for f in FACTORS}
    runs = sorted({int(r["runs"]) for r in means})
    per_env = f"{runs[0]}" if len(runs) == 1 else f"{runs[0]}-{runs[-1]}"
    for name in dict.fromkeys(r["factor"] for r in means):
        if name not in factors:
            continue
        factor = factors[name]
        panels: dict[str, dict[str, list[Mapping[str, Any]]]] = {}
        for env_id in dict.fromkeys(r["env"] for r in means):
            rows = sorted(
                (r for r in means if r["env"] == env_id and r["factor"] == name),
                key=lambda r: int(r["index"]),
            )
            by_controller: dict[str, list[Mapping[str, Any]]] = {}
            for r in rows:
                by_controller.setdefault(str(r["controller"]), []).append(r)
            panels[env_id] = by_controller
        rings = {
            (str(b["env"]), str(b["controller"])): int(b["index"])
            for b in breaks
            if b["factor"] == name and b["index"] is not None
        }
        yield (
            f"realism_{name}.png",
            realism_figure(
                panels,
                [s.label for s in factor.steps],
                f"{factor.title} ({factor.unit})" if factor.unit else factor.title,
                title=f"{factor.title}, moved alone from the {factor.base_name} setting: means "
                f"over {per_env} held-out scenario{'s' if per_env != '1' else ''} per env",
                breaks=rings,
                severity_limit=SEVERITY_LIMIT,
            ),
        )


def write_outputs(
    means: Sequence[Mapping[str, Any]],
    runs: Sequence[Mapping[str, Any]],
    breaks: Sequence[Mapping[str, Any]],
    summary: Mapping[str, Any],
    out: Path,
) -> list[Path]:
    """The tables of the study in ``out``."""
    mean_keys = ["env", "factor", "index", "value", "label", "controller", *MEAN_KEYS,
                 "prone_severity", "diverged", "runs"]  # fmt: skip
    run_keys = ["env", "factor", "index", "value", "label", "controller", "scenario",
                *MEAN_KEYS, "diverged"]  # fmt: skip
    break_keys = list(breaks[0]) if breaks else ["env", "controller", "factor"]
    return [
        write_csv(means, out / "realism.csv", mean_keys),
        write_json(list(means), out / "realism.json"),
        write_csv(runs, out / "runs.csv", run_keys),
        write_csv(breaks, out / "breakpoints.csv", break_keys),
        write_json(list(breaks), out / "breakpoints.json"),
        write_json(dict(summary), out / "summary.json", indent=2),
    ]


def run_realism(
    study: RealismStudy,
    progress: bool = False,
    **sweep: Any,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], list[dict[str, Any]], float]:
    """Run ``study`` (on the sweep runner, serially unless ``sweep`` says otherwise: the
    keywords of :func:`experiments.sweep.run_sweep`) and compute its tables.

    Returns:
        The mean rows, the run rows, the break points and the wall time of the runs, s.
    """
    outcome = run_sweep(study, progress=progress, **sweep)
    means, runs = mean_rows(study, outcome.records)
    return means, runs, break_points(means), outcome.wall_time_s


# ---------------------------------------------------------------------------- command line
def _every_scenario() -> list[str]:
    return [s.id for s in (*HELD_OUT, *FIELD_HELD_OUT)]


@dataclass(frozen=True)
class RealismSpec:
    """Settings of ``drill-gym realism`` (each field is the option of the same name)."""

    envs: tuple[str, ...] = field(
        default=ENV_IDS,
        metadata=option(parse=names_type(lambda: ENV_IDS, "env"), metavar="ENV", flag="--env"),
    )
    """envs of the study"""
    controllers: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=names_type(controller_names, "controller"), metavar="NAME", default_text="all"
        ),
    )
    """controllers, by registered name"""
    factors: tuple[str, ...] = field(
        default=FACTOR_NAMES,
        metadata=option(parse=names_type(lambda: FACTOR_NAMES, "factor"), metavar="FACTOR"),
    )
    """factors to move (the ideal and field levels always run)"""
    scenarios: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=names_type(_every_scenario, "scenario"),
            metavar="ID",
            default_text="six of each env",
        ),
    )
    """held-out scenarios (h01-h20: DrillString-v0, f01-f16: DrillStringField-v0)"""
    duration_s: float = field(
        default=EPISODE_S,
        metadata=option(
            low=0.0, high=1e4, open_low=True, unit="s", metavar="S", aliases=("--episode",)
        ),
    )
    """length of every run, s (a whole number of seconds)"""
    seed: int = field(default=0, metadata=option(low=0, high=BASE_SEED_HIGH))
    """added to every scenario's own reset seed (it drives the noise)"""
    out: Path = field(
        default=Path("results/realism"), metadata=option(parse=output_folder, metavar="DIR")
    )
    """output folder"""
    no_plots: bool = False
    """write no figures"""
    no_progress: bool = False
    """no progress bar"""

    def __post_init__(self) -> None:
        if abs(self.duration_s - round(self.duration_s)) > 1e-9:
            raise ValueError(f"--duration-s: {self.duration_s:g} is not a whole number of seconds")
        self.scenarios_of()

    def scenarios_of(self) -> dict[str, tuple[str, ...]]:
        """The scenario ids each env runs."""
        chosen = {e: SCENARIOS[e] for e in dict.fromkeys(self.envs)}
        if self.scenarios:
            for env_id in chosen:
                own = {s.id for s in (FIELD_HELD_OUT if env_id == FIELD_ENV else HELD_OUT)}
                chosen[env_id] = tuple(dict.fromkeys(i for i in self.scenarios if i in own))
                if not chosen[env_id]:
                    raise ValueError(
                        f"--scenarios: none of {', '.join(self.scenarios)} is a held-out "
                        f"scenario of {env_id}"
                    )
        return chosen

    def study(self, task_runs: int | None = None) -> RealismStudy:
        """The study on the sweep runner (``task_runs``: runs per task, default
        :data:`TASK_RUNS`)."""
        return RealismStudy(
            envs=tuple(dict.fromkeys(self.envs)),
            controllers=tuple(dict.fromkeys(self.controllers or controller_names())),
            settings=tuple(study_settings(self.factors)),
            scenarios=self.scenarios_of(),
            episode_s=float(round(self.duration_s)),
            seed_offset=int(self.seed),
            task_runs=int(task_runs or TASK_RUNS),
        )


DESCRIPTION: Final = """\
Who survives realism: from the ideal level (whole state at every 1 ms step, ideal top drive)
one factor at a time moves toward and beyond the field's defaults, and each controller's break
point is found on both envs. Writes realism.csv/json, runs.csv, breakpoints.csv/json,
summary.json and figures/ into --out; prints the tables. The factors, their levels and the
break criterion: docs/reports/realism.md.

example: drill-gym realism --env DrillString-v0 --factors dead_time rate_limit
"""


def _parser() -> ArgumentParser:
    return spec_parser("drill-gym realism", DESCRIPTION, RealismSpec, RunnerSpec)


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym realism``; returns the exit code (see ``--help``)."""
    args = _parser().parse_args(list(argv) if argv is not None else None)
    return run_study(spec_from_args(RealismSpec, args), spec_from_args(RunnerSpec, args))


def run_study(spec: RealismSpec, runner: RunnerSpec | None = None) -> int:
    """Run the study of ``spec`` on ``runner`` (default: serially), write its outputs and
    print its tables; returns the exit code."""
    runner = runner or RunnerSpec()
    study = spec.study(runner.task_size)
    envs, scenarios, controllers = study.envs, study.scenarios, study.controllers
    out = spec.out
    t0, cpu0 = time.perf_counter(), time.process_time()
    means, runs, breaks, seconds = run_realism(
        study,
        progress=not spec.no_progress,
        backend=runner.backend(),
        results_path=runner.results_path(out / "realism.sqlite"),
        resume=runner.resume,
        overwrite=runner.overwrite,
    )
    summary = {
        "seconds": round(seconds, 1),
        "cpu_seconds": round(time.process_time() - cpu0, 1),
        "runs": len(study.items()),
        "settings": len(study.settings),
        "distinct_settings": len(study.keywords()),
        "scenarios": {e: list(s) for e, s in scenarios.items()},
        "prone": {e: [s for s in scenarios[e] if s in PRONE[e]] for e in scenarios},
        "episode_s": study.episode_s,
        "criterion": {
            "iae_ratio": IAE_RATIO,
            "severity_limit": SEVERITY_LIMIT,
            "limit_rise": LIMIT_RISE,
        },
    }
    loops = loop_numbers(envs)
    summary["loops"] = loops
    written = write_outputs(means, runs, breaks, summary, out)
    if not spec.no_plots:
        written += [
            save_figure(fig, output_file(out, "figures", name))
            for name, fig in realism_figures(means, breaks)
        ]
    for env_id in envs:
        prone = ", ".join(s for s in scenarios[env_id] if s in PRONE[env_id]) or "none"
        print(f"## {env_id}: mean IAE (rad) / stick-slip severity / severity on the prone "
              f"scenarios ({prone}) / stuck fraction over {', '.join(scenarios[env_id])}\n")  # fmt: skip
        print(means_table(means, env_id))
        print(f"\n## {env_id}: break points (first value where the controller breaks)\n")
        print(breaks_table(breaks, env_id))
        print()
    print("## What the break points meet: the speed loops' margins (z_torque's inner loop has the")
    print("## gains of stiff_pi) on the nominal string with the bit sliding, and the memory of the")
    print("## sliding-mode controllers' observer on surface signals\n")
    print(loops_table(loops))
    print()
    print(
        f"{summary['runs']} runs ({summary['distinct_settings']} distinct settings x "
        f"{len(controllers)} controllers x the scenarios, per env) in {seconds:.1f} s "
        f"({time.perf_counter() - t0:.1f} s with output, {summary['cpu_seconds']} s of CPU in "
        f"this process); wrote {len(written)} files to {out}/"
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
