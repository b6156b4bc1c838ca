"""``drill-gym coupled``: the coupled axial-torsional string with the regenerative bit
(:mod:`drill_env.coupled`, docs/coupled-model.md) at its standard operating points, and its
stability map.

1. **The standard run** at P1-P4 (:data:`drill_env.coupled.STANDARD_POINTS`): steady-drilling
   history, top drive at constant speed from ``Omega(0) = 0.9 Omega_0``, 400 s, features over
   [100, 400] s (:class:`drill_env.coupled.RunFeatures`), printed as one table.
2. **The critical speeds**: at each applied force of the map, the top-drive speed above which
   steady drilling is stable, from the roots of the linearised delay equation.
3. **The stability map** over (applied force, top-drive speed): the rightmost root's real part
   beside the simulated stick-slip and bounce fractions on the same grid.

The standard runs and the simulated map's cells are the items of a study on the sweep runner
(:class:`CoupledStudy`, :mod:`experiments.sweep`): serial by default, on Ray with
``--workers``, kept in a results database with ``--results`` and resumed with ``--resume``; the
roots (critical speeds, linear map) are computed directly, they are cheap.

Outputs (``--out``, default ``results/coupled``): ``coupled.json`` (the features, critical
speeds and maps) and ``figures/coupled_stability_map.png``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from drill_env.coupled import (
    FEATURE_SYMBOLS,
    RGD_PRESETS,
    STANDARD_DURATION_S,
    STANDARD_POINTS,
    STANDARD_WINDOW_S,
    SURFACE_RULES,
    critical_speed_rad_s,
    run_features,
    simulate,
    simulated_map,
    stability_map,
)
from drill_env.validation import shown
from experiments.arguments import ArgumentParser
from experiments.paths import output_file
from experiments.plots import save_figure
from experiments.results_db import Fields, Name, Number, Schema
from experiments.spec_cli import option, spec_from_args, spec_parser
from experiments.sweep import (
    RunnerSpec,
    Task,
    TaskResult,
    chunks,
)
from experiments.tables import Column, markdown_table, write_json

__all__ = [
    "FEATURE_COLUMNS",
    "CoupledSpec",
    "CoupledStudy",
    "cell_task",
    "main",
    "point_task",
    "run_coupled",
    "stability_figure",
]

DEFAULT_FORCES_KN: Final = (40.0, 50.0, 60.0, 75.0, 90.0, 105.0, 120.0)
"""Applied forces of the map, kN."""
DEFAULT_SPEEDS_RAD_S: Final = (2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 20.0, 25.0, 30.0)
"""Top-drive speeds of the map, rad/s."""
SPEED_RANGE_RAD_S: Final = (1.0, 60.0)
"""Speeds scanned for the critical speed, rad/s."""
MAP_NAMES: Final = ("frac_stick", "frac_bounce", "om_amp_rel")
"""Features of each simulated map cell (the keys of :func:`drill_env.coupled.simulated_map`)."""
TASK_ITEMS: Final = 1
"""Default items per task: a standard run or a map cell is a task of its own."""

FEATURE_COLUMNS: Final = (
    Column("point", "point", align="left"),
    Column("applied_force_kn", "W0 (kN)", "{:.0f}"),
    Column("top_drive_speed_rad_s", "Om0 (rad/s)", "{:.0f}"),
    Column("om_amp_rel", "Om_amp_rel", "{:.4f}"),
    Column("om_rms_dev_rad_s", "Om_rms_dev (rad/s)", "{:.4f}"),
    Column("om_min_rad_s", "Om min (rad/s)", "{:.3f}"),
    Column("frac_stick", "frac_stick", "{:.4f}"),
    Column("frac_bounce", "frac_bounce", "{:.4f}"),
    Column("frac_axhold", "frac_axhold", "{:.4f}"),
    Column("frac_stick_backtorque", "frac_stick_backtorque", "{:.4f}"),
    Column("rop_mm_s", "ROP (mm/s)", "{:.4f}"),
    Column("rop_rel", "ROP_rel", "{:.4f}"),
    Column("om_mean_rad_s", "Om_mean (rad/s)", "{:.4f}"),
    Column("period_s", "period (s)", "{:.3f}"),
    Column("wob_min_kn", "WOB min (kN)", "{:.2f}"),
    Column("wob_max_kn", "WOB max (kN)", "{:.2f}"),
    Column("wob_mean_kn", "WOB mean (kN)", "{:.3f}"),
    Column("tob_min_knm", "TOB min (kN m)", "{:.3f}"),
    Column("tob_max_knm", "TOB max (kN m)", "{:.3f}"),
    Column("tob_mean_knm", "TOB mean (kN m)", "{:.4f}"),
    Column("cpu_s", "CPU (s)", "{:.1f}"),
)
"""Columns of the standard-run table (the features of docs/coupled-model.md section 8)."""

CRITICAL_COLUMNS: Final = (
    Column("applied_force_kn", "W0 (kN)", "{:.0f}"),
    Column("critical_speed_rad_s", "critical Om0 (rad/s)", "{:.4f}", missing="none"),
    Column("hopf_closed_form_rad_s", "closed form 2 sqrt(2 k_a/M)/n (rad/s)", "{:.4f}"),
)

DESCRIPTION = """\
The coupled axial-torsional drill string with the regenerative (Richard-Germay-Detournay)
bit at the four operating points of the standard run, the critical top-drive speeds from the
linearised delay equation, and the stability map beside the simulated stick-slip and bounce.
Prints two tables and writes coupled.json and figures/coupled_stability_map.png into --out.
Model: docs/coupled-model.md; results: docs/reports/coupled.md.

