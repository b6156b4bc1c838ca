"""``drill-gym evaluate [MODEL ...]``: trained agents against every registered controller on a
held-out scenario set.

The set (:data:`HELD_OUT`) is an explicit list of 20 scenarios, none of them a training draw:
WOB 60-200 kN (eight with one step change at 40, 50 or 60 s), V_ref 4-16 rad/s, the four
Table 3 conditions, 0.1 rad/s measurement noise, 100 s from rest, each with its own fixed reset
seed (the noise). Every controller and every agent runs through the one scoring path::

    env = gym.make("DrillString-v0", **scenario, **policy.env_kwargs)   # agent
    env = gym.make("DrillString-v0", **scenario, base_controller=name)  # controller, ZeroAction
    episode_metrics(rollout(env, policy, seed))

so the base controller alone and the base controller plus the residual see the same plant,
the same WOB and reference profiles and the same noise samples.

Outputs (``--out``, default ``results/evaluate``): ``heldout.csv`` and ``heldout.json`` (one
row per scenario and controller), ``summary.json`` (means per controller, ratios to the base
controller and whether each agent meets the goal of :func:`summarize`: the lowest mean IAE and
prone severity of every controller, at most 1 % more RMSD and no more chattering than its base
controller, and at most 5 % more IAE than the base in any scenario) and figures under ``figures/`` (bit speed and torque, base controller against
residual agent, on the same seeds); a markdown table on standard output.

Examples::

    drill-gym evaluate                              # the shipped models in agents/models/
    drill-gym evaluate runs/residual_ppo__1/model   # a model of your own
    drill-gym evaluate --controllers proposed --no-plots
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np

import baselines  # noqa: F401  (registers the built-in controllers, in their order)
from agents.policy import (
    DEFAULT_MODEL_DIR,
    DEFAULT_MODEL_NAME,
    ResidualPolicy,
    is_model_folder,
    load_policy,
)
from baselines.registry import REFERENCE_CONTROLLER, rig_loops
from drill_env.control import controller_names
from drill_env.evaluation import Policy, Trace, ZeroAction, episode_metrics, termination_note
from drill_env.metrics import METRIC_KEYS
from drill_env.validation import printable, shown
from experiments.arguments import ArgumentParser, check_output_option, names_type, output_folder
from experiments.controllers import (
    CONTROLLERS_OPTION_HELP,
    ControllerError,
    controller_type,
    refuse_on_ray,
    user_controller_errors,
)
from experiments.field import (
    ENV_IDS,
    FIELD_ENV,
    HELD_OUT_FIGURES,
    OBSERVATIONS,
    PAPER_ENV,
    is_field,
    observations_of,
    run_label,
    run_on,
)
from experiments.heldout import (
    EPISODE_S,
    FIELD_HELD_OUT,
    HELD_OUT,
    SCENARIO_SETS,
    HeldOutScenario,
    held_out_set,
)
from experiments.paths import inside_output, output_file, output_path
from experiments.plots import (
    downsample,
    envelope,
    metric_bars_figure,
    panels_figure,
    save_figure,
    speed_torque_figure,
)
from experiments.results_db import Fields, Flag, Name, Number, Schema, Text, Values, exactly
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import (
    EVALUATE_TASK_SCENARIOS,
    RunnerSpec,
    SweepOutcome,
    Task,
    TaskResult,
    agent_fingerprint,
    check_controllers,
    check_observations,
    check_task_size,
    chunks,
)
from experiments.tables import write_csv, write_json

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "BASE_CONTROLLER",
    "EPISODE_S",
    "FIELD_HELD_OUT",
    "HELD_OUT",
    "RIG_LOOPS",
    "EvaluateSpec",
    "EvaluateStudy",
    "HeldOutScenario",
    "evaluate",
    "evaluate_scenarios_task",
    "goal_report",
    "heldout_figures",
    "main",
    "run_scenario",
    "summarize",
    "write_figures",
]

BASE_CONTROLLER: Final = REFERENCE_CONTROLLER[PAPER_ENV]
"""The controller the goal is measured against."""
RIG_LOOPS: Final = rig_loops()
"""The industry speed loops an agent of the field string is compared with (on surface signals,
as on a rig), those of them that are registered: :func:`versus_rig_loops`."""

FIGURE_SCENARIOS: Final = ("h01", "h02", "h08", "h14", *HELD_OUT_FIGURES)
"""Scenarios drawn one by one (bit speed and torque, base against residual)."""


def run_scenario(
    held_out: HeldOutScenario,
    policy: Policy,
    env_kwargs: Mapping[str, Any],
    env_id: str = PAPER_ENV,
) -> Trace:
    """One held-out run of ``policy`` in ``env_id(**scenario, **env_kwargs)``."""
    return run_on(env_id, {**held_out.env_kwargs(), **env_kwargs}, policy, held_out.seed)


def evaluate(
    agents: Sequence[ResidualPolicy],
    controllers: Sequence[str] | None = None,
    scenarios: Sequence[HeldOutScenario] = HELD_OUT,
    keep_traces: Sequence[str] = (),
    progress: bool = False,
    *,
    env_id: str = PAPER_ENV,
    observations: Sequence[str] = OBSERVATIONS,
) -> tuple[list[dict[str, Any]], dict[tuple[str, str], Trace]]:
    """Score every controller and agent on every scenario.

    Args:
        agents: Trained agents (their ``env_kwargs`` set the decision period etc.).
        controllers: Registered controller names (run as base controller with a zero residual);
            default all of them.
        scenarios: The scenarios (default :data:`HELD_OUT`).
        keep_traces: Labels (controller names or agent names) whose traces are returned.
        progress: Show a progress bar.
        env_id: The env of every run; on the field string each controller runs with each of
            ``observations`` it can use (:func:`experiments.field.observations_of`).
        observations: The observation modes of the field string.

    Returns:
        One row per (scenario, controller or agent) with the scenario, ``prone``, the metrics
        and ``note`` (and the ``observation`` mode on the field string); and the kept traces by
        (scenario id, label), a label being :func:`experiments.field.run_label` of the row.
        The note is empty, or why the run ended early (a controller's NaN or infinite torque:
        then ``diverged``), or on the field string why it could not run (no metrics).

    Raises:
        experiments.controllers.ControllerError: a user's controller raised or returned
            something that is not a torque.
    """
    field = is_field(env_id)
    names = list(controller_names() if controllers is None else controllers)
    # Controllers run with the first agent's decision period: the same noise stream, and a
    # zero residual is then exactly the agent's base controller.
    own = ("base_controller", "observation")
    common = {k: v for k, v in (agents[0].env_kwargs if agents else {}).items() if k not in own}
    jobs: list[tuple[str, str | None, Policy, dict[str, Any]]] = []
    for name in names:
        for obs in observations_of(name, observations) if field else (None,):
            kwargs = {**common, "base_controller": name}
            if obs is not None:
                kwargs["observation"] = obs
            jobs.append((name, obs, ZeroAction(), kwargs))
    for agent in agents:
        obs = agent.env_kwargs.get("observation", "surface") if field else None
        jobs.append((agent.name, obs, agent, dict(agent.env_kwargs)))
    rows: list[dict[str, Any]] = []
    traces: dict[tuple[str, str], Trace] = {}
    total = len(scenarios) * len(jobs)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=total, desc="held-out runs", unit="run")
    for scenario in scenarios:
        for label, obs, policy, kwargs in jobs:
            row = scenario.row()
            head: dict[str, Any] = {"scenario": row.pop("scenario"), "controller": label}
            if obs is not None:
                head["observation"] = obs
            try:
                with user_controller_errors(label, f" on {scenario.id}"):
                    trace = run_scenario(scenario, policy, kwargs, env_id)
            except ControllerError:
                raise
            except ValueError as err:
                if not field:
                    raise
                # A controller that cannot be made for this string (its tuning or model has
                # no solution there): a row without metrics and the reason.
                missing: dict[str, Any] = dict.fromkeys(METRIC_KEYS)
                rows.append({**head, **row, **missing, "diverged": False, "note": str(err)})
            else:
                note = {"note": termination_note(trace)}
                rows.append({**head, **row, **episode_metrics(trace), **note})
                if run_label(head) in keep_traces:
                    traces[(scenario.id, run_label(head))] = trace
            if bar is not None:
                bar.update()
    if bar is not None:
        bar.close()
    return rows, traces


def _mean(values: Sequence[float | None]) -> float:
    clean = [float(v) for v in values if v is not None and math.isfinite(float(v))]
    return float(np.mean(clean)) if clean else math.nan


GOAL_RMSD_RATIO: Final = 1.01
"""The goal's most RMSD of an agent, relative to its base controller's."""
GOAL_WORST_IAE_RATIO: Final = 1.05
"""The goal's most IAE of an agent in any one scenario, relative to its base controller's."""


def summarize(
    rows: Sequence[Mapping[str, Any]],
    base: str = BASE_CONTROLLER,
    agents: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Means per controller, ratios to ``base`` and whether each meets the goal.

    The goal of a learned controller is to be the best controller of the set: a mean IAE
    below every engineered controller's, a mean severity over the stick-slip-prone scenarios
    below every engineered controller's, a mean RMSD at most ``GOAL_RMSD_RATIO`` times the
    base controller's, a mean chattering no higher than the base's, and in no scenario an
    IAE above ``GOAL_WORST_IAE_RATIO`` times the base's. ``agents`` names the learned
    controllers (labels); every other label is an engineered one (``None``: every label but
    the one checked). Rows of runs that could not be made (a ``note``, no metrics: a
    controller that cannot be made for the string) are left out. A controller with a
    diverged run never sets the bar, and an agent with one misses the goal. Rows are
    grouped by :func:`experiments.field.run_label` (on the field string: controller and
    observation mode, so ``base`` is then for example ``proposed (state)``).
    """
    labels = list(dict.fromkeys(run_label(r) for r in rows))
    means: dict[str, dict[str, float]] = {}
    for label in labels:
        mine = [r for r in rows if run_label(r) == label and not _not_run(r)]
        prone = [r for r in mine if r["prone"]]
        entry = {key: _mean([r[key] for r in mine]) for key in METRIC_KEYS}
        entry["severity_prone"] = _mean([r["stick_slip_severity"] for r in prone])
        entry["unsettled"] = float(sum(r["settling_time_s"] is None for r in mine))
        entry["diverged"] = float(sum(bool(r["diverged"]) for r in mine))
        if len(mine) != sum(run_label(r) == label for r in rows):
            entry["runs"] = float(len(mine))  # some scenarios could not be run
        means[label] = entry
    summary: dict[str, Any] = {"base_controller": base, "means": means, "goal": {}}
    if base in means:
        ref = means[base]
        base_iae = {
            r["scenario"]: r["iae"] for r in rows if run_label(r) == base and "scenario" in r
        }
        for label in labels:
            m = means[label]
            engineered = [e for e in labels if e != label and (agents is None or e not in agents)]
            complete = [e for e in engineered if _comparable(means[e])]
            best_iae = min((means[e]["iae"] for e in complete), default=math.inf)
            best_severity = min((means[e]["severity_prone"] for e in complete), default=math.inf)
            worst = max(
                (
                    float(r["iae"]) / float(base_iae[r["scenario"]])
                    for r in rows
                    if run_label(r) == label and r.get("scenario") in base_iae
                    and r["iae"] is not None and base_iae[r["scenario"]]
                ),
                default=math.nan,
            )  # fmt: skip
            goal: dict[str, Any] = {
                "iae_ratio": m["iae"] / ref["iae"],
                "rmsd_ratio": m["rmsd_nm"] / ref["rmsd_nm"],
                "severity_prone_ratio": m["severity_prone"] / ref["severity_prone"],
                "chattering_ratio": m["chattering_nm_per_s"] / ref["chattering_nm_per_s"],
                "worst_iae_ratio": worst,
                "best_engineered_iae": best_iae,
                "best_engineered_severity_prone": best_severity,
            }
            checks = {
                "IAE below every engineered controller's": m["iae"] < best_iae,
                "prone severity below every engineered controller's": (
                    m["severity_prone"] < best_severity
                ),
                f"RMSD at most {GOAL_RMSD_RATIO:g} x the base's": (
                    goal["rmsd_ratio"] <= GOAL_RMSD_RATIO
                ),
                "chattering no higher than the base's": goal["chattering_ratio"] <= 1.0,
                f"IAE at most {GOAL_WORST_IAE_RATIO:g} x the base's in every scenario": not (
                    worst > GOAL_WORST_IAE_RATIO
                ),
            }
            if m["diverged"]:
                checks["no diverged run"] = False
            goal["missed"] = [name for name, ok in checks.items() if not ok]
            goal["met"] = not goal["missed"]
            summary["goal"][label] = goal
    return summary


