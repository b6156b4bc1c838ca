"""The studies of ``drill-gym`` on the sweep runner (:mod:`experiments.sweep`): the stick-slip
map, the comparison and the held-out evaluation, split into tasks, on either env
(``DrillString-v0`` or ``DrillStringField-v0``, :data:`experiments.field.ENV_IDS`).

* :class:`MapStudy`: an item is one WOB row of one map (a controller; on the field string a
  controller, an observation mode and a measured depth); a task is a block of consecutive rows
  of one map, simulated by :func:`experiments.stick_slip_map.compute_map` as the strings of
  one ``gym.make_vec`` (cell ``i`` of the whole grid, WOB-major, keeps its reset seed
  ``seed + i``), so the map equals the one ``compute_map`` computes over the whole grid.
* :class:`CompareStudy`: an item is one run of the comparison
  (:func:`experiments.compare.run_comparison` of one controller with one observation mode,
  one case and one noise level); a task is a few runs.
* :class:`EvaluateStudy`: an item is one held-out scenario run by every controller and agent
  (:func:`experiments.evaluate.evaluate` of that scenario); a task is a few scenarios.

Each study's ``spec()`` holds everything its numbers depend on (the env, the cases, the
observation modes, the depths, the controllers' model), so a study of other settings never
reads these rows of the results database. Traces for the figures travel back in memory (a task's extras), never into the
results database: after ``--resume`` the runs read from it have none, and the commands then
draw no figures (they say so). Every record, made or read back, is checked against the study's
``record_schema`` (:mod:`experiments.results_db`).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import inspect
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, NamedTuple, TypeAlias

import numpy as np

from drill_env.control import controller_names
from drill_env.distributed import DISTRIBUTED_PRESETS, with_measured_depth
from drill_env.metrics import METRIC_KEYS
from drill_env.options import realism_keywords
from drill_env.parameters import PRESETS
from experiments.field import (
    COMPARE_DEPTHS_M,
    FIELD_ENV,
    OBSERVATIONS,
    PAPER_ENV,
    is_field,
    observations_of,
    run_label,
)
from experiments.results_db import (
    Exactly,
    Fields,
    Flag,
    Name,
    Near,
    Number,
    Schema,
    Text,
    Values,
    exactly,
)
from experiments.stick_slip_map import DEFAULT_WINDOW_S, StickSlipMap, compute_map, map_realism
from experiments.stick_slip_map import DEFAULTS as MAP_DEFAULTS
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
    "CompareJob",
    "CompareStudy",
    "EvaluateStudy",
    "MapRun",
    "MapStudy",
    "agent_fingerprint",
    "compare_item",
    "compare_runs_task",
    "evaluate_scenarios_task",
    "map_key",
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


def _check_observations(modes: Sequence[str]) -> None:
    if not modes:
        raise ValueError(
            f"observations = [] is empty: allowed one or more of {', '.join(OBSERVATIONS)}"
        )
    for mode in modes:
        if mode not in OBSERVATIONS:
            raise ValueError(
                f"observation = {mode!r} is not valid: allowed {', '.join(OBSERVATIONS)}"
            )


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
MapRun: TypeAlias = tuple[str, str | None, float | None]
"""One map of a study: (controller, observation mode, measured depth in m); the last two are
``None`` on ``DrillString-v0``."""

_ARRAY_FIELDS: Final = ("wob_n", "reference_speed_rad_s", "severity", "stuck_fraction")
"""The fields of a :class:`StickSlipMap` that are its grid and its cells (not its settings)."""
_STUDY_KEYWORDS: Final = (
    "controller", "wob_n", "reference_speed_rad_s", "duration_s", "window_s", "noise_std_rad_s",
    "seed", "parameters", "progress", "env_id", "observation", "measured_depth_m",
)  # fmt: skip
"""The :func:`compute_map` arguments a :class:`MapStudy` sets itself (not in its ``keywords``)."""


def map_key(controller: str, observation: str | None = None, depth_m: float | None = None) -> str:
    """The item prefix of one map: ``stiff_pi`` on ``DrillString-v0``, ``stiff_pi/surface/
    1500.0m`` on the field string (the depth as its exact ``repr``)."""
    if observation is None or depth_m is None:
        return controller
    return f"{controller}/{observation}/{float(depth_m)!r}m"


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
    env_id: str = PAPER_ENV,
    observation: str | None = None,
    measured_depth_m: float | None = None,
    keywords: Mapping[str, Any] | None = None,
) -> TaskResult:
    """The WOB rows ``rows`` (consecutive indices into the whole grid; ``wob_n`` their WOB
    values) of one map: one :func:`compute_map` over them (on ``env_id``, with ``observation``,
    ``measured_depth_m`` and the further compute_map ``keywords``), cell ``i`` of the grid
    reset with ``seed + i``. Records ``{map_key}/row{r}``: ``severity`` and ``stuck_fraction``
    per reference speed (``None``: diverged) and ``map``, the map's settings as compute_map
    reports them (every field of :class:`StickSlipMap` but its arrays and wall time)."""
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
        env_id=env_id,
        observation=observation,
        measured_depth_m=measured_depth_m,
        **dict(keywords or {}),
    )
    settings = {
        f.name: getattr(result, f.name)
        for f in dataclasses.fields(result)
        if f.name not in (*_ARRAY_FIELDS, "wall_time_s")
    }
    settings["seed"] = int(seed)  # the map's cell 0, not this block's
    prefix = map_key(controller, observation, measured_depth_m)
    records = {
        f"{prefix}/row{r}": {
            "severity": result.severity[k].tolist(),
            "stuck_fraction": result.stuck_fraction[k].tolist(),
            "map": settings,
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

    On ``DrillString-v0`` one map per controller; on ``DrillStringField-v0`` one per
    controller, measured depth and observation mode it can use (:meth:`runs`, the order of
    ``drill-gym map``). Each map equals the one :func:`compute_map` computes over the whole
    grid, in every field but its wall time.

    Attributes:
        controllers: Registered controller names.
        wob_n: WOB of each grid row, N.
        reference_speed_rad_s: Reference bit speed of each grid column, rad/s.
        duration_s, window_s, noise_std_rad_s, seed: As
            :func:`experiments.stick_slip_map.compute_map`.
        parameters: Plant preset of ``env_id`` (``None``: the env's default, ``zribi2024`` or
            ``field_2500m``).
        task_cells: Cells per task (rounded down to whole rows, at least one row); does not
            change the numbers.
        name: Name of the sweep.
        env_id: The env of the cells (:data:`experiments.field.ENV_IDS`).
        observations: On the field string, the observation modes to map each controller with
            (each with those it can use, :func:`experiments.field.observations_of`); not used
            on ``DrillString-v0``.
        depths_m: On the field string, the measured depths, m, one map each (empty: the
            preset's); none on ``DrillString-v0``.
        keywords: Further keywords of :func:`compute_map`, the same for every map (any it
            accepts but those the study sets itself); passed to every call and part of the
            spec.
    """

    controllers: tuple[str, ...]
    wob_n: tuple[float, ...]
    reference_speed_rad_s: tuple[float, ...]
    duration_s: float = 100.0
    window_s: float = DEFAULT_WINDOW_S
    noise_std_rad_s: float = 0.0
    seed: int = 0
    parameters: str | None = None
    task_cells: int = MAP_TASK_CELLS
    name: str = "map"
    env_id: str = PAPER_ENV
    observations: tuple[str, ...] = OBSERVATIONS
    depths_m: tuple[float, ...] = ()
    keywords: Mapping[str, Any] = field(default_factory=dict)

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
        presets = DISTRIBUTED_PRESETS if self.field else PRESETS
        if self.preset not in presets:
            raise ValueError(
                f"parameters = {self.preset!r} is not a preset of {self.env_id}: allowed "
                f"{', '.join(sorted(presets))}"
            )
        if self.field:
            _check_observations(self.observations)
            for depth in self.depths_m:
                with_measured_depth(self.preset, depth)  # a depth the string cannot have
        elif self.depths_m:
            raise ValueError(
                f"depths_m = {list(self.depths_m)!r}: measured depths are a setting of the field "
                f"string ({FIELD_ENV}), not of {self.env_id}"
            )
        accepted = set(inspect.signature(compute_map).parameters) - set(_STUDY_KEYWORDS)
        for key in self.keywords:
            if key not in accepted:
                raise ValueError(
                    f"keywords: {key!r} is not a further keyword of compute_map: allowed "
                    f"{', '.join(sorted(accepted)) or 'none'}"
                )

    @property
    def field(self) -> bool:
        """Whether the maps are of the field string (raises for an unknown env)."""
        return is_field(self.env_id)

    @property
    def preset(self) -> str:
        """The plant preset of the maps."""
        if self.parameters is not None:
            return self.parameters
        return str(MAP_DEFAULTS[self.env_id].parameters)

    def runs(self) -> list[MapRun]:
        """The maps, in the order of ``drill-gym map``: each controller, then (on the field
        string) each depth, then each observation mode the controller can use (with a level
        of realism in :attr:`keywords`, the level's observation for every controller)."""
        if not self.field:
            return list(dict.fromkeys((c, None, None) for c in self.controllers))
        depths = self.depths_m or (DISTRIBUTED_PRESETS[self.preset].measured_depth_m,)
        level = map_realism(self.env_id, self.keywords.get("realism"))
        fixed = None if level is None else (str(realism_keywords(level)["observation"]),)
        return list(
            dict.fromkeys(
                (c, o, float(d))
                for c in self.controllers
                for d in depths
                for o in (fixed or observations_of(c, self.observations))
            )
        )

    def spec(self) -> dict[str, Any]:
        """The map's settings (not the task size)."""
        return {
            "env_id": self.env_id,
            "maps": [list(run) for run in self.runs()],
            "wob_n": [float(w) for w in self.wob_n],
            "reference_speed_rad_s": [float(v) for v in self.reference_speed_rad_s],
            "duration_s": float(self.duration_s),
            "window_s": float(self.window_s),
            "noise_std_rad_s": float(self.noise_std_rad_s),
            "seed": int(self.seed),
            "parameters": self.preset,
            "keywords": dict(self.keywords),
        }

    def items(self) -> list[str]:
        """One item per (map, WOB row)."""
        return [f"{map_key(*run)}/row{r}" for run in self.runs() for r in range(len(self.wob_n))]

    @functools.cached_property
    def _run_of_prefix(self) -> dict[str, MapRun]:
        return {map_key(*run): run for run in self.runs()}

    def record_schema(self, item: str) -> Schema:
        """A WOB row: the severity (>= 0) and the stuck fraction (in [0, 1]) at each reference
        speed (``None``: diverged), and the map's settings, which must be this study's."""
        controller, observation, depth = self._run_of_prefix[item.rpartition("/row")[0]]
        speeds = len(self.reference_speed_rad_s)
        settings = {
            "controller": controller,
            "noise_std_rad_s": float(self.noise_std_rad_s),
            "seed": int(self.seed),
            "parameters": self.preset,
            "env_id": self.env_id,
            "observation": observation,
            "measured_depth_m": depth,
            "realism": map_realism(self.env_id, self.keywords.get("realism")),
        }
        return Fields(
            {
                "severity": Values(Number(low=0.0), speeds),
                "stuck_fraction": Values(Number(low=0.0, high=1.0), speeds),
                "map": Fields(
                    {
                        **exactly(settings),  # the run's duration and window in whole steps
                        "duration_s": Near(float(self.duration_s)),
                        "window_s": Near(float(self.window_s)),
                    }
                ),
            }
        )

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """Blocks of consecutive missing rows of one map, ``task_cells`` cells each."""
        per_task = max(1, self.task_cells // len(self.reference_speed_rad_s))
        wanted = set(missing)
        tasks: list[Task] = []
        for controller, observation, depth in self.runs():
            prefix = map_key(controller, observation, depth)
            rows = [r for r in range(len(self.wob_n)) if f"{prefix}/row{r}" in wanted]
            blocks: list[list[int]] = []
            for r in rows:  # consecutive runs, then blocks of per_task rows
                if blocks and blocks[-1][-1] == r - 1:
                    blocks[-1].append(r)
                else:
                    blocks.append([r])
            for run in blocks:
                for block in chunks(run, per_task):
                    tasks.append(
                        Task(
                            key=f"{prefix}/rows{block[0]}-{block[-1]}",
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
                                "parameters": self.preset,
                                "env_id": self.env_id,
                                "observation": observation,
                                "measured_depth_m": depth,
                                "keywords": dict(self.keywords),
                            },
                            items=tuple(f"{prefix}/row{r}" for r in block),
                        )
                    )
        return tasks

    def maps(self, outcome: SweepOutcome) -> list[StickSlipMap]:
        """The maps, in the order of :meth:`runs`, from the sweep's records (their wall time:
        the sweep's)."""
        maps = []
        for run in self.runs():
            prefix = map_key(*run)
            records = [outcome.records[f"{prefix}/row{r}"] for r in range(len(self.wob_n))]
            maps.append(
                StickSlipMap(
                    wob_n=np.asarray(self.wob_n, dtype=np.float64),
                    reference_speed_rad_s=np.asarray(self.reference_speed_rad_s, dtype=np.float64),
                    severity=np.stack([_floats(r["severity"]) for r in records]),
                    stuck_fraction=np.stack([_floats(r["stuck_fraction"]) for r in records]),
                    wall_time_s=outcome.wall_time_s,
                    **records[0]["map"],
                )
            )
        return maps