example: drill-gym coupled --points P3 P4 --no-map
"""


def _feature_row(point: str, trace_features: Any, om_min: float, cpu_s: float) -> dict[str, Any]:
    force, speed = STANDARD_POINTS[point]
    f = dataclasses.asdict(trace_features)
    return {
        "point": point,
        "applied_force_kn": force / 1e3,
        "top_drive_speed_rad_s": speed,
        **f,
        "om_min_rad_s": om_min,
        "rop_mm_s": f["rop_m_s"] * 1e3,
        "wob_min_kn": f["wob_min_n"] / 1e3,
        "wob_max_kn": f["wob_max_n"] / 1e3,
        "wob_mean_kn": f["wob_mean_n"] / 1e3,
        "tob_min_knm": f["tob_min_nm"] / 1e3,
        "tob_max_knm": f["tob_max_nm"] / 1e3,
        "tob_mean_knm": f["tob_mean_nm"] / 1e3,
        "cpu_s": cpu_s,
    }


def stability_figure(
    forces_n: Sequence[float],
    speeds_rad_s: Sequence[float],
    abscissa: npt.NDArray[np.float64],
    critical: Sequence[float | None],
    simulated: dict[str, npt.NDArray[np.float64]] | None,
    title: str,
) -> Any:
    """The stability map: the rightmost root's real part over (speed, force) with its zero
    line and the critical speeds; beside it the simulated stick and bounce fractions with the
    linear boundary drawn over them."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import SymLogNorm
    from matplotlib.figure import Figure

    panels = 1 if simulated is None else 2
    fig = Figure(figsize=(6.0 * panels, 5.2), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, panels, squeeze=False)[0]
    force_kn = np.asarray(forces_n) / 1e3
    speeds = np.asarray(speeds_rad_s)
    limit = max(float(np.nanmax(np.abs(abscissa))), 0.1)
    norm = SymLogNorm(linthresh=0.01, vmin=-limit, vmax=limit)
    mesh = axes[0].pcolormesh(
        speeds, force_kn, abscissa, cmap="RdBu_r", norm=norm, shading="nearest"
    )
    fig.colorbar(mesh, ax=axes[0], label="max Re s of (6.1), 1/s (red: unstable)")
    crit_x = [c for c in critical if c is not None]
    crit_y = [f for f, c in zip(force_kn, critical, strict=True) if c is not None]
    for ax in axes:
        ax.plot(crit_x, crit_y, "k-o", ms=3, label="critical speed (roots)")
        ax.set_xlabel("top-drive speed (rad/s)")
        ax.set_ylabel("applied force (kN)")
    for point, (force, speed) in STANDARD_POINTS.items():
        for ax in axes:
            ax.annotate(point, (speed, force / 1e3), xytext=(3, 3), textcoords="offset points",
                        color="k", fontsize=9, weight="bold")  # fmt: skip
    axes[0].set_title("linear: rightmost root of steady drilling")
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside lower left", fontsize=8)
    if simulated is not None:
        stick = axes[1].pcolormesh(
            speeds, force_kn, simulated["frac_stick"], cmap="viridis", vmin=0, vmax=1, shading="nearest"
        )  # fmt: skip
        fig.colorbar(stick, ax=axes[1], label="stuck fraction")
        bounce = simulated["frac_bounce"]
        ys, xs = np.nonzero(bounce > 0)
        marks = axes[1].scatter(speeds[xs], force_kn[ys], s=14 + 400 * bounce[ys, xs], marker="x",
                                color="tab:red", label="bounce (size: fraction off the rock)")  # fmt: skip
        axes[1].set_title("simulated: stick-slip and bounce")
        fig.legend([marks], [marks.get_label()], loc="outside lower right", fontsize=8)
    fig.suptitle(title)
    return fig


