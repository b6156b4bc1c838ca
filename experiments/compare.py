"""``drill-gym compare``: the controllers on the paper's scenarios, scored on the paper's metrics.

By default every registered controller (the paper's four first: ``csmc``, ``msmc``, ``asmc``,
``proposed``) runs on the docs/specification.md section 2 scenario (WOB 97,347 N, V_ref 12 rad/s, 150 s from
rest) under each Table 3 uncertainty condition, without and with 0.1 rad/s measurement noise:
32 runs for the four SMCs. The agent shipped for the env (:func:`shipped_agent`; numpy
inference, no extra needed) is added as one more row per scenario.

Every run goes through the one scoring path of the project::

    env = gym.make("DrillString-v0", randomize=False, base_controller=name, ...)
    trace = rollout(env, ZeroAction(), seed)      # the base controller acts at every 1 ms step
    row = episode_metrics(trace)                  # docs/specification.md section 4, from plant-rate samples

The decision period of the (idle) agent is long (``control_dt_s`` up to 1 s) only to keep the
Python overhead low; the controller still runs inside the compiled plant loop at 1 kHz, and the
metrics do not depend on the decision period.

Outputs (``--out``, default ``results/``): ``compare.csv`` and ``compare.json`` (one row per
run) and ``compare.md`` (the same as a markdown table), PNG figures under ``figures/``; on
standard output a ranked summary (:func:`summary_table`: one line per controller, the means of
the paper's metrics over its runs, lowest mean IAE first).

Example::

    drill-gym compare                                   # the default comparison
    drill-gym compare --gains rescaled                  # Table 1 gains x J_dt (see RESCALED_GAINS)
    drill-gym compare --reading controller --out results/controller-reading
    drill-gym compare --controllers csmc proposed --conditions nominal --noise 0 --duration 20
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NamedTuple

import numpy as np

import baselines  # noqa: F401  (registers the built-in controllers, in their order)
from agents import DEFAULT_MODEL_DIR, load_policy
from agents.config import TrainConfig
from agents.policy import is_model_folder
from baselines.registry import family_members
from drill_env.control import controller_names, make_controller
from drill_env.evaluation import Trace, ZeroAction, episode_metrics, termination_note
from drill_env.files import write_text
from drill_env.metrics import METRIC_KEYS
from drill_env.parameters import PLANT_DT_S, resolve_parameters
from drill_env.scenarios import UNCERTAINTY_CONDITIONS, Scenario, SpeedProfile, WobProfile
from drill_env.validation import printable, shown
from experiments.arguments import (
    SEED_HIGH,
    ArgumentParser,
    check_output_option,
    names_type,
    one_line,
    output_folder,
)
from experiments.controllers import (
    CONTROLLERS_OPTION_HELP,
    controller_type,
    refuse_on_ray,
    user_controller_errors,
)
from experiments.field import (
    COMPARE_CONDITIONS,
    COMPARE_DEPTHS_M,
    COMPARE_POINTS,
    CONTROLLER_MODELS,
    ENV_IDS,
    FIELD_CONDITIONS,
    OBSERVATIONS,
    PAPER_ENV,
    FieldCase,
    compare_cases,
    figure_cases,
    file_label,
    is_field,
    observations_of,
    run_label,
    run_on,
)
from experiments.paths import inside_output, output_file, output_path
from experiments.plots import (
    Envelope,
    adaptive_gains_figure,
    downsample,
    envelope,
    metric_bars_figure,
    panels_figure,
    save_figure,
    speed_torque_figure,
    time_window,
    value_label,
)
from experiments.results_db import Exactly, Fields, Flag, Name, Number, Schema, Text, exactly
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import (
    COMPARE_TASK_RUNS,
    Backend,
    RunnerSpec,
    SweepOutcome,
    Task,
    TaskResult,
    agent_fingerprint,
    check_controllers,
    check_observations,
    check_task_size,
    chunks,
    run_sweep,
)
from experiments.tables import Column, write_csv, write_json
from experiments.tables import markdown_table as _markdown

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "CONDITIONS",
    "FIELD_ROW_KEYS",
    "GAIN_PRESETS",
    "PAPER_CONTROLLERS",
    "RESCALED_GAINS",
    "ROW_KEYS",
    "SCENARIO",
    "Case",
    "CompareJob",
    "CompareSpec",
    "CompareStudy",
    "RunTraces",
    "compare_item",
    "compare_runs_task",
    "comparison_cases",
    "compare_run",
    "comparison_figures",
    "default_controllers",
    "main",
    "markdown_table",
    "run_comparison",
    "write_figures",
]

PAPER_CONTROLLERS: Final = family_members("sliding_mode")
"""The paper's four controllers, listed first in every table."""

CONDITIONS: Final = tuple(UNCERTAINTY_CONDITIONS)
"""The Table 3 uncertainty conditions: nominal, condition1..3."""

DEFAULT_NOISE_RAD_S: Final = (0.0, 0.1)
"""Measurement noise levels of the default comparison, rad/s (docs/specification.md section 2)."""

DEFAULT_DURATION_S: Final = 150.0
"""Run length of the paper's protocol, s."""

SCENARIO: Final = Scenario(wob=WobProfile(97_347.0), reference=SpeedProfile.constant(12.0))
"""The paper's scenario (docs/specification.md section 2): constant WOB and reference, from
rest; the comparison varies its uncertainty condition, reading and noise."""

_J_DT: Final = resolve_parameters("zribi2024").J_dt

RESCALED_GAINS: Final[dict[str, dict[str, float]]] = {
    "csmc": {"k1": 3.0 * _J_DT},
    "msmc": {"k2": 3.0 * _J_DT, "k3": 0.001 * _J_DT},
    "asmc": {"mu11": 0.1 * _J_DT, "mu22": 0.01 * _J_DT, "k0": 0.2 * _J_DT},
    "proposed": {
        "mu1": 3.0 * _J_DT,
        "mu2": 0.001 * _J_DT,
        "alpha": 0.1 * _J_DT,
        "k0": 0.2 * _J_DT,
    },
}
"""The ``rescaled`` gain preset: the Table 1 gains read per unit top-drive inertia.

With the exact equivalent control, ``s' = u_disc / J_dt``: the Table 1 gains used as torques
(N m) move ``s`` by a few mrad/s^2 against about 13 kN m of load. Read instead as acting on
``s'`` directly (rad/s^2), every torque-valued gain (``k1``, ``k2``, ``k3``, the adaptive gains'
initial values ``k0``, thresholds ``alpha`` and rates ``mu``) is multiplied by
``J_dt = 930 kg m^2``; ``lam``, ``delta``, ``a`` and ``b`` are unchanged. Use as
``make_controller("proposed", **RESCALED_GAINS["proposed"])``. This is not the paper's table;
the reproduction report gives both.
"""

