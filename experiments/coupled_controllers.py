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

Every episode (a grid run, an evaluation episode of the agent or of its base loops) is an item
of the sweep runner (:class:`CoupledStudy`, :mod:`experiments.sweep`): serially by default, on
Ray with ``--workers N``, into the SQLite results database ``OUT/coupled_controllers.sqlite``
with ``--results`` (or on Ray, ``--resume``); ``--resume`` runs only the missing episodes and
the tables are made from the records, so they are those of a clean run.
"""

from __future__ import annotations

import math
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
from experiments.controllers import refuse_on_ray
from experiments.paths import output_file
from experiments.plots import save_figure
from experiments.results_db import Exactly, Fields, Flag, Name, Number, Schema, Values, exactly
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import (
    Backend,
    RunnerSpec,
    Task,
    TaskResult,
    agent_fingerprint,
    check_task_size,
    chunks,
    run_sweep,
)
from experiments.tables import Column, markdown_table, write_csv, write_json

__all__ = [
    "AXIAL_LOOPS",
    "TORQUE_LOOPS",
    "CoupledControllersSpec",
    "CoupledStudy",
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


def agent_episode(policy: Any, agent: bool, episode: int) -> dict[str, Any]:
    """One randomised episode (reset seed ``AGENT_SEED + episode``) of ``DrillStringCoupled-v0``
    with ``policy``'s env keywords, driven by ``policy`` (``agent``) or by its base loops alone
    (zero action): per decision, the reward, each reward term, the applied force (N) and the
    top-drive torque (N m); the episode metrics at its end."""
    env = gym.make(drill_env.COUPLED_ENV_ID, **policy.env_kwargs).unwrapped
    assert isinstance(env, DrillStringCoupledEnv)
    steps: dict[str, list[float]] = {}
    obs, _ = env.reset(seed=AGENT_SEED + episode)
    done = False
    while not done:
        if agent:
            action, _ = policy.predict(obs, deterministic=True)
        else:
            action = np.zeros(2 if env.config.action_mode == "both" else 1, np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        done = terminated or truncated
        for key, value in {
            "reward": float(reward),
            **info["reward_terms"],
            "applied_force_n": info["applied_force_n"],
            "applied_force_sq": info["applied_force_n"] ** 2,
            "torque_nm": info["top_drive_torque_nm"],
        }.items():
            steps.setdefault(key, []).append(float(value))
    metrics = env.episode_metrics()
    return {
        "controller": _agent_label(policy, agent),
        "episode": episode,
        "reset_seed": AGENT_SEED + episode,
        "keys": list(steps),
        "steps": list(steps.values()),
        "metrics": {key: float(metrics[key]) for key in AGENT_METRICS},
    }


AGENT_METRICS: Final = ("rop_m_s", "stuck_fraction", "bounce_fraction", "mse_pa")
"""Episode metrics of an agent evaluation episode (:meth:`DrillStringCoupledEnv.episode_metrics`)."""


def _agent_label(policy: Any, agent: bool) -> str:
    return f"agent {policy.name}" if agent else "base loops"


def agent_row(episodes: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The evaluation row of one controller (the agent or its base loops) from its episodes
    (:func:`agent_episode`, in episode order): the mean of each reward term per decision over
    every decision, the episode metrics averaged over the episodes."""
    sums: dict[str, float] = {}
    decisions = 0
    for record in episodes:
        columns = dict(zip(record["keys"], record["steps"], strict=True))
        for k in range(len(record["steps"][0])):
            decisions += 1
            for key, values in columns.items():
                sums[key] = sums.get(key, 0.0) + values[k]
    row: dict[str, Any] = {key: value / decisions for key, value in sums.items()}
    metrics = [record["metrics"] for record in episodes]
    row.update(
        controller=episodes[0]["controller"],
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
    return row


def load_coupled_agent(model: Path) -> Any:
    """The ``DrillStringCoupled-v0`` model at ``model``.

    Raises:
        ValueError: it is a model for another env (or no model).
    """
    policy = load_policy(model)
    if policy.env_id != drill_env.COUPLED_ENV_ID:
        raise ValueError(f"{str(model)!r} is a model for {policy.env_id}, not the coupled env")
    return policy


def evaluate_agent(model: Path, episodes: int) -> list[dict[str, Any]]:
    """A trained ``DrillStringCoupled-v0`` agent and its base loops alone (zero action) on the
    same randomised episodes (reset seeds ``AGENT_SEED + k``): the mean of each reward term
    per decision and the episode metrics, averaged over the episodes (serially, through the
    runner)."""
    study = CoupledStudy(agent=load_coupled_agent(model), agent_episodes=episodes, grid=False)
    return study.agent_rows(run_sweep(study, Backend(), progress=False).records)


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
    return spec_parser(
        "drill-gym coupled-controllers", DESCRIPTION, CoupledControllersSpec, RunnerSpec
    )


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym coupled-controllers``: run the grid, print the tables, write the files."""
    parser = _parser()
    args = parser.parse_args(argv)
    runner = spec_from_args(RunnerSpec, args)
    spec = spec_from_args(CoupledControllersSpec, args)
    refuse_on_ray(
        parser.fail, runner.backend().distributed, [n for n in spec.torque_loops if n != "pi"]
    )
    return run_study(spec, runner)


# ---------------------------------------------------------------------------- the study
def grid_item(torque_loop: str, axial_loop: str, force_kn: float, speed_rad_s: float) -> str:
    """The item key of one grid run."""
    return f"{torque_loop}/{axial_loop}/W0={float(force_kn)!r}kN/ref={float(speed_rad_s)!r}"


def agent_item(agent: bool, episode: int) -> str:
    """The item key of one evaluation episode of the agent (or of its base loops)."""
    return f"{'agent' if agent else 'base loops'}/episode={episode}"


GridPoint = tuple[str, str, float, float]
"""``(top-drive loop, axial loop, applied force in kN, reference speed in rad/s)``."""


def coupled_points_task(points: Sequence[GridPoint], duration_s: float) -> TaskResult:
    """Grid runs (:func:`run_point`), records by :func:`grid_item`."""
    return TaskResult(
        {
            grid_item(*point): run_point(point[0], point[1], point[2] * 1e3, point[3], duration_s)
            for point in points
        }
    )


def coupled_agent_task(policy: Any, episodes: Sequence[tuple[bool, int]]) -> TaskResult:
    """Evaluation episodes (:func:`agent_episode`) of ``(agent or base loops, episode)``,
    records by :func:`agent_item`."""
    return TaskResult(
        {agent_item(agent, k): agent_episode(policy, agent, k) for agent, k in episodes}
    )


_NUMBERS: Final = tuple(c.key for c in ROW_COLUMNS[4:])
"""The scores of a grid row (``None`` in its record where not defined)."""


@dataclass(frozen=True)
class CoupledStudy:
    """The study on the sweep runner: an item is one grid run (top-drive loop, axial loop,
    applied force, reference speed) or one evaluation episode of the agent or its base loops;
    a task ``task_items`` of them.

    Attributes: as :class:`CoupledControllersSpec` (``grid``: run the grid), ``agent`` the
    loaded ``DrillStringCoupled-v0`` model (``None``: no evaluation).
    """

    torque_loops: tuple[str, ...] = TORQUE_LOOPS
    axial_loops: tuple[str, ...] = tuple(AXIAL_LOOPS)
    forces_kn: tuple[float, ...] = DEFAULT_FORCES_KN
    speeds_rad_s: tuple[float, ...] = DEFAULT_SPEEDS_RAD_S
    duration_s: float = 30.0
    grid: bool = True
    agent: Any = field(default=None, compare=False)
    agent_episodes: int = 8
    task_items: int = 1
    name: str = "coupled-controllers"

    def __post_init__(self) -> None:
        check_task_size("task_items", self.task_items)
        if not self.grid and self.agent is None:
            raise ValueError("nothing to run: no grid and no agent")

    def points(self) -> list[GridPoint]:
        """The grid runs, in table order (axial loop, top-drive loop, force, speed)."""
        if not self.grid:
            return []
        return [
            (loop, axial, float(force), float(speed))
            for axial in self.axial_loops
            for loop in self.torque_loops
            for force in self.forces_kn
            for speed in self.speeds_rad_s
        ]

    def episodes(self) -> list[tuple[bool, int]]:
        """The evaluation episodes: the base loops' then the agent's."""
        if self.agent is None:
            return []
        return [(agent, k) for agent in (False, True) for k in range(self.agent_episodes)]

    def spec(self) -> dict[str, Any]:
        """The study's settings (not the task size)."""
        return {
            "points": [list(p) for p in self.points()],
            "duration_s": float(self.duration_s),
            "agent": agent_fingerprint(self.agent),
            "agent_episodes": int(self.agent_episodes) if self.agent is not None else 0,
            "agent_seed": AGENT_SEED,
        }

    def items(self) -> list[str]:
        """The agent's episodes, then the grid runs."""
        return [agent_item(*e) for e in self.episodes()] + [grid_item(*p) for p in self.points()]

    def record_schema(self, item: str) -> Schema:
        """A grid run's row (:func:`run_point`) or an evaluation episode
        (:func:`agent_episode`), each setting this study's."""
        for agent, k in self.episodes():
            if item == agent_item(agent, k):
                return Fields(
                    {
                        "controller": Exactly(_agent_label(self.agent, agent)),
                        "episode": Exactly(k),
                        "reset_seed": Exactly(AGENT_SEED + k),
                        "keys": Values(Name()),
                        "steps": Values(Values(Number(nullable=False))),
                        "metrics": Fields({key: Number(nullable=False) for key in AGENT_METRICS}),
                    }
                )
        loop, axial, force, speed = next(p for p in self.points() if grid_item(*p) == item)
        return Fields(
            {
                **exactly(
                    {
                        "torque_loop": loop,
                        "axial_loop": axial,
                        "applied_force_kn": force * 1e3 / 1e3,
                        "reference_rad_s": speed,
                    }
                ),
                "diverged": Flag(),
                **{key: Number() for key in _NUMBERS},
            }
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """``task_items`` missing episodes or runs per task."""
        wanted = set(missing)
        episodes = [e for e in self.episodes() if agent_item(*e) in wanted]
        points = [p for p in self.points() if grid_item(*p) in wanted]
        tasks = [
            Task(
                key="/".join(agent_item(*e) for e in block),
                function=coupled_agent_task,
                kwargs={"policy": self.agent, "episodes": block},
                items=tuple(agent_item(*e) for e in block),
            )
            for block in chunks(episodes, self.task_items)
        ]
        return tasks + [
            Task(
                key="/".join(grid_item(*p) for p in block),
                function=coupled_points_task,
                kwargs={"points": block, "duration_s": self.duration_s},
                items=tuple(grid_item(*p) for p in block),
            )
            for block in chunks(points, self.task_items)
        ]

    def agent_rows(self, records: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
        """The evaluation rows (:func:`agent_row`): the base loops', then the agent's."""
        return [
            agent_row([records[agent_item(agent, k)] for k in range(self.agent_episodes)])
            for agent in (False, True)
        ]

    def grid_rows(self, records: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
        """The grid rows in table order (an undefined score as NaN)."""
        rows = []
        for point in self.points():
            row = dict(records[grid_item(*point)])
            rows.append({k: math.nan if v is None and k in _NUMBERS else v for k, v in row.items()})
        return rows


def run_study(spec: CoupledControllersSpec, runner: RunnerSpec | None = None) -> int:
    """Run what ``spec`` asks for on the runner ``runner`` (default: serially, no results
    database), print the tables, write the files; returns the exit code."""
    runner = runner or RunnerSpec()
    if spec.agent is not None and not spec.agent.exists():
        raise ValueError(f"--agent: {str(spec.agent)!r} does not exist")
    agent = None
    if spec.agent is not None:
        try:
            agent = load_coupled_agent(spec.agent)
        except ValueError as err:
            raise ValueError(f"--agent: {err}") from None
    out = spec.out  # made by the first write, once every input is checked
    if spec.no_grid and agent is None:
        return 0
    study = CoupledStudy(
        torque_loops=spec.torque_loops,
        axial_loops=spec.axial_loops,
        forces_kn=spec.forces_kn,
        speeds_rad_s=spec.speeds_rad_s,
        duration_s=spec.duration_s,
        grid=not spec.no_grid,
        agent=agent,
        agent_episodes=spec.agent_episodes,
        task_items=runner.task_size or 1,
    )
    started = time.perf_counter()
    outcome = runner.run(study, out / "coupled_controllers.sqlite", progress=not spec.no_progress)
    wall = time.perf_counter() - started
    if agent is not None:
        agent_rows = study.agent_rows(outcome.records)
        print(f"Agent against its base loops ({spec.agent_episodes} randomised episodes, "
              f"reset seeds {AGENT_SEED}+k; reward terms are means per decision):\n")  # fmt: skip
        print(markdown_table(agent_rows, AGENT_COLUMNS))
        print()
        write_json({"model": str(spec.agent), "rows": agent_rows}, out / "coupled_agent.json")
    if spec.no_grid:
        return 0
    rows = study.grid_rows(outcome.records)
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
        written.append(save_figure(fig, output_file(out, "figures", "coupled_controllers_map.png")))
    print(f"\nwrote {', '.join(str(w) for w in written)} ({wall:.1f} s wall for the runs)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