def point_task(
    parameters: str,
    points: Sequence[str],
    duration_s: float,
    window_s: Sequence[float],
    step_s: float,
    surface: str,
) -> TaskResult:
    """A task of the sweep runner: the standard run at each of ``points``, one feature row
    (:data:`FEATURE_COLUMNS`) per item ``point/<name>``."""
    start_s, end_s = window_s
    records = {}
    for point in points:
        force, speed = STANDARD_POINTS[point]
        cpu = time.process_time()
        trace = simulate(
            RGD_PRESETS[parameters], speed, force, duration_s, step_s=step_s, surface=surface
        )
        cpu = time.process_time() - cpu
        features = run_features(trace, (start_s, end_s))
        i1 = round(start_s / trace.step_s)
        om_min = float(trace.bit_speed_rad_s[i1:].min())
        records[f"point/{point}"] = _feature_row(point, features, om_min, cpu)
        del trace
    return TaskResult(records)


def cell_task(
    parameters: str,
    cells: Sequence[Sequence[Any]],
    duration_s: float,
    step_s: float,
    surface: str,
) -> TaskResult:
    """A task of the sweep runner: each of ``cells`` (item key, applied force in N, top-drive
    speed in rad/s) simulated as one cell of :func:`drill_env.coupled.simulated_map`, its
    features over the second half of the run."""
    records = {}
    for item, force_n, speed_rad_s in cells:
        cell = simulated_map(
            RGD_PRESETS[parameters],
            [force_n],
            [speed_rad_s],
            duration_s=duration_s,
            window_s=(duration_s / 2, duration_s),
            step_s=step_s,
            surface=surface,
        )
        records[str(item)] = {name: float(cell[name][0, 0]) for name in MAP_NAMES}
    return TaskResult(records)