GAIN_PRESETS: Final[dict[str, dict[str, dict[str, float]]]] = {
    "paper": {name: {} for name in PAPER_CONTROLLERS},
    "rescaled": RESCALED_GAINS,
}
"""Gain presets by name: controller name -> gain overrides. Controllers a preset does not list
run with their own defaults (reported as ``gains = "default"``)."""

STATIC_WINDOW_S: Final = 20.0
"""``static_error_rad_s`` is the mean tracking error over the last this many seconds, s."""

ROW_KEYS: Final = (
    "controller",
    "condition",
    "noise_std_rad_s",
    *METRIC_KEYS,
    "static_error_rad_s",
    "diverged",
    "gains",
    "uncertainty_reading",
    "seed",
    "duration_s",
    "note",
)
"""Columns of ``compare.csv`` and keys of each row of ``compare.json``: the docs/specification.md section 4
metrics, plus ``static_error_rad_s`` (mean of ``V_ref - w_bit`` over the last
:data:`STATIC_WINDOW_S`, the paper's "static error"), the run's settings and ``note``, why a
run ended early when the env named a cause (a controller's NaN or infinite torque; empty
otherwise, :func:`drill_env.evaluation.termination_note`)."""

FIELD_ROW_KEYS: Final = (
    "controller",
    "observation",
    "scenario",
    "parameters",
    "measured_depth_m",
    "reference_speed_rad_s",
    "wob_n",
    "wob_step_time_s",
    "wob_final_n",
    "condition",
    "mu_a",
    "mu_0",
    "xi",
    "mud_damping_factor",
    "noise_std_rad_s",
    *METRIC_KEYS,
    "static_error_rad_s",
    "diverged",
    "gains",
    "controller_model",
    "seed",
    "duration_s",
    "note",
)
"""The columns of a comparison on ``DrillStringField-v0``: the controller and the observation
mode it ran with, the field scenario (:class:`experiments.field.FieldCase`: string, depth,
operating point, friction and damping), the metrics and the run's settings
(``controller_model``: ``nominal`` or ``exact``, what the controllers knew of the string)."""

PLOT_EVERY: Final = 10
"""Plant-rate samples kept for the whole-run figures: one bin of this many (100 Hz; torques
keep each bin's extreme, see :func:`drill_env.plots.downsample`)."""

TAIL_S: Final = 0.2
"""Length of the full-rate end of each run kept for the zoomed torque figure, s."""


BAND_S: Final = 0.1
"""Bin of the torque envelope of the whole-run figures, s (mean line, min-max band)."""


class RunTraces(NamedTuple):
    """What the figures need of one run."""

    overview: Trace
    """The whole run, downsampled (:data:`PLOT_EVERY`)."""
    tail: Trace
    """The last :data:`TAIL_S` seconds at full rate."""
    torque: Envelope
    """The top-drive torque of the whole run per :data:`BAND_S` bin: minimum, mean, maximum."""


_DECISION_PERIODS_S: Final = (1.0, 0.5, 0.25, 0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.002, 0.001)


def default_controllers() -> list[str]:
    """Every registered controller, the paper's four first, the others in registry order."""
    names = controller_names()
    return [n for n in PAPER_CONTROLLERS if n in names] + [
        n for n in names if n not in PAPER_CONTROLLERS
    ]


def decision_period(duration_s: float) -> float:
    """The longest idle-agent decision period (at most 1 s) that divides ``duration_s``.

    Raises:
        ValueError: if ``duration_s`` is not positive or not a multiple of the 1 ms plant step.
    """
    if not (math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"duration = {shown(duration_s)} is out of range: allowed > 0 s")
    for dt in _DECISION_PERIODS_S:
        n = duration_s / dt
        if n >= 1 and abs(n - round(n)) < 1e-6:
            return dt
    raise ValueError(
        f"duration = {shown(duration_s)} is out of range: allowed a multiple of {PLANT_DT_S} s"
    )


def scenario_kwargs(
    condition: str, noise_std_rad_s: float, duration_s: float, reading: str
) -> dict[str, Any]:
    """The ``DrillString-v0`` keywords of one comparison scenario (no controller keywords)."""
    scenario = dataclasses.replace(
        SCENARIO,
        uncertainty=UNCERTAINTY_CONDITIONS[condition],
        reading="controller" if reading == "controller" else "plant",
        noise_std_rad_s=float(noise_std_rad_s),
    )
    return {**scenario.keywords(), "episode_s": float(duration_s)}


QUIET_SENSORS: Final = {"torque_noise_std_nm": 0.0, "telemetry_noise_std_rad_s": 0.0}
"""The field env's keywords of a run without noise: with the speeds noiseless
(``noise_std_rad_s = 0``) the surface torque and the telemetry are noiseless too."""


class Case(NamedTuple):
    """One scenario of a comparison, as data: its name and how to make its env keywords and
    its row columns. The paper's cases are its uncertainty conditions; the field string's are
    :class:`experiments.field.FieldCase` scenarios."""

    name: str
    """The case's name (the row's ``condition`` on the paper's string, ``scenario`` on the
    field string)."""
    head: dict[str, Any]
    """Row columns after the controller's (and before the noise)."""
    tail: dict[str, Any]
    """Row columns after ``gains`` (the reading or the controllers' model)."""
    field: FieldCase | None = None
    """The field scenario (``None``: the paper's scenario under condition ``name``)."""

    def keywords(self, noise_std_rad_s: float, duration_s: float, reading: str) -> dict[str, Any]:
        """The env keywords of a run of this case (no controller keywords)."""
        if self.field is None:
            return scenario_kwargs(self.name, noise_std_rad_s, duration_s, reading)
        model = str(self.tail["controller_model"])
        scenario = self.field.scenario(noise_std_rad_s, model)
        return {
            **scenario.keywords(),
            **(QUIET_SENSORS if noise_std_rad_s == 0.0 else {}),
            "episode_s": float(duration_s),
        }


