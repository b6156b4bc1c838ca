"""The sweep runner: a study split into tasks, run in this process or on a Ray cluster.

A study (a stick-slip map, a probability map, a comparison, a held-out evaluation) is a list
of *items*, the units of its results (a WOB row of a map, one cell of a probability map, one
run of a comparison), and a way to group the items still missing into *tasks*, the units of
work (a batch of map rows simulated as the strings of one ``gym.make_vec``, a batch of runs).
A task is a module-level function and its keyword arguments; it returns a :class:`TaskResult`:
one JSON record per item, and optional extras (traces for figures) that stay in memory.

:func:`run_sweep` runs the tasks

* **serially** (:class:`Backend` with ``workers=1``): each task function called in this
  process, one after the other;
* **on Ray** (``workers > 1``, ``use_ray`` or an ``address``): each task a Ray task of one
  CPU, on a local cluster that ``ray.init`` starts (``num_cpus=workers``, no dashboard) or on
  the cluster at ``address`` (or ``$RAY_ADDRESS``). Results stream back as tasks finish; a
  task whose worker process dies is run again (Ray's ``max_retries``). Workers run with
  :data:`WORKER_ENV` (one thread for BLAS, OpenMP and numba: one task per CPU); each worker
  process loads numba's on-disk cache of ``drill_env`` the first time it runs a task (a few
  seconds; longer when the cache is cold and numba compiles).

Both paths call the same task functions with the same arguments, and every seed is a pure
function of the study's spec and an item's index, so the numbers do not depend on the
backend, on the number of workers, on the task size or on the order tasks finish in. Every
record passes through its JSON encoding (non-finite floats as ``null``; Python's float
``repr`` round-trips exactly), on every path, so a resumed sweep assembles exactly the tables
of a clean one.

The results database (:mod:`experiments.results_db`, SQLite): one row per finished item,
keyed by the study's settings hash (:func:`spec_hash`), the package version and the item,
each finished task written in one transaction as it arrives. Several studies (and several
processes) share one file, each with its own rows. With ``resume=True`` the items of the same
settings and version already in the file are not run again (each read back through the
study's :meth:`Study.record_schema`); without it, a file that already holds rows of these
settings is refused, unless ``overwrite``, which deletes just those rows. A file that is not a
results database is refused before any work starts and never written.

Ray is imported only when a sweep runs on it (the ``[scale]`` extra).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import math
import os
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NamedTuple, Protocol

import numpy as np

from drill_env.control import controller_names
from drill_env.validation import shown
from experiments.controllers import user_code_fingerprints
from experiments.field import OBSERVATIONS
from experiments.results_db import ResultsDatabase, Schema, SchemaError, as_json
from experiments.spec_cli import option
from experiments.tables import json_clean

if TYPE_CHECKING:  # pragma: no cover
    pass

__all__ = [
    "ADDRESS_VARIABLE",
    "COMPARE_TASK_RUNS",
    "DEFAULT_MAX_RETRIES",
    "EVALUATE_TASK_SCENARIOS",
    "MAP_TASK_CELLS",
    "PROBABILITY_TASK_CELLS",
    "WORKER_ENV",
    "Backend",
    "RunnerSpec",
    "Study",
    "SweepOutcome",
    "Task",
    "TaskResult",
    "agent_fingerprint",
    "check_controllers",
    "check_observations",
    "check_task_size",
    "chunks",
    "item_tasks",
    "ray_session",
    "read_results",
    "report_outcome",
    "run_sweep",
    "spec_hash",
    "study_settings",
]

WORKER_ENV: Final[dict[str, str]] = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}
"""Environment of every Ray worker: one thread per task (a task holds one CPU)."""
ADDRESS_VARIABLE: Final = "RAY_ADDRESS"
"""Environment variable with the address of a Ray cluster to join (``--address`` wins)."""
DEFAULT_MAX_RETRIES: Final = 3
"""Times a task is run again when its worker process dies."""
MAP_TASK_CELLS: Final = 80
"""Default cells per map task (rounded down to whole WOB rows, at least one row): enough
strings per compiled call to amortise the cost of a task (``benchmarks/sweep_scaling.py``:
tasks of 16-32 cells of 50 s runs took about 1.8 x as long as tasks of 80 on 2 workers)."""
PROBABILITY_TASK_CELLS: Final = 2
"""Default cells per probability-map task (each cell is ``draws`` runs)."""
COMPARE_TASK_RUNS: Final = 1
"""Default runs per comparison task (a run is 150 s of plant time: a task of its own)."""
EVALUATE_TASK_SCENARIOS: Final = 1
"""Default held-out scenarios per evaluation task (each run by every controller and agent)."""


class TaskResult(NamedTuple):
    """What a task returns.

    Attributes:
        records: One JSON-able record per item the task produced, by item key.
        extras: Anything else the driver needs in memory (traces for figures); never written
            to the results database (``None``: nothing).
    """

    records: dict[str, dict[str, Any]]
    extras: Any = None


@dataclass(frozen=True)
class Task:
    """One unit of work.

    Attributes:
        key: Unique within the sweep (``stiff_pi/rows/0-3``).
        function: A module-level function (importable by the workers) called as
            ``function(**kwargs)``; returns a :class:`TaskResult` with a record for every one
            of ``items``.
        kwargs: Its keyword arguments (picklable).
        items: The item keys it produces.
    """

    key: str
    function: Callable[..., TaskResult]
    kwargs: Mapping[str, Any]
    items: tuple[str, ...]


class Study(Protocol):
    """A study on the runner."""

    @property
    def name(self) -> str:
        """Name of the sweep, in the results database and the progress bar."""
        ...

    def spec(self) -> dict[str, Any]:
        """Everything the results depend on, as JSON (not the backend nor the task size)."""
        ...

    def items(self) -> list[str]:
        """Every item key, in the order of the final tables."""
        ...

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        """Tasks that produce exactly the items ``missing`` (in item order)."""
        ...

    def record_schema(self, item: str) -> Schema:
        """What the record of ``item`` must be (:mod:`experiments.results_db`); every record,
        made now or read back from the results database, is checked against it."""
        ...


@dataclass(frozen=True)
class Backend:
    """Where the tasks run.

    Attributes:
        workers: CPUs of the local Ray cluster (tasks at a time); 1 with neither ``use_ray``
            nor ``address``: serially in this process. On a cluster that Ray is already
            connected to, or at ``address``: the most tasks in flight (1: no limit).
        use_ray: Run on Ray even with one worker.
        address: Address of a running Ray cluster to join (``None``: ``$RAY_ADDRESS`` if set,
            else a local cluster is started when Ray is used).
        max_retries: Times a task is run again when its worker dies, >= 0.
    """

    workers: int = 1
    use_ray: bool = False
    address: str | None = None
    max_retries: int = DEFAULT_MAX_RETRIES

    def __post_init__(self) -> None:
        for name, low in (("workers", 1), ("max_retries", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ValueError(
                    f"{name} = {shown(value)} is out of range: allowed an integer >= {low}"
                )
        if self.address is not None and not str(self.address).strip():
            raise ValueError("address = '' is not valid: give a Ray address or leave it out")

    @property
    def distributed(self) -> bool:
        """Whether the tasks run on Ray."""
        return self.use_ray or self.workers > 1 or self.address is not None

    def describe(self) -> str:
        """One line: ``serial`` or ``Ray (2 workers)``/``Ray at ADDRESS``."""
        if not self.distributed:
            return "serial"
        if self.address:
            return f"Ray at {self.address}"
        return f"Ray ({self.workers} worker{'s' if self.workers != 1 else ''})"


@dataclass
class SweepOutcome:
    """The results of a sweep.

    Attributes:
        records: Item key -> record, for every item, in the study's item order.
        extras: Task key -> the extras of the tasks run this time (none for loaded items).
        ran: Keys of the tasks run this time, in the order they finished.
        loaded: Items read from the results database (resume).
        wall_time_s: Wall-clock time of the sweep, s.
        results_path: The results database (``None``: none written).
        other_rows: Rows of other studies (other settings or versions) in the results database,
            left as they are.
    """

    records: dict[str, dict[str, Any]]
    extras: dict[str, Any] = field(default_factory=dict)
    ran: list[str] = field(default_factory=list)
    loaded: int = 0
    wall_time_s: float = 0.0
    results_path: Path | None = None
    other_rows: int = 0


def study_settings(study: Study) -> dict[str, Any]:
    """What identifies ``study``'s results: its settings (``study.spec()``), and, when they name
    users' own classes, the SHA-256 of each one's file
    (:func:`experiments.controllers.user_code_fingerprints`): an edited class is a new study."""
    spec = study.spec()
    code = user_code_fingerprints(json_clean(dict(spec)))
    return {**spec, "user_code": code} if code else spec


def spec_hash(name: str, spec: Mapping[str, Any]) -> str:
    """SHA-256 of the sweep's name and its JSON spec (keys sorted)."""
    text = json.dumps({"sweep": name, "spec": json_clean(dict(spec))}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _encoded(record: Mapping[str, Any]) -> dict[str, Any]:
    """``record`` as it reads back from JSON (the same on every path)."""
    decoded: dict[str, Any] = as_json(dict(record))
    return decoded


def read_results(path: Path, study: Study) -> dict[str, dict[str, Any]]:
    """The records of ``study`` (its settings and the package version) in the results
    database ``path``, by item, each read through the study's schema; nothing is written.

    Raises:
        ValueError: ``path`` is not a results database, or a row of the study does not fit
            its schema (the message names the file and the row).
        OSError: ``path`` does not exist or cannot be read.
    """
    spec = study_settings(study)
    database = ResultsDatabase.open(
        path, study.name, spec, spec_hash(study.name, spec), read_only=True
    )
    try:
        return database.load(study.items(), study.record_schema)
    finally:
        database.close()


def chunks(values: Sequence[Any], size: int) -> Iterator[list[Any]]:
    """``values`` in consecutive lists of at most ``size`` (>= 1)."""
    for start in range(0, len(values), max(1, int(size))):
        yield list(values[start : start + max(1, int(size))])


def item_tasks(
    prefix: str,
    function: Callable[..., TaskResult],
    argument: str,
    records: Sequence[Mapping[str, Any]],
    size: int,
) -> list[Task]:
    """Tasks of at most ``size`` of ``records`` (mappings with an ``"item"`` key), each passed
    to ``function`` as the keyword ``argument`` and keyed ``PREFIX/<its first item>``."""
    return [
        Task(
            f"{prefix}/{chunk[0]['item']}",
            function,
            {argument: chunk},
            tuple(r["item"] for r in chunk),
        )  # fmt: skip
        for chunk in chunks(records, size)
    ]


def _execute(function: Callable[..., TaskResult], kwargs: Mapping[str, Any]) -> TaskResult:
    """Run one task (in a worker or in this process)."""
    result = function(**kwargs)
    if not isinstance(result, TaskResult):  # pragma: no cover - a task's own bug
        raise TypeError(f"task function {shown(function)} returned {type(result).__name__}")
    return result


def run_sweep(
    study: Study,
    backend: Backend | None = None,
    results_path: Path | None = None,
    resume: bool = False,
    progress: bool = True,
    overwrite: bool = False,
) -> SweepOutcome:
    """Run the missing items of ``study`` on ``backend`` and collect every record.

    Args:
        study: The study.
        backend: Where the tasks run (default: serially in this process).
        results_path: The results database (:mod:`experiments.results_db`; a missing file is
            made; ``None``: none is written and nothing can be resumed).
        resume: Keep the items of the same settings and version already in ``results_path``
            and run only the rest.
        progress: Show a progress bar of finished tasks on standard error.
        overwrite: Delete the rows of the same settings and version from ``results_path``
            first (without it, and without ``resume``, such rows are an error).

    Returns:
        The :class:`SweepOutcome`.

    Raises:
        ValueError: ``resume`` or ``overwrite`` without ``results_path``, a file that is not a
            results database, rows of the same settings without ``resume`` or ``overwrite``,
            a row that does not fit the study's schema, a study without items, or tasks that
            do not produce their items.
        OSError: The results database cannot be made or written.
    """
    backend = backend or Backend()
    started = time.perf_counter()
    spec = study_settings(study)
    items = list(study.items())
    if not items:
        raise ValueError(f"sweep {shown(study.name)} has no items: the grid is empty")
    if resume and results_path is None:
        raise ValueError("resume needs a results file (--results)")
    if overwrite and results_path is None:
        raise ValueError("overwrite needs a results file (--results)")
    if backend.distributed:
        import ray  # noqa: F401  (a missing scale extra fails here, before any file is written)
    database = None
    if results_path is not None:
        database = ResultsDatabase.open(
            results_path,
            study.name,
            spec,
            spec_hash(study.name, spec),
            resume=resume,
            overwrite=overwrite,
        )
    try:
        loaded = {} if database is None else database.load(items, study.record_schema)
        missing = [k for k in items if k not in loaded]
        tasks = study.tasks(missing) if missing else []
        produced = [i for t in tasks for i in t.items]
        if sorted(produced) != sorted(missing):
            raise ValueError(
                f"sweep {shown(study.name)}: its tasks do not produce the missing items"
            )
        outcome = SweepOutcome(
            records=dict(loaded),
            loaded=len(loaded),
            results_path=results_path,
            other_rows=0 if database is None else database.other_rows,
        )

        from tqdm import tqdm

        bar = tqdm(
            total=len(tasks),
            desc=f"{study.name} ({backend.describe()})",
            unit="task",
            file=sys.stderr,
            disable=not progress,
            leave=False,
        )

        def finished(task: Task, result: TaskResult) -> None:
            if set(result.records) != set(task.items):
                raise ValueError(f"task {shown(task.key)} returned items other than its own")
            encoded = {k: _encoded(result.records[k]) for k in task.items}
            for item, record in encoded.items():
                try:
                    study.record_schema(item).check(record, "")
                except SchemaError as err:
                    raise ValueError(
                        f"sweep {shown(study.name)}: task {shown(task.key)} made a record of item "
                        f"{shown(item)} that does not fit the study's schema: {err}"
                    ) from None
            if database is not None:
                database.add(task.key, encoded)
            outcome.records.update(encoded)
            if result.extras is not None:
                outcome.extras[task.key] = result.extras
            outcome.ran.append(task.key)
            bar.set_postfix_str(task.key, refresh=False)
            bar.update()

        with bar:
            if backend.distributed and tasks:
                _run_on_ray(tasks, backend, finished)
            else:
                for task in tasks:
                    finished(task, _execute(task.function, task.kwargs))
    finally:
        if database is not None:
            database.close()
    outcome.records = {k: outcome.records[k] for k in items}
    outcome.wall_time_s = time.perf_counter() - started
    return outcome


@contextlib.contextmanager
def ray_session(backend: Backend) -> Iterator[Any]:
    """The ``ray`` module, connected: to the running session if there is one, else to
    ``backend.address`` (or ``$RAY_ADDRESS``), else to a new local cluster of
    ``backend.workers`` CPUs without dashboard; a connection made here is shut down after."""
    import ray

    if ray.is_initialized():
        yield ray
        return
    runtime_env = {"env_vars": dict(WORKER_ENV)}
    address = backend.address or os.environ.get(ADDRESS_VARIABLE) or None
    if address:
        ray.init(address=address, runtime_env=runtime_env, logging_level=logging.WARNING)
    else:
        ray.init(
            num_cpus=backend.workers,
            include_dashboard=False,
            runtime_env=runtime_env,
            logging_level=logging.WARNING,
        )
    try:
        yield ray
    finally:
        ray.shutdown()


def _run_on_ray(
    tasks: Sequence[Task], backend: Backend, finished: Callable[[Task, TaskResult], None]
) -> None:
    """Submit ``tasks`` as Ray tasks and hand each result to ``finished`` as it arrives."""
    with ray_session(backend) as ray:
        remote = ray.remote(num_cpus=1, max_retries=backend.max_retries, retry_exceptions=False)(
            _execute
        )
        joined = backend.address or os.environ.get(ADDRESS_VARIABLE)
        limit = backend.workers if (backend.workers > 1 or not joined) else math.inf
        queue = list(tasks)
        pending: dict[Any, Task] = {}
        try:
            while queue or pending:
                while queue and len(pending) < limit:
                    task = queue.pop(0)
                    pending[remote.remote(task.function, dict(task.kwargs))] = task
                done, _ = ray.wait(list(pending), num_returns=1)
                for ref in done:
                    task = pending.pop(ref)
                    try:
                        result = ray.get(ref)
                    except ray.exceptions.RayTaskError as exc:
                        cause = exc.cause if isinstance(exc.cause, BaseException) else exc
                        raise cause from None
                    finished(task, result)
        finally:
            for ref in pending:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)