def _not_run(row: Mapping[str, Any]) -> bool:
    """Whether ``row`` is of a run that could not be made (a note and no metrics), not of one
    that ran (a diverged run may have a note too: why it ended)."""
    return bool(row.get("note")) and not row.get("diverged")


def _comparable(means: Mapping[str, float]) -> bool:
    """Whether a controller's means may set the bar of the goal: it ran every scenario and
    none of its runs diverged (a diverged run's metrics cover only its steps before the end)."""
    return "runs" not in means and not means["diverged"]


def _best_engineered(
    means: Mapping[str, Mapping[str, float]], label: str, agents: Sequence[str], key: str
) -> str | None:
    """The engineered controller with the lowest mean ``key`` (as :func:`summarize` picks it:
    every label but ``label`` and the agents, run on every scenario, none diverged)."""
    engineered = [e for e in means if e != label and e not in agents and _comparable(means[e])]
    return min(engineered, key=lambda e: means[e][key], default=None)


def goal_report(
    summary: Mapping[str, Any], agents: Sequence[str], kinds: Mapping[str, str] | None = None
) -> str:
    """The goal check of each agent of ``agents`` in plain words: which criterion, the
    agent's number, the number it is held against and whether it holds.

    ``kinds`` describes each agent (``residual torque on proposed``); :func:`summarize`
    decides every criterion, this only words them.
    """
    base = str(summary["base_controller"])
    means = summary["means"]
    lines = [
        "Goal check. A learned agent's goal is to be the best controller of the set: lower "
        "mean IAE and lower mean stick-slip severity (over the prone scenarios) than every "
        f"engineered controller, at the RMSD and chattering of {base}, and in no scenario "
        f"more than {GOAL_WORST_IAE_RATIO:g} x the IAE of {base}."
    ]
    for label in agents:
        g = summary["goal"].get(label)
        if g is None:
            continue
        m = means[label]
        best_iae = _best_engineered(means, label, agents, "iae")
        best_sev = _best_engineered(means, label, agents, "severity_prone")
        rmsd_allowed = (GOAL_RMSD_RATIO - 1.0) * 100.0
        checks = [
            (
                f"mean IAE {m['iae']:.1f} rad against {g['best_engineered_iae']:.1f} of the "
                f"best engineered controller ({best_iae})",
                m["iae"] < g["best_engineered_iae"],
            ),
            (
                f"prone severity {m['severity_prone']:.3f} against "
                f"{g['best_engineered_severity_prone']:.3f} ({best_sev})",
                m["severity_prone"] < g["best_engineered_severity_prone"],
            ),
            (
                f"RMSD {(g['rmsd_ratio'] - 1) * 100:+.1f} % of {base}'s "
                f"(allowed up to {rmsd_allowed:+.0f} %)",
                g["rmsd_ratio"] <= GOAL_RMSD_RATIO,
            ),
            (
                f"chattering {(g['chattering_ratio'] - 1) * 100:+.1f} % of {base}'s "
                "(allowed up to +0 %)",
                g["chattering_ratio"] <= 1.0,
            ),
            (
                f"worst scenario IAE {g['worst_iae_ratio']:.2f} x {base}'s "
                f"(allowed up to {GOAL_WORST_IAE_RATIO:g} x)",
                not g["worst_iae_ratio"] > GOAL_WORST_IAE_RATIO,
            ),
        ]
        if m["diverged"]:
            checks.append((f"{int(m['diverged'])} diverged runs (allowed none)", False))
        held = sum(ok for _, ok in checks)
        kind = f", {kinds[label]}" if kinds and label in kinds else ""
        verdict = "goal met" if g["met"] else "goal not met"
        lines.append(f"{label}{kind}: {held} of {len(checks)} criteria hold, {verdict}")
        lines += [f"  {'holds ' if ok else 'misses'}  {text}" for text, ok in checks]
    return "\n".join(lines)