def comparison_cases(
    env_id: str,
    conditions: Sequence[str],
    *,
    reading: str = "plant",
    depths_m: Sequence[float] = COMPARE_DEPTHS_M,
    controller_model: str = "nominal",
) -> list[Case]:
    """The cases of a comparison on ``env_id``: the paper's scenario under each Table 3
    condition, or on the field string :func:`experiments.field.compare_cases` of ``depths_m``
    and the field ``conditions``.

    Raises:
        ValueError: for an unknown env, condition or controller model.
    """
    if not is_field(env_id):
        for c in conditions:
            if c not in UNCERTAINTY_CONDITIONS:
                raise ValueError(
                    f"condition = {shown(c)} is not an uncertainty condition of {env_id}: allowed "
                    f"{', '.join(CONDITIONS)}"
                )
        return [Case(c, {"condition": c}, {"uncertainty_reading": reading}) for c in conditions]
    if controller_model not in CONTROLLER_MODELS:
        raise ValueError(
            f"controller_model = {shown(controller_model)} is not valid: allowed "
            f"{', '.join(CONTROLLER_MODELS)}"
        )
    return [
        Case(c.id, {"scenario": c.id, **c.columns()}, {"controller_model": controller_model}, c)
        for c in compare_cases(depths_m, conditions)
    ]


def static_error(trace: Trace, window_s: float = STATIC_WINDOW_S) -> float:
    """Mean tracking error ``V_ref - w_bit`` over the last ``window_s`` of ``trace``, rad/s."""
    n = max(1, round(window_s / trace.plant_dt_s))
    return float(np.mean(trace.reference_rad_s[-n:] - trace.bit_speed_rad_s[-n:]))


def _row(
    controller: str,
    observation: str | None,
    case: Case,
    noise: float,
    metrics: Mapping[str, Any],
    gains: str,
    seed: int,
    duration_s: float,
) -> dict[str, Any]:
    row: dict[str, Any] = {"controller": controller}
    if observation is not None:
        row["observation"] = observation
    row.update(case.head)
    row["noise_std_rad_s"] = float(noise)
    for key in (*METRIC_KEYS, "static_error_rad_s"):
        row[key] = metrics[key]
    row["diverged"] = bool(metrics["diverged"])
    row["gains"] = gains
    row.update(case.tail)
    row["seed"] = seed
    row["duration_s"] = duration_s
    row["note"] = str(metrics.get("note", ""))
    return row


def compare_run(
    job: CompareJob,
    *,
    duration_s: float,
    seed: int,
    reading: str,
    gains: str,
    agent: Any,
    env_id: str,
) -> tuple[dict[str, Any], Trace]:
    """One run of the comparison: ``job``'s controller (or ``agent``) on its case at its noise
    level, on ``env_id``; its row (:data:`ROW_KEYS`, :data:`FIELD_ROW_KEYS`) and its trace."""
    scenario = job.case.keywords(job.noise, duration_s, reading)
    if job.is_agent:
        own = {k: v for k, v in dict(agent.env_kwargs).items() if k != "max_episode_steps"}
        trace = run_on(env_id, {**own, **scenario}, agent, seed)
        gain_label = "agent"
    else:
        overrides = GAIN_PRESETS[gains].get(job.label)
        controller = make_controller(job.label, **(overrides or {}))
        kwargs = {
            **scenario,
            "base_controller": controller,
            "control_dt_s": decision_period(duration_s),
        }
        if job.observation is not None:
            kwargs["observation"] = job.observation
        where = f" on {job.case.name}, noise {job.noise:g} rad/s"
        with user_controller_errors(job.label, where):
            trace = run_on(env_id, kwargs, ZeroAction(), seed)
        gain_label = gains if overrides is not None else "default"
    metrics = {
        **episode_metrics(trace),
        "static_error_rad_s": static_error(trace),
        "note": termination_note(trace),
    }
    row = _row(
        job.label, job.observation, job.case, job.noise, metrics, gain_label, seed, duration_s
    )
    return row, trace


def run_comparison(
    controllers: Sequence[str],
    conditions: Sequence[str],
    noises: Sequence[float],
    *,
    duration_s: float = DEFAULT_DURATION_S,
    seed: int = 0,
    reading: str = "plant",
    gains: str = "paper",
    agent: Any = None,
    keep_traces: bool = True,
    progress: bool = True,
    env_id: str = PAPER_ENV,
    cases: Sequence[Case] | None = None,
    observations: Sequence[str] = OBSERVATIONS,
) -> tuple[list[dict[str, Any]], dict[tuple[str, str, float], RunTraces]]:
    """Every controller (and ``agent``) on every case and noise level: the
    :class:`CompareStudy` run serially in this process (no results database).

    Args:
        controllers: Registered controller names.
        conditions: Condition names (:func:`comparison_cases`); not used when ``cases`` is
            given.
        noises: Measurement noise levels on the speeds, rad/s.
        duration_s: Run length, s.
        seed: Reset seed of every run (it drives the noise).
        reading: Uncertainty reading, ``plant`` or ``controller`` (``DrillString-v0``).
        gains: Gain preset name (:data:`GAIN_PRESETS`).
        agent: ``None``, or a policy with ``predict``, ``env_kwargs`` and ``name`` (and
            ``env_id``, ``DrillString-v0`` when it has none); it runs only on its own env.
        keep_traces: Keep light copies of the traces (:class:`RunTraces`) for figures.
        progress: Show a progress bar on standard error.
        env_id: The env of every run (:data:`experiments.field.ENV_IDS`).
        cases: The cases (:func:`comparison_cases`); default those of ``conditions``.
        observations: On the field string, the observation modes to run the controllers with
            (each with those it can use, :func:`experiments.field.observations_of`).

    Returns:
        The rows (see :data:`ROW_KEYS`, :data:`FIELD_ROW_KEYS`) and the traces by
        ``(run label, case name, noise)``.
    """
    study = CompareStudy(
        tuple(controllers),
        tuple(c.name for c in cases) if cases is not None else tuple(conditions),
        tuple(float(n) for n in noises),
        duration_s=duration_s,
        seed=seed,
        reading=reading,
        gains=gains,
        agent=agent,
        keep_traces=keep_traces,
        env_id=env_id,
        observations=tuple(observations),
        case_list=None if cases is None else tuple(cases),
    )
    if not study.jobs():
        return [], {}
    return study.results(run_sweep(study, Backend(workers=1), progress=progress))