@dataclass(frozen=True)
class CoupledStudy:
    """The study on the sweep runner: one item per standard run (``point/P3``) and, with the
    simulated map, one per map cell (``cell/<force index>/<speed index>``).

    Attributes:
        settings: The command's settings.
        task_items: Items per task.
    """

    settings: CoupledSpec
    task_items: int = TASK_ITEMS

    @property
    def name(self) -> str:
        """The sweep's name."""
        return "coupled"

    @property
    def simulates_map(self) -> bool:
        """Whether the simulated map is part of the study."""
        return not (self.settings.no_map or self.settings.no_simulated_map)

    def spec(self) -> dict[str, Any]:
        """Everything the results depend on."""
        s = self.settings
        return {
            "parameters": s.parameters,
            "parameter_values": dataclasses.asdict(RGD_PRESETS[s.parameters]),
            "points": list(s.points),
            "duration_s": s.duration_s,
            "window_s": list(s.window_s),
            "step_s": s.step_s,
            "surface": s.surface,
            "map": self.simulates_map,
            "forces_kn": list(s.forces_kn),
            "speeds_rad_s": list(s.speeds_rad_s),
            "map_duration_s": s.map_duration_s,
        }

    def cells(self) -> list[tuple[str, float, float]]:
        """The simulated map's cells: item key, applied force (N), top-drive speed (rad/s)."""
        if not self.simulates_map:
            return []
        return [
            (f"cell/{i}/{j}", force * 1e3, speed)
            for i, force in enumerate(self.settings.forces_kn)
            for j, speed in enumerate(self.settings.speeds_rad_s)
        ]

    def items(self) -> list[str]:
        """Every item key: the standard runs, then the map cells row by row."""
        return [f"point/{p}" for p in self.settings.points] + [c[0] for c in self.cells()]

    def record_schema(self, item: str) -> Schema:
        """A feature row (the point's name and numbers) or a cell's fractions."""
        if item.startswith("point/"):
            return Fields({"point": Name()}, rest=Number())
        unit = Number(nullable=False, low=0.0, high=1.0)
        return Fields({"frac_stick": unit, "frac_bounce": unit, "om_amp_rel": Number()})

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """The missing standard runs and cells in tasks of :attr:`task_items`."""
        s = self.settings
        wanted = set(missing)
        points = [p for p in s.points if f"point/{p}" in wanted]
        tasks = [
            Task(
                f"coupled/point/{chunk[0]}",
                point_task,
                {
                    "parameters": s.parameters,
                    "points": chunk,
                    "duration_s": s.duration_s,
                    "window_s": list(s.window_s),
                    "step_s": s.step_s,
                    "surface": s.surface,
                },
                tuple(f"point/{p}" for p in chunk),
            )
            for chunk in chunks(points, self.task_items)
        ]
        cells = [list(c) for c in self.cells() if c[0] in wanted]
        tasks += [
            Task(
                f"coupled/{chunk[0][0]}",
                cell_task,
                {
                    "parameters": s.parameters,
                    "cells": chunk,
                    "duration_s": s.map_duration_s,
                    "step_s": s.step_s,
                    "surface": s.surface,
                },
                tuple(c[0] for c in chunk),
            )
            for chunk in chunks(cells, self.task_items)
        ]
        return tasks

    def simulated(self, records: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
        """The simulated map from the cells' records: each feature as (forces, speeds)."""
        shape = (len(self.settings.forces_kn), len(self.settings.speeds_rad_s))
        result = {name: np.zeros(shape) for name in MAP_NAMES}
        for item, *_ in self.cells():
            i, j = (int(k) for k in item.split("/")[1:])
            for name in MAP_NAMES:
                value = records[item][name]
                result[name][i, j] = math.nan if value is None else value
        return result


@dataclass(frozen=True)
class CoupledSpec:
    """Settings of ``drill-gym coupled`` (each field is the option of the same name)."""

    parameters: str = field(default="rgd_a", metadata=option(choices=tuple(sorted(RGD_PRESETS))))
    """parameter set"""
    points: tuple[str, ...] = field(
        default=tuple(STANDARD_POINTS), metadata=option(choices=tuple(STANDARD_POINTS))
    )
    """operating points of the standard run"""
    duration_s: float = field(
        default=STANDARD_DURATION_S,
        metadata=option(
            low=0.0, high=2000.0, open_low=True, unit="s", metavar="S", aliases=("--duration",)
        ),
    )
    """length of each standard run, s"""
    window_s: tuple[float, ...] = field(
        default=STANDARD_WINDOW_S,
        metadata=option(low=0.0, high=2000.0, unit="s", metavar="S", flag="--window"),
    )
    """window of the features: START END, s"""
    step_s: float = field(
        default=1e-4, metadata=option(low=1e-7, high=1e-4, unit="s", metavar="S", flag="--step")
    )
    """integration step, s"""
    surface: str = field(default="max", metadata=option(choices=SURFACE_RULES))
    """rock-surface rule"""
    forces_kn: tuple[float, ...] = field(
        default=DEFAULT_FORCES_KN,
        metadata=option(low=0.0, high=1e5, open_low=True, unit="kN", metavar="KN", flag="--forces"),
    )
    """applied forces of the map and of the critical speeds, kN"""
    speeds_rad_s: tuple[float, ...] = field(
        default=DEFAULT_SPEEDS_RAD_S,
        metadata=option(
            low=0.0, high=1000.0, open_low=True, unit="rad/s", metavar="RAD_S", flag="--speeds"
        ),
    )
    """top-drive speeds of the map, rad/s"""
    map_duration_s: float = field(
        default=100.0,
        metadata=option(
            low=0.0, high=2000.0, open_low=True, unit="s", metavar="S", flag="--map-duration"
        ),
    )
    """length of each simulated run of the map, s (features over its second half)"""
    no_map: bool = False
    """skip the stability maps"""
    no_simulated_map: bool = False
    """map the roots only, simulate no grid"""
    out: Path = field(default=Path("results/coupled"), metadata=option(metavar="DIR"))
    """output folder"""
    no_plots: bool = False
    """write no figure"""
    no_progress: bool = False
    """no progress lines"""

    def __post_init__(self) -> None:
        if len(self.window_s) != 2:
            raise ValueError(
                f"--window: {' '.join(f'{w:g}' for w in self.window_s)}: allowed two values, "
                "START END"
            )
        start_s, end_s = self.window_s
        if not start_s < end_s <= self.duration_s:
            raise ValueError(
                f"--window: {start_s:g} {end_s:g} is out of range: allowed START < END <= "
                "--duration-s"
            )
        if self.parameters not in RGD_PRESETS:
            raise ValueError(
                f"--parameters: {shown(self.parameters)} is not valid: allowed "
                f"{', '.join(sorted(RGD_PRESETS))}"
            )
        floor_kn = RGD_PRESETS[self.parameters].contact_force_n / 1e3
        for force in self.forces_kn:
            if force <= floor_kn:
                raise ValueError(
                    f"--forces: {force:g} is out of range: allowed > W_f_bar = {floor_kn:g} kN"
                )


def _parser() -> ArgumentParser:
    return spec_parser("drill-gym coupled", DESCRIPTION, CoupledSpec, RunnerSpec)


def main(argv: Sequence[str] | None = None) -> int:
    """``drill-gym coupled``: run, print the tables, write ``coupled.json`` and the figure."""
    args = _parser().parse_args(argv)
    return run_coupled(spec_from_args(CoupledSpec, args), spec_from_args(RunnerSpec, args))


def run_coupled(spec: CoupledSpec, runner: RunnerSpec | None = None) -> int:
    """Run the study of ``spec`` on ``runner`` (default: serially), print its tables, write
    ``coupled.json`` and the figure."""
    runner = runner or RunnerSpec()
    start_s, end_s = spec.window_s
    parameters = RGD_PRESETS[spec.parameters]
    started = time.perf_counter()

    def note(text: str) -> None:
        if not spec.no_progress:
            print(f"coupled: {text}", file=sys.stderr)

    study = CoupledStudy(spec, runner.task_size or TASK_ITEMS)
    records: dict[str, dict[str, Any]] = {}
    if study.items():
        note(f"{len(spec.points)} standard runs, {len(study.cells())} simulated map cells")
        outcome = runner.run(study, spec.out / "coupled.sqlite", progress=not spec.no_progress)
        records = outcome.records
    rows = [records[f"point/{p}"] for p in spec.points]
    runs_s = time.perf_counter() - started
    print(f"1. Standard run ({spec.parameters}, surface '{spec.surface}', step {spec.step_s:g} s, "
          f"{spec.duration_s:g} s, features over [{start_s:g}, {end_s:g}] s):\n")  # fmt: skip
    print(markdown_table(rows, FEATURE_COLUMNS))
    what = "standard runs and simulated map" if study.simulates_map else "standard runs"
    print(f"\n({what}: {runs_s:.1f} s wall)")

    forces_n = [f * 1e3 for f in spec.forces_kn]
    hopf = 2 * np.sqrt(2 * parameters.k_a / parameters.axial_mass_kg) / parameters.blades
    critical: list[float | None] = []
    crit_rows = []
    result: dict[str, Any] = {
        "parameters": dataclasses.asdict(parameters),
        "surface": spec.surface,
        "step_s": spec.step_s,
        "duration_s": spec.duration_s,
        "window_s": [start_s, end_s],
        "feature_symbols": FEATURE_SYMBOLS,
        "standard_run": rows,
    }
    if not spec.no_map:
        note("critical speeds from the roots of the characteristic equation")
        for force in forces_n:
            try:
                value: float | None = critical_speed_rad_s(
                    parameters, force, speed_range_rad_s=SPEED_RANGE_RAD_S, grid=30
                )
            except ValueError:
                value = None
            critical.append(value)
            crit_rows.append(
                {
                    "applied_force_kn": force / 1e3,
                    "critical_speed_rad_s": value,
                    "hopf_closed_form_rad_s": hopf,
                }
            )
        print("\n2. Critical top-drive speeds (steady drilling stable above):\n")
        print(markdown_table(crit_rows, CRITICAL_COLUMNS))
        note("stability map from the roots")
        abscissa = stability_map(parameters, forces_n, spec.speeds_rad_s)
        simulated = study.simulated(records) if study.simulates_map else None
        result.update(
            critical_speeds=crit_rows,
            map_forces_n=forces_n,
            map_speeds_rad_s=list(spec.speeds_rad_s),
            rightmost_root_real=abscissa.tolist(),
            simulated=None if simulated is None else {k: v.tolist() for k, v in simulated.items()},
        )
    out = spec.out
    out.mkdir(parents=True, exist_ok=True)
    written = [write_json(result, out / "coupled.json", indent=2)]
    if not spec.no_map and not spec.no_plots:
        fig = stability_figure(
            forces_n,
            spec.speeds_rad_s,
            abscissa,
            critical,
            simulated,
            f"{spec.parameters}: steady drilling stability and simulated stick-slip/bounce",
        )
        written.append(save_figure(fig, output_file(out, "figures", "coupled_stability_map.png")))
    total_s = time.perf_counter() - started
    print(f"\nwrote {', '.join(str(w) for w in written)} ({total_s:.1f} s wall in all)")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
