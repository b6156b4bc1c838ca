"""``drill-gym coupled-controllers``: which controllers hold where on the coupled string's
stability map.

Every top-drive loop (the env's own PI speed loop ``pi``, the industry loops ``stiff_pi``,
``soft_speed``, ``z_torque`` and the sliding-mode controllers) is run on
``DrillStringCoupled-v0`` (the 4-DOF string of the paper on the regenerative bit) with each
axial loop: a fixed applied force (RGD's constant hook load, the set point) or the autodriller
(:mod:`baselines.autodriller`) feeding the hook through the string's axial spring, over a grid
of applied force (the set point) x reference speed. One deterministic episode each (nominal
rock, the bit started at 0.9 of the reference), scored over the second half of the episode:
stuck and bounce fractions, rate of penetration, mechanical specific energy (bit work over the
rock volume cut in the window), bit-speed error and the env's reward per decision.

Outputs (``--out``, default ``results/coupled-controllers``): ``coupled_controllers.json``
and ``.csv`` (one row per run) and ``figures/coupled_controllers_map.png``.
"""

from __future__ import annotations

import math
import sys
import textwrap
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import gymnasium as gym
import numpy as np

import baselines  # noqa: F401  (registers the controllers and the autodriller)
import drill_env
from agents import load_policy
from drill_env.coupled_env import DrillStringCoupledEnv
from experiments.arguments import ArgumentParser, names_type, output_folder
from experiments.plots import save_figure
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.tables import Column, markdown_table, write_csv, write_json

__all__ = [
    "AXIAL_LOOPS",
    "TORQUE_LOOPS",
    "CoupledControllersSpec",
    "main",
    "map_figure",
    "run_point",
    "run_study",
]

TORQUE_LOOPS: Final = ("pi", "stiff_pi", "soft_speed", "z_torque", "csmc", "proposed")
"""Top-drive loops of the study by default."""
AXIAL_LOOPS: Final[dict[str, dict[str, Any]]] = {
    "fixed_force": {"axial_input": "force", "force_loop": "fixed"},
    "autodriller": {"axial_input": "hook_speed", "force_loop": "autodriller"},
}
"""Axial loops of the study: the env keywords of each."""
DEFAULT_FORCES_KN: Final = (45.0, 60.0, 90.0, 120.0)
DEFAULT_SPEEDS_RAD_S: Final = (4.0, 8.0, 12.0, 20.0)
HOLD_STUCK: Final = 0.01
"""A loop holds a point when the bit is stuck less than this fraction of the window and..."""
HOLD_BOUNCE: Final = 0.01
"""... off the rock less than this fraction (and the run did not diverge)."""

ROW_COLUMNS: Final = (
    Column("torque_loop", "top drive", align="left"),
    Column("axial_loop", "axial", align="left"),
    Column("applied_force_kn", "W0 (kN)", "{:.0f}"),
    Column("reference_rad_s", "ref (rad/s)", "{:.0f}"),
    Column("stuck_fraction", "stuck", "{:.3f}"),
    Column("bounce_fraction", "bounce", "{:.3f}"),
    Column("rop_mm_s", "ROP (mm/s)", "{:.2f}"),
    Column("mse_mpa", "MSE (MPa)", "{:.1f}"),
    Column("wob_mean_kn", "WOB (kN)", "{:.1f}"),
    Column("speed_error_rel", "|w-ref|/ref", "{:.3f}"),
    Column("reward", "reward/decision", "{:.3f}"),
    Column("depth_of_cut_end_mm", "d_n at end (mm)", "{:.2f}"),
)
SUMMARY_COLUMNS: Final = (
    Column("torque_loop", "top drive", align="left"),
    Column("axial_loop", "axial", align="left"),
    Column("held", "points held", align="left"),
    Column("stalled", "stalled", "{:d}"),
    Column("diverged", "diverged", "{:d}"),
    Column("stuck_mean", "mean stuck", "{:.3f}"),
    Column("bounce_mean", "mean bounce", "{:.3f}"),
    Column("rop_mean_mm_s", "mean ROP (mm/s)", "{:.2f}"),
    Column("mse_mean_mpa", "mean MSE (MPa, drilling runs)", "{:.1f}"),
    Column("reward_mean", "mean reward", "{:.3f}"),
)

