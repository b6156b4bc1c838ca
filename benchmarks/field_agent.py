"""Train the shipped field agent with its defaults and time it; draw learning curves.

``drill-gym train --env DrillStringField-v0`` with every other setting at the field defaults
(:data:`agents.config.ENV_DEFAULTS`): a residual PPO policy on top of ``z_torque_tuned`` that
sees the rig's surface signals and the mud-pulse telemetry (``frame_stack`` 1: the current
observation only).
Prints the wall time (the whole run: simulation, PPO updates, validations, checkpoints) and
the selected model; ``--ship`` copies the model to ``agents/models/field_agent/`` (recording
the command that retrains it) and the learning curves to ``docs/reports/figures/``. Then
``drill-gym evaluate --env DrillStringField-v0`` scores it on the field held-out set.

``--curves LABEL=RUN_DIR ...`` only draws the learning curves of finished runs (for example
the tries of docs/reports/field-agent.md) into ``--figure``. ``--figures [MODEL]`` only draws the
hardest held-out scenarios (:data:`FIGURE_SCENARIOS`: bit speed, top-drive speed and torque
of the agent against ``soft_speed`` and ``z_torque`` on surface signals, the same noise
samples) into ``docs/reports/figures/field_agent_<id>.png``, from the shipped model by default.
``--groups HELDOUT_CSV`` prints the means of a field ``heldout.csv`` (written by ``drill-gym
evaluate --env DrillStringField-v0``) by group (:data:`GROUPS`: within the training ranges, the
deep string, outside the ranges, all): IAE, RMSD and the stick-slip severity of the prone
scenarios. ``--depth-validation LOW HIGH N MODEL ...`` scores models as the validation does
(ratios to the base controller alone and the selection score on N scenarios of the env's
randomisation, the validation's reset seeds) with the depth drawn from LOW-HIGH m only: does
a deeper validation set rank checkpoints as the deep held-out strings do? ``--ship-model
MODEL --wall-s S`` ships the model of a finished run of the default command
(``drill-gym train --env DrillStringField-v0 --run-dir ... --save-dir ...``) with the command
and its wall time recorded in its ``source``.

Run from the repository root::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/field_agent.py --ship
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from agents.config import FIELD_ENV_ID, TrainConfig
from agents.policy import DEFAULT_MODEL_DIR, load_policy
from drill_env.evaluation import ZeroAction
from experiments.plots import save_figure, text_problems

NAME = "field_agent"
FIGURE = Path("docs/reports/figures/field_agent_learning_curve.png")
RETRAIN = f"drill-gym train --env {FIELD_ENV_ID}"
FIGURE_SCENARIOS = ("f02", "f04", "f10", "f15")
"""Held-out scenarios drawn: one the agent wins (f02), the hardest in the training ranges
(f04), the deep string (f10) and the point outside every range (f15)."""
LOOPS = ("soft_speed", "z_torque")
"""The rig loops drawn beside the agent (on surface signals)."""
GROUPS: dict[str, Callable[[Mapping[str, str]], bool]] = {
    "in the training ranges (f01-f08)": lambda r: r["in_range"] == "True",
    "deep string deep_5000m (f09-f12)": lambda r: r["parameters"] == "deep_5000m",
    "outside the ranges (f13-f16)": lambda r: (
        r["in_range"] != "True" and r["parameters"] != "deep_5000m"
    ),
    "all (f01-f16)": lambda r: True,
}
"""Groups of the field held-out set, by the columns of its rows."""


def group_means(rows: Sequence[Mapping[str, str]]) -> list[dict[str, Any]]:
    """Per group of :data:`GROUPS` and controller (with its observation mode): the number of
    scenarios, the mean IAE, the mean RMSD (kN m) and the mean stick-slip severity over the
    group's prone scenarios (``None`` without one), from the rows of a field ``heldout.csv``
    (a row without an IAE, a controller that could not run there, is left out)."""
    labels = list(dict.fromkeys(f"{r['controller']} ({r['observation']})" for r in rows))
    out: list[dict[str, Any]] = []
    for group, member in GROUPS.items():
        for label in labels:
            mine = [
                r
                for r in rows
                if f"{r['controller']} ({r['observation']})" == label and r["iae"] and member(r)
            ]
            if not mine:
                continue
            prone = [float(r["stick_slip_severity"]) for r in mine if r["prone"] == "True"]
            out.append(
                {
                    "group": group,
                    "controller": label,
                    "n": len(mine),
                    "iae": sum(float(r["iae"]) for r in mine) / len(mine),
                    "rmsd_knm": sum(float(r["rmsd_nm"]) for r in mine) / len(mine) / 1e3,
                    "severity_prone": sum(prone) / len(prone) if prone else None,
                    "n_prone": len(prone),
                }
            )
    return out


def depth_validation(
    models: Sequence[Path], depth_range_m: tuple[float, float], episodes: int
) -> list[dict[str, Any]]:
    """Per model: its validation against its base controller alone
    (:func:`agents.train.validation_score` with the model's own severity weight: the ratios of
    the mean IAE, RMSD and stick-slip severity, of the severity's interquartile means, and the
    selection score) on ``episodes`` scenarios of the field randomisation with the measured
    depth drawn from ``depth_range_m`` (m), at the validation's reset seeds and noise."""
    import gymnasium as gym

    import drill_env  # noqa: F401  (registers the envs)
    from agents.train import VALIDATION_SEED, validation_score
    from drill_env.evaluation import episode_metrics, rollout

    seeds = [VALIDATION_SEED + k for k in range(episodes)]
    out: list[dict[str, Any]] = []
    reference: dict[str, list[dict[str, float]]] = {}
    for model in models:
        policy = load_policy(model)
        record = policy.metadata.get("train_config", {})
        common = {
            "randomize": True,
            "max_episode_steps": -1,
            "episode_s": record.get("episode_s", 100.0),
            "noise_std_rad_s": record.get("noise_std_rad_s", 0.05),
            "randomization": {"measured_depth_range_m": depth_range_m},
        }
        base = policy.env_kwargs["base_controller"]
        if base not in reference:
            env = gym.make(policy.env_id, **common, **policy.env_kwargs)
            reference[base] = [episode_metrics(rollout(env, ZeroAction(), s)) for s in seeds]
        env = gym.make(policy.env_id, **common, **policy.env_kwargs)
        metrics = [episode_metrics(rollout(env, policy, s)) for s in seeds]
        weight = record.get("validation_severity_weight", 0.0)
        out.append(
            {"model": str(model), **validation_score(metrics, reference[base], weight)._asdict()}
        )
    return out


