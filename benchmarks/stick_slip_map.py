"""Wall time of ``drill-gym map``: the default 20 x 16 grid of 100 s runs, per controller.

Prints, for each controller, the wall time of :func:`experiments.stick_slip_map.compute_map` on
the default grid (WOB 40-200 kN x 16 reference speeds 1-16 rad/s, runs of 100 s from rest),
the simulated seconds per wall second (cells x 100 s / wall time) and the ratio to the
target of 60 s. Numba's compilation is warmed up first on a one-cell map, so the numbers are
what a second ``drill-gym map`` call sees (compilation is cached on disk anyway).

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/stick_slip_map.py``
(``--controller stiff_pi soft_speed``, ``--noise 0.1``, ``--repeat 3``).
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np

from experiments.stick_slip_map import compute_map

TARGET_S = 60.0
"""The budget for the default 20 x 16 grid of 100 s runs on 2 cores, s."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--controller", nargs="+", default=["stiff_pi", "soft_speed", "z_torque", "proposed"]
    )
    parser.add_argument("--duration", type=float, default=100.0)
    parser.add_argument("--noise", type=float, default=0.0)
    parser.add_argument("--repeat", type=int, default=1)
    args = parser.parse_args()
    wobs = np.linspace(40e3, 200e3, 20)
    speeds = np.linspace(1.0, 16.0, 16)
    print(
        f"cpus {os.cpu_count()}, numba threads {numba.get_num_threads()}, grid "
        f"{wobs.size} x {speeds.size}, runs of {args.duration:g} s, noise {args.noise:g} rad/s"
    )
    for name in args.controller:
        compute_map(name, [1e5], [5.0], duration_s=1.0, window_s=1.0, progress=False)  # warm up
        best = float("inf")
        for _ in range(args.repeat):
            start = time.perf_counter()
            result = compute_map(
                name,
                wobs,
                speeds,
                duration_s=args.duration,
                noise_std_rad_s=args.noise,
                progress=False,
            )
            best = min(best, time.perf_counter() - start)
        simulated = result.cells * result.duration_s
        print(
            f"{name:>10}: {best:6.2f} s wall for {simulated:,.0f} simulated s = "
            f"{simulated / best:8,.0f} simulated s per wall s; {best / TARGET_S:.2f} of the "
            f"{TARGET_S:g} s target; {int(result.unstable().sum())} cells in stick-slip"
        )


if __name__ == "__main__":
    main()