DESCRIPTION = """\
Which controllers hold where on the coupled string's stability map: every top-drive loop
with a fixed applied force and with the autodriller on DrillStringCoupled-v0, over applied
force x reference speed, scored over the second half of each episode (stuck and bounce
fractions, ROP, MSE, reward). Prints the summary and every row; writes
coupled_controllers.json/.csv and figures/coupled_controllers_map.png into --out.

example: drill-gym coupled-controllers --torque-loops stiff_pi soft_speed --forces 60 90
"""


def run_point(
    torque_loop: str, axial_loop: str, force_n: float, speed_rad_s: float, episode_s: float
) -> dict[str, Any]:
    """One deterministic episode of ``DrillStringCoupled-v0`` with the base loops only (zero
    action); the scores over its second half."""
    env = gym.make(
        drill_env.COUPLED_ENV_ID,
        torque_loop=torque_loop,
        applied_force_n=force_n,
        reference_speed_rad_s=speed_rad_s,
        episode_s=episode_s,
        randomize=False,
        **AXIAL_LOOPS[axial_loop],
    ).unwrapped
    assert isinstance(env, DrillStringCoupledEnv)
    env.reset(seed=0)
    action = np.zeros(2 if env.config.action_mode == "both" else 1, dtype=np.float32)
    steps = round(episode_s / env.config.control_dt_s)
    half = steps // 2
    sums = {"stuck": 0.0, "bounce": 0.0, "wob": 0.0, "error": 0.0, "reward": 0.0}
    mid: dict[str, float] = {}
    counted = 0
    diverged = False
    for k in range(steps):
        _, reward, terminated, _, info = env.step(action)
        if terminated:
            diverged = True
            break
        if k == half - 1:
            mid = env.episode_metrics()
        if k >= half:
            counted += 1
            sums["stuck"] += info["stuck_fraction"]
            sums["bounce"] += info["bounce_fraction"]
            sums["wob"] += info["wob_n"]
            sums["error"] += -info["reward_terms"]["speed_error"]
            sums["reward"] += float(reward)
    row: dict[str, Any] = {
        "torque_loop": torque_loop,
        "axial_loop": axial_loop,
        "applied_force_kn": force_n / 1e3,
        "reference_rad_s": speed_rad_s,
        "diverged": diverged,
    }
    if diverged or counted == 0:
        return {**row, **dict.fromkeys([c.key for c in ROW_COLUMNS[4:]], math.nan)}
    end = env.episode_metrics()
    window_s = end["time_s"] - mid["time_s"]
    volume = end["rock_volume_m3"] - mid["rock_volume_m3"]
    depth = volume / (math.pi * env.config.bit_parameters.bit_radius_m**2)
    work = end["bit_work_j"] - mid["bit_work_j"]
    weight = env.config.reward_weights.speed_error or 1.0
    return {
        **row,
        "stuck_fraction": sums["stuck"] / counted,
        "bounce_fraction": sums["bounce"] / counted,
        "rop_mm_s": 1e3 * depth / window_s,
        "mse_mpa": work / volume / 1e6 if volume > 0 else math.nan,
        "wob_mean_kn": sums["wob"] / counted / 1e3,
        "speed_error_rel": sums["error"] / counted / weight,
        "reward": sums["reward"] / counted,
        "depth_of_cut_end_mm": 1e3 * info["depth_of_cut_m"],
    }


AGENT_SEED: Final = 30_000
"""Agent evaluation episodes are reset with seeds ``AGENT_SEED + k`` (training uses the
seed of the run and its successors, validation ``agents.train.VALIDATION_SEED + k``)."""
AGENT_COLUMNS: Final = (
    Column("controller", "controller", align="left"),
    Column("reward", "reward/decision", "{:.4f}"),
    Column("rop", "rop term", "{:.4f}"),
    Column("speed_error", "speed term", "{:.4f}"),
    Column("stuck", "stuck term", "{:.4f}"),
    Column("bounce", "bounce term", "{:.4f}"),
    Column("energy", "energy term", "{:.4f}"),
    Column("rop_mm_s", "ROP (mm/s)", "{:.2f}"),
    Column("stuck_fraction", "stuck", "{:.4f}"),
    Column("bounce_fraction", "bounce", "{:.4f}"),
    Column("mse_mpa", "MSE (MPa)", "{:.1f}"),
    Column("applied_force_kn", "mean W0 (kN)", "{:.1f}"),
    Column("applied_force_std_kn", "std W0 (kN)", "{:.2f}"),
    Column("torque_knm", "mean torque (kN m)", "{:.2f}"),
)


