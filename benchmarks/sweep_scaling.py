"""Scaling of the sweep runner: one stick-slip map serial, on Ray with 1 worker and with 2.

All in one process, warm (numba's cache loaded in the driver and in every Ray worker by a
first small sweep that is not timed), the measurements interleaved round by round, on the default grid of ``drill-gym map`` (20 WOB x 16
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
sizes (cells per task, whole WOB rows) with 1 and 2 workers: the task size that amortises the
cost of a task (a vector env made and reset, a Ray task sent and its result returned). The cluster start is timed on its own. Timings on a shared machine are noisy:
read the ratios.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/sweep_scaling.py``
(``--duration 50``, ``--task-size 80``, ``--sizes 16 32 80 160 320``, ``--repeat 3``: three
interleaved rounds of every measurement, the fastest of each counts; needs the scale extra).
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

from experiments.stick_slip_map import MapStudy, compute_map
from experiments.sweep import MAP_TASK_CELLS, Backend, ray_session, run_sweep


def _wall(function: object, *args: object, **kwargs: object) -> tuple[float, object]:
    start = time.perf_counter()
    result = function(*args, **kwargs)  # type: ignore[operator]
    return time.perf_counter() - start, result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controller", default="stiff_pi")
    parser.add_argument("--duration", type=float, default=50.0)
    parser.add_argument("--task-size", type=int, default=MAP_TASK_CELLS)
    parser.add_argument("--sizes", type=int, nargs="+", default=[16, 32, 80, 160, 320])
    parser.add_argument("--repeat", type=int, default=3, help="rounds; the fastest counts")
    args = parser.parse_args()
    wobs = tuple(float(w) for w in np.linspace(40e3, 200e3, 20))
    speeds = tuple(float(v) for v in np.linspace(1.0, 16.0, 16))
    cells = len(wobs) * len(speeds)
    simulated = cells * args.duration
    threads = numba.get_num_threads()
    print(
        f"load average {os.getloadavg()[0]:.1f} at the start; cpus {os.cpu_count()}, numba "
        f"threads {threads} (serial); map of {cells} cells x {args.duration:g} s = "
        f"{simulated:,.0f} simulated s, controller {args.controller}; {args.repeat} rounds"
    )

    def study(task_cells: int) -> MapStudy:
        return MapStudy(
            (args.controller,), wobs, speeds, duration_s=args.duration, task_cells=task_cells
        )

    warm = MapStudy(
        (args.controller,), wobs[:2], speeds, duration_s=1.0, window_s=0.5, task_cells=16
    )
    compute_map(args.controller, wobs[:2], speeds, duration_s=1.0, window_s=0.5, progress=False)
    names = [
        f"serial (compute_map, {threads} numba threads)",
        f"serial runner ({args.task_size} cells/task, 1 thread)",
        f"Ray, 1 worker ({args.task_size} cells/task)",
        f"Ray, 2 workers ({args.task_size} cells/task)",
    ]
    best = dict.fromkeys(names, float("inf"))
    sizes = {(size, w): float("inf") for size in args.sizes for w in (1, 2)}
    start = time.perf_counter()
    with ray_session(Backend(workers=2)):
        cluster_s = time.perf_counter() - start
        start = time.perf_counter()
        run_sweep(warm, Backend(workers=2), progress=False)  # the workers load numba's cache
        warm_s = time.perf_counter() - start
        for _ in range(args.repeat):  # interleaved: a drift of the machine's load hits all alike
            wall, reference = _wall(
                compute_map, args.controller, wobs, speeds, duration_s=args.duration, progress=False
            )
            best[names[0]] = min(best[names[0]], wall)
            numba.set_num_threads(1)
            wall, _ = _wall(run_sweep, study(args.task_size), progress=False)
            numba.set_num_threads(threads)
            best[names[1]] = min(best[names[1]], wall)
            for name, workers in ((names[2], 1), (names[3], 2)):
                wall, outcome = _wall(
                    run_sweep, study(args.task_size), Backend(workers=workers), progress=False
                )
                best[name] = min(best[name], wall)
                swept = study(args.task_size).maps(outcome)[0]  # type: ignore[arg-type]
                expected = reference.severity  # type: ignore[attr-defined]
                same = np.array_equal(swept.severity, expected, equal_nan=True)
                assert same, "the map on Ray differs from the serial one"
            for size, workers in sizes:
                wall, _ = _wall(run_sweep, study(size), Backend(workers=workers), progress=False)
                sizes[(size, workers)] = min(sizes[(size, workers)], wall)
    serial_s, runner_s, ray1_s, ray2_s = (best[n] for n in names)
    print(
        f"\nlocal Ray cluster start: {cluster_s:.1f} s; first sweep (the workers load numba's "
        f"cache): {warm_s:.1f} s\n"
    )
    print("| run | wall (s) | simulated s / wall s |")
    print("|---|---:|---:|")
    for name, wall in best.items():
        print(f"| {name} | {wall:.2f} | {simulated / wall:,.0f} |")
    print(
        f"\nRay overhead (Ray 1 worker / serial runner): {ray1_s / runner_s:.2f}; "
        f"speed-up of 2 workers over 1: {ray1_s / ray2_s:.2f}; "
        f"Ray 2 workers vs serial compute_map: {serial_s / ray2_s:.2f} x as fast"
    )
    print(
        "\n| cells per task | tasks | wall, 1 worker (s) | wall, 2 workers (s) | speed-up, 2 / 1 "
        "| 2 workers vs serial compute_map |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for size in args.sizes:
        tasks = len(study(size).tasks(study(size).items()))
        one, two = sizes[(size, 1)], sizes[(size, 2)]
        print(
            f"| {size} | {tasks} | {one:.2f} | {two:.2f} | {one / two:.2f} | {serial_s / two:.2f} |"
        )
    print(
        "\nthe maps on Ray equal the serial one bit for bit; load average "
        f"{os.getloadavg()[0]:.1f} at the end"
    )


if __name__ == "__main__":
    main()