def versus_rig_loops(summary: Mapping[str, Any], agents: Sequence[str]) -> dict[str, Any]:
    """Each agent against each rig loop of :data:`RIG_LOOPS` on surface signals that the
    summary has: the ratios of mean IAE, mean RMSD and mean severity over the prone
    scenarios, and whether the agent beats the loop (lower IAE and prone severity at no more
    RMSD). Controllers that could not run everywhere are left out (their means cover fewer
    scenarios)."""
    means = summary["means"]
    out: dict[str, Any] = {}
    for agent in agents:
        if agent not in means:
            continue
        mine = means[agent]
        out[agent] = {}
        for loop in RIG_LOOPS:
            label = run_label({"controller": loop, "observation": "surface"})
            ref = means.get(label)
            if ref is None or "runs" in ref:
                continue
            iae = mine["iae"] / ref["iae"]
            rmsd = mine["rmsd_nm"] / ref["rmsd_nm"]
            severity = mine["severity_prone"] / ref["severity_prone"]
            out[agent][label] = {
                "iae_ratio": iae,
                "rmsd_ratio": rmsd,
                "severity_prone_ratio": severity,
                "beats": bool(iae < 1.0 and severity < 1.0 and rmsd <= 1.0),
            }
    return out


def markdown_table(summary: Mapping[str, Any]) -> str:
    """The per-controller means as a markdown table (ratios to the base controller)."""
    base = str(summary.get("base_controller", BASE_CONTROLLER))
    lines = [
        f"| controller | IAE (rad) | vs {base} | RMSD (kN m) | vs {base} | severity, prone | "
        "severity, all | overshoot (%) | unsettled | stuck | chattering (kN m/s) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    goal = summary.get("goal", {})
    for label, m in summary["means"].items():
        g = goal.get(label, {})
        iae_r = f"{(g['iae_ratio'] - 1) * 100:+.1f} %" if g else ""
        rmsd_r = f"{(g['rmsd_ratio'] - 1) * 100:+.1f} %" if g else ""
        if "runs" in m:  # some scenarios could not be run for it
            label = f"{label} ({int(m['runs'])} runs)"
        if m.get("diverged"):  # its means cover only the steps before each end
            label = f"{label} ({int(m['diverged'])} diverged)"
        lines.append(
            f"| {label} | {m['iae']:.1f} | {iae_r} | {m['rmsd_nm'] / 1e3:.2f} | {rmsd_r} | "
            f"{m['severity_prone']:.3f} | {m['stick_slip_severity']:.3f} | "
            f"{m['overshoot_pct']:.1f} | {int(m['unsettled'])} | {m['stuck_fraction']:.3f} | "
            f"{m['chattering_nm_per_s'] / 1e3:.0f} |"
        )
    return "\n".join(lines)


def per_scenario_table(rows: Sequence[Mapping[str, Any]], labels: Sequence[str]) -> str:
    """IAE and severity per scenario for ``labels`` (markdown; on the field string with the
    string and its depth)."""
    field = bool(rows) and "measured_depth_m" in rows[0]
    extra = ["string"] if field else []
    head = (
        "| scenario | "
        + "".join(f"{e} | " for e in extra)
        + "V_ref | WOB (kN) | condition | prone | "
        + " | ".join(f"IAE {label} | sev. {label}" for label in labels)
    )
    lines = [head + " |", "|" + "---|" * (5 + len(extra) + 2 * len(labels))]
    by_key = {(r["scenario"], run_label(r)): r for r in rows}
    for scenario in dict.fromkeys(r["scenario"] for r in rows):
        first = next(r for r in rows if r["scenario"] == scenario)
        wob = f"{first['wob_n'] / 1e3:.0f}"
        if first["wob_final_n"] is not None:
            wob += f" -> {first['wob_final_n'] / 1e3:.0f} @ {first['wob_step_time_s']:.0f} s"
        cells = [scenario]
        if field:
            cells.append(f"{first['parameters']} at {first['measured_depth_m']:,.0f} m")
        cells += [
            f"{first['reference_speed_rad_s']:.3g}"
            if field
            else f"{first['reference_speed_rad_s']:g}",
            wob,
            first["condition"] if field else first["uncertainty"],
            "yes" if first["prone"] else "",
        ]
        for label in labels:
            r = by_key.get((scenario, label))
            if r is None:
                cells += ["", ""]
            elif r["iae"] is None:  # not run: the controller cannot be made for this string
                cells += ["n/a", "n/a"]
            else:
                cells += [f"{r['iae']:.0f}", f"{r['stick_slip_severity']:.2f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_outputs(
    rows: Sequence[Mapping[str, Any]], summary: Mapping[str, Any], out: Path
) -> list[Path]:
    """``heldout.csv``, ``heldout.json`` and ``summary.json`` in ``out``."""
    keys = list(rows[0]) if rows else []
    return [
        write_csv(rows, output_file(out, "heldout.csv"), keys),
        write_json(list(rows), output_file(out, "heldout.json")),
        write_json(summary, output_file(out, "summary.json"), indent=2),
    ]


def _scenario_title(row: Mapping[str, Any], lines: int = 1) -> str:
    """``h08: V_ref 8 rad/s, WOB 100 -> 190 kN at 50 s, nominal`` (on two lines if asked; on
    the field string the string's depth and the reference in rpm)."""
    wob = f"{row['wob_n'] / 1e3:.0f}"
    if row["wob_final_n"] is not None:
        wob += f" -> {row['wob_final_n'] / 1e3:.0f} kN at {row['wob_step_time_s']:g} s"
    else:
        wob += " kN"
    if "measured_depth_m" in row:
        rpm = row["reference_speed_rad_s"] * 60.0 / (2.0 * math.pi)
        head = f"{row['scenario']}: {row['measured_depth_m']:,.0f} m, {rpm:.0f} rpm, {row['condition']}"
    else:
        head = (
            f"{row['scenario']}: V_ref {row['reference_speed_rad_s']:g} rad/s, {row['uncertainty']}"
        )
    return f"{head}\nWOB {wob}" if lines == 2 else f"{head}, WOB {wob}"


def heldout_figures(
    rows: Sequence[Mapping[str, Any]],
    traces: Mapping[tuple[str, str], Trace],
    labels: Sequence[str],
) -> Iterator[tuple[str, Figure]]:
    """The held-out figures as (file name, figure): bit speed and torque (base controller
    against the agents) of each of :data:`FIGURE_SCENARIOS`, small multiples of the bit speed
    and of the torque of every scenario, and IAE and severity per scenario."""

    first_row = {r["scenario"]: r for r in reversed(rows)}
    scenario_ids = list(dict.fromkeys(r["scenario"] for r in rows))
    for sid in FIGURE_SCENARIOS:
        chosen = {label: traces[(sid, label)] for label in labels if (sid, label) in traces}
        if len(chosen) < 2:
            continue
        yield (
            f"speed_torque_{sid}.png",
            speed_torque_figure(
                {"controller": {k: downsample(v, 10) for k, v in chosen.items()}},
                _scenario_title(first_row[sid])
                + "; torque: mean per 0.1 s, light band from minimum to maximum",
                envelopes={k: envelope(v, 0.1) for k, v in chosen.items()},
            ),
        )
    for quantity, name in (("bit_speed", "bit speed"), ("torque", "top-drive torque")):
        panels = {
            _scenario_title(first_row[sid], lines=2): {
                label: traces[(sid, label)]
                if quantity == "torque"
                else downsample(traces[(sid, label)], 50)
                for label in labels
                if (sid, label) in traces
            }
            for sid in scenario_ids
        }
        panels = {k: v for k, v in panels.items() if v}
        if panels:
            note = "mean per 0.5 s, band from minimum to maximum" if quantity == "torque" else ""
            yield (
                f"heldout_{quantity}.png",
                panels_figure(
                    panels,
                    f"held-out scenarios: {name}" + (f" ({note})" if note else ""),
                    quantity=quantity,
                    ncols=4,
                    reference=True,
                    band_s=0.5 if quantity == "torque" else None,
                ),
            )
    chosen_rows = [{**r, "controller": run_label(r)} for r in rows if run_label(r) in labels]
    if chosen_rows:
        yield (
            "heldout_iae_severity.png",
            metric_bars_figure(
                chosen_rows,
                ["iae", "stick_slip_severity"],
                group="scenario",
                hue="controller",
                title="held-out scenarios: IAE and stick-slip severity per scenario",
            ),
        )


def write_figures(
    rows: Sequence[Mapping[str, Any]],
    traces: Mapping[tuple[str, str], Trace],
    labels: Sequence[str],
    out: Path,
    *,
    root: Path | None = None,
) -> list[Path]:
    """Write :func:`heldout_figures` as PNG files into ``out``; returns their paths. Every
    file is checked to lie inside ``out`` and, when given, inside the output folder ``root``
    (``out`` a link inside it to elsewhere is refused with a ``ValueError``)."""
    if root is not None:
        inside_output(root, out)
    written = []
    for name, fig in heldout_figures(rows, traces, labels):
        path = output_file(out, name)
        written.append(save_figure(fig, path if root is None else inside_output(root, path)))
    return written


def shipped_models() -> list[Path]:
    """Model folders under ``agents/models/`` (the default residual agent first)."""
    if not DEFAULT_MODEL_DIR.is_dir():
        return []
    found = sorted(p for p in DEFAULT_MODEL_DIR.iterdir() if is_model_folder(p))
    found.sort(key=lambda p: p.name != DEFAULT_MODEL_NAME)
    return found


DESCRIPTION: Final = """\
Score trained agents and every registered controller on a held-out scenario set (20 fixed
scenarios on DrillString-v0, 16 on the field string, 100 s each), print the means per
controller and the IAE and severity per scenario, and write heldout.csv/.json, summary.json
and figures/ into --out (docs/specification.md section 15).

example: drill-gym evaluate runs/residual_ppo__1/model --controllers proposed --scenarios h01
"""

_SCENARIO_IDS: Final = tuple(
    s.id for env_sets in SCENARIO_SETS.values() for v in env_sets.values() for s in v
)
"""Every held-out scenario id of either env (``--scenarios``)."""


@dataclass(frozen=True)
class EvaluateSpec:
    """The settings of ``drill-gym evaluate`` (its options are these fields, and the model
    folders also as arguments)."""

    env_id: str = field(
        default=PAPER_ENV, metadata=option(choices=ENV_IDS, flag="--env", aliases=("--env-id",))
    )
    """the env of the held-out set"""
    models: tuple[str, ...] = field(
        default=(), metadata=option(metavar="PATH", default_text="the shipped models")
    )
    """model folders (also given as MODEL)"""
    observations: tuple[str, ...] = field(
        default=OBSERVATIONS, metadata=option(choices=OBSERVATIONS)
    )
    """observation modes of the speed loops on the field string"""
    controllers: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=controller_type, help=CONTROLLERS_OPTION_HELP, metavar="NAME", default_text="all"
        ),
    )
    # help: CONTROLLERS_OPTION_HELP (user classes are the same in every study)
    scenario_set: str = field(
        default="heldout",
        metadata=option(
            choices=tuple(dict.fromkeys(n for sets in SCENARIO_SETS.values() for n in sets))
        ),
    )
    """the held-out set (corners: DrillString-v0 only)"""
    scenarios: tuple[str, ...] = field(
        default=(),
        metadata=option(
            parse=names_type(lambda: _SCENARIO_IDS, "scenario"), metavar="ID", default_text="all"
        ),
    )
    """only these scenarios of the set"""
    out: Path | None = field(
        default=None,
        metadata=option(parse=output_folder, metavar="DIR", default_text="results/evaluate[_SET]"),
    )
    """output folder"""
    no_plots: bool = field(default=False, metadata=option(aliases=("--no-figures",)))
    """write no figures"""
    no_progress: bool = False
    """no progress bar"""
    trust_pickle: bool = False
    """also load Stable-Baselines3 .zip models (unpickling runs code: trusted files only)"""

    def __post_init__(self) -> None:
        try:
            held_out = held_out_set(self.env_id, self.scenario_set)
        except ValueError:
            allowed = ", ".join(SCENARIO_SETS[FIELD_ENV if is_field(self.env_id) else PAPER_ENV])
            raise ValueError(
                f"argument --scenario-set: {self.scenario_set} is not a held-out set of "
                f"{self.env_id}: allowed {allowed}"
            ) from None
        ids = {s.id for s in held_out}
        wrong = [i for i in self.scenarios if i not in ids]
        if wrong:
            raise ValueError(
                f"argument --scenarios: {', '.join(wrong)} is not a scenario of the "
                f"{self.scenario_set} set of {self.env_id}: allowed {held_out[0].id} to "
                f"{held_out[-1].id}"
            )
        check_output_option(self.output)

    @property
    def output(self) -> Path:
        """The output folder (default: ``results/evaluate``, ``results/evaluate_SET`` for
        another set)."""
        if self.out is not None:
            return self.out
        name = "evaluate" if self.scenario_set == "heldout" else f"evaluate_{self.scenario_set}"
        return Path("results") / name

    def held_out(self) -> tuple[HeldOutScenario, ...]:
        """The scenarios to run, in the set's order."""
        held_out = held_out_set(self.env_id, self.scenario_set)
        return tuple(s for s in held_out if not self.scenarios or s.id in self.scenarios)