def group_table(heldout_csv: Path) -> str:
    """:func:`group_means` of ``heldout_csv`` as a markdown table."""
    from experiments.tables import Column, markdown_table

    with heldout_csv.open(newline="") as f:
        rows = list(csv.DictReader(f))
    columns = [
        Column("group", "held-out group", align="left"),
        Column("controller", "controller", align="left"),
        Column("n", "scenarios"),
        Column("iae", "mean IAE", "{:.1f}"),
        Column("rmsd_knm", "mean RMSD (kN m)", "{:.2f}"),
        Column("severity_prone", "mean severity, prone", "{:.3f}"),
        Column("n_prone", "prone scenarios"),
    ]
    return markdown_table(group_means(rows), columns)


def scenario_figures(model: Path, out: Path) -> list[Path]:
    """:data:`FIGURE_SCENARIOS` with the agent of ``model`` and :data:`LOOPS`, each checked
    for overlapping or cut-off text, as ``out/field_agent_<id>.png``."""
    from experiments.evaluate import FIELD_HELD_OUT, run_scenario
    from experiments.plots import trace_response_figure

    agent = load_policy(model)
    common = {k: v for k, v in agent.env_kwargs.items() if k != "base_controller"}
    written = []
    for held_out in (s for s in FIELD_HELD_OUT if s.id in FIGURE_SCENARIOS):
        traces = {
            f"{loop} (surface)": run_scenario(
                held_out, ZeroAction(), {**common, "base_controller": loop}, FIELD_ENV_ID
            )
            for loop in LOOPS
        }
        traces[f"{agent.name} (surface)"] = run_scenario(
            held_out, agent, agent.env_kwargs, FIELD_ENV_ID
        )
        case = held_out.field
        assert case is not None
        wob = f"{case.wob.initial_n / 1e3:.0f} kN"
        if case.wob.final_n is not None:
            wob += f" -> {case.wob.final_n / 1e3:.0f} kN at {case.wob.step_time_s:g} s"
        title = (
            f"{case.id}: {case.parameters} at {case.measured_depth_m:,.0f} m, "
            f"{case.reference_rpm:g} rpm, WOB {wob}, {case.condition.name} friction and damping"
        )
        fig = trace_response_figure(traces, title)
        problems = text_problems(fig)
        if problems:
            raise RuntimeError(f"figure of {held_out.id}: {problems}")
        written.append(save_figure(fig, out / f"{NAME}_{held_out.id}.png"))
    return written


def ship(model: Path, source: str) -> Path:
    """Copy the model folder ``model`` to ``agents/models/field_agent/`` with ``source`` (the
    command that retrains it) in its record and the folders of the run that trained it left
    out (they name the trainer's machine, not the command); ``model`` may be that folder
    itself."""
    policy = load_policy(model)  # read before the target is cleared
    policy.metadata["source"] = source
    record = policy.metadata.get("train_config")
    if isinstance(record, dict):
        record.update(run_dir="", save_dir="")
    target = DEFAULT_MODEL_DIR / NAME
    if target.exists():
        shutil.rmtree(target)
    return policy.save(target)


