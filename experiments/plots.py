"""The studies' figures: episode traces and metric tables (comparison, held-out evaluation),
stick-slip maps, and training learning curves.

Every function draws one PNG with matplotlib's object-oriented API on the Agg canvas (no
``pyplot``, no global state, safe in worker processes) and returns the path it wrote. Traces
are :class:`drill_env.evaluation.Trace` objects; a 150 s run has 150,000 plant-rate samples,
so keep :func:`downsample` (or :func:`time_window`) copies for figures. Long series are drawn
with peak detection (each bin's minimum and maximum), never by plain striding, which would
alias a torque that switches at every 1 ms step into a flat line.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from drill_env.evaluation import Trace

if TYPE_CHECKING:  # pragma: no cover
    from experiments.stick_slip_map import StickSlipMap

__all__ = [
    "METRIC_LABELS",
    "SEVERITY_LIMIT",
    "downsample",
    "plot_adaptive_gains",
    "plot_learning_curves",
    "plot_map",
    "plot_maps",
    "plot_metric_bars",
    "plot_panels",
    "plot_speed_and_torque",
    "read_csv_columns",
    "time_window",
]

METRIC_LABELS: Final[dict[str, str]] = {
    "ise": "ISE (rad$^2$/s)",
    "iae": "IAE (rad)",
    "rmse": "RMSE (rad/s)",
    "rmsd_nm": "RMSD (N m)",
    "overshoot_pct": "overshoot (%)",
    "settling_time_s": "settling time (s)",
    "chattering_nm_per_s": "chattering (N m/s)",
    "stick_slip_severity": "stick-slip severity",
    "stuck_fraction": "stuck fraction",
}
"""Axis label (with unit) of each metric key of :mod:`drill_env.metrics`."""

DPI: Final = 80
"""Resolution of every figure, dots per inch (small files, quick to write)."""
SEVERITY_LIMIT: Final = 2.0
"""Upper end of the stick-slip severity colour scale (larger values show in the top colour)."""

_MARGINS: Final = {"left": 0.1, "right": 0.97, "bottom": 0.1, "top": 0.9, "hspace": 0.12}


def _peaks(values: npt.NDArray[np.float64], every: int) -> npt.NDArray[np.float64]:
    """One value per bin of ``every`` samples: the bin's maximum in even bins, its minimum in
    odd ones ("peak detect"), so a line through them spans what the signal spans."""
    n = values.shape[0]
    bins = -(-n // every)
    padded = np.empty(bins * every)
    padded[:n] = values
    padded[n:] = values[-1] if n else 0.0
    grid = padded.reshape(bins, every)
    out = grid.max(axis=1)
    out[1::2] = grid[1::2].min(axis=1)
    return out


def downsample(trace: Trace, every: int) -> Trace:
    """A lighter trace for figures: one sample per bin of ``every`` plant steps.

    Speeds, twists and the other smooth channels keep the first sample of each bin; the torques
    (``torque_nm``, ``base_torque_nm``) keep each bin's extreme, alternately its maximum and its
    minimum, so a torque that switches at every 1 ms step (chattering) still shows as a band
    instead of aliasing to a flat line. The result's ``plant_dt_s`` is ``every`` times the
    original, so ``time_s`` and ``duration_s`` stay right. For plotting only: metrics need
    every sample.

    Raises:
        ValueError: if ``every`` is not a positive integer.
    """
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ValueError(f"every = {every!r} is out of range: allowed an integer >= 1")
    if every == 1:
        return trace
    cut = slice(None, None, every)
    return dataclasses.replace(
        trace,
        time_s=trace.time_s[cut].copy(),
        states=trace.states[cut].copy(),
        torque_nm=_peaks(trace.torque_nm, every),
        base_torque_nm=_peaks(trace.base_torque_nm, every),
        reference_rad_s=trace.reference_rad_s[cut].copy(),
        wob_n=trace.wob_n[cut].copy(),
        bit_stuck=trace.bit_stuck[cut].copy(),
        sliding_variable=trace.sliding_variable[cut].copy(),
        adaptive_gain=trace.adaptive_gain[cut].copy(),
        plant_dt_s=trace.plant_dt_s * every,
    )


def time_window(trace: Trace, start_s: float, end_s: float | None = None) -> Trace:
    """The plant-rate samples of ``trace`` with ``start_s <= time_s < end_s`` (to the end when
    ``end_s`` is ``None``), at full rate; decision-rate arrays are kept whole."""
    t = trace.time_s
    lo = int(np.searchsorted(t, start_s))
    hi = len(t) if end_s is None else int(np.searchsorted(t, end_s))
    cut = slice(lo, hi)
    return dataclasses.replace(
        trace,
        time_s=trace.time_s[cut].copy(),
        states=trace.states[cut].copy(),
        torque_nm=trace.torque_nm[cut].copy(),
        base_torque_nm=trace.base_torque_nm[cut].copy(),
        reference_rad_s=trace.reference_rad_s[cut].copy(),
        wob_n=trace.wob_n[cut].copy(),
        bit_stuck=trace.bit_stuck[cut].copy(),
        sliding_variable=trace.sliding_variable[cut].copy(),
        adaptive_gain=trace.adaptive_gain[cut].copy(),
    )


def _figure(size: tuple[float, float], **margins: float) -> Figure:
    # Fixed margins rather than a layout engine: constrained layout draws every figure twice.
    fig = Figure(figsize=size, dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(**{**_MARGINS, **margins})
    return fig


def _save(fig: Figure, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=DPI)
    return out


MAX_POINTS: Final = 4000
"""Most points drawn per line; longer series are reduced by peak detection."""


def _series(
    t: npt.NDArray[np.float64],
    y: npt.NDArray[np.float64],
    window_s: tuple[float, float] | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The points to draw: the samples within ``window_s``, reduced to at most about
    ``MAX_POINTS`` by keeping each bin's extremes (so chattering and spikes stay visible)."""
    if window_s is not None:
        lo = int(np.searchsorted(t, window_s[0]))
        hi = int(np.searchsorted(t, window_s[1], side="right"))
        t, y = t[lo:hi], y[lo:hi]
    if t.shape[0] <= MAX_POINTS:
        return t, y
    every = math.ceil(2 * t.shape[0] / MAX_POINTS)
    return t[::every], _peaks(y, every)


