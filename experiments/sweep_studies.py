"""The studies of ``drill-gym`` on the sweep runner (:mod:`experiments.sweep`): the stick-slip
map, the comparison and the held-out evaluation, split into tasks.

* :class:`MapStudy`: an item is one WOB row of one controller's map; a task is a block of
  consecutive rows, simulated by :func:`experiments.stick_slip_map.compute_map` as the strings
  of one ``gym.make_vec`` (cell ``i`` of the whole grid, WOB-major, keeps its reset seed
  ``seed + i``), so the map equals the one ``compute_map`` computes over the whole grid.
* :class:`CompareStudy`: an item is one run of the comparison
  (:func:`experiments.compare.run_comparison` of one controller, condition and noise); a task
  is a few runs.
* :class:`EvaluateStudy`: an item is one held-out scenario run by every controller and agent
  (:func:`experiments.evaluate.evaluate` of that scenario); a task is a few scenarios.

Traces for the figures travel back in memory (a task's extras), never into the results file:
after ``--resume`` the runs read from the file have none, and the commands then draw no
figures (they say so).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drill_env.control import controller_names
from experiments.stick_slip_map import DEFAULT_WINDOW_S, StickSlipMap, compute_map
from experiments.sweep import (
    COMPARE_TASK_RUNS,
    EVALUATE_TASK_SCENARIOS,
    MAP_TASK_CELLS,
    SweepOutcome,
    Task,
    TaskResult,
    chunks,
)

__all__ = [
    "COMPARE_TASK_RUNS",
    "EVALUATE_TASK_SCENARIOS",
    "MAP_TASK_CELLS",
    "CompareStudy",
    "EvaluateStudy",
    "MapStudy",
    "agent_fingerprint",
    "compare_runs_task",
    "evaluate_scenarios_task",
    "map_rows_task",
]


def _check_controllers(names: Sequence[str]) -> None:
    valid = controller_names()
    if not names:
        raise ValueError(f"controllers = [] is empty: allowed one or more of {', '.join(valid)}")
    for name in names:
        if name not in valid:
            raise ValueError(f"unknown controller {name!r}: valid names are {', '.join(valid)}")


def _check_task_size(name: str, value: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} = {value!r} is out of range: allowed an integer >= 1")


def agent_fingerprint(agent: Any) -> dict[str, Any] | None:
    """What identifies an agent in a sweep's spec: its name, its env keywords and a SHA-256 of
    its weights and normalisation (when it has them); ``None`` for no agent."""
    if agent is None:
        return None
    digest = hashlib.sha256()
    weights = getattr(agent, "weights", None)
    if isinstance(weights, Mapping):
        for key in sorted(weights):
            digest.update(key.encode())
            digest.update(np.ascontiguousarray(weights[key], dtype=np.float64).tobytes())
    for name in ("obs_mean", "obs_std"):
        value = getattr(agent, name, None)
        if value is not None:
            digest.update(np.ascontiguousarray(value, dtype=np.float64).tobytes())
    env_kwargs = {k: str(v) for k, v in dict(getattr(agent, "env_kwargs", {}) or {}).items()}
    return {"name": str(agent.name), "env_kwargs": env_kwargs, "sha256": digest.hexdigest()}


# ----------------------------------------------------------------------------------- maps
def map_rows_task(
    controller: str,
    rows: Sequence[int],
    wob_n: Sequence[float],
    reference_speed_rad_s: Sequence[float],
    duration_s: float,
    window_s: float,
    noise_std_rad_s: float,
    seed: int,
    parameters: str,
) -> TaskResult:
    """The WOB rows ``rows`` (consecutive indices into the whole grid; ``wob_n`` their WOB
    values) of a map: one :func:`compute_map` over them, cell ``i`` of the grid reset with
    ``seed + i``. Records ``{controller}/row{r}``: ``severity`` and ``stuck_fraction`` per
    reference speed (``None``: diverged) and the analysed ``window_s``."""
    first = int(rows[0])
    assert list(rows) == list(range(first, first + len(rows))), "rows must be consecutive"
    result = compute_map(
        controller,
        list(wob_n),
        list(reference_speed_rad_s),
        duration_s=duration_s,
        window_s=window_s,
        noise_std_rad_s=noise_std_rad_s,
        seed=seed + first * len(reference_speed_rad_s),
        parameters=parameters,
        progress=False,
    )
    records = {
        f"{controller}/row{r}": {
            "severity": result.severity[k].tolist(),
            "stuck_fraction": result.stuck_fraction[k].tolist(),
            "window_s": result.window_s,
            "duration_s": result.duration_s,
        }
        for k, r in enumerate(rows)
    }
    return TaskResult(records)


def _floats(values: Sequence[Any]) -> np.ndarray:
    """A record's list of numbers with ``None`` (a non-finite value in JSON) as NaN."""
    return np.array([math.nan if v is None else float(v) for v in values], dtype=np.float64)