# ----------------------------------------------------------------------------- output
TABLE_COLUMNS: Final = (
    Column("controller", "controller", align="left"),
    Column("condition", "condition", align="left"),
    Column("noise_std_rad_s", "noise (rad/s)", "{:g}"),
    Column("ise", "ISE", "{:.1f}"),
    Column("iae", "IAE", "{:.1f}"),
    Column("rmse", "RMSE (rad/s)", "{:.3f}"),
    Column("static_error_rad_s", "static error (rad/s)", "{:.2f}"),
    Column("rmsd_nm", "RMSD (N m)", "{:,.0f}"),
    Column("overshoot_pct", "overshoot %", "{:.1f}"),
    Column("settling_time_s", "settling (s)", "{:.1f}", missing="never"),
    Column("chattering_nm_per_s", "chattering (N m/s)", "{:,.0f}"),
    Column("stick_slip_severity", "severity", "{:.3f}"),
    Column("stuck_fraction", "stuck fraction", "{:.3f}"),
)
"""The columns of the comparison's markdown table."""

FIELD_TABLE_COLUMNS: Final = (
    Column("controller", "controller", align="left"),
    Column("observation", "observation", align="left"),
    Column("scenario", "scenario", align="left"),
    *TABLE_COLUMNS[2:],
)
"""The columns of the markdown table of a comparison on the field string."""


def _diverged_cell(row: Mapping[str, Any], column: Column) -> str | None:
    if column.key == "settling_time_s" and row.get("diverged"):
        return "diverged"
    return None


def markdown_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """The rows as a markdown table (settling ``never``: the run ends outside the 5 % band;
    static error: mean of ``V_ref - w_bit`` over the last 20 s); the field string's rows
    (with a ``scenario``) also show the observation mode and the scenario."""
    field = bool(rows) and "scenario" in rows[0]
    return _markdown(rows, FIELD_TABLE_COLUMNS if field else TABLE_COLUMNS, _diverged_cell)


SUMMARY_COLUMNS: Final = (
    Column("rank", "rank", "{:d}"),
    Column("label", "controller", align="left"),
    Column("runs", "runs", "{:d}"),
    Column("ise", "ISE", "{:.1f}"),
    Column("iae", "IAE", "{:.1f}"),
    Column("rmse", "RMSE (rad/s)", "{:.3f}"),
    Column("rmsd_nm", "RMSD (N m)", "{:,.0f}"),
    Column("overshoot_pct", "overshoot %", "{:.1f}"),
    Column("settling_time_s", "settling (s)", "{:.1f}", missing="never"),
    Column("unsettled", "unsettled", "{:d}"),
    Column("chattering_nm_per_s", "chattering (N m/s)", "{:,.0f}"),
    Column("stick_slip_severity", "severity", "{:.3f}"),
    Column("diverged", "diverged", "{:d}"),
)
"""The columns of the ranked summary: the means of the paper's metrics per controller."""

SUMMARY_METRICS: Final = (
    "ise",
    "iae",
    "rmse",
    "rmsd_nm",
    "overshoot_pct",
    "chattering_nm_per_s",
    "stick_slip_severity",
)
"""The metrics the summary averages over every run of a controller."""


def _finite_mean(values: Sequence[Any]) -> float | None:
    clean = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(clean)) if clean else None