# ---------------------------------------------------------------------------- command line
SWEEP_GROUP: Final = "sweeps (Ray: the scale extra)"
"""Help section of the runner's options."""


@dataclass(frozen=True)
class RunnerSpec:
    """How a study runs: serially or on Ray, into which results database, resumed or not.

    The same options in every study that runs on the runner (:func:`spec_parser` of
    :mod:`experiments.spec_cli` after the study's own Spec). None of them changes the numbers.
    """

    workers: int = field(default=1, metadata=option(low=1, high=4096, group=SWEEP_GROUP))
    """tasks at a time: 1 serially here, N > 1 on Ray"""
    ray: bool = field(default=False, metadata=option(group=SWEEP_GROUP))
    """run on Ray even with one worker"""
    address: str | None = field(
        default=None,
        metadata=option(
            metavar="ADDR", group=SWEEP_GROUP, default_text=f"${ADDRESS_VARIABLE} or a new one"
        ),
    )
    """join the Ray cluster at ADDR (host:port or 'auto')"""
    task_size: int | None = field(
        default=None,
        metadata=option(low=1, high=10**6, group=SWEEP_GROUP, default_text="the study's"),
    )
    """items per task (rows of a map, runs of a comparison)"""
    results: Path | None = field(
        default=None,
        metadata=option(
            metavar="FILE",
            group=SWEEP_GROUP,
            default_text="none; in --out on Ray, with --resume or --overwrite",
        ),
    )
    """SQLite results database (studies may share one)"""
    resume: bool = field(default=False, metadata=option(group=SWEEP_GROUP))
    """keep this study's results already in the database"""
    overwrite: bool = field(default=False, metadata=option(group=SWEEP_GROUP))
    """delete this study's results of these settings first"""
    max_retries: int = field(
        default=DEFAULT_MAX_RETRIES, metadata=option(low=0, high=100, group=SWEEP_GROUP)
    )
    """reruns of a task whose worker dies"""

    @property
    def requested(self) -> bool:
        """Whether anything beyond a plain serial run is asked for (Ray, a database, a resume)."""
        return bool(
            self.workers > 1
            or self.ray
            or self.address
            or self.results is not None
            or self.resume
            or self.overwrite
            or self.task_size is not None
        )

    def backend(self) -> Backend:
        """The :class:`Backend` these options ask for."""
        return Backend(
            workers=self.workers,
            use_ray=self.ray,
            address=self.address or None,
            max_retries=self.max_retries,
        )

    def run(self, study: Study, default_results: Path, progress: bool = True) -> SweepOutcome:
        """Run ``study`` as these options ask (:func:`run_sweep` on :meth:`backend`, into
        :meth:`results_path` of ``default_results``, resumed or overwritten); says where it ran
        and what it read when anything beyond a plain serial run was asked for."""
        backend = self.backend()
        outcome = run_sweep(
            study,
            backend,
            self.results_path(default_results),
            self.resume,
            progress,
            overwrite=self.overwrite,
        )
        if self.requested:
            report_outcome(study.name, outcome, backend)
        return outcome

    def results_path(self, default: Path) -> Path | None:
        """The results database: ``results``, else ``default`` when the sweep is on Ray,
        resumes or overwrites, else ``None``."""
        if self.results is not None:
            return Path(self.results)
        if self.resume or self.overwrite or self.backend().distributed:
            return default
        return None