@dataclass(frozen=True)
class MapStudy:
    """Stick-slip maps of ``controllers`` over the same grid on the sweep runner.

    Attributes:
        controllers: Registered controller names.
        wob_n: WOB of each grid row, N.
        reference_speed_rad_s: Reference bit speed of each grid column, rad/s.
        duration_s, window_s, noise_std_rad_s, seed, parameters: As
            :func:`experiments.stick_slip_map.compute_map`.
        task_cells: Cells per task (rounded down to whole rows, at least one row); does not
            change the numbers.
    """

    controllers: tuple[str, ...]
    wob_n: tuple[float, ...]
    reference_speed_rad_s: tuple[float, ...]
    duration_s: float = 100.0
    window_s: float = DEFAULT_WINDOW_S
    noise_std_rad_s: float = 0.0
    seed: int = 0
    parameters: str = "zribi2024"
    task_cells: int = MAP_TASK_CELLS
    name: str = "map"

    def __post_init__(self) -> None:
        _check_controllers(self.controllers)
        for label, values in (
            ("wob_n", self.wob_n),
            ("reference_speed_rad_s", self.reference_speed_rad_s),
        ):
            if not values:
                raise ValueError(f"{label} = [] is empty: the grid needs at least one value")
        _check_task_size("task_cells", self.task_cells)
        steps = self.duration_s / 0.1
        if not (math.isfinite(steps) and 0 < steps <= 1e5 and abs(steps - round(steps)) < 1e-6):
            raise ValueError(
                f"duration_s = {self.duration_s!r} is out of range: allowed (0, 10000], a "
                "multiple of 0.1 s"
            )
        if not (math.isfinite(self.window_s) and 0 < self.window_s <= self.duration_s):
            raise ValueError(
                f"window_s = {self.window_s!r} is out of range: allowed (0, duration_s = "
                f"{self.duration_s:g}]"
            )

    def spec(self) -> dict[str, Any]:
        """The map's settings (not the task size)."""
        return {
            "controllers": list(self.controllers),
            "wob_n": [float(w) for w in self.wob_n],
            "reference_speed_rad_s": [float(v) for v in self.reference_speed_rad_s],
            "duration_s": float(self.duration_s),
            "window_s": float(self.window_s),
            "noise_std_rad_s": float(self.noise_std_rad_s),
            "seed": int(self.seed),
            "parameters": self.parameters,
        }

    def items(self) -> list[str]:
        """One item per (controller, WOB row)."""
        return [f"{c}/row{r}" for c in self.controllers for r in range(len(self.wob_n))]

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """Blocks of consecutive missing rows of one controller, ``task_cells`` cells each."""
        per_task = max(1, self.task_cells // len(self.reference_speed_rad_s))
        wanted = set(missing)
        tasks: list[Task] = []
        for controller in self.controllers:
            rows = [r for r in range(len(self.wob_n)) if f"{controller}/row{r}" in wanted]
            runs: list[list[int]] = []
            for r in rows:  # consecutive runs, then blocks of per_task rows
                if runs and runs[-1][-1] == r - 1:
                    runs[-1].append(r)
                else:
                    runs.append([r])
            for run in runs:
                for block in chunks(run, per_task):
                    tasks.append(
                        Task(
                            key=f"{controller}/rows{block[0]}-{block[-1]}",
                            function=map_rows_task,
                            kwargs={
                                "controller": controller,
                                "rows": block,
                                "wob_n": [self.wob_n[r] for r in block],
                                "reference_speed_rad_s": list(self.reference_speed_rad_s),
                                "duration_s": self.duration_s,
                                "window_s": self.window_s,
                                "noise_std_rad_s": self.noise_std_rad_s,
                                "seed": self.seed,
                                "parameters": self.parameters,
                            },
                            items=tuple(f"{controller}/row{r}" for r in block),
                        )
                    )
        return tasks

    def maps(self, outcome: SweepOutcome) -> list[StickSlipMap]:
        """The maps, one per controller, from the sweep's records."""
        maps = []
        for controller in self.controllers:
            records = [outcome.records[f"{controller}/row{r}"] for r in range(len(self.wob_n))]
            maps.append(
                StickSlipMap(
                    controller=controller,
                    wob_n=np.asarray(self.wob_n, dtype=np.float64),
                    reference_speed_rad_s=np.asarray(self.reference_speed_rad_s, dtype=np.float64),
                    severity=np.stack([_floats(r["severity"]) for r in records]),
                    stuck_fraction=np.stack([_floats(r["stuck_fraction"]) for r in records]),
                    duration_s=float(records[0]["duration_s"]),
                    window_s=float(records[0]["window_s"]),
                    noise_std_rad_s=float(self.noise_std_rad_s),
                    seed=int(self.seed),
                    parameters=self.parameters,
                    wall_time_s=outcome.wall_time_s,
                )
            )
        return maps


# ----------------------------------------------------------------------------- compare
def compare_runs_task(
    runs: Sequence[tuple[str, bool, str, float]],
    duration_s: float,
    seed: int,
    reading: str,
    gains: str,
    agent: Any,
    keep_traces: bool,
) -> TaskResult:
    """Runs of the comparison, each one :func:`experiments.compare.run_comparison` of one
    controller (or the agent), one condition and one noise level; records by
    :func:`compare_item`, extras: the light traces by ``(label, condition, noise)``."""
    from experiments.compare import run_comparison

    records: dict[str, dict[str, Any]] = {}
    traces: dict[tuple[str, str, float], Any] = {}
    for label, is_agent, condition, noise in runs:
        rows, run_traces = run_comparison(
            [] if is_agent else [label], [condition], [noise], duration_s=duration_s,
            seed=seed, reading=reading, gains=gains, agent=agent if is_agent else None,
            keep_traces=keep_traces, progress=False,
        )  # fmt: skip
        records[compare_item(label, condition, noise)] = rows[0]
        traces.update(run_traces)
    return TaskResult(records, traces or None)


def compare_item(label: str, condition: str, noise: float) -> str:
    """The item key of one comparison run."""
    return f"{label}/{condition}/noise={float(noise)!r}"


@dataclass(frozen=True)
class CompareStudy:
    """The comparison (:func:`experiments.compare.run_comparison`) on the sweep runner: an
    item is one run (controller or agent, condition, noise), a task ``task_runs`` of them.

    Attributes: as :func:`experiments.compare.run_comparison`, plus ``task_runs``, the runs
    per task (does not change the numbers).
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

    def __post_init__(self) -> None:
        from experiments.compare import CONDITIONS, GAIN_PRESETS, decision_period

        _check_controllers(self.controllers)
        for label, values, allowed in (
            ("conditions", self.conditions, CONDITIONS),
            ("noises", self.noises, None),
        ):
            if not values:
                raise ValueError(f"{label} = [] is empty: the comparison needs at least one")
            if allowed is not None:
                bad = [v for v in values if v not in allowed]
                if bad:
                    raise ValueError(f"unknown condition {bad[0]!r}: allowed {', '.join(allowed)}")
        if self.gains not in GAIN_PRESETS:
            raise ValueError(f"gains = {self.gains!r}: allowed {', '.join(GAIN_PRESETS)}")
        decision_period(self.duration_s)
        _check_task_size("task_runs", self.task_runs)

    def jobs(self) -> list[tuple[str, bool, str, float]]:
        """The runs in table order, as :func:`experiments.compare.run_comparison` makes them:
        (label, is the agent, condition, noise)."""
        labels = [(c, False) for c in self.controllers]
        if self.agent is not None:
            labels.append((str(self.agent.name), True))
        return [
            (c, a, cond, float(n))
            for c, a in labels
            for cond in self.conditions
            for n in self.noises
        ]

    def spec(self) -> dict[str, Any]:
        """The comparison's settings (not the task size, nor whether traces are kept)."""
        return {
            "jobs": [list(j) for j in self.jobs()],
            "duration_s": float(self.duration_s),
            "seed": int(self.seed),
            "reading": self.reading,
            "gains": self.gains,
            "agent": agent_fingerprint(self.agent),
        }

    def items(self) -> list[str]:
        """One item per run."""
        return [compare_item(label, c, n) for label, _, c, n in self.jobs()]

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """``task_runs`` missing runs per task."""
        wanted = set(missing)
        jobs = [j for j in self.jobs() if compare_item(j[0], j[2], j[3]) in wanted]
        return [
            Task(
                key="/".join(compare_item(j[0], j[2], j[3]) for j in block),
                function=compare_runs_task,
                kwargs={
                    "runs": block,
                    "duration_s": self.duration_s,
                    "seed": self.seed,
                    "reading": self.reading,
                    "gains": self.gains,
                    "agent": self.agent if any(j[1] for j in block) else None,
                    "keep_traces": self.keep_traces,
                },
                items=tuple(compare_item(j[0], j[2], j[3]) for j in block),
            )
            for block in chunks(jobs, self.task_runs)
        ]

    def results(
        self, outcome: SweepOutcome
    ) -> tuple[list[dict[str, Any]], dict[tuple[str, str, float], Any]]:
        """The rows in table order and the traces of the runs made this time."""
        rows = [outcome.records[k] for k in self.items()]
        traces: dict[tuple[str, str, float], Any] = {}
        for extras in outcome.extras.values():
            traces.update(extras)
        return rows, traces


# ----------------------------------------------------------------------------- evaluate
def evaluate_scenarios_task(
    scenarios: Sequence[Any],
    agents: Sequence[Any],
    controllers: Sequence[str] | None,
    keep_traces: Sequence[str],
) -> TaskResult:
    """Held-out scenarios, each run by every controller and agent
    (:func:`experiments.evaluate.evaluate`); one record per scenario id (``rows``: its rows in
    table order), extras: the kept traces by ``(scenario id, label)``."""
    from experiments.evaluate import evaluate

    rows, traces = evaluate(list(agents), controllers, list(scenarios), keep_traces=keep_traces)
    records = {s.id: {"rows": [r for r in rows if r["scenario"] == s.id]} for s in scenarios}
    return TaskResult(records, traces or None)


@dataclass(frozen=True)
class EvaluateStudy:
    """The held-out evaluation (:func:`experiments.evaluate.evaluate`) on the sweep runner: an
    item is one held-out scenario run by every controller and agent (the controllers run with
    the first agent's decision period, so a scenario is the unit), a task ``task_scenarios`` of
    them.

    Attributes: as :func:`experiments.evaluate.evaluate`, plus ``task_scenarios`` (does not
    change the numbers).
    """

    agents: tuple[Any, ...]
    controllers: tuple[str, ...] | None
    scenarios: tuple[Any, ...]
    keep_traces: tuple[str, ...] = ()
    task_scenarios: int = EVALUATE_TASK_SCENARIOS
    name: str = "evaluate"

    def __post_init__(self) -> None:
        if self.controllers is not None:
            _check_controllers(self.controllers)
        if not self.scenarios:
            raise ValueError("scenarios = [] is empty: the evaluation needs at least one")
        _check_task_size("task_scenarios", self.task_scenarios)

    def spec(self) -> dict[str, Any]:
        """The evaluation's settings (not the task size, nor which traces are kept)."""
        return {
            "scenarios": [s.id for s in self.scenarios],
            "controllers": None if self.controllers is None else list(self.controllers),
            "agents": [agent_fingerprint(a) for a in self.agents],
        }

    def items(self) -> list[str]:
        """One item per held-out scenario."""
        return [s.id for s in self.scenarios]

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


# ------------------------------------------------------------------------- command lines
def _report(study_name: str, outcome: SweepOutcome, backend: Any) -> None:
    where = f"; results in {outcome.results_path}" if outcome.results_path else ""
    loaded = f", {outcome.loaded} items read from the results file" if outcome.loaded else ""
    print(
        f"sweep {study_name} on {backend.describe()}: {len(outcome.ran)} tasks run in "
        f"{outcome.wall_time_s:.1f} s{loaded}{where}"
    )


def run_map_sweep(
    args: Any, controllers: Sequence[str], wobs: Iterable[float], speeds: Iterable[float]
) -> list[StickSlipMap]:
    """``drill-gym map`` on the sweep runner (its parsed options ``args``)."""
    from pathlib import Path

    from experiments.sweep import backend_from_args, results_path_from_args, run_sweep

    study = MapStudy(
        tuple(controllers),
        tuple(float(w) for w in wobs),
        tuple(float(v) for v in speeds),
        duration_s=args.duration,
        window_s=args.window,
        noise_std_rad_s=args.noise,
        seed=args.seed,
        parameters=args.parameters,
        task_cells=args.task_size or MAP_TASK_CELLS,
    )
    backend = backend_from_args(args)
    path = results_path_from_args(args, Path(args.out) / "stick_slip_map.jsonl")
    outcome = run_sweep(study, backend, path, resume=args.resume, progress=not args.no_progress)
    _report(study.name, outcome, backend)
    return study.maps(outcome)


def run_compare_sweep(
    args: Any,
    controllers: Sequence[str],
    conditions: Sequence[str],
    noises: Sequence[float],
    agent: Any,
    keep_traces: bool,
) -> tuple[list[dict[str, Any]], dict[tuple[str, str, float], Any], bool]:
    """``drill-gym compare`` on the sweep runner: the rows, the traces and whether every run
    has its traces (not when some were read from the results file)."""
    from pathlib import Path

    from experiments.sweep import backend_from_args, results_path_from_args, run_sweep

    study = CompareStudy(
        tuple(controllers),
        tuple(conditions),
        tuple(float(n) for n in noises),
        duration_s=args.duration,
        seed=args.seed,
        reading=args.reading,
        gains=args.gains,
        agent=agent,
        keep_traces=keep_traces,
        task_runs=args.task_size or COMPARE_TASK_RUNS,
    )
    backend = backend_from_args(args)
    path = results_path_from_args(args, Path(args.out) / "compare.jsonl")
    outcome = run_sweep(study, backend, path, resume=args.resume, progress=not args.no_progress)
    _report(study.name, outcome, backend)
    rows, traces = study.results(outcome)
    return rows, traces, outcome.loaded == 0


def run_evaluate_sweep(
    args: Any,
    agents: Sequence[Any],
    controllers: Sequence[str] | None,
    scenarios: Sequence[Any],
    keep: Sequence[str],
) -> tuple[list[dict[str, Any]], dict[tuple[str, str], Any], bool]:
    """``drill-gym evaluate`` on the sweep runner: the rows, the kept traces and whether every
    run has its trace (not when some were read from the results file)."""
    from pathlib import Path

    from experiments.sweep import backend_from_args, results_path_from_args, run_sweep

    study = EvaluateStudy(
        tuple(agents),
        None if controllers is None else tuple(controllers),
        tuple(scenarios),
        keep_traces=tuple(keep) if not args.no_plots else (),
        task_scenarios=args.task_size or EVALUATE_TASK_SCENARIOS,
    )
    backend = backend_from_args(args)
    path = results_path_from_args(args, Path(args.out) / "heldout.jsonl")
    outcome = run_sweep(study, backend, path, resume=args.resume, progress=not args.no_progress)
    _report(study.name, outcome, backend)
    rows, traces = study.results(outcome)
    return rows, traces, outcome.loaded == 0