def ranked_summary(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """One entry per controller (on the field string per controller and observation mode,
    :func:`experiments.field.run_label`): the mean of each of :data:`SUMMARY_METRICS` over its
    runs, the mean settling time of the runs that settle (``None``: none does), the number of
    runs that never settle and of those that diverge; ranked by mean IAE, lowest first (a
    controller with a diverged run after every one without)."""
    entries = []
    for label in dict.fromkeys(run_label(r) for r in rows):
        mine = [r for r in rows if run_label(r) == label]
        entry: dict[str, Any] = {"label": label, "runs": len(mine)}
        for key in SUMMARY_METRICS:
            entry[key] = _finite_mean([r[key] for r in mine])
        entry["settling_time_s"] = _finite_mean([r["settling_time_s"] for r in mine])
        entry["unsettled"] = sum(r["settling_time_s"] is None for r in mine)
        entry["diverged"] = sum(bool(r["diverged"]) for r in mine)
        entries.append(entry)
    entries.sort(key=lambda e: (e["diverged"] > 0, math.inf if e["iae"] is None else e["iae"]))
    for rank, entry in enumerate(entries, start=1):
        entry["rank"] = rank
    return entries


def _write_text(text: str, path: Path) -> Path:
    write_text(path, text)
    return path


def summary_table(rows: Sequence[Mapping[str, Any]]) -> str:
    """:func:`ranked_summary` as a markdown table: one line per controller."""
    return _markdown(ranked_summary(rows), SUMMARY_COLUMNS)


INDUSTRY_CONTROLLERS: Final = family_members("speed_loop")
"""The industry top-drive speed loops, default and tuned (:mod:`baselines.tuned`), drawn
together in the noise figure."""


def _families(rows: Sequence[Mapping[str, Any]]) -> dict[str, list[str]]:
    """The controllers of ``rows`` by family, for the noise figure's columns."""
    families: dict[str, list[str]] = {}
    for label in dict.fromkeys(r["controller"] for r in rows):
        agent = any(r["controller"] == label and r["gains"] == "agent" for r in rows)
        name = label.split(" (")[0]  # a field run's label: controller (observation)
        if agent:
            family = "learned agent"
        elif name in PAPER_CONTROLLERS:
            family = "the paper's sliding-mode controllers"
        elif name in INDUSTRY_CONTROLLERS:
            family = "industry speed loops"
        else:
            family = "other controllers"
        families.setdefault(family, []).append(label)
    order = (
        "the paper's sliding-mode controllers",
        "industry speed loops",
        "other controllers",
        "learned agent",
    )
    return {f: families[f] for f in order if f in families}


def comparison_figures(
    rows: Sequence[Mapping[str, Any]],
    runs: Mapping[tuple[str, str, float], RunTraces],
    cases: Sequence[str] | None = None,
    focus: str | None = None,
) -> Iterator[tuple[str, Figure]]:
    """The comparison's figures as (file name, figure), in the spirit of the paper's Figs 3-12.

    * ``speed_torque_<controller>.png``: bit speed and torque under each uncertainty condition
      (on the field string: in each of ``cases``), noise off (Figs 6-9);
    * ``noise_speed_torque.png``: every controller with noise on, one column per family
      (Figs 3-4a); ``noise_torque_zoom.png``: the torque of each controller over the last
      0.2 s at full rate, without and with noise (Fig 4b);
    * ``bars_rmse.png``, ``bars_ise_iae.png`` (noise off, by condition), ``bars_rmsd.png`` and
      ``bars_chattering.png`` (first condition, with and without noise) (Figs 5, 10-12);
    * ``adaptive_gains.png``: the adaptive gain k of the adaptive laws against time (noise off).

    Args:
        rows: The comparison's rows.
        runs: Its traces by (run label, case name, noise).
        cases: The cases of the per-controller figures and the bars (default: all of them).
        focus: The case of the figures of one case (noise, zoom, RMSD, chattering; default the
            first of ``cases``).

    On the field string a run's label is its controller and observation mode
    (:func:`experiments.field.run_label`) and its figure names use
    :func:`experiments.field.file_label`.
    """

    field = bool(rows) and "scenario" in rows[0]
    case_key, case_title = (
        ("scenario", "scenario") if field else ("condition", "uncertainty condition")
    )
    if field:  # figures see one label per run and the case under "case"
        rows = [{**r, "controller": run_label(r), "case": r["scenario"]} for r in rows]
    labels = list(dict.fromkeys(r["controller"] for r in rows))
    conditions = list(cases) if cases else list(dict.fromkeys(r[case_key] for r in rows))
    noises = sorted({float(r["noise_std_rad_s"]) for r in rows})
    quiet, loud = noises[0], noises[-1]
    quiet_text = value_label("noise_std_rad_s", quiet)
    loud_text = value_label("noise_std_rad_s", loud)
    first = focus or conditions[0]
    band = f"torque: mean per {BAND_S:g} s, light band from minimum to maximum"
    for label in labels:
        by_condition = {c: runs[(label, c, quiet)] for c in conditions if (label, c, quiet) in runs}
        if by_condition:
            yield (
                f"speed_torque_{file_label(label) if field else label}.png",
                speed_torque_figure(
                    {case_title: {c: r.overview for c, r in by_condition.items()}},
                    f"{label}, {quiet_text}; {band}",
                    envelopes={c: r.torque for c, r in by_condition.items()},
                ),
            )
    noisy = {lab: runs[(lab, first, loud)] for lab in labels if (lab, first, loud) in runs}
    if noisy:
        columns = {
            family: {lab: noisy[lab].overview for lab in members if lab in noisy}
            for family, members in _families(rows).items()
        }
        yield (
            "noise_speed_torque.png",
            speed_torque_figure(
                {k: v for k, v in columns.items() if v},
                f"{first}, {loud_text}; {band}",
                envelopes={lab: run.torque for lab, run in noisy.items()},
            ),
        )
        panels = {
            lab: {
                value_label("noise_std_rad_s", n): runs[(lab, first, n)].tail
                for n in (quiet, loud)
                if (lab, first, n) in runs
            }
            for lab in labels
        }
        yield (
            "noise_torque_zoom.png",
            panels_figure(
                {k: v for k, v in panels.items() if v},
                f"top-drive torque at 1 kHz, {first}, last {TAIL_S:g} s",
                ncols=2,
            ),
        )
    hue = "case" if field else "condition"
    quiet_rows = [
        r for r in rows if float(r["noise_std_rad_s"]) == quiet and r[case_key] in conditions
    ]
    first_rows = [r for r in rows if r[case_key] == first]
    yield (
        "bars_rmse.png",
        metric_bars_figure(
            quiet_rows, "rmse", hue=hue, title=f"RMSE of the bit speed, {quiet_text}"
        ),
    )
    yield (
        "bars_ise_iae.png",
        metric_bars_figure(quiet_rows, ("ise", "iae"), hue=hue, title=f"ISE and IAE, {quiet_text}"),
    )
    yield (
        "bars_rmsd.png",
        metric_bars_figure(
            first_rows,
            "rmsd_nm",
            hue="noise_std_rad_s",
            title=f"RMSD of the top-drive torque with and without noise ({first}); "
            "change with noise beside each controller",
            zoom=True,
        ),
    )
    yield (
        "bars_chattering.png",
        metric_bars_figure(
            first_rows,
            "chattering_nm_per_s",
            hue="noise_std_rad_s",
            title=f"chattering (total variation of the torque per second), {first}",
            log=True,
        ),
    )
    agents = {r["controller"] for r in rows if r["gains"] == "agent"}
    gains = {
        (f"{lab} (its base controller)" if lab in agents else lab, c): runs[
            (lab, c, quiet)
        ].overview
        for lab in labels
        for c in conditions
        if (lab, c, quiet) in runs and np.any(runs[(lab, c, quiet)].overview.adaptive_gain != 0.0)
    }
    adaptive = ", ".join(dict.fromkeys(lab.split(" ")[0] for lab, _ in gains)) or "none"
    yield (
        "adaptive_gains.png",
        adaptive_gains_figure(
            gains,
            f"adaptive switching gain k of the adaptive SMCs ({adaptive}), {quiet_text}",
        ),
    )


def write_figures(
    rows: Sequence[Mapping[str, Any]],
    runs: Mapping[tuple[str, str, float], RunTraces],
    folder: Path,
    cases: Sequence[str] | None = None,
    focus: str | None = None,
    *,
    out: Path | None = None,
) -> list[Path]:
    """Write :func:`comparison_figures` as PNG files into ``folder``; returns their paths.

    Every file is checked to lie inside ``folder`` and, when given, inside the output folder
    ``out`` (a ``folder`` inside ``out`` that is a link to elsewhere is refused with a
    ``ValueError`` before anything is written; :func:`experiments.paths.output_path`)."""
    if out is not None:
        inside_output(out, folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, fig in comparison_figures(rows, runs, cases, focus):
        path = output_file(folder, name)
        written.append(save_figure(fig, path if out is None else inside_output(out, path)))
    return written


# ---------------------------------------------------------------------------- the agent
def shipped_agent(env_id: str = PAPER_ENV) -> Any:
    """The agent shipped for ``env_id``: the model ``agents/models/<name>`` that the env's
    training recipe writes (``agents.config.TrainConfig.for_env(env_id).exp_name``:
    ``residual_ppo`` on ``DrillString-v0``, ``field_agent`` on ``DrillStringField-v0``), or
    ``None`` when it is not shipped."""

    folder = DEFAULT_MODEL_DIR / TrainConfig.for_env(env_id).exp_name
    return load_policy(folder) if is_model_folder(folder) else None


def load_agent(loader: Callable[[], Any] | None = None, env_id: str = PAPER_ENV) -> Any:
    """The shipped agent of ``env_id`` (:func:`shipped_agent`, or ``loader()`` when given): a
    policy with ``predict``, ``env_kwargs`` and ``name``, or ``None``.

    ``None`` when the loader needs a missing package or no model is shipped; a model that fails
    to load is reported on standard error and skipped.
    """
    try:
        policy = shipped_agent(env_id) if loader is None else loader()
    except ImportError as exc:
        print(f"compare: no agent row ({one_line(str(exc))})", file=sys.stderr)
        return None
    except Exception as exc:  # a broken model must not stop the baseline comparison
        print(
            f"compare: the shipped agent failed to load, skipped: {one_line(repr(exc))}",
            file=sys.stderr,
        )
        return None
    return policy


# -------------------------------------------------------------------------------- CLI
DESCRIPTION: Final = """\
Run each controller and the env's shipped agent on the paper's scenario under each
uncertainty condition and noise level, print a ranked summary of the paper's metrics and write
compare.md/.csv/.json and figures/ into --out (docs/specification.md section 2.2).

example: drill-gym compare --controllers csmc proposed --conditions nominal --duration-s 20
"""

FIELD_NOISE_RAD_S: Final = (0.0, 0.05)
"""Noise levels of the measured speeds in the field comparison, rad/s (0.05: the env's)."""

ALL_CONDITIONS: Final = (*CONDITIONS, *(c for c in FIELD_CONDITIONS if c not in CONDITIONS))
"""The conditions of either env (``--conditions``)."""


@dataclass(frozen=True)
class CompareSpec:
    """The settings of ``drill-gym compare`` (its options are these fields)."""

    env_id: str = field(
        default=PAPER_ENV, metadata=option(choices=ENV_IDS, flag="--env", aliases=("--env-id",))
    )
    """the env of every run"""
    controllers: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=controller_type,
            help=CONTROLLERS_OPTION_HELP,
            metavar="NAME",
            default_text="all registered",
        ),
    )
    # help: CONTROLLERS_OPTION_HELP (user classes are the same in every study)
    conditions: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=names_type(lambda: ALL_CONDITIONS, "condition"),
            metavar="NAME",
            default_text="nominal condition1-3; field: " + " ".join(COMPARE_CONDITIONS),
        ),
    )
    """uncertainty conditions; on the field string friction and damping conditions"""
    noise: tuple[float, ...] = field(
        default=(),
        metadata=option(
            low=0.0,
            high=10.0,
            unit="rad/s",
            metavar="STD",
            default_text=" ".join(f"{n:g}" for n in DEFAULT_NOISE_RAD_S)
            + "; field: "
            + " ".join(f"{n:g}" for n in FIELD_NOISE_RAD_S),
        ),
    )
    """standard deviations of the noise on the measured speeds, rad/s"""
    duration_s: float = field(
        default=DEFAULT_DURATION_S,
        metadata=option(
            low=0.0, high=1e5, open_low=True, unit="s", metavar="S", aliases=("--duration",)
        ),
    )
    """length of every run, s (a multiple of the 1 ms plant step)"""
    seed: int = field(default=0, metadata=option(low=0, high=SEED_HIGH))
    """reset seed of every run (drives the noise)"""
    reading: str = field(default="plant", metadata=option(choices=("plant", "controller")))
    """uncertainty in the plant or in the controllers' model"""
    gains: str = field(default="paper", metadata=option(choices=tuple(GAIN_PRESETS)))
    """the paper's gains, or rescaled x J_dt"""
    depths: tuple[float, ...] = field(
        default=COMPARE_DEPTHS_M,
        metadata=option(low=300.0, high=10_000.0, unit="m", metavar="M"),
    )
    """measured depths of the field string, m"""
    observations: tuple[str, ...] = field(
        default=OBSERVATIONS, metadata=option(choices=OBSERVATIONS)
    )
    """observation modes of the speed loops on the field string"""
    controller_model: str = field(default="nominal", metadata=option(choices=CONTROLLER_MODELS))
    """what the controllers know of the field string"""
    out: Path = field(default=Path("results"), metadata=option(parse=output_folder, metavar="DIR"))
    """output folder"""
    no_plots: bool = False
    """write no figures"""
    no_agent: bool = False
    """leave out the env's shipped agent"""
    no_progress: bool = False
    """no progress bar"""

    def __post_init__(self) -> None:
        check_output_option(self.out)
        try:
            decision_period(self.duration_s)
        except ValueError:
            raise ValueError(
                f"argument --duration-s: {self.duration_s:g} is not a multiple of the "
                f"{PLANT_DT_S:g} s plant step"
            ) from None
        allowed = FIELD_CONDITIONS if is_field(self.env_id) else CONDITIONS
        wrong = [c for c in self.conditions if c not in allowed]
        if wrong:
            raise ValueError(
                f"argument --conditions: {', '.join(wrong)} is not a condition of {self.env_id}: "
                f"allowed {', '.join(allowed)}"
            )

    @property
    def controller_names(self) -> tuple[str, ...]:
        """The controllers, each once (default: :func:`default_controllers`)."""
        return tuple(dict.fromkeys(self.controllers or default_controllers()))

    @property
    def condition_names(self) -> tuple[str, ...]:
        """The conditions, each once (default: the env's)."""
        field_env = is_field(self.env_id)
        default = COMPARE_CONDITIONS if field_env else CONDITIONS
        return tuple(dict.fromkeys(self.conditions or default))

    @property
    def noise_levels(self) -> tuple[float, ...]:
        """The noise levels, each once, rad/s (default: the env's)."""
        default = FIELD_NOISE_RAD_S if is_field(self.env_id) else DEFAULT_NOISE_RAD_S
        return tuple(dict.fromkeys(float(n) for n in self.noise or default))