def _parser() -> ArgumentParser:
    parser = spec_parser("drill-gym evaluate", DESCRIPTION, EvaluateSpec, RunnerSpec)
    parser.usage = "drill-gym evaluate [MODEL ...] [OPTIONS]"
    parser.add_argument("model_folders", nargs="*", metavar="MODEL", help="model folders")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym evaluate [MODEL ...]``; returns the exit code (see ``--help``)."""
    parser = _parser()
    args = parser.parse_args(list(argv) if argv is not None else None)
    args.models = [*args.model_folders, *args.models]
    runner = spec_from_args(RunnerSpec, args)
    try:
        spec = spec_from_args(EvaluateSpec, args)
    except ValueError as err:
        parser.error(str(err))
    out = spec.output
    field_env = is_field(spec.env_id)
    paths = [Path(p) for p in spec.models] or shipped_models()
    if not paths and not field_env:
        parser.error(f"no MODEL given and no model shipped in {DEFAULT_MODEL_DIR}")
    agents = [load_policy(p, trust_pickle=spec.trust_pickle) for p in paths]
    for agent, path in zip(agents, paths, strict=True):
        if agent.env_id != spec.env_id:
            if spec.models:
                parser.error(f"MODEL {path} is for {agent.env_id}, not for {spec.env_id}")
            print(
                f"evaluate: {printable(path.name)} is for {printable(agent.env_id)}, left out "
                f"(drill-gym evaluate --env {printable(agent.env_id)} scores it)",
                file=sys.stderr,
            )
    paths = [p for a, p in zip(agents, paths, strict=True) if a.env_id == spec.env_id]
    agents = [a for a in agents if a.env_id == spec.env_id]
    labels = [a.name for a in agents]
    if len(set(labels)) != len(labels):
        for a, p in zip(agents, paths, strict=True):
            a.name = f"{a.name}:{p}"
        labels = [a.name for a in agents]
    scenarios = spec.held_out()
    figure_folder = None if spec.no_plots else output_path(out, "figures")  # before the runs
    t0 = time.perf_counter()
    base_names = sorted({a.env_kwargs.get("base_controller") or BASE_CONTROLLER for a in agents})
    if field_env and not agents:
        base_names = [BASE_CONTROLLER]
    controllers = None
    if spec.controllers:
        controllers = list(dict.fromkeys([*spec.controllers, *base_names]))
        refuse_on_ray(parser.fail, runner.backend().distributed, controllers)
    base_label = BASE_CONTROLLER
    bases = base_names
    if field_env:  # a run's label is its controller and observation mode
        base_label = run_label({"controller": BASE_CONTROLLER, "observation": "state"})
        bases = list(
            dict.fromkeys(
                run_label(
                    {
                        "controller": a.env_kwargs.get("base_controller") or BASE_CONTROLLER,
                        "observation": a.env_kwargs.get("observation", "surface")
                        if a.env_kwargs.get("base_controller")
                        else "state",
                    }
                )
                for a in agents
            )
        ) or [base_label]
    agent_labels = labels  # the agents' rows as the tables label them
    if field_env:
        agent_labels = [
            run_label(
                {"controller": a.name, "observation": a.env_kwargs.get("observation", "surface")}
            )
            for a in agents
        ]
    keep = [*bases, *agent_labels]
    try:
        study = EvaluateStudy(
            tuple(agents),
            None if controllers is None else tuple(controllers),
            scenarios,
            keep_traces=tuple(keep) if not spec.no_plots else (),
            task_scenarios=runner.task_size or EVALUATE_TASK_SCENARIOS,
            env_id=spec.env_id,
            observations=tuple(dict.fromkeys(spec.observations)),
        )
    except ValueError as err:
        parser.error(str(err))
    outcome = runner.run(study, out / "heldout.sqlite", progress=not spec.no_progress)
    rows, traces = study.results(outcome)
    figures = not spec.no_plots and outcome.loaded == 0
    if not spec.no_plots and not figures:
        print("no figures: runs read from the results file keep no traces (rerun without "
              "--resume for the figures)")  # fmt: skip
    summary = summarize(rows, base_label, agents=agent_labels)
    if field_env:
        summary["versus_rig_loops"] = versus_rig_loops(summary, agent_labels)
    summary["seconds"] = round(time.perf_counter() - t0, 1)
    summary["models"] = {a.name: str(p) for a, p in zip(agents, paths, strict=True)}
    written = write_outputs(rows, summary, out)
    if figures:
        assert figure_folder is not None
        written += write_figures(rows, traces, keep, figure_folder, root=out)
    total = time.perf_counter() - t0
    print(markdown_table(summary))
    print()
    print(per_scenario_table(rows, list(summary["means"]) if field_env else keep))
    print()
    kinds = {
        label: (
            f"residual torque on {a.env_kwargs['base_controller']}"
            if a.env_kwargs.get("base_controller")
            else "direct torque, no base controller"
        )
        for label, a in zip(agent_labels, agents, strict=True)
    }
    if any(label in summary["goal"] for label in agent_labels):
        print(goal_report(summary, agent_labels, kinds))
    for agent, loops in summary.get("versus_rig_loops", {}).items():
        for loop, v in loops.items():
            print(
                f"{agent}: IAE {(v['iae_ratio'] - 1) * 100:+.1f} %, RMSD "
                f"{(v['rmsd_ratio'] - 1) * 100:+.1f} %, severity (prone) "
                f"{(v['severity_prone_ratio'] - 1) * 100:+.1f} % vs {loop}: "
                + ("beats it" if v["beats"] else "does NOT beat it")
                + " (lower IAE and prone severity at no more RMSD)"
            )
    print(
        f"\n{len(rows)} runs simulated in {summary['seconds']} s ({total:.1f} s with output); "
        f"wrote {len(written)} files to {out}/"
    )
    return 0


# ------------------------------------------------------------------- sweep adapter
# ----------------------------------------------------------------------------- evaluate
def evaluate_scenarios_task(
    scenarios: Sequence[Any],
    agents: Sequence[Any],
    controllers: Sequence[str] | None,
    keep_traces: Sequence[str],
    env_id: str = PAPER_ENV,
    observations: Sequence[str] = OBSERVATIONS,
) -> TaskResult:
    """Held-out scenarios, each run by every controller (with each observation mode it can use
    on the field string) and agent (:func:`experiments.evaluate.evaluate` on ``env_id``); one
    record per scenario id (``rows``: its rows in table order), extras: the kept traces by
    ``(scenario id, run label)``."""

    rows, traces = evaluate(
        list(agents),
        controllers,
        list(scenarios),
        keep_traces=keep_traces,
        env_id=env_id,
        observations=list(observations),
    )
    records = {s.id: {"rows": [r for r in rows if r["scenario"] == s.id]} for s in scenarios}
    return TaskResult(records, traces or None)


@dataclass(frozen=True)
class EvaluateStudy:
    """The held-out evaluation (:func:`experiments.evaluate.evaluate`) on the sweep runner: an
    item is one held-out scenario run by every controller and agent (the controllers run with
    the first agent's decision period, so a scenario is the unit), a task ``task_scenarios`` of
    them.

    Attributes: as :func:`experiments.evaluate.evaluate` (``env_id``, and on the field string
    ``observations``: the modes the controllers run with), plus ``task_scenarios`` (does not
    change the numbers).
    """

    agents: tuple[Any, ...]
    controllers: tuple[str, ...] | None
    scenarios: tuple[Any, ...]
    keep_traces: tuple[str, ...] = ()
    task_scenarios: int = EVALUATE_TASK_SCENARIOS
    name: str = "evaluate"
    env_id: str = PAPER_ENV
    observations: tuple[str, ...] = OBSERVATIONS

    def __post_init__(self) -> None:
        if self.controllers is not None:
            check_controllers(self.controllers)
        if not self.scenarios:
            raise ValueError("scenarios = [] is empty: the evaluation needs at least one")
        check_task_size("task_scenarios", self.task_scenarios)
        field_env = is_field(self.env_id)
        if field_env:
            check_observations(self.observations)
        for s in self.scenarios:
            if (s.field is not None) != field_env:
                raise ValueError(
                    f"scenario {shown(s.id)} is not a held-out scenario of {self.env_id}: "
                    f"{'f01-f16' if field_env else 'h01-h20'} are"
                )
        ids = [s.id for s in self.scenarios]
        if len(set(ids)) != len(ids):
            raise ValueError(f"scenarios = {shown(ids)}: each held-out scenario at most once")

    def spec(self) -> dict[str, Any]:
        """The evaluation's settings (not the task size, nor which traces are kept)."""
        return {
            "env_id": self.env_id,
            "scenarios": [s.row() for s in self.scenarios],
            "controllers": None if self.controllers is None else list(self.controllers),
            "observations": list(self.observations) if is_field(self.env_id) else None,
            "agents": [agent_fingerprint(a) for a in self.agents],
        }

    def items(self) -> list[str]:
        """One item per held-out scenario."""
        return [s.id for s in self.scenarios]

    def record_schema(self, item: str) -> Schema:
        """A scenario's rows, one per controller and agent: the scenario's own columns, the
        run's name (and observation mode), the metrics (numbers, ``None``: not defined),
        ``diverged`` and, on the field string, a note."""
        scenario = next(s for s in self.scenarios if s.id == item)
        row = Fields(
            {**exactly(scenario.row()), "controller": Name(), "diverged": Flag()},
            optional={"observation": Name(), "note": Text()},
            rest=Number(),
        )
        return Fields({"rows": Values(row)})

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """``task_scenarios`` missing scenarios per task."""
        wanted = set(missing)
        chosen = [s for s in self.scenarios if s.id in wanted]
        return [
            Task(
                key="/".join(s.id for s in block),
                function=evaluate_scenarios_task,
                kwargs={
                    "scenarios": block,
                    "agents": list(self.agents),
                    "controllers": None if self.controllers is None else list(self.controllers),
                    "keep_traces": list(self.keep_traces),
                    "env_id": self.env_id,
                    "observations": list(self.observations),
                },
                items=tuple(s.id for s in block),
            )
            for block in chunks(chosen, self.task_scenarios)
        ]

    def results(
        self, outcome: SweepOutcome
    ) -> tuple[list[dict[str, Any]], dict[tuple[str, str], Any]]:
        """The rows in table order and the kept traces of the runs made this time."""
        rows = [row for k in self.items() for row in outcome.records[k]["rows"]]
        traces: dict[tuple[str, str], Any] = {}
        for extras in outcome.extras.values():
            traces.update(extras)
        return rows, traces


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
