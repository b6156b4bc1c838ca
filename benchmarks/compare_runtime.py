"""Wall time of ``drill-gym compare``, end to end, in a fresh process (imports included).

Measures, with numba's cache warm (one untimed run first):

(a) the paper's comparison: ``--controllers csmc msmc asmc proposed`` x 4 conditions x 2 noise
    levels = 32 runs of 150 s, with and without figures (the target is <= 10 s on 2 cores);
(b) the command's own default (every registered controller, and the shipped agent if any),
    with figures.

For each it prints the median wall time over ``--repeat`` runs (and the CPU time of the
process, which is what a busy machine does not inflate much), runs per second, simulated
seconds per wall second, and the split the command reports (simulation against output). It
asserts nothing. Run: ``.venv/bin/python benchmarks/compare_runtime.py``.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PAPER = ["--controllers", "csmc", "msmc", "asmc", "proposed", "--no-agent"]
DURATION_S = 150.0


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run_once(args: list[str], out: Path) -> tuple[float, int, float, float, float]:
    """Wall time (s), runs, the simulation and total times the command reports (s), and the
    CPU time of the process (s)."""
    cmd = [sys.executable, "-m", "experiments.cli", "compare", *args, "--no-progress"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    cpu0 = _children_cpu_s()
    start = time.perf_counter()
    done = subprocess.run(
        [*cmd, "--out", str(out)], capture_output=True, text=True, env=env, check=True
    )
    wall = time.perf_counter() - start
    cpu = _children_cpu_s() - cpu0
    m = re.search(r"(\d+) runs simulated in ([\d.]+) s \(([\d.]+) s with output\)", done.stdout)
    if m is None:
        raise RuntimeError(f"unexpected output of {' '.join(cmd)}:\n{done.stdout[-500:]}")
    return wall, int(m.group(1)), float(m.group(2)), float(m.group(3)), cpu


def measure(label: str, args: list[str], repeat: int, folder: Path) -> None:
    results = [run_once(args, folder / f"{label}-{k}") for k in range(repeat)]
    wall = statistics.median(r[0] for r in results)
    runs = results[0][1]
    sim = statistics.median(r[2] for r in results)
    total = statistics.median(r[3] for r in results)
    cpu = statistics.median(r[4] for r in results)
    print(
        f"{label:<34} {wall:6.2f} s wall ({cpu:5.2f} s CPU)  {runs:3d} runs  "
        f"{runs / wall:5.1f} runs/s  {runs * DURATION_S / wall:6.0f} sim s / wall s  "
        f"(simulation {sim:.2f} s, output {total - sim:.2f} s, start-up {wall - total:.2f} s)"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="timed runs per case (median)")
    args = parser.parse_args()
    print(f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs; median of {args.repeat}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        run_once([*PAPER, "--no-plots"], folder / "warm-up")  # fills numba's cache if cold
        measure("paper's 32 runs, no figures", [*PAPER, "--no-plots"], args.repeat, folder)
        measure("paper's 32 runs, with figures", PAPER, args.repeat, folder)
        measure("default (all registered), figures", [], args.repeat, folder)


if __name__ == "__main__":
    main()