def _parser() -> ArgumentParser:
    parser = spec_parser("drill-gym compare", DESCRIPTION, CompareSpec, RunnerSpec)
    parser.usage = "drill-gym compare [OPTIONS]"
    return parser


def main(argv: Sequence[str] | None = None, agent_loader: Callable[[], Any] | None = None) -> int:
    """Run the comparison; print the table; write CSV, JSON and figures. Returns 0.

    ``agent_loader`` returns the learned agent to add as a row (``None``: the shipped one).
    """
    parser = _parser()
    args = parser.parse_args(argv)
    runner = spec_from_args(RunnerSpec, args)
    try:
        spec = spec_from_args(CompareSpec, args)
    except ValueError as err:
        parser.error(str(err))
    refuse_on_ray(parser.fail, runner.backend().distributed, spec.controller_names)
    figure_folder = None if spec.no_plots else output_path(spec.out, "figures")  # before the runs
    agent = load_agent(agent_loader, spec.env_id) if not spec.no_agent else None
    try:
        study = CompareStudy.from_spec(
            spec,
            agent,
            keep_traces=not spec.no_plots,
            task_runs=runner.task_size or COMPARE_TASK_RUNS,
        )
    except ValueError as err:
        parser.error(str(err))
    start = time.perf_counter()
    outcome = runner.run(study, spec.out / "compare.sqlite", progress=not spec.no_progress)
    rows, traces = study.results(outcome)
    figures = not spec.no_plots and outcome.loaded == 0
    if not spec.no_plots and not figures:
        print("no figures: runs read from the results file keep no traces (rerun without "
              "--resume for the figures)")  # fmt: skip
    simulated = time.perf_counter() - start
    out = spec.out
    out.mkdir(parents=True, exist_ok=True)
    field_env = is_field(spec.env_id)
    if field_env:
        points = ", ".join(f"{w:g} kN at {r:g} rpm" for w, r in COMPARE_POINTS)
        print(
            f"Scenarios: field_2500m at {', '.join(f'{d:,.0f}' for d in spec.depths)} m; {points}; "
            f"conditions {', '.join(spec.condition_names)}; {spec.duration_s:g} s from rest; the "
            f"controllers know the {spec.controller_model} string; gains '{spec.gains}', seed "
            f"{spec.seed}.\n"
        )
    else:
        print(
            f"Scenario: WOB {SCENARIO.wob.initial_n:,.0f} N, V_ref "
            f"{SCENARIO.reference.value(0.0):g} rad/s, {spec.duration_s:g} s from rest; "
            f"uncertainty reading '{spec.reading}', gains '{spec.gains}', seed {spec.seed}.\n"
        )
    keys = FIELD_ROW_KEYS if field_env else ROW_KEYS
    written = [
        write_csv(rows, output_file(out, "compare.csv"), keys),
        write_json([{k: r[k] for k in keys} for r in rows], output_file(out, "compare.json")),
        _write_text(markdown_table(rows) + "\n", output_file(out, "compare.md")),
    ]
    cases = study.cases()
    per = len(rows) // max(1, len({run_label(r) for r in rows}))
    print(
        f"Ranked by mean IAE (rad), lowest first: the means of the paper's metrics over the "
        f"{per} run{'s' * (per != 1)} of each controller ({len(cases)} "
        f"{'scenario' if field_env else 'condition'}{'s' * (len(cases) != 1)} x noise "
        f"{', '.join(f'{n:g}' for n in spec.noise_levels)} rad/s); settling: mean over the runs "
        f"that settle. Every run: {out / 'compare.md'} (also .csv, .json).\n"
    )
    print(summary_table(rows))
    ended = [r for r in rows if r["diverged"]]
    if ended:
        print(f"\nDiverged runs ({len(ended)}), ranked after every controller without one:")
        for r in ended:
            case = r.get("scenario", r.get("condition"))
            why = printable(r["note"] or "the state left its bounds")
            noise = f"noise {r['noise_std_rad_s']:g} rad/s"
            print(f"  {printable(run_label(r))} on {case}, {noise}: {why}")
    if figures and rows:
        chosen, focus = (
            figure_cases([c.field for c in cases if c.field is not None])
            if field_env
            else (None, None)
        )
        assert figure_folder is not None
        written += write_figures(rows, traces, figure_folder, chosen, focus, out=out)
    total = time.perf_counter() - start
    print(
        f"\n{len(rows)} runs simulated in {simulated:.1f} s ({total:.1f} s with output); "
        f"wrote {len(written)} files to {out}/"
    )
    return 0