def plot_speed_and_torque(
    traces: Mapping[str, Trace],
    path: str | Path,
    title: str = "",
    *,
    window_s: tuple[float, float] | None = None,
) -> Path:
    """Bit speed (with the reference) and top-drive torque of several runs against time.

    Args:
        traces: Label -> trace; one line per trace in each panel.
        path: PNG file to write (its folder is created).
        title: Figure title.
        window_s: Show only ``[t0, t1]`` seconds (a zoom); the whole run when ``None``.

    Returns:
        ``path``.
    """
    fig = _figure((8.0, 5.5))
    ax_w, ax_u = fig.subplots(2, 1, sharex=True)
    reference_drawn = False
    for label, trace in traces.items():
        t = trace.time_s
        ax_w.plot(*_series(t, trace.bit_speed_rad_s, window_s), lw=1.0, label=label)
        tu, u = _series(t, trace.torque_nm, window_s)
        ax_u.plot(tu, u / 1e3, lw=0.8, label=label)
        if not reference_drawn and len(tu):
            ax_w.plot(
                *_series(t, trace.reference_rad_s, window_s), "k--", lw=0.8, label="reference"
            )
            reference_drawn = True
    ax_w.set_ylabel("bit speed (rad/s)")
    ax_u.set_ylabel("top-drive torque (kN m)")
    ax_u.set_xlabel("time (s)")
    for ax in (ax_w, ax_u):
        ax.grid(True, alpha=0.3)
        ax.ticklabel_format(axis="x", useOffset=False)
    ax_w.legend(fontsize="small", ncol=min(len(traces) + 1, 3))
    if title:
        fig.suptitle(title)
    return _save(fig, path)


_QUANTITIES: Final[dict[str, tuple[str, float]]] = {
    "torque": ("top-drive torque (kN m)", 1e-3),
    "bit_speed": ("bit speed (rad/s)", 1.0),
    "top_drive_speed": ("top-drive speed (rad/s)", 1.0),
    "adaptive_gain": ("adaptive gain (N m)", 1.0),
}


def _quantity(trace: Trace, quantity: str) -> npt.NDArray[np.float64]:
    if quantity == "torque":
        return trace.torque_nm
    if quantity == "bit_speed":
        return trace.bit_speed_rad_s
    if quantity == "top_drive_speed":
        return trace.top_drive_speed_rad_s
    return trace.adaptive_gain