# ------------------------------------------------------------- checks of the studies
def check_controllers(names: Sequence[str]) -> None:
    valid = controller_names()
    if not names:
        raise ValueError(f"controllers = [] is empty: allowed one or more of {', '.join(valid)}")
    for name in names:
        if name not in valid:
            raise ValueError(
                f"unknown controller {shown(name)}: valid names are {', '.join(valid)}"
            )


def check_task_size(name: str, value: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed an integer >= 1")


def check_observations(modes: Sequence[str]) -> None:
    if not modes:
        raise ValueError(
            f"observations = [] is empty: allowed one or more of {', '.join(OBSERVATIONS)}"
        )
    for mode in modes:
        if mode not in OBSERVATIONS:
            raise ValueError(
                f"observation = {shown(mode)} is not valid: allowed {', '.join(OBSERVATIONS)}"
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


def report_outcome(study_name: str, outcome: SweepOutcome, backend: Any) -> None:
    where = f"; results in {outcome.results_path}" if outcome.results_path else ""
    loaded = f", {outcome.loaded} items read from the results database" if outcome.loaded else ""
    print(
        f"sweep {study_name} on {backend.describe()}: {len(outcome.ran)} tasks run in "
        f"{outcome.wall_time_s:.1f} s{loaded}{where}"
    )
