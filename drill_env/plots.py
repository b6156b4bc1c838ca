"""Figures of episode traces and metric tables, shared by the comparison, the stick-slip map
and the agent evaluation.

Every function draws one PNG with matplotlib's object-oriented API on the Agg canvas (no
``pyplot``, no global state, safe in worker processes) and returns the path it wrote. Traces
are :class:`drill_env.evaluation.Trace` objects; pass them through :func:`downsample` first:
a 150 s run has 150,000 plant-rate samples, more than a figure can show.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from drill_env.evaluation import Trace

__all__ = [
    "METRIC_LABELS",
    "downsample",
    "plot_adaptive_gains",
    "plot_metric_bars",
    "plot_panels",
    "plot_speed_and_torque",
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


def downsample(trace: Trace, every: int) -> Trace:
    """Keep every ``every``-th plant-rate sample of ``trace`` (decision-rate arrays are kept).

    The result's ``plant_dt_s`` is ``every`` times the original, so ``time_s`` and
    ``duration_s`` stay right. For plotting only: metrics need every sample.

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
        torque_nm=trace.torque_nm[cut].copy(),
        base_torque_nm=trace.base_torque_nm[cut].copy(),
        reference_rad_s=trace.reference_rad_s[cut].copy(),
        wob_n=trace.wob_n[cut].copy(),
        bit_stuck=trace.bit_stuck[cut].copy(),
        sliding_variable=trace.sliding_variable[cut].copy(),
        adaptive_gain=trace.adaptive_gain[cut].copy(),
        plant_dt_s=trace.plant_dt_s * every,
    )


def _figure(rows: int, cols: int = 1, size: tuple[float, float] = (8.0, 5.5)) -> Figure:
    fig = Figure(figsize=size, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=DPI)
    return out


def _window(
    trace: Trace, window_s: tuple[float, float] | None
) -> tuple[npt.NDArray[np.float64], slice]:
    t = trace.time_s
    if window_s is None:
        return t, slice(None)
    lo, hi = np.searchsorted(t, window_s[0]), np.searchsorted(t, window_s[1], side="right")
    return t, slice(int(lo), int(hi))


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
    fig = _figure(2)
    ax_w, ax_u = fig.subplots(2, 1, sharex=True)
    reference_drawn = False
    for label, trace in traces.items():
        t, cut = _window(trace, window_s)
        ax_w.plot(t[cut], trace.bit_speed_rad_s[cut], lw=1.0, label=label)
        ax_u.plot(t[cut], trace.torque_nm[cut] / 1e3, lw=0.8, label=label)
        if not reference_drawn and len(t[cut]):
            ax_w.plot(t[cut], trace.reference_rad_s[cut], "k--", lw=0.8, label="reference")
            reference_drawn = True
    ax_w.set_ylabel("bit speed (rad/s)")
    ax_u.set_ylabel("top-drive torque (kN m)")
    ax_u.set_xlabel("time (s)")
    for ax in (ax_w, ax_u):
        ax.grid(True, alpha=0.3)
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
        ValueError: for an unknown ``quantity`` or no panels.
    """
    if quantity not in _QUANTITIES:
        raise ValueError(f"quantity = {quantity!r} is not valid: allowed {list(_QUANTITIES)}")
    if not panels:
        raise ValueError("panels is empty: nothing to plot")
    ylabel, factor = _QUANTITIES[quantity]
    ncols = max(1, min(ncols, len(panels)))
    nrows = math.ceil(len(panels) / ncols)
    fig = _figure(nrows, ncols, size=(4.2 * ncols + 0.5, 2.4 * nrows + 0.6))
    axes = fig.subplots(nrows, ncols, squeeze=False, sharex=True).ravel()
    for ax, (name, traces) in zip(axes, panels.items(), strict=False):
        for label, trace in traces.items():
            t, cut = _window(trace, window_s)
            ax.plot(t[cut], _quantity(trace, quantity)[cut] * factor, lw=0.8, label=label)
        ax.set_title(name, fontsize="medium")
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
    fig = _figure(1, size=(8.0, 4.0))
    ax = fig.subplots()
    drawn = 0
    for label, trace in traces.items():
        gain = trace.adaptive_gain
        if not np.any(gain != 0.0):
            continue
        ax.plot(trace.time_s, gain, lw=1.0, label=label)
        drawn += 1
    if drawn:
        ax.set_yscale("log")
        ax.legend(fontsize="small", ncol=2)
    else:
        ax.text(0.5, 0.5, "no adaptive gains", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("adaptive gain (N m)")
    ax.grid(True, alpha=0.3, which="both")
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
    ax.grid(True, axis="y", alpha=0.3, which="both")


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
    fig = _figure(1, len(metrics), size=(4.5 * len(metrics) + 1.5, 4.0))
    axes = fig.subplots(1, len(metrics), squeeze=False)[0]
    for ax, m in zip(axes, metrics, strict=True):
        _bars(ax, rows, m, group, hue, log)
    axes[0].legend(fontsize="small", title=hue)
    if title:
        fig.suptitle(title)
    return _save(fig, path)
