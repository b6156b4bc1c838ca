"""Scaling of the sweep runner: one stick-slip map serial, on Ray with 1 worker and with 2.

All in one process, warm (numba's cache loaded in the driver and in every Ray worker by a
first small sweep that is not timed), on the default grid of ``drill-gym map`` (20 WOB x 16
reference speeds) with runs of ``--duration`` seconds:

* ``serial``: :func:`experiments.stick_slip_map.compute_map` over the whole grid in this
  process, the path of ``drill-gym map`` without ``--workers`` (numba threads over the
  strings of one vector env);
* ``serial runner``: the same map on the sweep runner in this process, tasks of
  ``--task-size`` cells one after the other, numba on one thread (the work a Ray worker
  does, without Ray);
* ``Ray, 1 worker`` and ``Ray, 2 workers``: the sweep runner on a local Ray cluster of
  2 CPUs with at most 1 or 2 tasks in flight.

Ratios: Ray's overhead (Ray with 1 worker / serial runner: the same tasks with and without
Ray), the speed-up of 2 workers over 1, and each against ``serial``. Then a table over task
sizes (cells per task, whole WOB rows) with 2 workers: the task size that amortises Ray's
per-task cost. The cluster start is timed on its own. Timings on a shared machine are noisy:
read the ratios.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/sweep_scaling.py``
(``--duration 100``, ``--task-size 32``, ``--sizes 16 32 80 160``, ``--repeat 2``: the
fastest of 2 runs per measurement; needs the scale extra).
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

from experiments.stick_slip_map import compute_map
from experiments.sweep import Backend, ray_session, run_sweep
from experiments.sweep_studies import MapStudy

REPEAT = 1
"""Runs of each measurement; the fastest counts (set by ``--repeat``)."""


def _timed(function: object, *args: object, **kwargs: object) -> tuple[float, object]:
    """The fastest of ``REPEAT`` calls and its result."""
    best, result = float("inf"), None
    for _ in range(REPEAT):
        start = time.perf_counter()
        result = function(*args, **kwargs)  # type: ignore[operator]
        best = min(best, time.perf_counter() - start)
    return best, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", default="stiff_pi")
    parser.add_argument("--duration", type=float, default=100.0)
    parser.add_argument("--task-size", type=int, default=32)
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 80, 160])
    parser.add_argument("--repeat", type=int, default=2, help="runs per measurement (fastest)")
    args = parser.parse_args()
    global REPEAT
    REPEAT = max(1, args.repeat)
    wobs = tuple(float(w) for w in np.linspace(40e3, 200e3, 20))
    speeds = tuple(float(v) for v in np.linspace(1.0, 16.0, 16))
    cells = len(wobs) * len(speeds)
    simulated = cells * args.duration
    threads = numba.get_num_threads()
    print(
        f"cpus {os.cpu_count()}, numba threads {threads} (serial), map of {cells} cells x "
        f"{args.duration:g} s = {simulated:,.0f} simulated s, controller {args.controller}"
    )

    def study(task_cells: int) -> MapStudy:
        return MapStudy(
            (args.controller,), wobs, speeds, duration_s=args.duration, task_cells=task_cells
        )

    warm = MapStudy(
        (args.controller,), wobs[:2], speeds, duration_s=1.0, window_s=0.5, task_cells=16
    )
    compute_map(args.controller, wobs[:2], speeds, duration_s=1.0, window_s=0.5, progress=False)
    serial_s, reference = _timed(
        compute_map, args.controller, wobs, speeds, duration_s=args.duration, progress=False
    )
    numba.set_num_threads(1)
    runner_s, _ = _timed(run_sweep, study(args.task_size), progress=False)
    numba.set_num_threads(threads)
    rows: list[tuple[str, float]] = [
        (f"serial (compute_map, {threads} numba threads)", serial_s),
        (f"serial runner ({args.task_size} cells/task, 1 thread)", runner_s),
    ]
    start = time.perf_counter()
    with ray_session(Backend(workers=2)):
        cluster_s = time.perf_counter() - start
        start = time.perf_counter()
        run_sweep(warm, Backend(workers=2), progress=False)  # the workers load numba's cache
        warm_s = time.perf_counter() - start
        ray1_s, out1 = _timed(run_sweep, study(args.task_size), Backend(workers=1), progress=False)
        ray2_s, out2 = _timed(run_sweep, study(args.task_size), Backend(workers=2), progress=False)
        for outcome in (out1, out2):
            swept = study(args.task_size).maps(outcome)[0]  # type: ignore[arg-type]
            assert np.array_equal(swept.severity, reference.severity, equal_nan=True)  # type: ignore[attr-defined]
        sizes = []
        for size in args.sizes:
            wall, _ = _timed(run_sweep, study(size), Backend(workers=2), progress=False)
            sizes.append((size, wall))
    rows += [
        (f"Ray, 1 worker ({args.task_size} cells/task)", ray1_s),
        (f"Ray, 2 workers ({args.task_size} cells/task)", ray2_s),
    ]
    print(
        f"\nlocal Ray cluster start: {cluster_s:.1f} s; first sweep (workers load numba's cache): {warm_s:.1f} s\n"
    )
    print("| run | wall (s) | simulated s / wall s |")
    print("|---|---:|---:|")
    for name, wall in rows:
        print(f"| {name} | {wall:.2f} | {simulated / wall:,.0f} |")
    print(
        f"\nRay overhead (Ray 1 worker / serial runner): {ray1_s / runner_s:.2f}; "
        f"speed-up of 2 workers over 1: {ray1_s / ray2_s:.2f}; "
        f"Ray 2 workers vs serial compute_map: {serial_s / ray2_s:.2f} x as fast"
    )
    print("\n| cells per task | tasks | wall, 2 workers (s) | x as fast as serial compute_map |")
    print("|---:|---:|---:|---:|")
    for size, wall in sizes:
        tasks = len(study(size).tasks(study(size).items()))
        print(f"| {size} | {tasks} | {wall:.2f} | {serial_s / wall:.2f} |")
    print("\nthe maps on Ray equal the serial one bit for bit")


if __name__ == "__main__":
    main()