# ----------------------------------------------------------------------------- compare
class CompareJob(NamedTuple):
    """One run of a comparison, as the task that makes it needs it."""

    label: str
    """The controller's name, or the agent's."""
    observation: str | None
    """The field env's observation mode of the run (``None`` on ``DrillString-v0``)."""
    is_agent: bool
    """Whether the run is the agent's."""
    case: Any
    """The :class:`experiments.compare.Case` of the run."""
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
    """Runs of the comparison, each one :func:`experiments.compare.run_comparison` of one
    controller (or the agent), with one observation mode, on one case and one noise level;
    records by :attr:`CompareJob.item`, extras: the light traces by ``(run label, case,
    noise)``."""
    from experiments.compare import run_comparison

    records: dict[str, dict[str, Any]] = {}
    traces: dict[tuple[str, str, float], Any] = {}
    for job in runs:
        rows, run_traces = run_comparison(
            [] if job.is_agent else [job.label], [job.case.name], [job.noise],
            duration_s=duration_s, seed=seed, reading=reading, gains=gains,
            agent=agent if job.is_agent else None, keep_traces=keep_traces, progress=False,
            env_id=env_id, cases=[job.case],
            observations=OBSERVATIONS if job.observation is None else [job.observation],
        )  # fmt: skip
        assert len(rows) == 1, f"{job.item} made {len(rows)} rows"
        records[job.item] = rows[0]
        traces.update(run_traces)
    return TaskResult(records, traces or None)