def plot_panels(
    panels: Mapping[str, Mapping[str, Trace]],
    path: str | Path,
    title: str = "",
    *,
    quantity: str = "torque",
    window_s: tuple[float, float] | None = None,
    ncols: int = 2,
) -> Path:
    """Small multiples: one panel per group of traces, each with its own value axis.

    Args:
        panels: Panel title -> (label -> trace), for example controller -> noise level -> trace.
        path: PNG file to write.
        title: Figure title.
        quantity: ``torque``, ``bit_speed``, ``top_drive_speed`` or ``adaptive_gain``.
        window_s: Show only ``[t0, t1]`` seconds; the whole run when ``None``.
        ncols: Panels per row.

    Returns:
        ``path``.

    Raises:
        ValueError: for an unknown ``quantity``, no panels or a panel without traces.
    """
    if quantity not in _QUANTITIES:
        raise ValueError(f"quantity = {quantity!r} is not valid: allowed {list(_QUANTITIES)}")
    if not panels:
        raise ValueError("panels is empty: nothing to plot")
    empty = [name for name, traces in panels.items() if not traces]
    if empty:
        raise ValueError(f"panel(s) {', '.join(map(repr, empty))} have no traces")
    ylabel, factor = _QUANTITIES[quantity]
    ncols = max(1, min(ncols, len(panels)))
    nrows = math.ceil(len(panels) / ncols)
    fig = _figure(
        (4.2 * ncols + 0.5, 2.4 * nrows + 0.8),
        left=0.8 / (4.2 * ncols + 0.5),
        bottom=0.5 / (2.4 * nrows + 0.8),
        top=1 - 0.55 / (2.4 * nrows + 0.8),
        hspace=0.35,
        wspace=0.25,
    )
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True).ravel()
    for ax, (name, traces) in zip(axes, panels.items(), strict=False):
        for label, trace in traces.items():
            t, y = _series(trace.time_s, _quantity(trace, quantity), window_s)
            ax.plot(t, y * factor, lw=0.8, label=label)
        ax.set_title(name, fontsize="medium")
        ax.ticklabel_format(axis="x", useOffset=False)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize="x-small")
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    for ax in axes[::ncols]:
        ax.set_ylabel(ylabel, fontsize="small")
    for ax in axes[-ncols:]:
        ax.set_xlabel("time (s)")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_adaptive_gains(traces: Mapping[str, Trace], path: str | Path, title: str = "") -> Path:
    """The base controller's adaptive gain (``trace.adaptive_gain``) against time, log scale.

    Args:
        traces: Label -> trace; traces whose gain is 0 throughout (fixed-gain laws) are skipped.
        path: PNG file to write.
        title: Figure title.

    Returns:
        ``path``.
    """
    fig = _figure((8.0, 4.0), bottom=0.13)
    ax = fig.subplots()
    drawn = 0
    for label, trace in traces.items():
        gain = trace.adaptive_gain
        if not np.any(gain != 0.0):
            continue
        ax.plot(*_series(trace.time_s, gain), lw=1.0, label=label)
        drawn += 1
    if drawn:
        ax.set_yscale("log")
        ax.legend(fontsize="small", ncol=2)
    else:
        ax.text(0.5, 0.5, "no adaptive gains", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("adaptive gain (N m)")
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title)
    return _save(fig, path)


def _bars(
    ax: Axes,
    rows: Sequence[Mapping[str, Any]],
    metric: str,
    group: str,
    hue: str,
    log: bool,
) -> None:
    groups = list(dict.fromkeys(r[group] for r in rows))
    hues = list(dict.fromkeys(r[hue] for r in rows))
    value: dict[tuple[Any, Any], float] = {}
    for r in rows:
        v = r.get(metric)
        value[(r[group], r[hue])] = math.nan if v is None else float(v)
    width = 0.8 / max(len(hues), 1)
    x = np.arange(len(groups))
    for k, h in enumerate(hues):
        heights = [value.get((g, h), math.nan) for g in groups]
        ax.bar(x + (k - (len(hues) - 1) / 2) * width, heights, width, label=str(h))
    ax.set_xticks(x, [str(g) for g in groups], rotation=30 if len(groups) > 4 else 0)
    ax.set_ylabel(METRIC_LABELS.get(metric, metric))
    if log:
        ax.set_yscale("log")
    ax.grid(True, axis="y", alpha=0.3)


