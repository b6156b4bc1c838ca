"""Train the shipped field agent with its defaults and time it; draw learning curves.

``drill-gym train --env DrillStringField-v0`` with every other setting at the field defaults
(:data:`agents.config.ENV_DEFAULTS`): a residual PPO policy on top of ``soft_speed`` that sees
the rig's surface signals and the mud-pulse telemetry, with its last observations stacked.
Prints the wall time (the whole run: simulation, PPO updates, validations, checkpoints) and
the selected model; ``--ship`` copies the model to ``agents/models/field_agent/`` (recording
the command that retrains it) and the learning curves to ``docs/figures/``. Then
``drill-gym evaluate --env DrillStringField-v0`` scores it on the field held-out set.

``--curves LABEL=RUN_DIR ...`` only draws the learning curves of finished runs (for example
the tries of docs/field-agent.md) into ``--figure``. ``--figures [MODEL]`` only draws the
hardest held-out scenarios (:data:`FIGURE_SCENARIOS`: bit speed, top-drive speed and torque
of the agent against ``soft_speed`` and ``z_torque`` on surface signals, the same noise
samples) into ``docs/figures/field_agent_<id>.png``, from the shipped model by default.

Run from the repository root::

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/field_agent.py --ship
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

from agents.config import FIELD_ENV_ID, TrainConfig
from agents.policy import DEFAULT_MODEL_DIR, load_policy
from drill_env.evaluation import ZeroAction
from experiments.plots import plot_learning_curves, save_figure, text_problems

NAME = "field_agent"
FIGURE = Path("docs/figures/field_agent_learning_curve.png")
RETRAIN = f"drill-gym train --env {FIELD_ENV_ID}"
FIGURE_SCENARIOS = ("f02", "f04", "f10", "f15")
"""Held-out scenarios drawn: one the agent wins (f02), the hardest in the training ranges
(f04), the deep string (f10) and the point outside every range (f15)."""
LOOPS = ("soft_speed", "z_torque")
"""The rig loops drawn beside the agent (on surface signals)."""


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


def curves(runs: dict[str, Path], figure: Path) -> Path:
    """The validation ratios to the base controller (IAE, RMSD, severity) and the training
    return of ``runs``, as one figure."""
    return plot_learning_curves(
        runs,
        figure,
        "residual PPO on soft_speed, field string (validation set)",
        reference="soft_speed alone",
        short="soft_speed",
        goal=None,
        severity=True,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", default="runs/field-agent", help="folder of the run")
    parser.add_argument("--seed", type=int, default=TrainConfig.seed, help="seed of the run")
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
        "one) into docs/figures/",
    )
    args = parser.parse_args()
    if args.figures:
        for path in scenario_figures(args.figures, FIGURE.parent):
            print(f"figure: {path}")
        return
    if args.curves:
        runs = dict(
            (label, Path(folder)) for label, folder in (c.split("=", 1) for c in args.curves)
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
        policy = load_policy(model_dir)
        policy.metadata["source"] = (
            f"{RETRAIN} --seed {args.seed} (benchmarks/field_agent.py --ship: {wall:.0f} s wall)"
        )
        target = DEFAULT_MODEL_DIR / NAME
        if target.exists():
            shutil.rmtree(target)
        policy.save(target)
        print(f"  shipped to {target}")
    figure = FIGURE if args.ship else Path(args.out) / FIGURE.name
    print(f"learning curves: {curves({NAME: run_dir}, figure)}")


if __name__ == "__main__":
    main()
