"""Write the synthetic laboratory and field logs of docs/calibration.md as CSV files.

    python examples/make_synthetic_log.py OUT_DIR [--seed N]

``OUT_DIR/lab_log.csv``: 60 s of a laboratory rig at 1 kHz (:func:`experiments.synthetic_log.lab_log`);
``OUT_DIR/field_log.csv``: 400 s of the ``zribi2024`` 4-DOF plant at 5 Hz
(:func:`experiments.synthetic_log.field_log`). Both carry white measurement noise and defects
(a gap, spikes, a flat line, a stall) at the times listed in that module. Existing files of
these names are refused.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from drill_env.measured_log import write_log_csv
from experiments.synthetic_log import field_log, lab_log


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out", type=Path, help="output directory")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default: 0)")
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name, make in (("lab_log.csv", lab_log), ("field_log.csv", field_log)):
        path = args.out / name
        if path.exists():
            raise SystemExit(f"{path} exists: not overwritten")
        write_log_csv(make(args.seed), path)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
