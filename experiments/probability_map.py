"""``drill-gym probability-map``: the probability of stick-slip over WOB x reference speed (or
measured depth x reference speed) under parametric uncertainty.

A stick-slip map (``drill-gym map``) runs each cell once, on the nominal plant. A driller does
not know the plant that well: the damping of the mud, the friction at the bit and the
stiffness of the pipe are uncertain. Here every cell runs ``draws`` times from rest, each run
on a plant drawn from the env's own randomisation:

* ``DrillString-v0``: the uncertainty Deltas (relative increases of ``c_pi``, ``k_pi`` and
  ``c_dt``) of :class:`drill_env.scenarios.Randomization`, uniform over ``delta_range``
  (0 to 0.75 by default, the span of the paper's Table 3);
* ``DrillStringField-v0``: the friction and damping of
  :class:`drill_env.scenarios.FieldRandomization` (static friction ``mu_a`` 0.6-1.0, the ratio
  ``mu_0 / mu_a`` 0.5-0.8, the Stribeck rate ``xi`` 0.3-1.0 s/rad, the mud damping factor
  0.5-2), at the cell's measured depth.

WOB and reference are constant, as in the map (the randomisation's WOB and reference ranges
are set to the cell's values and its WOB step to none, so only the plant is drawn). A draw is
in stick-slip by the map's criterion (:func:`experiments.stick_slip_map.stick_slip`: the bit
sticks in the analysis window, or its severity exceeds 0.5, or the run diverged); a cell's
probability is the share of its draws in stick-slip.

Draw ``k`` of every cell uses the reset seed ``seed + k``: every cell sees the same ``draws``
plants (common random numbers), so neighbouring cells differ by their WOB, speed or depth and
not by their luck, and the numbers depend only on the settings, never on how the cells are
batched or scheduled.

The cells run on the sweep runner (:mod:`experiments.sweep`): a task is ``--task-size`` cells,
all their draws the strings of one ``gym.make_vec`` (one compiled call per step); serially,
or on Ray with ``--workers N``.

Rows: ``--rows wob`` (default) maps WOB x reference speed (on the field string at the fixed
``--depth``, by default the preset's); ``--rows depth`` (``DrillStringField-v0`` only) maps
measured depth x reference speed at the fixed ``--wob``: how the risk moves as the well gets
deeper and the pipe softer.

Outputs (``--out``): per controller ``stick_slip_probability_<name>.csv`` (columns: the row
value ``wob_n`` or ``measured_depth_m``, ``reference_speed_rad_s``, ``draws``,
``stick_slip_probability``, ``mean_severity``, ``mean_stuck_fraction``, ``diverged``) and
``stick_slip_probability_<name>.png`` (heatmap, contours at 0.1, 0.5 and 0.9).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import gymnasium as gym
import numpy as np
import numpy.typing as npt

import baselines  # noqa: F401  (registers the built-in controllers, in their order)
import drill_env
from drill_env.control import controller_names
from drill_env.distributed import DISTRIBUTED_PRESETS, resolve_distributed_parameters
from drill_env.evaluation import reset_each
from drill_env.limits import MAX_REFERENCE_RAD_S, MAX_WOB_N
from drill_env.metrics import WindowStatistics
from drill_env.parameters import PLANT_DT_S, PRESETS
from drill_env.scenarios import FieldRandomization, Randomization
from drill_env.validation import printable, shown
from experiments.arguments import (
    BASE_SEED_HIGH,
    ArgumentParser,
    check_output_option,
    names_type,
    output_folder,
)
from experiments.paths import output_path
from experiments.plots import cell_edges, new_figure, save_figure, suptitle
from experiments.results_db import Fields, Number, Schema, Values
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.stick_slip_map import DEFAULT_WINDOW_S, grid_values, stick_slip
from experiments.sweep import (
    PROBABILITY_TASK_CELLS,
    RunnerSpec,
    SweepOutcome,
    Task,
    TaskResult,
    chunks,
    run_sweep,
)
from experiments.tables import write_csv

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = [
    "CSV_COLUMNS",
    "ENVS",
    "ProbabilityMap",
    "ProbabilitySpec",
    "ProbabilityStudy",
    "main",
    "probability_cells_task",
    "probability_figure",
    "write_probability_csv",
]

ENVS: Final = (drill_env.ENV_ID, drill_env.FIELD_ENV_ID)
"""The envs a probability map runs on."""
ROW_AXES: Final = ("wob", "depth")
"""What the rows of the map are: WOB, or measured depth (the field string)."""
ROW_KEYS: Final = {"wob": "wob_n", "depth": "measured_depth_m"}
"""CSV column of the row value."""
CSV_TAIL: Final = (
    "reference_speed_rad_s",
    "draws",
    "stick_slip_probability",
    "mean_severity",
    "mean_stuck_fraction",
    "diverged",
)
CSV_COLUMNS: Final = {axis: (key, *CSV_TAIL) for axis, key in ROW_KEYS.items()}
"""Columns of the CSV by row axis, one row per cell."""
DEFAULT_DELTA_RANGE: Final = Randomization().delta_range
MAX_DEPTH_M: Final = 20_000.0
"""Deepest measured depth of a depth row (or of ``--depth``), m."""
"""Range of each uncertainty Delta on ``DrillString-v0`` (the env's default)."""
MAX_CHUNK_STEPS: Final = 1000
"""Plant steps per compiled call (1 s)."""


def _chunk_steps(total_steps: int) -> int:
    """The largest divisor of ``total_steps`` up to ``MAX_CHUNK_STEPS``."""
    return next(d for d in range(min(MAX_CHUNK_STEPS, total_steps), 0, -1) if total_steps % d == 0)


def _randomization(
    env_id: str, wob_n: float, speed: float, depth_m: float | None, delta_range: Sequence[float]
) -> Randomization | FieldRandomization:
    """The env's randomisation with WOB and reference fixed to a cell's, no WOB step, and (on
    the field string) the depth fixed: only the plant is drawn."""
    if env_id == drill_env.FIELD_ENV_ID:
        assert depth_m is not None
        return FieldRandomization(
            wob_range_n=(wob_n, wob_n),
            wob_step_probability=0.0,
            reference_range_rad_s=(speed, speed),
            measured_depth_range_m=(depth_m, depth_m),
        )
    return Randomization(
        wob_range_n=(wob_n, wob_n),
        wob_step_probability=0.0,
        reference_range_rad_s=(speed, speed),
        delta_range=(float(delta_range[0]), float(delta_range[1])),
    )


def probability_cells_task(
    env_id: str,
    controller: str,
    cells: Sequence[tuple[str, float, float, float | None]],
    draws: int,
    duration_s: float,
    window_s: float,
    noise_std_rad_s: float,
    seed: int,
    parameters: str,
    delta_range: Sequence[float],
    depth_span_m: Sequence[float] | None,
) -> TaskResult:
    """Every draw of the ``cells`` (item key, WOB in N, reference in rad/s, depth in m or
    ``None``) as the strings of one vector env; draw ``k`` reset with ``seed + k``.

    Records per cell: ``severity`` and ``stuck_fraction`` of each draw over the last
    ``window_s`` (``None``: diverged).
    """
    total_steps = round(duration_s / PLANT_DT_S)
    chunk = _chunk_steps(total_steps)
    n = len(cells) * draws
    options = [
        {"randomization": _randomization(env_id, wob, speed, depth, delta_range)}
        for _, wob, speed, depth in cells
        for _ in range(draws)
    ]
    first = cells[0]
    # The make-time randomisation spans every depth of the sweep (the engine sizes its chain
    # for the deepest string), the same for every task.
    depth0 = None if depth_span_m is None else float(depth_span_m[0])
    make_randomization = _randomization(env_id, first[1], first[2], depth0, delta_range)
    if isinstance(make_randomization, FieldRandomization) and depth_span_m is not None:
        make_randomization = FieldRandomization(
            wob_range_n=make_randomization.wob_range_n,
            wob_step_probability=0.0,
            reference_range_rad_s=make_randomization.reference_range_rad_s,
            measured_depth_range_m=(float(depth_span_m[0]), float(depth_span_m[1])),
        )
    venv = gym.make_vec(
        env_id,
        num_envs=n,
        parameters=parameters,
        randomize=True,
        randomization=make_randomization,
        base_controller=controller,
        control_dt_s=chunk * PLANT_DT_S,
        episode_s=total_steps * PLANT_DT_S,
        noise_std_rad_s=float(noise_std_rad_s),
    )
    try:
        reset_each(venv, [seed + k for _ in cells for k in range(draws)], options)
        window_start = total_steps - round(window_s / PLANT_DT_S)
        stats = WindowStatistics(n)
        diverged = np.zeros(n, dtype=bool)
        actions = np.zeros((n, 1), dtype=np.float32)
        for k in range(total_steps // chunk):
            _, _, terminated, _, _ = venv.step(actions)
            diverged |= terminated
            start = max(window_start - k * chunk, 0)
            if start >= chunk:
                continue
            samples = venv.unwrapped.plant_samples()  # type: ignore[attr-defined]
            stats.add(samples.bit_speed_rad_s[:, start:], samples.bit_stuck[:, start:])
    finally:
        venv.close()
    severity = stats.severity()
    stuck = stats.stuck_fraction()
    severity[diverged] = np.nan
    stuck[diverged] = np.nan
    records = {
        key: {
            "severity": severity[c * draws : (c + 1) * draws].tolist(),
            "stuck_fraction": stuck[c * draws : (c + 1) * draws].tolist(),
        }
        for c, (key, _, _, _) in enumerate(cells)
    }
    return TaskResult(records)


@dataclass(frozen=True)
class ProbabilityMap:
    """The probability of stick-slip of one controller over a grid.

    Attributes:
        controller: Registered controller name.
        env_id: ``DrillString-v0`` or ``DrillStringField-v0``.
        row_axis: ``wob`` (rows are WOB, N) or ``depth`` (measured depth, m).
        rows: Value of each grid row, (n_rows,): N or m.
        reference_speed_rad_s: Reference bit speed of each column, (n_speed,), rad/s.
        severity: Severity of every draw, (n_rows, n_speed, draws); NaN: diverged.
        stuck_fraction: Stuck fraction of every draw, (n_rows, n_speed, draws).
        wob_n: The fixed WOB with ``depth`` rows, N (``None`` with ``wob`` rows).
        depth_m: The fixed measured depth with ``wob`` rows on the field string, m (``None``
            otherwise).
        draws: Parameter draws per cell.
        uncertainty: What is drawn, in words.
        duration_s, window_s, noise_std_rad_s, seed, parameters: The settings.
        wall_time_s: Wall-clock time of the sweep, s.
    """

    controller: str
    env_id: str
    row_axis: str
    rows: npt.NDArray[np.float64]
    reference_speed_rad_s: npt.NDArray[np.float64]
    severity: npt.NDArray[np.float64]
    stuck_fraction: npt.NDArray[np.float64]
    wob_n: float | None
    depth_m: float | None
    draws: int
    uncertainty: str
    duration_s: float
    window_s: float
    noise_std_rad_s: float
    seed: int
    parameters: str
    wall_time_s: float

    @property
    def unstable(self) -> npt.NDArray[np.bool_]:
        """Whether each draw is in stick-slip (:func:`stick_slip`), (n_rows, n_speed, draws)."""
        return stick_slip(self.severity, self.stuck_fraction)

    @property
    def probability(self) -> npt.NDArray[np.float64]:
        """Share of the draws in stick-slip per cell, (n_rows, n_speed)."""
        result: npt.NDArray[np.float64] = self.unstable.mean(axis=2)
        return result

    def table(self) -> list[dict[str, Any]]:
        """One CSV row per cell (``CSV_COLUMNS[row_axis]``), row-major."""
        probability = self.probability
        out = []
        for i, row in enumerate(self.rows):
            for j, speed in enumerate(self.reference_speed_rad_s):
                sev = self.severity[i, j]
                ok = ~np.isnan(sev)
                out.append(
                    {
                        ROW_KEYS[self.row_axis]: f"{row:.6g}",
                        "reference_speed_rad_s": f"{speed:.6g}",
                        "draws": self.draws,
                        "stick_slip_probability": f"{probability[i, j]:.6g}",
                        "mean_severity": f"{sev[ok].mean():.6g}" if ok.any() else None,
                        "mean_stuck_fraction": (
                            f"{self.stuck_fraction[i, j][ok].mean():.6g}" if ok.any() else None
                        ),
                        "diverged": int((~ok).sum()),
                    }
                )
        return out


def write_probability_csv(result: ProbabilityMap, path: str | Path) -> Path:
    """Write the map as CSV (``CSV_COLUMNS[result.row_axis]``, one row per cell)."""
    return write_csv(result.table(), Path(path), CSV_COLUMNS[result.row_axis])


def _check(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


@dataclass(frozen=True)
class ProbabilityStudy:
    """Probability maps of ``controllers`` over one grid on the sweep runner.

    Attributes:
        env_id: ``DrillString-v0`` or ``DrillStringField-v0``.
        controllers: Registered controller names.
        row_axis: ``wob`` or ``depth`` (``DrillStringField-v0`` only).
        rows: WOB of each row (N) or measured depth (m).
        reference_speed_rad_s: Reference bit speed of each column, rad/s.
        draws: Parameter draws per cell (>= 1).
        wob_n: Fixed WOB with depth rows, N.
        depth_m: Fixed measured depth with WOB rows on the field string, m (``None``: the
            preset's).
        duration_s: Length of each run from rest, s (a multiple of 0.1 s).
        window_s: Analysis window at the end of each run, s.
        noise_std_rad_s: Measurement noise on the speeds, rad/s.
        seed: Draw ``k`` of every cell is reset with ``seed + k``.
        parameters: Plant preset (``None``: the env's default).
        delta_range: Range of each uncertainty Delta (``DrillString-v0``).
        task_cells: Cells per task (does not change the numbers).
    """

    env_id: str
    controllers: tuple[str, ...]
    row_axis: str
    rows: tuple[float, ...]
    reference_speed_rad_s: tuple[float, ...]
    draws: int = 32
    wob_n: float = 100e3
    depth_m: float | None = None
    duration_s: float = 100.0
    window_s: float = DEFAULT_WINDOW_S
    noise_std_rad_s: float = 0.0
    seed: int = 0
    parameters: str | None = None
    delta_range: tuple[float, float] = DEFAULT_DELTA_RANGE
    task_cells: int = PROBABILITY_TASK_CELLS
    name: str = "probability-map"

    def __post_init__(self) -> None:
        _check(self.env_id in ENVS, f"unknown env {shown(self.env_id)}: allowed {', '.join(ENVS)}")
        valid = controller_names()
        _check(bool(self.controllers), "controllers = [] is empty: allowed one or more names")
        for name in self.controllers:
            _check(
                name in valid,
                f"unknown controller {shown(name)}: valid names are {', '.join(valid)}",
            )
        _check(self.row_axis in ROW_AXES, f"rows = {shown(self.row_axis)}: allowed wob, depth")
        _check(
            self.row_axis == "wob" or self.field,
            f"rows = 'depth' needs the distributed string: allowed with {drill_env.FIELD_ENV_ID}",
        )
        for label, values in (
            ("rows", self.rows),
            ("reference_speed_rad_s", self.reference_speed_rad_s),
        ):
            _check(bool(values), f"{label} = [] is empty: the grid needs at least one value")
        ok = isinstance(self.draws, int) and not isinstance(self.draws, bool) and self.draws >= 1
        _check(ok, f"draws = {shown(self.draws)} is out of range: allowed an integer >= 1")
        ok = isinstance(self.task_cells, int) and self.task_cells >= 1
        _check(
            ok, f"task_cells = {shown(self.task_cells)} is out of range: allowed an integer >= 1"
        )
        steps = self.duration_s / (100 * PLANT_DT_S)
        _check(
            math.isfinite(self.duration_s)
            and 0 < self.duration_s <= 1e4
            and abs(steps - round(steps)) < 1e-6,
            f"duration_s = {shown(self.duration_s)} is out of range: allowed (0, 10000], a multiple of 0.1 s",
        )
        _check(
            math.isfinite(self.window_s) and 0 < self.window_s <= self.duration_s,
            f"window_s = {shown(self.window_s)} is out of range: allowed (0, duration_s = {self.duration_s:g}]",
        )
        _check(
            math.isfinite(self.noise_std_rad_s) and 0 <= self.noise_std_rad_s <= 10,
            f"noise_std_rad_s = {shown(self.noise_std_rad_s)} is out of range: allowed [0, 10]",
        )
        presets = DISTRIBUTED_PRESETS if self.field else PRESETS
        _check(
            self.parameters is None or self.parameters in presets,
            f"parameters = {shown(self.parameters)} is not a preset of {self.env_id}: allowed "
            f"{', '.join(sorted(presets))}",
        )
        # The randomisations validate the values of every cell (one line naming the field).
        for row in self.rows:
            for speed in self.reference_speed_rad_s:
                _randomization(self.env_id, *self._cell(row, speed), self.delta_range)

    @property
    def field(self) -> bool:
        """Whether the map is of the distributed string."""
        return self.env_id == drill_env.FIELD_ENV_ID

    @property
    def preset(self) -> str:
        """The plant preset used."""
        if self.parameters is not None:
            return self.parameters
        return "field_2500m" if self.field else "zribi2024"

    @property
    def fixed_depth_m(self) -> float | None:
        """The measured depth of WOB rows on the field string, m (``None``: not fixed)."""
        if not self.field or self.row_axis == "depth":
            return None
        if self.depth_m is not None:
            return float(self.depth_m)
        return float(resolve_distributed_parameters(self.preset).measured_depth_m)

    def _cell(self, row: float, speed: float) -> tuple[float, float, float | None]:
        """(WOB in N, reference in rad/s, depth in m or ``None``) of a cell."""
        if self.row_axis == "depth":
            return float(self.wob_n), float(speed), float(row)
        return float(row), float(speed), self.fixed_depth_m

    def spec(self) -> dict[str, Any]:
        """The settings (not the task size)."""
        return {
            "env_id": self.env_id,
            "controllers": list(self.controllers),
            "row_axis": self.row_axis,
            "rows": [float(r) for r in self.rows],
            "reference_speed_rad_s": [float(v) for v in self.reference_speed_rad_s],
            "draws": self.draws,
            "wob_n": float(self.wob_n) if self.row_axis == "depth" else None,
            "depth_m": self.fixed_depth_m,
            "duration_s": float(self.duration_s),
            "window_s": float(self.window_s),
            "noise_std_rad_s": float(self.noise_std_rad_s),
            "seed": int(self.seed),
            "parameters": self.preset,
            "delta_range": None if self.field else [float(d) for d in self.delta_range],
        }

    def _key(self, controller: str, i: int, j: int) -> str:
        return f"{controller}/{i}/{j}"

    def items(self) -> list[str]:
        """One item per (controller, row, column)."""
        return [
            self._key(c, i, j)
            for c in self.controllers
            for i in range(len(self.rows))
            for j in range(len(self.reference_speed_rad_s))
        ]

    def record_schema(self, item: str) -> Schema:
        """A cell: the severity (>= 0) and the stuck fraction (in [0, 1]) of each draw
        (``None``: diverged)."""
        return Fields(
            {
                "severity": Values(Number(low=0.0), self.draws),
                "stuck_fraction": Values(Number(low=0.0, high=1.0), self.draws),
            }
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """``task_cells`` missing cells of one controller per task."""
        wanted = set(missing)
        span: tuple[float, float] | None = None
        if self.field:
            fixed = self.fixed_depth_m
            depths = [float(d) for d in self.rows] if fixed is None else [fixed]
            span = (min(depths), max(depths))
        tasks = []
        for controller in self.controllers:
            cells = [
                (self._key(controller, i, j), *self._cell(row, speed))
                for i, row in enumerate(self.rows)
                for j, speed in enumerate(self.reference_speed_rad_s)
                if self._key(controller, i, j) in wanted
            ]
            for block in chunks(cells, self.task_cells):
                tasks.append(
                    Task(
                        key=f"{block[0][0]}..{block[-1][0]}",
                        function=probability_cells_task,
                        kwargs={
                            "env_id": self.env_id,
                            "controller": controller,
                            "cells": block,
                            "draws": self.draws,
                            "duration_s": self.duration_s,
                            "window_s": self.window_s,
                            "noise_std_rad_s": self.noise_std_rad_s,
                            "seed": self.seed,
                            "parameters": self.preset,
                            "delta_range": self.delta_range,
                            "depth_span_m": span,
                        },
                        items=tuple(cell[0] for cell in block),
                    )
                )
        return tasks

    def uncertainty(self) -> str:
        """What each draw draws, in words."""
        if self.field:
            r = FieldRandomization()
            return (
                f"mu_a {r.mu_a_range[0]:g}-{r.mu_a_range[1]:g}, mu_0/mu_a "
                f"{r.mu_0_ratio_range[0]:g}-{r.mu_0_ratio_range[1]:g}, xi {r.xi_range[0]:g}-"
                f"{r.xi_range[1]:g} s/rad, mud damping x{r.mud_damping_factor_range[0]:g}-"
                f"{r.mud_damping_factor_range[1]:g}"
            )
        lo, hi = self.delta_range
        return f"Delta of c_pi, k_pi, c_dt each uniform in [{lo:g}, {hi:g}]"

    def maps(self, outcome: SweepOutcome) -> list[ProbabilityMap]:
        """One :class:`ProbabilityMap` per controller from the sweep's records."""

        def floats(values: Sequence[Any]) -> list[float]:
            return [math.nan if v is None else float(v) for v in values]

        shape = (len(self.rows), len(self.reference_speed_rad_s), self.draws)
        out = []
        for c in self.controllers:
            cells = [outcome.records[k] for k in self.items() if k.startswith(f"{c}/")]
            out.append(
                ProbabilityMap(
                    controller=c,
                    env_id=self.env_id,
                    row_axis=self.row_axis,
                    rows=np.asarray(self.rows, dtype=np.float64),
                    reference_speed_rad_s=np.asarray(self.reference_speed_rad_s, dtype=np.float64),
                    severity=np.array([floats(r["severity"]) for r in cells]).reshape(shape),
                    stuck_fraction=np.array([floats(r["stuck_fraction"]) for r in cells]).reshape(
                        shape
                    ),
                    wob_n=float(self.wob_n) if self.row_axis == "depth" else None,
                    depth_m=self.fixed_depth_m,
                    draws=self.draws,
                    uncertainty=self.uncertainty(),
                    duration_s=float(self.duration_s),
                    window_s=float(self.window_s),
                    noise_std_rad_s=float(self.noise_std_rad_s),
                    seed=int(self.seed),
                    parameters=self.preset,
                    wall_time_s=outcome.wall_time_s,
                )
            )
        return out


# ---------------------------------------------------------------------------- command line
DESCRIPTION: Final = """\
Probability of stick-slip over WOB (or measured depth) x reference speed under parametric
uncertainty: each cell runs --draws times from rest on plants drawn from the env's
randomisation; its probability is the share of draws in stick-slip. CSV and PNG per controller
into --out (docs/reports/probability-maps.md).

example: drill-gym probability-map --wob-n 4 --speed-n 4 --draws 8 --duration-s 40 --window-s 20
"""

_WOB: Final = {"low": 0.0, "high": MAX_WOB_N, "open_low": True, "unit": "N", "metavar": "N"}
_SPEED: Final = {"low": 0.0, "high": MAX_REFERENCE_RAD_S, "open_low": True, "unit": "rad/s"}
_DEPTH: Final = {"low": 1.0, "high": MAX_DEPTH_M, "unit": "m", "metavar": "M"}
_COUNT: Final = {"low": 1, "high": 1000}
_DELTA: Final = {"low": -0.9, "high": 10.0}


@dataclass(frozen=True)
class ProbabilitySpec:
    """The settings of ``drill-gym probability-map`` (its options are these fields)."""

    env_id: str = field(
        default=drill_env.ENV_ID,
        metadata=option(choices=ENVS, flag="--env", aliases=("--env-id",)),
    )
    """the env (plant) mapped"""
    controllers: tuple[str, ...] = field(
        default=("stiff_pi",),
        metadata=option(parse=names_type(controller_names, "controller"), metavar="NAME"),
    )
    """controllers to map, by registered name"""
    rows: str = field(default="wob", metadata=option(choices=ROW_AXES))
    """rows of the map (depth: field string only)"""
    wob_min: float = field(default=40e3, metadata=option(**_WOB))
    """lowest WOB, N"""
    wob_max: float = field(default=200e3, metadata=option(**_WOB))
    """highest WOB, N"""
    wob_n: int = field(default=9, metadata=option(**_COUNT))
    """number of WOB rows"""
    wob: float = field(default=100e3, metadata=option(**_WOB))
    """the WOB of depth rows, N"""
    depth_min: float = field(default=1000.0, metadata=option(**_DEPTH))
    """shallowest depth, m"""
    depth_max: float = field(default=5000.0, metadata=option(**_DEPTH))
    """deepest depth, m"""
    depth_n: int = field(default=5, metadata=option(**_COUNT))
    """number of depths"""
    depth: float | None = field(default=None, metadata=option(**_DEPTH, default_text="preset's"))
    """measured depth of WOB rows on the field string, m"""
    speed_min: float = field(default=1.0, metadata=option(**_SPEED))
    """lowest reference speed, rad/s"""
    speed_max: float = field(default=16.0, metadata=option(**_SPEED))
    """highest reference speed, rad/s"""
    speed_n: int = field(default=8, metadata=option(**_COUNT))
    """number of reference speeds"""
    draws: int = field(default=32, metadata=option(low=1, high=100_000))
    """parameter draws per cell"""
    delta_min: float = field(default=DEFAULT_DELTA_RANGE[0], metadata=option(**_DELTA))
    """lowest uncertainty Delta (DrillString-v0)"""
    delta_max: float = field(default=DEFAULT_DELTA_RANGE[1], metadata=option(**_DELTA))
    """highest uncertainty Delta (DrillString-v0)"""
    duration_s: float = field(
        default=100.0,
        metadata=option(low=0.0, high=1e4, open_low=True, unit="s", aliases=("--duration",)),
    )
    """run length, s (a multiple of 0.1 s)"""
    window_s: float = field(
        default=DEFAULT_WINDOW_S,
        metadata=option(low=0.0, high=1e4, open_low=True, unit="s", aliases=("--window",)),
    )
    """analysed end of each run, s"""
    noise: float = field(default=0.0, metadata=option(low=0.0, high=10.0, unit="rad/s"))
    """speed measurement noise, rad/s"""
    parameters: str | None = field(
        default=None,
        metadata=option(
            choices=sorted(PRESETS) + sorted(DISTRIBUTED_PRESETS), default_text="the env's"
        ),
    )
    """plant preset"""
    out: Path = field(default=Path("results"), metadata=option(parse=output_folder, metavar="DIR"))
    """output folder"""
    seed: int = field(default=0, metadata=option(low=0, high=BASE_SEED_HIGH))
    """reset seed of draw 0 (draw k: seed + k)"""
    no_plots: bool = False
    """write the CSV files only"""
    no_progress: bool = False
    """no progress bar"""

    def __post_init__(self) -> None:
        check_output_option(self.out)
        field_env = self.env_id == drill_env.FIELD_ENV_ID
        if self.rows == "depth" and not field_env:
            raise ValueError(
                "argument --rows: depth needs the distributed string: add --env "
                + drill_env.FIELD_ENV_ID
            )
        if self.depth is not None and not field_env:
            raise ValueError(
                "argument --depth: is for the distributed string: add --env "
                + drill_env.FIELD_ENV_ID
            )
        presets = DISTRIBUTED_PRESETS if field_env else PRESETS
        if self.parameters is not None and self.parameters not in presets:
            raise ValueError(
                f"argument --parameters: {shown(self.parameters)} is not a preset of {self.env_id}: "
                f"allowed {', '.join(sorted(presets))}"
            )
        if self.window_s > self.duration_s:
            raise ValueError(
                f"argument --window-s: {self.window_s:g} is out of range: allowed (0, "
                f"--duration-s = {self.duration_s:g}] s"
            )
        if abs(round(self.duration_s * 10) - self.duration_s * 10) > 1e-6:
            raise ValueError(
                f"argument --duration-s: {self.duration_s:g} is not a multiple of 0.1 s"
            )
        if self.delta_max < self.delta_min:
            raise ValueError(
                f"argument --delta-max: {self.delta_max:g} is below --delta-min = "
                f"{self.delta_min:g}"
            )
        try:  # the grid's own checks name the option
            self.row_values()
            self.speeds()
        except ValueError as err:
            raise ValueError(f"argument {err}") from None

    def row_values(self) -> np.ndarray:
        """The WOB (N) or measured depth (m) of each row."""
        if self.rows == "depth":
            return grid_values("depth", self.depth_min, self.depth_max, self.depth_n, MAX_DEPTH_M)
        return grid_values("wob", self.wob_min, self.wob_max, self.wob_n, MAX_WOB_N)

    def speeds(self) -> np.ndarray:
        """The reference bit speed of each column, rad/s."""
        return grid_values(
            "speed", self.speed_min, self.speed_max, self.speed_n, MAX_REFERENCE_RAD_S
        )

    def study(self, task_cells: int = PROBABILITY_TASK_CELLS) -> ProbabilityStudy:
        """The study of these settings, ``task_cells`` cells per task."""
        return ProbabilityStudy(
            env_id=self.env_id,
            controllers=tuple(dict.fromkeys(self.controllers)),
            row_axis=self.rows,
            rows=tuple(float(r) for r in self.row_values()),
            reference_speed_rad_s=tuple(float(v) for v in self.speeds()),
            draws=self.draws,
            wob_n=self.wob,
            depth_m=self.depth,
            duration_s=self.duration_s,
            window_s=self.window_s,
            noise_std_rad_s=self.noise,
            seed=self.seed,
            parameters=self.parameters,
            delta_range=(self.delta_min, self.delta_max),
            task_cells=task_cells,
        )


def _parser() -> ArgumentParser:
    parser = spec_parser("drill-gym probability-map", DESCRIPTION, ProbabilitySpec, RunnerSpec)
    parser.usage = "drill-gym probability-map [OPTIONS]"
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym probability-map``: compute, write and plot; returns the exit code."""
    parser = _parser()
    args = parser.parse_args(argv)
    runner = spec_from_args(RunnerSpec, args)
    try:
        spec = spec_from_args(ProbabilitySpec, args)
        study = spec.study(runner.task_size or PROBABILITY_TASK_CELLS)
    except ValueError as err:
        parser.error(str(err))
    backend = runner.backend()
    path = runner.results_path(spec.out / "stick_slip_probability.sqlite")
    started = time.perf_counter()
    outcome = run_sweep(
        study, backend, path, runner.resume, not spec.no_progress, overwrite=runner.overwrite
    )
    print(
        f"{study.name} on {backend.describe()}: {len(study.items())} cells x {study.draws} draws "
        f"x {study.duration_s:g} s ({len(outcome.ran)} tasks run, {outcome.loaded} cells read "
        f"from the results database) in {time.perf_counter() - started:.1f} s"
        + (f"; results in {path}" if path else "")
    )
    for result in study.maps(outcome):
        name = printable(result.controller)
        stem = f"stick_slip_probability_{result.controller}"
        csv_path = output_path(spec.out, stem, suffix=".csv")
        written = [write_probability_csv(result, csv_path)]
        if not spec.no_plots:
            figure = probability_figure(result)
            written.append(save_figure(figure, output_path(spec.out, stem, suffix=".png")))
        p = result.probability
        print(
            f"{name}: probability of stick-slip {p.min():.2f} to {p.max():.2f} over "
            f"{p.size} cells ({int((p >= 0.5).sum())} cells at 0.5 or more); wrote "
            + " and ".join(str(w) for w in written)
        )
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())


# ------------------------------------------------------------- probability of stick-slip
PROBABILITY_LEVELS: Final = (0.1, 0.5, 0.9)
"""Contour lines of the probability maps."""
PROBABILITY_LABEL: Final = "probability of stick-slip (share of the draws)"
"""Colour-bar label of the probability maps."""
_ROW_LABELS: Final = {"wob": ("WOB (kN)", 1e-3), "depth": ("measured depth (m)", 1.0)}


def probability_figure(result: ProbabilityMap) -> Figure:
    """The probability of stick-slip of one controller as a heatmap over (WOB or depth) x
    reference speed, with contour lines at :data:`PROBABILITY_LEVELS` (labelled) and a
    labelled colour bar."""
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    fig = new_figure(8.0, 5.6)
    ax = fig.subplots()
    label, scale = _ROW_LABELS[result.row_axis]
    probability = result.probability
    mesh = ax.pcolormesh(
        cell_edges(result.reference_speed_rad_s),
        cell_edges(result.rows) * scale,
        probability,
        cmap="YlOrRd",
        norm=Normalize(0.0, 1.0),
        shading="flat",
    )
    fig.colorbar(mesh, ax=ax, label=PROBABILITY_LABEL)
    drawn = [v for v in PROBABILITY_LEVELS if probability.min() < v < probability.max()]
    if drawn and min(probability.shape) > 1:
        styles = {0.1: ":", 0.5: "-", 0.9: "--"}
        lines = ax.contour(
            result.reference_speed_rad_s,
            result.rows * scale,
            probability,
            levels=drawn,
            colors="black",
            linestyles=[styles.get(v, "-") for v in drawn],
            linewidths=1.6,
        )
        ax.clabel(lines, fmt="%.1f", fontsize=9, inline=True)
        handles = [
            Line2D([], [], color="black", ls=styles.get(v, "-"), lw=1.6, label=f"p = {v:g}")
            for v in drawn
        ]
        fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=10)
    ax.set_xlabel("reference bit speed (rad/s)")
    ax.set_ylabel(label)
    ax.set_title(f"{result.controller} on {result.env_id}")
    fixed = ""
    if result.wob_n is not None:
        fixed = f", WOB {result.wob_n / 1e3:g} kN"
    elif result.depth_m is not None:
        fixed = f", measured depth {result.depth_m:g} m"
    noise = "no noise" if result.noise_std_rad_s == 0 else f"noise {result.noise_std_rad_s:g} rad/s"
    suptitle(
        fig,
        f"plant {result.parameters}{fixed}; {result.draws} draws per cell ({result.uncertainty}); "
        f"runs of {result.duration_s:g} s from rest, last {result.window_s:g} s analysed, {noise}",
    )
    return fig