# ------------------------------------------------------------------- sweep adapter
# ----------------------------------------------------------------------------- compare
class CompareJob(NamedTuple):
    """One run of a comparison, as the task that makes it needs it."""

    label: str
    """The controller's name, or the agent's."""
    observation: str | None
    """The field env's observation mode of the run (``None`` on ``DrillString-v0``)."""
    is_agent: bool
    """Whether the run is the agent's."""
    case: Case
    """The case of the run."""
    noise: float
    """Measurement noise on the speeds, rad/s."""

    @property
    def run_label(self) -> str:
        """``label``, with the observation mode in brackets on the field string."""
        return run_label({"controller": self.label, "observation": self.observation})

    @property
    def item(self) -> str:
        """The item key of the run."""
        return compare_item(self.run_label, self.case.name, self.noise)


def compare_runs_task(
    runs: Sequence[CompareJob],
    duration_s: float,
    seed: int,
    reading: str,
    gains: str,
    agent: Any,
    keep_traces: bool,
    env_id: str = PAPER_ENV,
) -> TaskResult:
    """Runs of the comparison (:func:`compare_run`), records by :attr:`CompareJob.item`;
    extras (with ``keep_traces``): the light traces (:class:`RunTraces`) by ``(run label,
    case, noise)``."""
    records: dict[str, dict[str, Any]] = {}
    traces: dict[tuple[str, str, float], RunTraces] = {}
    for job in runs:
        row, trace = compare_run(
            job,
            duration_s=duration_s,
            seed=seed,
            reading=reading,
            gains=gains,
            agent=agent if job.is_agent else None,
            env_id=env_id,
        )
        records[job.item] = row
        if keep_traces:
            traces[(job.run_label, job.case.name, job.noise)] = RunTraces(
                downsample(trace, PLOT_EVERY),
                time_window(trace, max(trace.duration_s - TAIL_S, 0.0)),
                envelope(trace, BAND_S),
            )
    return TaskResult(records, traces or None)


def compare_item(label: str, condition: str, noise: float) -> str:
    """The item key of one comparison run (``label``: the run label, with the observation
    mode on the field string; ``condition``: the case's name)."""
    return f"{label}/{condition}/noise={float(noise)!r}"