def evaluate_agent(model: Path, episodes: int) -> list[dict[str, Any]]:
    """A trained ``DrillStringCoupled-v0`` agent and its base loops alone (zero action) on the
    same randomised episodes (reset seeds ``AGENT_SEED + k``): the mean of each reward term
    per decision and the episode metrics, averaged over the episodes."""
    policy = load_policy(model)
    if policy.env_id != drill_env.COUPLED_ENV_ID:
        raise ValueError(f"{str(model)!r} is a model for {policy.env_id}, not the coupled env")
    rows = []
    for label, agent in (("base loops", None), (f"agent {policy.name}", policy)):
        env = gym.make(drill_env.COUPLED_ENV_ID, **policy.env_kwargs).unwrapped
        assert isinstance(env, DrillStringCoupledEnv)
        sums: dict[str, float] = {}
        decisions = 0
        metrics: list[dict[str, float]] = []
        for k in range(episodes):
            obs, _ = env.reset(seed=AGENT_SEED + k)
            done = False
            while not done:
                if agent is None:
                    action = np.zeros(2 if env.config.action_mode == "both" else 1, np.float32)
                else:
                    action, _ = agent.predict(obs, deterministic=True)
                obs, reward, terminated, truncated, info = env.step(action)
                done = terminated or truncated
                decisions += 1
                for key, value in {
                    "reward": float(reward),
                    **info["reward_terms"],
                    "applied_force_n": info["applied_force_n"],
                    "applied_force_sq": info["applied_force_n"] ** 2,
                    "torque_nm": info["top_drive_torque_nm"],
                }.items():
                    sums[key] = sums.get(key, 0.0) + value
            metrics.append(env.episode_metrics())
        row: dict[str, Any] = {key: value / decisions for key, value in sums.items()}
        row.update(
            controller=label,
            rop_mm_s=1e3 * float(np.mean([m["rop_m_s"] for m in metrics])),
            stuck_fraction=float(np.mean([m["stuck_fraction"] for m in metrics])),
            bounce_fraction=float(np.mean([m["bounce_fraction"] for m in metrics])),
            mse_mpa=float(np.mean([m["mse_pa"] for m in metrics])) / 1e6,
            applied_force_kn=row["applied_force_n"] / 1e3,
            applied_force_std_kn=math.sqrt(
                max(row.pop("applied_force_sq") - row.pop("applied_force_n") ** 2, 0.0)
            )
            / 1e3,
            torque_knm=row.pop("torque_nm") / 1e3,
        )
        rows.append(row)
    return rows


def holds(row: dict[str, Any]) -> bool:
    """Whether a run holds its point: no divergence, stuck and bounce below the thresholds."""
    return (
        not row["diverged"]
        and row["stuck_fraction"] < HOLD_STUCK
        and row["bounce_fraction"] < HOLD_BOUNCE
    )