def compare_item(label: str, condition: str, noise: float) -> str:
    """The item key of one comparison run (``label``: the run label, with the observation
    mode on the field string; ``condition``: the case's name)."""
    return f"{label}/{condition}/noise={float(noise)!r}"


@dataclass(frozen=True)
class CompareStudy:
    """The comparison (:func:`experiments.compare.run_comparison`) on the sweep runner: an
    item is one run (controller or agent, observation mode, case, noise), a task
    ``task_runs`` of them.

    Attributes: as :func:`experiments.compare.run_comparison` and
    :func:`experiments.compare.comparison_cases` (``conditions`` are the paper's Table 3
    conditions on ``DrillString-v0``, the field conditions on ``DrillStringField-v0``;
    ``depths_m``, ``controller_model`` and ``observations`` are the field string's), plus
    ``task_runs``, the runs per task (does not change the numbers). The agent runs only on its
    own env (its ``env_id``, ``DrillString-v0`` when it has none).
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

    def __post_init__(self) -> None:
        from experiments.compare import GAIN_PRESETS, decision_period

        _check_controllers(self.controllers)
        for label, values in (("conditions", self.conditions), ("noises", self.noises)):
            if not values:
                raise ValueError(f"{label} = [] is empty: the comparison needs at least one")
        if self.gains not in GAIN_PRESETS:
            raise ValueError(f"gains = {self.gains!r}: allowed {', '.join(GAIN_PRESETS)}")
        decision_period(self.duration_s)
        _check_task_size("task_runs", self.task_runs)
        if is_field(self.env_id):
            _check_observations(self.observations)
            if not self.depths_m:
                raise ValueError("depths_m = [] is empty: the comparison needs at least one")
        for case in self.cases():  # unknown conditions, bad depths
            if case.field is not None:
                case.field.nominal_string()

    def cases(self) -> list[Any]:
        """The cases (:func:`experiments.compare.comparison_cases`), in table order."""
        from experiments.compare import comparison_cases

        return comparison_cases(
            self.env_id,
            list(self.conditions),
            reading=self.reading,
            depths_m=[float(d) for d in self.depths_m],
            controller_model=self.controller_model,
        )

    def jobs(self) -> list[CompareJob]:
        """The runs in table order, as :func:`experiments.compare.run_comparison` makes them:
        each controller with each observation mode it can use (the agent last, on its own env
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
            }
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
    env_id: str = PAPER_ENV,
    observations: Sequence[str] = OBSERVATIONS,
) -> TaskResult:
    """Held-out scenarios, each run by every controller (with each observation mode it can use
    on the field string) and agent (:func:`experiments.evaluate.evaluate` on ``env_id``); one
    record per scenario id (``rows``: its rows in table order), extras: the kept traces by
    ``(scenario id, run label)``."""
    from experiments.evaluate import evaluate

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
            _check_controllers(self.controllers)
        if not self.scenarios:
            raise ValueError("scenarios = [] is empty: the evaluation needs at least one")
        _check_task_size("task_scenarios", self.task_scenarios)
        field_env = is_field(self.env_id)
        if field_env:
            _check_observations(self.observations)
        for s in self.scenarios:
            if (s.field is not None) != field_env:
                raise ValueError(
                    f"scenario {s.id!r} is not a held-out scenario of {self.env_id}: "
                    f"{'f01-f16' if field_env else 'h01-h20'} are"
                )
        ids = [s.id for s in self.scenarios]
        if len(set(ids)) != len(ids):
            raise ValueError(f"scenarios = {ids!r}: each held-out scenario at most once")

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