@dataclass(frozen=True)
class CompareStudy:
    """The comparison on the sweep runner: an item is one run (controller or agent,
    observation mode, case, noise), a task ``task_runs`` of them.

    Attributes: as :func:`run_comparison` and :func:`comparison_cases` (``conditions`` are
    the paper's Table 3 conditions on ``DrillString-v0``, the field conditions on
    ``DrillStringField-v0``; ``depths_m``, ``controller_model`` and ``observations`` are the
    field string's), plus ``task_runs``, the runs per task (does not change the numbers), and
    ``case_list``, cases to run instead of those of ``conditions`` (``None``: those). The agent
    runs only on its own env (its ``env_id``, ``DrillString-v0`` when it has none).
    """

    controllers: tuple[str, ...]
    conditions: tuple[str, ...]
    noises: tuple[float, ...]
    duration_s: float
    seed: int = 0
    reading: str = "plant"
    gains: str = "paper"
    agent: Any = field(default=None, compare=False)
    keep_traces: bool = False
    task_runs: int = COMPARE_TASK_RUNS
    name: str = "compare"
    env_id: str = PAPER_ENV
    depths_m: tuple[float, ...] = COMPARE_DEPTHS_M
    controller_model: str = "nominal"
    observations: tuple[str, ...] = OBSERVATIONS
    case_list: tuple[Case, ...] | None = None

    @classmethod
    def from_spec(
        cls, spec: CompareSpec, agent: Any = None, *, keep_traces: bool, task_runs: int
    ) -> CompareStudy:
        """The study of ``drill-gym compare``'s settings ``spec`` (``agent``: the agent to add,
        if any; ``keep_traces``: keep the traces for figures)."""
        return cls(
            spec.controller_names,
            spec.condition_names,
            spec.noise_levels,
            duration_s=spec.duration_s,
            seed=spec.seed,
            reading=spec.reading,
            gains=spec.gains,
            agent=agent,
            keep_traces=keep_traces,
            task_runs=task_runs,
            env_id=spec.env_id,
            depths_m=tuple(dict.fromkeys(float(d) for d in spec.depths)),
            controller_model=spec.controller_model,
            observations=tuple(dict.fromkeys(spec.observations)),
        )

    def __post_init__(self) -> None:
        if self.controllers:  # none: only the agent runs
            check_controllers(self.controllers)
        for label, values in (("conditions", self.conditions), ("noises", self.noises)):
            if not values:
                raise ValueError(f"{label} = [] is empty: the comparison needs at least one")
        if self.gains not in GAIN_PRESETS:
            raise ValueError(f"gains = {shown(self.gains)}: allowed {', '.join(GAIN_PRESETS)}")
        decision_period(self.duration_s)
        check_task_size("task_runs", self.task_runs)
        if is_field(self.env_id):
            check_observations(self.observations)
            if not self.depths_m:
                raise ValueError("depths_m = [] is empty: the comparison needs at least one")
        for case in self.cases():  # unknown conditions, bad depths
            if case.field is not None:
                case.field.nominal_string()

    def cases(self) -> list[Case]:
        """The cases (:attr:`case_list`, else :func:`comparison_cases`), in table order."""
        if self.case_list is not None:
            return list(self.case_list)
        return comparison_cases(
            self.env_id,
            list(self.conditions),
            reading=self.reading,
            depths_m=[float(d) for d in self.depths_m],
            controller_model=self.controller_model,
        )

    def jobs(self) -> list[CompareJob]:
        """The runs in table order: each controller with each observation mode it can use (the agent last, on its own env
        only), on each case, at each noise level."""
        field_env = is_field(self.env_id)
        labels: list[tuple[str, str | None, bool]] = []
        for c in self.controllers:
            modes = observations_of(c, self.observations) if field_env else (None,)
            labels += [(c, o, False) for o in modes]
        if self.agent_runs:
            own = dict(self.agent.env_kwargs).get("observation", "surface") if field_env else None
            labels.append((str(self.agent.name), own, True))
        cases = self.cases()
        return [
            CompareJob(label, obs, is_agent, case, float(n))
            for label, obs, is_agent in labels
            for case in cases
            for n in self.noises
        ]

    @property
    def agent_runs(self) -> bool:
        """Whether the agent runs (there is one, and it is for this env)."""
        return self.agent is not None and getattr(self.agent, "env_id", PAPER_ENV) == self.env_id

    def spec(self) -> dict[str, Any]:
        """The comparison's settings (not the task size, nor whether traces are kept)."""
        return {
            "env_id": self.env_id,
            "jobs": [
                [j.label, j.observation, j.is_agent, j.case.name, j.noise] for j in self.jobs()
            ],
            "cases": [[c.name, c.head, c.tail] for c in self.cases()],
            "duration_s": float(self.duration_s),
            "seed": int(self.seed),
            "reading": self.reading,
            "gains": self.gains,
            "agent": agent_fingerprint(self.agent) if self.agent_runs else None,
        }

    def items(self) -> list[str]:
        """One item per run."""
        return [j.item for j in self.jobs()]

    @functools.cached_property
    def _job_of_item(self) -> dict[str, CompareJob]:
        return {j.item: j for j in self.jobs()}

    def record_schema(self, item: str) -> Schema:
        """A run's row: the run's controller (or agent), observation mode, case and noise,
        the metrics (numbers, ``None``: not defined), ``diverged`` and the settings, each
        setting this study's."""
        job = self._job_of_item[item]
        head: dict[str, Any] = {"controller": job.label}
        if job.observation is not None:
            head["observation"] = job.observation
        head.update(job.case.head)
        head["noise_std_rad_s"] = float(job.noise)
        return Fields(
            {
                **exactly(head),
                **{key: Number() for key in (*METRIC_KEYS, "static_error_rad_s")},
                "diverged": Flag(),
                "gains": Name(),
                **exactly(job.case.tail),
                "seed": Exactly(int(self.seed)),
                "duration_s": Exactly(float(self.duration_s)),
            },
            optional={"note": Text()},
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """``task_runs`` missing runs per task."""
        wanted = set(missing)
        jobs = [j for j in self.jobs() if j.item in wanted]
        return [
            Task(
                key="/".join(j.item for j in block),
                function=compare_runs_task,
                kwargs={
                    "runs": block,
                    "duration_s": self.duration_s,
                    "seed": self.seed,
                    "reading": self.reading,
                    "gains": self.gains,
                    "agent": self.agent if any(j.is_agent for j in block) else None,
                    "keep_traces": self.keep_traces,
                    "env_id": self.env_id,
                },
                items=tuple(j.item for j in block),
            )
            for block in chunks(jobs, self.task_runs)
        ]

    def results(
        self, outcome: SweepOutcome
    ) -> tuple[list[dict[str, Any]], dict[tuple[str, str, float], Any]]:
        """The rows in table order and the traces of the runs made this time."""
        records = [outcome.records[k] for k in self.items()]
        rows = [{**r, "note": r.get("note", "")} for r in records]  # older files have none
        traces: dict[tuple[str, str, float], Any] = {}
        for extras in outcome.extras.values():
            traces.update(extras)
        return rows, traces


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