def plot_metric_bars(
    rows: Sequence[Mapping[str, Any]],
    metric: str | Sequence[str],
    path: str | Path,
    *,
    group: str = "controller",
    hue: str = "condition",
    title: str = "",
    log: bool = False,
) -> Path:
    """Grouped bar chart of one or more metrics from a table of runs.

    Args:
        rows: One mapping per run (for example the rows of ``compare.json``); each holds the
            ``group`` and ``hue`` keys and the metric(s). A ``None`` value draws no bar.
        metric: A metric key, or several (one panel each, side by side).
        path: PNG file to write.
        group: Key whose values label the groups on the x axis.
        hue: Key whose values give one bar (and legend entry) per group.
        title: Figure title.
        log: Logarithmic value axis.

    Returns:
        ``path``.

    Raises:
        ValueError: if ``rows`` is empty.
    """
    if not rows:
        raise ValueError("rows is empty: nothing to plot")
    metrics = [metric] if isinstance(metric, str) else list(metric)
    width = 4.5 * len(metrics) + 1.5
    fig = _figure((width, 4.0), left=0.8 / width, bottom=0.2, wspace=0.3)
    axes = fig.subplots(1, len(metrics), squeeze=False)[0]
    for ax, m in zip(axes, metrics, strict=True):
        _bars(ax, rows, m, group, hue, log)
    axes[0].legend(fontsize="small", title=hue)
    if title:
        fig.suptitle(title)
    return _save(fig, path)


# ------------------------------------------------------------------- stick-slip maps
def _edges(values: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Cell edges around grid centres (a unit-wide cell around a single value)."""
    if values.size == 1:
        half = 0.05 * values[0]
        return np.array([values[0] - half, values[0] + half])
    mid = 0.5 * (values[1:] + values[:-1])
    return np.concatenate(([2 * values[0] - mid[0]], mid, [2 * values[-1] - mid[-1]]))


def _heatmap(ax: Axes, result: StickSlipMap, quantity: str, title: str) -> object:
    if quantity == "severity":
        data, norm, cmap = result.severity, Normalize(0.0, SEVERITY_LIMIT), "magma"
    else:
        data, norm, cmap = result.stuck_fraction, Normalize(0.0, 1.0), "viridis"
    mesh = ax.pcolormesh(
        _edges(result.reference_speed_rad_s),
        _edges(result.wob_n) / 1e3,
        np.ma.masked_invalid(data),
        cmap=cmap,
        norm=norm,
        shading="flat",
    )
    unstable = result.unstable()
    if unstable.any() and not unstable.all() and min(data.shape) > 1:
        ax.contour(
            result.reference_speed_rad_s,
            result.wob_n / 1e3,
            unstable.astype(float),
            levels=[0.5],
            colors="white",
            linewidths=1.0,
        )
    ax.set_title(title, fontsize=9)
    ax.set_xlabel("reference bit speed (rad/s)")
    ax.set_ylabel("WOB (kN)")
    return mesh


def plot_map(result: StickSlipMap, path: str | Path) -> Path:
    """Severity and stuck-fraction heatmaps of one map in one PNG; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(9.0, 3.6), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 2)
    labels = {"severity": "stick-slip severity", "stuck": "stuck fraction"}
    for ax, quantity in zip(axes, ("severity", "stuck"), strict=True):
        mesh = _heatmap(ax, result, quantity, f"{result.controller}: {labels[quantity]}")
        fig.colorbar(mesh, ax=ax, extend="max" if quantity == "severity" else "neither")  # type: ignore[arg-type]
    fig.suptitle(_caption(result), fontsize=8)
    fig.savefig(path)
    return path


def plot_maps(results: Sequence[StickSlipMap], path: str | Path) -> Path:
    """All maps side by side: one column per controller, severity above stuck fraction."""
    if not results:
        raise ValueError("plot_maps needs at least one map")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    n = len(results)
    fig = Figure(figsize=(2.9 * n + 1.2, 5.6), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = np.asarray(fig.subplots(2, n, squeeze=False, sharex=True, sharey=True))
    meshes = []
    for col, result in enumerate(results):
        meshes.append(_heatmap(axes[0, col], result, "severity", f"{result.controller}"))
        last = _heatmap(axes[1, col], result, "stuck", f"{result.controller}")
        if col:
            axes[0, col].set_ylabel("")
            axes[1, col].set_ylabel("")
        axes[0, col].set_xlabel("")
    fig.colorbar(meshes[-1], ax=list(axes[0]), extend="max", label="stick-slip severity")  # type: ignore[arg-type]
    fig.colorbar(last, ax=list(axes[1]), label="stuck fraction")  # type: ignore[arg-type]
    fig.suptitle(_caption(results[0]) + "; white line: stick-slip boundary", fontsize=8)
    fig.savefig(path)
    return path


def _caption(result: StickSlipMap) -> str:
    return (
        f"{result.parameters}, runs of {result.duration_s:g} s from rest, last "
        f"{result.window_s:g} s analysed, noise {result.noise_std_rad_s:g} rad/s"
    )


# -------------------------------------------------------------------- learning curves
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