# ------------------------------------------------------------------------- command lines
def _report(study_name: str, outcome: SweepOutcome, backend: Any) -> None:
    where = f"; results in {outcome.results_path}" if outcome.results_path else ""
    loaded = f", {outcome.loaded} items read from the results database" if outcome.loaded else ""
    print(
        f"sweep {study_name} on {backend.describe()}: {len(outcome.ran)} tasks run in "
        f"{outcome.wall_time_s:.1f} s{loaded}{where}"
    )


def run_map_sweep(
    args: Any, runs: Sequence[MapRun], wobs: Iterable[float], speeds: Iterable[float]
) -> list[StickSlipMap]:
    """``drill-gym map`` on the sweep runner (its parsed options ``args``): the maps of
    ``runs`` (controller, observation mode, depth; in this order), on ``args.env``."""
    from pathlib import Path

    from experiments.sweep import backend_from_args, results_path_from_args, run_sweep

    # Further compute_map keywords of the command line: one entry per option (none for the
    # default map, so that its spec, and the results files written for it, stay as they were).
    level = map_realism(args.env, args.realism)
    keywords: dict[str, Any] = {} if level is None else {"realism": level}
    study = MapStudy(
        tuple(dict.fromkeys(run[0] for run in runs)),
        tuple(float(w) for w in wobs),
        tuple(float(v) for v in speeds),
        duration_s=args.duration,
        window_s=args.window,
        noise_std_rad_s=args.noise,
        seed=args.seed,
        parameters=args.parameters,
        task_cells=args.task_size or MAP_TASK_CELLS,
        env_id=args.env,
        observations=tuple(dict.fromkeys(args.observations)),
        depths_m=tuple(dict.fromkeys(float(run[2]) for run in runs if run[2] is not None)),
        keywords=keywords,
    )
    assert study.runs() == [tuple(run) for run in runs], "the maps of drill-gym map, in order"
    backend = backend_from_args(args)
    path = results_path_from_args(args, Path(args.out) / "stick_slip_map.sqlite")
    outcome = run_sweep(
        study, backend, path, args.resume, not args.no_progress, overwrite=args.overwrite
    )
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
    """``drill-gym compare`` on the sweep runner (on ``args.env``): the rows, the traces and
    whether every run has its traces (not when some were read from the results file)."""
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
        env_id=args.env,
        depths_m=tuple(dict.fromkeys(float(d) for d in args.depths)),
        controller_model=args.controller_model,
        observations=tuple(dict.fromkeys(args.observations)),
    )
    backend = backend_from_args(args)
    path = results_path_from_args(args, Path(args.out) / "compare.sqlite")
    outcome = run_sweep(
        study, backend, path, args.resume, not args.no_progress, overwrite=args.overwrite
    )
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
    """``drill-gym evaluate`` on the sweep runner (on ``args.env``): the rows, the kept traces
    and whether every run has its trace (not when some were read from the results file)."""
    from pathlib import Path

    from experiments.sweep import backend_from_args, results_path_from_args, run_sweep

    study = EvaluateStudy(
        tuple(agents),
        None if controllers is None else tuple(controllers),
        tuple(scenarios),
        keep_traces=tuple(keep) if not args.no_plots else (),
        task_scenarios=args.task_size or EVALUATE_TASK_SCENARIOS,
        env_id=args.env,
        observations=tuple(dict.fromkeys(args.observations)),
    )
    backend = backend_from_args(args)
    path = results_path_from_args(args, Path(args.out) / "heldout.sqlite")
    outcome = run_sweep(
        study, backend, path, args.resume, not args.no_progress, overwrite=args.overwrite
    )
    _report(study.name, outcome, backend)
    rows, traces = study.results(outcome)
    return rows, traces, outcome.loaded == 0