def summary(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (top-drive loop, axial loop): points held, runs stalled (the bit stuck
    through the whole window: no depth drilled), means over the grid (the MSE over the runs
    that drilled)."""
    out = []
    pairs = dict.fromkeys((r["torque_loop"], r["axial_loop"]) for r in rows)
    for torque_loop, axial_loop in pairs:
        mine = [r for r in rows if (r["torque_loop"], r["axial_loop"]) == (torque_loop, axial_loop)]
        ok = [r for r in mine if not r["diverged"]]

        def mean(key: str, runs: list[dict[str, Any]] = ok) -> float:
            values = [r[key] for r in runs if not math.isnan(r[key])]
            return float(np.mean(values)) if values else math.nan

        out.append(
            {
                "torque_loop": torque_loop,
                "axial_loop": axial_loop,
                "held": f"{sum(holds(r) for r in mine)}/{len(mine)}",
                "stalled": sum(r["rop_mm_s"] == 0.0 for r in ok),
                "diverged": len(mine) - len(ok),
                "stuck_mean": mean("stuck_fraction"),
                "bounce_mean": mean("bounce_fraction"),
                "rop_mean_mm_s": mean("rop_mm_s"),
                "mse_mean_mpa": mean("mse_mpa"),
                "reward_mean": mean("reward"),
            }
        )
    return out


def map_figure(
    rows: Sequence[dict[str, Any]],
    torque_loops: Sequence[str],
    forces_kn: Sequence[float],
    speeds_rad_s: Sequence[float],
) -> Any:
    """One panel per (axial loop, top-drive loop): the stuck fraction over (reference speed,
    applied force), a red x where the bit bounces (size: fraction off the rock), a black
    square where the run diverged, the ROP (mm/s) written in each cell."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    axials = list(dict.fromkeys(r["axial_loop"] for r in rows))
    n_cols = len(torque_loops)
    fig = Figure(figsize=(2.7 * n_cols + 1.2, 2.7 * len(axials) + 1.2), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(axials), n_cols, squeeze=False, sharex=True, sharey=True)
    speeds = np.asarray(speeds_rad_s)
    forces = np.asarray(forces_kn)
    index = {(r["torque_loop"], r["axial_loop"], r["applied_force_kn"], r["reference_rad_s"]): r
             for r in rows}  # fmt: skip
    mesh = None
    for i, axial in enumerate(axials):
        for j, loop in enumerate(torque_loops):
            ax = axes[i, j]
            stuck = np.full((forces.size, speeds.size), np.nan)
            for a, f in enumerate(forces):
                for b, s in enumerate(speeds):
                    r = index.get((loop, axial, f, s))
                    if r is None:
                        continue
                    if r["diverged"]:
                        ax.scatter([b], [a], marker="s", s=120, color="k")
                        continue
                    stuck[a, b] = r["stuck_fraction"]
                    if r["bounce_fraction"] > 0.001:
                        ax.scatter([b], [a], marker="x", color="tab:red",
                                   s=20 + 300 * r["bounce_fraction"])  # fmt: skip
                    ax.text(b, a - 0.3, f"{r['rop_mm_s']:.0f}", ha="center", va="center",
                            fontsize=7, color="w" if stuck[a, b] > 0.5 else "k")  # fmt: skip
            mesh = ax.imshow(stuck, origin="lower", cmap="viridis", vmin=0, vmax=1, aspect="auto")
            ax.set_xticks(range(speeds.size), [f"{s:g}" for s in speeds])
            ax.set_yticks(range(forces.size), [f"{f:g}" for f in forces])
            ax.set_title(f"{loop} / {axial}", fontsize=9)
            if i == len(axials) - 1:
                ax.set_xlabel("reference (rad/s)")
            if j == 0:
                ax.set_ylabel("W0 (kN)")
    assert mesh is not None
    fig.colorbar(mesh, ax=axes, label="stuck fraction", shrink=0.8)
    title = (
        "DrillStringCoupled-v0: stuck fraction (colour), bounce (red x), diverged (black), "
        "ROP mm/s (number)"
    )
    fig.suptitle(textwrap.fill(title, int(10 * fig.get_figwidth())), fontsize=10)
    return fig


def _loop_names() -> list[str]:
    return ["pi", *drill_env.controller_names()]


@dataclass(frozen=True)
class CoupledControllersSpec:
    """Settings of ``drill-gym coupled-controllers`` (each field is the option of the same
    name)."""

    torque_loops: tuple[str, ...] = field(
        default=TORQUE_LOOPS, metadata=option(parse=names_type(_loop_names, "loop"), metavar="NAME")
    )
    """top-drive loops: pi (the env's own) or registered controller names"""
    axial_loops: tuple[str, ...] = field(
        default=tuple(AXIAL_LOOPS), metadata=option(choices=tuple(AXIAL_LOOPS))
    )
    """axial loops"""
    forces_kn: tuple[float, ...] = field(
        default=DEFAULT_FORCES_KN,
        metadata=option(low=31.2, high=250.0, unit="kN", metavar="KN", flag="--forces"),
    )
    """applied-force set points, kN"""
    speeds_rad_s: tuple[float, ...] = field(
        default=DEFAULT_SPEEDS_RAD_S,
        metadata=option(low=0.5, high=100.0, unit="rad/s", metavar="RAD_S", flag="--speeds"),
    )
    """reference speeds, rad/s"""
    duration_s: float = field(
        default=30.0,
        metadata=option(low=0.1, high=1000.0, unit="s", metavar="S", aliases=("--episode",)),
    )
    """episode length, s (scored over its second half)"""
    out: Path = field(
        default=Path("results/coupled-controllers"),
        metadata=option(parse=output_folder, metavar="DIR"),
    )
    """output folder"""
    agent: Path | None = field(default=None, metadata=option(metavar="MODEL"))
    """also score this DrillStringCoupled-v0 model against its base loops"""
    agent_episodes: int = field(default=8, metadata=option(low=1, high=1000))
    """randomised episodes of the agent's evaluation"""
    no_grid: bool = False
    """skip the controllers' grid"""
    no_plots: bool = False
    """write no figure"""
    no_progress: bool = False
    """no progress lines"""


def _parser() -> ArgumentParser:
    return spec_parser("drill-gym coupled-controllers", DESCRIPTION, CoupledControllersSpec)


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym coupled-controllers``: run the grid, print the tables, write the files."""
    return run_study(spec_from_args(CoupledControllersSpec, _parser().parse_args(argv)))


def run_study(spec: CoupledControllersSpec) -> int:
    """Run what ``spec`` asks for, print the tables, write the files; returns the exit code."""
    if spec.agent is not None and not spec.agent.exists():
        raise ValueError(f"--agent: {str(spec.agent)!r} does not exist")
    out = spec.out  # made by the first write, once the agent has loaded
    if spec.agent is not None:
        try:
            agent_rows = evaluate_agent(spec.agent, spec.agent_episodes)
        except ValueError as err:
            raise ValueError(f"--agent: {err}") from None
        print(f"Agent against its base loops ({spec.agent_episodes} randomised episodes, "
              f"reset seeds {AGENT_SEED}+k; reward terms are means per decision):\n")  # fmt: skip
        print(markdown_table(agent_rows, AGENT_COLUMNS))
        print()
        write_json({"model": str(spec.agent), "rows": agent_rows}, out / "coupled_agent.json")
    if spec.no_grid:
        return 0
    started = time.perf_counter()
    rows = []
    for axial in spec.axial_loops:
        for loop in spec.torque_loops:
            if not spec.no_progress:
                print(f"coupled-controllers: {loop} / {axial}", file=sys.stderr)
            for force in spec.forces_kn:
                for speed in spec.speeds_rad_s:
                    rows.append(run_point(loop, axial, force * 1e3, speed, spec.duration_s))
    wall = time.perf_counter() - started
    print(f"Controllers on DrillStringCoupled-v0 ({spec.duration_s:g} s episodes, scored over "
          f"the second half; a point is held with stuck < {HOLD_STUCK:g} and bounce < "
          f"{HOLD_BOUNCE:g}):\n")  # fmt: skip
    table = summary(rows)
    print(markdown_table(table, SUMMARY_COLUMNS))
    print("\nEvery run:\n")
    print(markdown_table(rows, ROW_COLUMNS))
    result = {
        "episode_s": spec.duration_s,
        "forces_kn": list(spec.forces_kn),
        "speeds_rad_s": list(spec.speeds_rad_s),
        "summary": table,
        "rows": rows,
    }
    written = [
        write_json(result, out / "coupled_controllers.json", indent=2),
        write_csv(rows, out / "coupled_controllers.csv", [c.key for c in ROW_COLUMNS]),
    ]
    if not spec.no_plots:
        fig = map_figure(rows, spec.torque_loops, spec.forces_kn, spec.speeds_rad_s)
        written.append(save_figure(fig, out / "figures" / "coupled_controllers_map.png"))
    print(f"\nwrote {', '.join(str(w) for w in written)} ({wall:.1f} s wall for the runs)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
