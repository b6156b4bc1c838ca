"""Learning-curve figure of training runs (``validation.csv`` and ``progress.csv`` of each run
folder), drawn with matplotlib's object-oriented API on the Agg canvas."""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

__all__ = ["plot_learning_curves", "read_csv_columns"]


def read_csv_columns(path: str | Path) -> dict[str, list[float]]:
    """Columns of a CSV file as floats (empty cells become NaN)."""
    columns: dict[str, list[float]] = {}
    with Path(path).open(newline="") as f:
        for row in csv.DictReader(f):
            for key, value in row.items():
                columns.setdefault(key, []).append(
                    float(value) if value not in ("", None) else math.nan
                )
    return columns


def plot_learning_curves(runs: Mapping[str, str | Path], path: str | Path, title: str = "") -> Path:
    """Validation mean IAE and RMSD relative to the proposed SMC, and the training return,
    against decisions, for each run folder.

    Args:
        runs: Label -> run folder (with ``validation.csv`` and ``progress*.csv``).
        path: PNG file to write.
        title: Figure title.

    Returns:
        ``path``.
    """
    fig = Figure(figsize=(8.0, 6.0), dpi=80, layout="constrained")
    FigureCanvasAgg(fig)
    ax_iae, ax_rmsd, ax_ret = fig.subplots(3, 1, sharex=True)
    for label, folder in runs.items():
        run = Path(folder)
        validation = run / "validation.csv"
        if validation.is_file():
            v = read_csv_columns(validation)
            steps = [s / 1e6 for s in v["timesteps"]]
            ax_iae.plot(steps, v["iae_ratio"], marker="o", ms=3, label=label)
            ax_rmsd.plot(steps, v["rmsd_ratio"], marker="o", ms=3, label=label)
        xs: list[float] = []
        ys: list[float] = []
        for progress in sorted(run.glob("progress*.csv")):
            p = read_csv_columns(progress)
            if "rollout/ep_rew_mean" in p:
                xs += [s / 1e6 for s in p["time/total_timesteps"]]
                ys += p["rollout/ep_rew_mean"]
        if xs:
            pairs = sorted(zip(xs, ys, strict=True))
            ax_ret.plot([a for a, _ in pairs], [b for _, b in pairs], lw=1.0, label=label)
    ax_iae.axhline(1.0, color="k", lw=0.8, ls="--")
    ax_iae.axhline(0.7, color="tab:red", lw=0.8, ls=":", label="goal (0.7)")
    ax_iae.set_ylabel("mean IAE / proposed")
    ax_iae.set_yscale("log")
    ax_rmsd.axhline(1.0, color="k", lw=0.8, ls="--")
    ax_rmsd.set_ylabel("mean RMSD / proposed")
    ax_ret.set_ylabel("training return\n(each run's reward)")
    ax_ret.set_xlabel("decisions (millions)")
    for ax in (ax_iae, ax_rmsd, ax_ret):
        ax.grid(True, alpha=0.3)
    ax_iae.legend(fontsize="small")
    if title:
        fig.suptitle(title)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=80)
    return out