def curves(runs: dict[str, Path], figure: Path) -> Path:
    """The validation ratios to the base controller (IAE, RMSD, severity) and the training
    return of ``runs``, as one figure."""
    from experiments.plots import learning_curves_figure

    fig = learning_curves_figure(
        runs,
        "field agent on the validation set",
        reference="soft_speed alone",
        short="soft_speed",
        goal=None,
        severity=True,
    )
    problems = text_problems(fig)
    if problems:
        raise RuntimeError(f"learning curves: {problems}")
    return save_figure(fig, figure)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="runs/field-agent", help="folder of the run")
    parser.add_argument(
        "--seed",
        type=int,
        default=TrainConfig.for_env(FIELD_ENV_ID).seed,
        help="seed of the run (the field default)",
    )
    parser.add_argument(
        "--ship", action="store_true", help="copy the model to agents/models/ and the figure"
    )
    parser.add_argument(
        "--curves",
        nargs="+",
        metavar="LABEL=RUN_DIR",
        default=None,
        help="only draw the learning curves of these finished runs",
    )
    parser.add_argument("--figure", type=Path, default=None, help="where --curves draws")
    parser.add_argument(
        "--figures",
        nargs="?",
        const=DEFAULT_MODEL_DIR / NAME,
        type=Path,
        default=None,
        metavar="MODEL",
        help="only draw the hardest held-out scenarios with this model (default: the shipped "
        "one) into docs/reports/figures/",
    )
    parser.add_argument(
        "--groups",
        type=Path,
        default=None,
        metavar="HELDOUT_CSV",
        help="only print the group means of a field heldout.csv",
    )
    parser.add_argument(
        "--depth-validation",
        nargs="+",
        default=None,
        metavar="ARG",
        help="LOW HIGH N MODEL ...: validation ratios on depths LOW-HIGH m only",
    )
    parser.add_argument(
        "--ship-model",
        type=Path,
        default=None,
        metavar="MODEL",
        help="only ship this model of a finished run of the default command",
    )
    parser.add_argument(
        "--wall-s", type=float, default=None, help="wall time of that run, s (with --ship-model)"
    )
    args = parser.parse_args()
    if args.groups:
        print(group_table(args.groups))
        return
    if args.depth_validation:
        try:
            low, high, n, *models = args.depth_validation
            depths_m, episodes = (float(low), float(high)), int(n)
        except ValueError:
            parser.error("--depth-validation: expected LOW HIGH N MODEL ... (m, m, episodes)")
        if not (0 < depths_m[0] <= depths_m[1] and episodes >= 1 and models):
            parser.error("--depth-validation: allowed 0 < LOW <= HIGH m, N >= 1, a MODEL")
        rows = depth_validation([Path(m) for m in models], depths_m, episodes)
        for row in rows:
            print(
                f"{row['model']}: IAE ratio {row['iae_ratio']:.3f}, RMSD ratio "
                f"{row['rmsd_ratio']:.3f}, severity ratio {row['severity_ratio']:.3f} (of the "
                f"IQMs {row['severity_iqm_ratio']:.3f}), score {row['score']:.3f}"
            )
        return
    if args.ship_model:
        record = load_policy(args.ship_model).metadata
        seed = record["train_config"]["seed"]
        selected = record.get("selected", "best on validation")
        timed = "" if args.wall_s is None else f", {args.wall_s:.0f} s wall"
        source = f"{RETRAIN} --seed {seed} (the selected model: {selected}{timed})"
        print(f"shipped to {ship(args.ship_model, source)}")
        return
    if args.figures:
        for path in scenario_figures(args.figures, FIGURE.parent):
            print(f"figure: {path}")
        return
    if args.curves:
        runs = dict(
            (label, Path(folder)) for label, folder in (c.rsplit("=", 1) for c in args.curves)
        )
        print(f"learning curves: {curves(runs, args.figure or FIGURE)}")
        return
    from agents.train import train

    run_dir = Path(args.out) / NAME
    config = TrainConfig.for_env(FIELD_ENV_ID, seed=args.seed, run_dir=str(run_dir))
    t0 = time.perf_counter()
    model_dir = train(config)
    wall = time.perf_counter() - t0
    record = json.loads((model_dir / "config.json").read_text())
    print(
        f"{NAME}: {wall:.0f} s wall ({record['wall_time_s']} s in PPO.learn), "
        f"{record['run_timesteps']} decisions; model at {record['timesteps']} ({record['selected']})"
    )
    if args.ship:
        source = (
            f"{RETRAIN} --seed {args.seed} (benchmarks/field_agent.py --ship: {wall:.0f} s wall)"
        )
        print(f"  shipped to {ship(model_dir, source)}")
    figure = FIGURE if args.ship else Path(args.out) / FIGURE.name
    print(f"learning curves: {curves({NAME: run_dir}, figure)}")


if __name__ == "__main__":
    main()
