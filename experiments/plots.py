"""The figure kit every study draws with: the palette (:func:`color_of`), the labels of the
metrics and row keys, the blank figure (:func:`new_figure`), the text-overlap check, episode
trace figures, metric bar charts, the realism panels and training learning curves. A study's
own figures live in the study's module (the maps in :mod:`experiments.stick_slip_map`, the
probability map in :mod:`experiments.probability_map`, the string's waves in
:mod:`experiments.waves`), built on this kit; this module imports no study.

Every ``*_figure`` function builds one :class:`~matplotlib.figure.Figure` with matplotlib's
object-oriented API on the Agg canvas (no ``pyplot``, no global state, safe in worker processes)
and returns it (matplotlib is imported there, when a figure is drawn, so that a command starts
without it); :func:`save_figure` writes it as PNG. :func:`text_overlaps` lists the pairs of
texts of a figure that overlap (titles, labels, tick labels, legends, notes) and
:func:`text_outside` the texts cut off by its edge: the tests check every figure the commands
write with both.

Traces are :class:`drill_env.evaluation.Trace` objects; a 150 s run has 150,000 plant-rate
samples, so keep :func:`downsample` (or :func:`time_window`) copies and :class:`Envelope`
summaries for figures. Long series are drawn with peak detection (each bin's minimum and
maximum), never by plain striding, which would alias a torque that switches at every 1 ms step
into a flat line; a noisy torque is drawn as its band (each bin's minimum to maximum, light)
behind its bin mean.

A controller has the same colour in every figure (:func:`color_of`); lines that may lie on top
of each other get different dash patterns and widths, so each stays visible.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, NamedTuple

import numpy as np
import numpy.typing as npt

from baselines.registry import BUILT_IN
from drill_env.evaluation import Trace
from drill_env.files import replacing
from drill_env.metrics import METRIC_LABELS as CORE_METRIC_LABELS
from drill_env.metrics import STICK_SLIP_SEVERITY
from drill_env.validation import printable
from drill_env.validation import shown as shown_value

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.text import Text

__all__ = [
    "DPI",
    "KEY_LABELS",
    "METRIC_LABELS",
    "SEVERITY_LIMIT",
    "Envelope",
    "adaptive_gains_figure",
    "cell_edges",
    "color_of",
    "downsample",
    "envelope",
    "key_label",
    "learning_curves_figure",
    "legend_columns",
    "metric_bars_figure",
    "new_figure",
    "panels_figure",
    "plot_learning_curves",
    "read_csv_columns",
    "realism_figure",
    "save_figure",
    "speed_torque_figure",
    "suptitle",
    "text_outside",
    "text_overlaps",
    "text_problems",
    "time_window",
    "trace_response_figure",
    "value_label",
]

METRIC_LABELS: Final[dict[str, str]] = {
    **CORE_METRIC_LABELS,
    "static_error_rad_s": "static error (rad/s)",
}
"""Axis label (with unit) of each metric key of :mod:`drill_env.metrics` (its
:data:`~drill_env.metrics.METRIC_LABELS`) and of the comparison's static error."""

KEY_LABELS: Final[dict[str, str]] = {
    "controller": "controller",
    "condition": "uncertainty condition",
    "uncertainty": "uncertainty condition",
    "noise_std_rad_s": "measurement noise",
    "scenario": "held-out scenario",
    "reference_speed_rad_s": "reference bit speed (rad/s)",
    "wob_n": "WOB (N)",
    **METRIC_LABELS,
}
"""Readable label of each row key the figures group, colour or label by."""

DPI: Final = 80
"""Resolution of every figure, dots per inch (small files, quick to write)."""
SEVERITY_LIMIT: Final = 2.0
"""Upper end of the stick-slip severity colour scale (larger values show in the top colour)."""
MAX_POINTS: Final = 4000
"""Most points drawn per line; longer series are reduced by peak detection."""
START_S: Final = 1.0
"""The first this many seconds of a run (the start-up torque peak) do not set the torque axis."""

_PALETTE: Final = (
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
    "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf",
)  # fmt: skip
_PALETTE_LIGHT: Final = (
    "#aec7e8", "#ffbb78", "#98df8a", "#ff9896", "#c5b0d5",
    "#c49c94", "#f7b6d2", "#c7c7c7", "#dbdb8d", "#9edae5",
)  # fmt: skip
"""The lighter partner of each colour of :data:`_PALETTE` (matplotlib's tab20 pairs)."""
_AGENTS: Final = ("residual_ppo", "direct_ppo")
"""The shipped agents, coloured after the built-in controllers."""
_DEFAULT_LOOPS: Final = [name for name, cls in BUILT_IN.items() if not hasattr(cls, "base_name")]
_NAMED_COLORS: Final[dict[str, str]] = {
    **{name: _PALETTE[k] for k, name in enumerate((*_DEFAULT_LOOPS, *_AGENTS))},
    **{
        name: _PALETTE_LIGHT[_DEFAULT_LOOPS.index(cls.base_name)]
        for name, cls in BUILT_IN.items()
        if hasattr(cls, "base_name")
    },
}
"""Every built-in controller's colour and the agents': the registry's order; a ``*_tuned``
loop in the lighter shade of its default loop."""
_DASHES: Final = (("-", 2.6), ("--", 1.8), (":", 2.2), ("-.", 1.2), ((0, (5, 1, 1, 1)), 1.0))
"""Line style and width of the k-th line of a panel: overlapping lines stay visible."""
_CONDITION_STYLES: Final[dict[str, Any]] = {
    "nominal": "-",
    "condition1": "--",
    "condition2": "-.",
    "condition3": ":",
}


def color_of(label: str, index: int = 0) -> str:
    """The colour of a controller (the same in every figure; the part of ``label`` before the
    first space or colon names it), or the ``index``-th colour of the palette for other
    labels."""
    name = label.split(" ")[0].split(":")[0]
    return _NAMED_COLORS.get(name, _PALETTE[index % len(_PALETTE)])


def key_label(key: str) -> str:
    """The readable name of a row key (``noise_std_rad_s`` -> ``measurement noise``)."""
    return KEY_LABELS.get(key, key.replace("_", " "))


def value_label(key: str, value: Any) -> str:
    """A value of the row key ``key`` as a legend or tick shows it (a noise level with its
    unit, ``off`` for none)."""
    if key == "noise_std_rad_s":
        v = float(value)
        return "noise off" if v == 0.0 else f"noise {v:g} rad/s"
    return str(value)


# ----------------------------------------------------------------------- trace helpers
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
        raise ValueError(f"every = {shown_value(every)} is out of range: allowed an integer >= 1")
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


class Envelope(NamedTuple):
    """A signal summarised per time bin: its minimum, mean and maximum.

    Attributes:
        time_s: Centre of each bin, (n,), s.
        low: Minimum of each bin, (n,).
        mean: Mean of each bin, (n,).
        high: Maximum of each bin, (n,).
    """

    time_s: npt.NDArray[np.float64]
    low: npt.NDArray[np.float64]
    mean: npt.NDArray[np.float64]
    high: npt.NDArray[np.float64]


def envelope(trace: Trace, bin_s: float = 0.1) -> Envelope:
    """The top-drive torque of ``trace`` (N m) per bin of ``bin_s`` seconds: minimum, mean
    and maximum. From a full-rate trace the band spans every sample and the mean is exact.

    Raises:
        ValueError: if ``bin_s`` is not positive.
    """
    if not (math.isfinite(bin_s) and bin_s > 0):
        raise ValueError(f"bin_s = {shown_value(bin_s)} is out of range: allowed > 0 s")
    every = max(1, round(bin_s / trace.plant_dt_s))
    values = np.asarray(trace.torque_nm, dtype=np.float64)
    n = values.shape[0]
    bins = -(-n // every)
    padded = np.full(bins * every, np.nan)
    padded[:n] = values
    grid = padded.reshape(bins, every)
    start = trace.time_s[::every][:bins] if n else np.zeros(0)
    return Envelope(
        start + 0.5 * (every - 1) * trace.plant_dt_s,
        np.nanmin(grid, axis=1) if n else np.zeros(0),
        np.nanmean(grid, axis=1) if n else np.zeros(0),
        np.nanmax(grid, axis=1) if n else np.zeros(0),
    )


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


# ------------------------------------------------------------------- figure plumbing
def new_figure(width_in: float, height_in: float) -> Figure:
    """An empty figure on the Agg canvas with constrained layout (no text collisions)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    fig.get_layout_engine().set(h_pad=0.04, w_pad=0.04)  # type: ignore[union-attr,call-arg]
    return fig


def _wrap(text: str, width_in: float, fontsize: float = 12.0) -> str:
    """``text`` broken into lines that fit ``width_in`` inches at ``fontsize`` points."""
    chars = max(20, int(width_in * 72 / (0.55 * fontsize)))
    return "\n".join(textwrap.wrap(text, chars, break_on_hyphens=False)) if text else text


def legend_columns(fig: Figure, labels: Sequence[str], fontsize: float, most: int = 6) -> int:
    """Columns of a legend under the axes: at most ``most``, and few enough that a row of the
    longest label fits the figure's width."""
    char_in = 0.55 * fontsize / 72.0
    entry_in = char_in * max((len(str(t)) for t in labels), default=1) + 0.7
    return max(1, min(len(labels), most, int(fig.get_figwidth() / entry_in)))


def suptitle(fig: Figure, text: str) -> None:
    """The figure title, wrapped to the figure's width."""
    if text:
        fig.suptitle(_wrap(text, fig.get_figwidth() - 0.3))


def _plain_texts(fig: Figure) -> None:
    """Draw names from outside as they are written: a ``$`` in a controller's or a model's
    name does not start mathtext (which could fail to parse), and control characters other
    than newlines are shown escaped. Only the labels of :data:`METRIC_LABELS` use mathtext."""
    from matplotlib.text import Text

    ours = set(METRIC_LABELS.values())
    for artist in fig.findobj(Text):
        text = artist.get_text()
        if "$" in text and text not in ours:
            artist.set_parse_math(False)
        if not all(c.isprintable() or c == "\n" for c in text):
            lines = (printable(line, len(line) * 6 + 3) for line in text.split("\n"))
            artist.set_text("\n".join(lines))


def save_figure(fig: Figure, path: str | Path) -> Path:
    """Write ``fig`` as PNG to ``path`` (its folder is created; written whole or not at all,
    never through a symbolic link: :func:`drill_env.files.replacing`); returns the path."""
    out = Path(path)
    _plain_texts(fig)
    with replacing(out, "wb") as f:
        fig.savefig(f, dpi=DPI, format="png")
    return out


def _visible(artist: Any) -> bool:
    axes = getattr(artist, "axes", None)
    return bool(artist.get_visible()) and (axes is None or bool(axes.get_visible()))


def _tick_labels(fig: Figure) -> tuple[list[Text], dict[int, str]]:
    """The tick labels that are drawn (inside their axis' view), and the axis of each."""
    labels: list[Text] = []
    owner: dict[int, str] = {}
    for k, ax in enumerate(fig.axes):
        if not ax.get_visible():
            continue
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            if not axis.get_visible():
                continue
            low, high = sorted(axis.get_view_interval())
            span = (high - low) * 1e-9
            ticks = [
                *axis.get_major_ticks(len(axis.get_majorticklocs())),
                *axis.get_minor_ticks(len(axis.get_minorticklocs())),
            ]
            for tick in ticks:
                if not low - span <= tick.get_loc() <= high + span:
                    continue
                for text in (tick.label1, tick.label2):
                    if text.get_visible() and text.get_text().strip():
                        labels.append(text)
                        owner[id(text)] = f"axes {k} {name}"
    return labels, owner


def _drawn_texts(fig: Figure) -> list[tuple[Text, str]]:
    """Every visible, non-empty text of ``fig`` with a short description (draws ``fig``)."""
    from matplotlib.text import Text

    fig.canvas.draw()
    ticks, owner = _tick_labels(fig)
    texts = [(t, f"tick label {shown_value(t.get_text())} ({owner[id(t)]})") for t in ticks]
    every_tick_text = {
        id(text)
        for ax in fig.axes
        for axis in (ax.xaxis, ax.yaxis)
        for tick in (*axis.majorTicks, *axis.minorTicks)
        for text in (tick.label1, tick.label2)
    }
    for text in fig.findobj(Text):
        if id(text) in every_tick_text or not (_visible(text) and text.get_text().strip()):
            continue
        texts.append((text, repr(text.get_text())))
    return texts


def _extents(fig: Figure, texts: Sequence[tuple[Text, str]]) -> npt.NDArray[np.float64]:
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    boxes = [t.get_window_extent(renderer) for t, _ in texts]
    return np.array([[b.x0, b.y0, b.x1, b.y1] for b in boxes]).reshape(-1, 4)


def _overlaps(
    texts: Sequence[tuple[Text, str]], box: npt.NDArray[np.float64], tolerance_px: float
) -> list[str]:
    if box.shape[0] < 2:
        return []
    x1 = np.minimum(box[:, None, 2], box[None, :, 2])
    x0 = np.maximum(box[:, None, 0], box[None, :, 0])
    y1 = np.minimum(box[:, None, 3], box[None, :, 3])
    y0 = np.maximum(box[:, None, 1], box[None, :, 1])
    hits = np.argwhere(np.triu((x1 - x0 > tolerance_px) & (y1 - y0 > tolerance_px), k=1))
    return [f"{texts[i][1]} overlaps {texts[j][1]}" for i, j in hits]


def _outside(
    fig: Figure,
    texts: Sequence[tuple[Text, str]],
    box: npt.NDArray[np.float64],
    tolerance_px: float,
) -> list[str]:
    width, height = fig.canvas.get_width_height()
    out = (
        (box[:, 0] < -tolerance_px)
        | (box[:, 1] < -tolerance_px)
        | (box[:, 2] > width + tolerance_px)
        | (box[:, 3] > height + tolerance_px)
    )
    return [f"{texts[int(i)][1]} reaches beyond the figure" for i in np.flatnonzero(out)]


def text_overlaps(fig: Figure, tolerance_px: float = 1.0) -> list[str]:
    """The pairs of drawn texts of ``fig`` whose boxes overlap by more than ``tolerance_px``
    in both directions: titles, the suptitle, axis labels, tick labels (of the same axis too),
    legend texts and titles, annotations and colour-bar labels. Draws the figure.

    Returns:
        One description per overlapping pair, empty when no texts overlap.
    """
    texts = _drawn_texts(fig)
    return _overlaps(texts, _extents(fig, texts), tolerance_px)


def text_outside(fig: Figure, tolerance_px: float = 1.0) -> list[str]:
    """The drawn texts of ``fig`` that reach beyond its edges (cut off in the PNG)."""
    texts = _drawn_texts(fig)
    return _outside(fig, texts, _extents(fig, texts), tolerance_px)


def text_problems(fig: Figure, tolerance_px: float = 1.0) -> list[str]:
    """:func:`text_overlaps` and :func:`text_outside` of ``fig`` with one drawing."""
    texts = _drawn_texts(fig)
    box = _extents(fig, texts)
    return _overlaps(texts, box, tolerance_px) + _outside(fig, texts, box, tolerance_px)


# ----------------------------------------------------------------------- value axes
class _Range(NamedTuple):
    low: float
    high: float
    clipped_high: float | None  # the largest value above ``high`` (None: nothing clipped)
    clipped_low: float | None


def _value_range(
    series: Iterable[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]],
    skip_s: float = START_S,
) -> _Range | None:
    """A value axis that shows the run: spanned by the samples after the first ``skip_s``
    seconds, unless the start-up values outside it would stretch the axis by more than a
    third (then those are clipped and reported)."""
    full_lo, full_hi = math.inf, -math.inf
    run_lo, run_hi = math.inf, -math.inf
    for t, y in series:
        finite = np.isfinite(y)
        if not finite.any():
            continue
        full_lo = min(full_lo, float(np.min(y[finite])))
        full_hi = max(full_hi, float(np.max(y[finite])))
        late = finite & (t >= t[0] + skip_s) if t.size else finite
        if late.sum() < 2:
            late = finite
        run_lo = min(run_lo, float(np.min(y[late])))
        run_hi = max(run_hi, float(np.max(y[late])))
    if not math.isfinite(full_lo):
        return None
    span = max(run_hi - run_lo, 1e-9 * max(abs(run_hi), 1.0), 1e-12)
    clip_hi = full_hi > run_hi + span / 3
    clip_lo = full_lo < run_lo - span / 3
    low = run_lo if clip_lo else full_lo
    high = run_hi if clip_hi else full_hi
    pad = 0.06 * max(high - low, 1e-9 * max(abs(high), 1.0), 1e-12)
    return _Range(low - pad, high + pad, full_hi if clip_hi else None, full_lo if clip_lo else None)


def _mark_clipped(
    ax: Axes,
    t: npt.NDArray[np.float64],
    y: npt.NDArray[np.float64],
    bounds: _Range,
    color: str,
) -> None:
    """A triangle at the edge of ``ax`` where ``y`` leaves the axis (one per excursion)."""
    for limit, above, marker in ((bounds.high, True, "^"), (bounds.low, False, "v")):
        if (bounds.clipped_high if above else bounds.clipped_low) is None:
            continue
        out = y > limit if above else y < limit
        if not out.any():
            continue
        starts = np.flatnonzero(out & ~np.concatenate(([False], out[:-1])))
        edge = limit - 0.035 * (bounds.high - bounds.low) * (1 if above else -1)
        ax.plot(t[starts], np.full(starts.shape, edge), ls="", marker=marker, ms=8, color=color)


def _clip_handle(bounds: _Range, scale: float, unit: str) -> Line2D | None:
    """The legend entry that explains the triangles of :func:`_mark_clipped`."""
    from matplotlib.lines import Line2D

    parts = []
    if bounds.clipped_high is not None:
        parts.append(f"up to {bounds.clipped_high * scale:.3g} {unit}")
    if bounds.clipped_low is not None:
        parts.append(f"down to {bounds.clipped_low * scale:.3g} {unit}")
    if not parts:
        return None
    marker = "^" if bounds.clipped_high is not None else "v"
    return Line2D(
        [], [], ls="", marker=marker, ms=8, color="0.3",
        label=f"off the axis at start-up ({', '.join(parts)})",
    )  # fmt: skip


def _merge(ranges: Sequence[_Range | None]) -> _Range | None:
    """One axis for several ranges: the union of their axes; a clipped value counts only
    where it is outside that union."""
    found = [r for r in ranges if r is not None]
    if not found:
        return None
    low = min(r.low for r in found)
    high = max(r.high for r in found)
    highs = [r.clipped_high for r in found if r.clipped_high is not None and r.clipped_high > high]
    lows = [r.clipped_low for r in found if r.clipped_low is not None and r.clipped_low < low]
    return _Range(low, high, max(highs) if highs else None, min(lows) if lows else None)


# ---------------------------------------------------------------- speed and torque
def _torque_series(
    trace: Trace, band: Envelope | None, window_s: tuple[float, float] | None
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    if band is not None:
        keep = np.ones(band.time_s.shape, dtype=bool)
        if window_s is not None:
            keep = (band.time_s >= window_s[0]) & (band.time_s <= window_s[1])
        return band.time_s[keep], band.high[keep]
    return _series(trace.time_s, trace.torque_nm, window_s)


def _band_low(
    band: Envelope, window_s: tuple[float, float] | None
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    keep = np.ones(band.time_s.shape, dtype=bool)
    if window_s is not None:
        keep = (band.time_s >= window_s[0]) & (band.time_s <= window_s[1])
    return band.time_s[keep], band.low[keep]


def _draw_torque(
    ax: Axes,
    label: str,
    trace: Trace,
    band: Envelope | None,
    window_s: tuple[float, float] | None,
    color: str,
    style: tuple[Any, float],
) -> None:
    """The torque of one run in kN m: its band (light) behind its bin mean, or its samples."""
    if band is None:
        t, u = _series(trace.time_s, trace.torque_nm, window_s)
        ax.plot(t, u / 1e3, color=color, ls=style[0], lw=min(style[1], 1.4), label=label)
        return
    keep = np.ones(band.time_s.shape, dtype=bool)
    if window_s is not None:
        keep = (band.time_s >= window_s[0]) & (band.time_s <= window_s[1])
    t = band.time_s[keep]
    ax.fill_between(t, band.low[keep] / 1e3, band.high[keep] / 1e3, color=color, alpha=0.18, lw=0)
    ax.plot(t, band.mean[keep] / 1e3, color=color, ls=style[0], lw=style[1], label=label)


def speed_torque_figure(
    columns: Mapping[str, Mapping[str, Trace]],
    title: str = "",
    *,
    envelopes: Mapping[str, Envelope] | None = None,
    window_s: tuple[float, float] | None = None,
    colors: Mapping[str, str] | None = None,
) -> Figure:
    """Bit speed (with the reference) above top-drive torque against time, one column of
    panels per group of runs.

    The speed axes are shared by all columns; each column has its own torque axis, spanned by
    the run after its first second (a start-up peak beyond it is marked with a triangle and
    its value in the legend). With an :class:`Envelope` for a label, its torque is drawn as the
    band of each bin (light) behind the bin mean, so noise does not hide the other lines.

    Args:
        columns: Column title (the legend title) -> (line label -> trace).
        title: Figure title.
        envelopes: Line label -> torque envelope (optional, per label).
        window_s: Show only ``[t0, t1]`` seconds (a zoom); the whole run when ``None``.
        colors: Line label -> colour (default: :func:`color_of` of the label).

    Returns:
        The figure.

    Raises:
        ValueError: if there is no column or a column has no trace.
    """
    if not columns:
        raise ValueError("columns is empty: nothing to plot")
    empty = [name for name, traces in columns.items() if not traces]
    if empty:
        raise ValueError(f"column(s) {', '.join(map(repr, empty))} have no traces")
    bands = envelopes or {}
    n = len(columns)
    fig = new_figure(4.6 * n + 0.9 if n > 1 else 8.5, 6.4)
    axes = np.asarray(fig.subplots(2, n, squeeze=False, sharex=True))
    for col in range(1, n):
        axes[0, col].sharey(axes[0, 0])
    for col, (name, traces) in enumerate(columns.items()):
        ax_w, ax_u = axes[0, col], axes[1, col]
        reference = next(iter(traces.values()))
        drawn: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], str]] = []
        ax_w.plot(
            *_series(reference.time_s, reference.reference_rad_s, window_s),
            color="k", ls=(0, (4, 2)), lw=1.0, label="reference", zorder=3,
        )  # fmt: skip
        ranges = []
        for k, (label, trace) in enumerate(traces.items()):
            color = (colors or {}).get(label) or color_of(label, k)
            style = _DASHES[k % len(_DASHES)]
            ax_w.plot(
                *_series(trace.time_s, trace.bit_speed_rad_s, window_s),
                color=color, ls=style[0], lw=style[1], label=label,
            )  # fmt: skip
            band = bands.get(label)
            _draw_torque(ax_u, label, trace, band, window_s, color, style)
            t, high = _torque_series(trace, band, window_s)
            drawn.append((t, high / 1e3, color))
            ranges.append(_value_range([(t, high / 1e3)]))
            if band is not None:
                t, low = _band_low(band, window_s)
                ranges.append(_value_range([(t, low / 1e3)]))
        bounds = _merge(ranges)
        handles, _ = ax_w.get_legend_handles_labels()
        if bounds is not None:
            ax_u.set_ylim(bounds.low, bounds.high)
            for t, u, color in drawn:
                _mark_clipped(ax_u, t, u, bounds, color)
            clip = _clip_handle(bounds, 1.0, "kN m")
            if clip is not None:
                handles.append(clip)
        ncol = 2 if n > 1 else 3
        while True:  # fewer columns while the legend is wider than its share of the figure
            legend = ax_w.legend(
                handles=handles,
                title=name or None,
                loc="lower center",
                bbox_to_anchor=(0.5, 1.02),
                ncol=ncol,
                fontsize=9,
                title_fontsize=10,
                frameon=False,
                borderaxespad=0.0,
            )
            width = legend.get_window_extent(fig.canvas.get_renderer()).width  # type: ignore[attr-defined]
            if ncol == 1 or width <= fig.get_figwidth() * fig.dpi / n:
                break
            ncol -= 1
        ax_u.set_xlabel("time (s)")
        for ax in (ax_w, ax_u):
            ax.grid(True, alpha=0.3)
            ax.ticklabel_format(axis="x", useOffset=False)
        if col == 0:
            ax_w.set_ylabel("bit speed (rad/s)")
            ax_u.set_ylabel("top-drive torque (kN m)")
        else:
            ax_w.tick_params(labelleft=False)
    if title:
        note = "; each column has its own torque axis" if n > 1 else ""
        suptitle(fig, title + note)
    return fig


# ---------------------------------------------------------------------- small multiples
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


def panels_figure(
    panels: Mapping[str, Mapping[str, Trace]],
    title: str = "",
    *,
    quantity: str = "torque",
    window_s: tuple[float, float] | None = None,
    ncols: int = 2,
    reference: bool = False,
    band_s: float | None = None,
    sharey: bool = False,
) -> Figure:
    """Small multiples: one panel per group of traces, one legend for all of them.

    Args:
        panels: Panel title -> (label -> trace), for example controller -> noise level -> trace.
            A label has the same colour in every panel.
        title: Figure title (it says when the panels have their own value axes).
        quantity: ``torque``, ``bit_speed``, ``top_drive_speed`` or ``adaptive_gain``.
        window_s: Show only ``[t0, t1]`` seconds; the whole run when ``None``.
        ncols: Panels per row.
        reference: Also draw each panel's reference bit speed (for the speed quantities).
        band_s: For ``torque``: draw each trace as the band of bins of this many seconds
            (light) behind the bin mean; ``None`` draws the samples.
        sharey: One value axis for all panels; otherwise each panel has its own, spanned by
            the run after its first second (start-up values beyond it are marked).

    Returns:
        The figure.

    Raises:
        ValueError: for an unknown ``quantity``, no panels or a panel without traces.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if quantity not in _QUANTITIES:
        raise ValueError(
            f"quantity = {shown_value(quantity)} is not valid: allowed {list(_QUANTITIES)}"
        )
    if not panels:
        raise ValueError("panels is empty: nothing to plot")
    empty = [name for name, traces in panels.items() if not traces]
    if empty:
        raise ValueError(f"panel(s) {', '.join(map(repr, empty))} have no traces")
    ylabel, factor = _QUANTITIES[quantity]
    ncols = max(1, min(ncols, len(panels)))
    nrows = math.ceil(len(panels) / ncols)
    fig = new_figure(3.7 * ncols + 0.6, 2.35 * nrows + 1.3)
    grid = np.asarray(fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=sharey))
    axes = grid.ravel()
    labels = list(dict.fromkeys(label for traces in panels.values() for label in traces))
    color = {label: color_of(label, k) for k, label in enumerate(labels)}
    style = {label: ("-", 1.3) for label in labels}
    clip_handle: Line2D | None = None
    for ax, (name, traces) in zip(axes, panels.items(), strict=False):
        ranges = []
        drawn: list[tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], str]] = []
        if reference and quantity in ("bit_speed", "top_drive_speed"):
            first = next(iter(traces.values()))
            ax.plot(
                *_series(first.time_s, first.reference_rad_s, window_s),
                color="k", ls=(0, (4, 2)), lw=1.0, zorder=3,
            )  # fmt: skip
        for label, trace in traces.items():
            lw = min(style[label][1], 1.6)
            if quantity == "torque" and band_s is not None:
                band = envelope(trace, band_s)
                _draw_torque(ax, label, trace, band, window_s, color[label], (style[label][0], lw))
                t, y = _torque_series(trace, band, window_s)
                t_low, y_low = _band_low(band, window_s)
                ranges.append(_value_range([(t_low, y_low * factor)]))
            else:
                t, y = _series(trace.time_s, _quantity(trace, quantity), window_s)
                ax.plot(t, y * factor, color=color[label], ls=style[label][0], lw=lw)
            drawn.append((t, y * factor, color[label]))
            ranges.append(_value_range([(t, y * factor)]))
        bounds = _merge(ranges)
        if bounds is not None and not sharey and window_s is None:
            ax.set_ylim(bounds.low, bounds.high)
            for t, y, c in drawn:
                _mark_clipped(ax, t, y, bounds, c)
            if _clip_handle(bounds, 1.0, "") is not None:
                clip_handle = Line2D(
                    [], [], ls="", marker="^", ms=8, color="0.3", label="off the axis at start-up"
                )
        ax.set_title(name, fontsize=10)
        ax.ticklabel_format(axis="x", useOffset=False)
        ax.grid(True, alpha=0.3)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    for row in grid:
        row[0].set_ylabel(ylabel, fontsize=9)
    for col in range(ncols):
        for row in range(nrows - 1, -1, -1):
            if row * ncols + col < len(panels):
                grid[row, col].set_xlabel("time (s)")
                grid[row, col].tick_params(labelbottom=True)
                break
    handles: list[Any] = [
        Line2D([], [], color=color[label], ls=style[label][0], lw=1.6, label=label)
        for label in labels
    ]
    if reference and quantity in ("bit_speed", "top_drive_speed"):
        handles.append(Line2D([], [], color="k", ls=(0, (4, 2)), lw=1.0, label="reference"))
    if clip_handle is not None:
        handles.append(clip_handle)
    if quantity == "torque" and band_s is not None:
        handles.append(Patch(color="0.5", alpha=0.3, label=f"band: min-max per {band_s:g} s"))
    fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 6), fontsize=10)
    if title:
        note = "" if sharey or len(panels) == 1 else " (each panel has its own value axis)"
        suptitle(fig, title + note)
    return fig


# -------------------------------------------------------------------- adaptive gains
def adaptive_gains_figure(traces: Mapping[tuple[str, str], Trace], title: str = "") -> Figure:
    """The adaptive switching gain ``k`` of the adaptive sliding-mode laws against time, log
    scale: colour per controller, line style per uncertainty condition.

    Args:
        traces: (controller label, condition) -> trace; traces whose gain is 0 throughout
            (fixed-gain laws) are skipped.
        title: Figure title.

    Returns:
        The figure.
    """
    from matplotlib.lines import Line2D

    fig = new_figure(9.0, 4.6)
    ax = fig.subplots()
    controllers: dict[str, str] = {}
    conditions: dict[str, Any] = {}
    for k, ((label, condition), trace) in enumerate(traces.items()):
        gain = trace.adaptive_gain
        if not np.any(gain != 0.0):
            continue
        color = controllers.setdefault(label, color_of(label, len(controllers)))
        style = conditions.setdefault(
            condition, _CONDITION_STYLES.get(condition, _DASHES[k % len(_DASHES)][0])
        )
        ax.plot(*_series(trace.time_s, gain), color=color, ls=style, lw=1.5)
    if controllers:
        ax.set_yscale("log")
        fig.legend(
            handles=[
                Line2D([], [], color=c, lw=2.5, label=label) for label, c in controllers.items()
            ],
            title="controller (colour)",
            loc="outside right upper",
            fontsize=10,
            title_fontsize=10,
        )
        fig.legend(
            handles=[
                Line2D([], [], color="k", ls=s, lw=1.5, label=condition)
                for condition, s in conditions.items()
            ],
            title="condition (line style)",
            loc="outside right lower",
            fontsize=10,
            title_fontsize=10,
        )
    else:
        ax.text(0.5, 0.5, "no adaptive gains", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("adaptive gain k (N m)")
    ax.grid(True, which="both", alpha=0.3)
    if title:
        ax.set_title(_wrap(title, fig.get_figwidth() - 2.5, 12.0))
    return fig


# ---------------------------------------------------------------------- metric charts
def _grouped(
    rows: Sequence[Mapping[str, Any]], metric: str, group: str, hue: str
) -> tuple[list[Any], list[Any], dict[tuple[Any, Any], float]]:
    groups = list(dict.fromkeys(r[group] for r in rows))
    hues = list(dict.fromkeys(r[hue] for r in rows))
    value: dict[tuple[Any, Any], float] = {}
    for r in rows:
        v = r.get(metric)
        value[(r[group], r[hue])] = math.nan if v is None else float(v)
    return groups, hues, value


def metric_bars_figure(
    rows: Sequence[Mapping[str, Any]],
    metric: str | Sequence[str],
    *,
    group: str = "controller",
    hue: str = "condition",
    title: str = "",
    log: bool = False,
    zoom: bool = False,
) -> Figure:
    """A metric of a table of runs per group and hue, one panel per metric.

    Groups with long names (controllers) are listed down the value axis (horizontal bars),
    many short ones (scenarios) along it, one panel per metric stacked; more than 12 long names
    (the field comparison's controllers and observation modes) stand upright along it. With ``zoom`` the values
    are drawn as dots on an axis fitted to them (not from zero), each group labelled with the
    change of its last hue against its first, so differences of a few percent show.

    Args:
        rows: One mapping per run (for example the rows of ``compare.json``); each holds the
            ``group`` and ``hue`` keys and the metric(s). A ``None`` value draws nothing.
        metric: A metric key, or several (one panel each).
        group: Key whose values label the groups.
        hue: Key whose values give one bar (and legend entry) per group.
        title: Figure title.
        log: Logarithmic value axis.
        zoom: Dots on a fitted axis with the relative change per group (see above).

    Returns:
        The figure.

    Raises:
        ValueError: if ``rows`` is empty.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    if not rows:
        raise ValueError("rows is empty: nothing to plot")
    metrics = [metric] if isinstance(metric, str) else list(metric)
    groups = list(dict.fromkeys(r[group] for r in rows))
    hues = list(dict.fromkeys(r[hue] for r in rows))
    long_names = max(len(str(g)) for g in groups) > 4
    horizontal = long_names and len(groups) <= 12
    colors = {
        h: (color_of(str(h), k) if hue == "controller" else _PALETTE[k % len(_PALETTE)])
        for k, h in enumerate(hues)
    }
    if horizontal:
        height = max(3.4, 0.17 * len(groups) * max(len(hues), 1.5) + 1.9)
        fig = new_figure(4.4 * len(metrics) + 2.8, height)
        axes = fig.subplots(1, len(metrics), squeeze=False, sharey=True)[0]
    else:
        upright = 0.09 * max(len(str(g)) for g in groups) if long_names else 0.0
        fig = new_figure(
            max(8.0, 0.45 * len(groups) * max(len(hues), 2) / 2 + 2.5),
            2.9 * len(metrics) + 1.0 + upright,
        )
        axes = fig.subplots(len(metrics), 1, squeeze=False, sharex=True)[:, 0]
    for ax, m in zip(axes, metrics, strict=True):
        _, _, value = _grouped(rows, m, group, hue)
        _draw_metric(ax, groups, hues, value, colors, horizontal, log, zoom)
        if long_names and not horizontal:  # many long names along the axis: stand them up
            ax.tick_params(axis="x", labelrotation=90)
        label = METRIC_LABELS.get(m, key_label(m))
        if log:
            label += ", log scale"
        (ax.set_xlabel if horizontal else ax.set_ylabel)(label)
    if horizontal:
        axes[0].set_ylabel(key_label(group))
    else:
        axes[-1].set_xlabel(key_label(group))
    if len(hues) > 1 or hue != group:
        handles = [
            Patch(color=colors[h], label=value_label(hue, h))
            if not zoom
            else Line2D(
                [],
                [],
                ls="",
                marker=_MARKERS[k % len(_MARKERS)],
                ms=8,
                color=colors[h],
                label=value_label(hue, h),
            )
            for k, h in enumerate(hues)
        ]
        fig.legend(
            handles=handles,
            title=key_label(hue),
            loc="outside lower center",
            ncol=legend_columns(fig, [value_label(hue, h) for h in hues], 10.0),
            fontsize=10,
            title_fontsize=10,
        )
    suptitle(fig, title)
    return fig


_MARKERS: Final = ("o", "s", "D", "^", "v", "P")


def _draw_metric(
    ax: Axes,
    groups: Sequence[Any],
    hues: Sequence[Any],
    value: Mapping[tuple[Any, Any], float],
    colors: Mapping[Any, str],
    horizontal: bool,
    log: bool,
    zoom: bool,
) -> None:
    width = 0.8 / max(len(hues), 1)
    position = np.arange(len(groups), dtype=float)
    for k, h in enumerate(hues):
        offset = (k - (len(hues) - 1) / 2) * width
        heights = np.array([value.get((g, h), math.nan) for g in groups])
        where = position + offset  # first hue on top (the y axis of horizontal bars is inverted)
        if zoom:
            xy = (heights, where) if horizontal else (where, heights)
            ax.plot(*xy, ls="", marker=_MARKERS[k % len(_MARKERS)], ms=8, color=colors[h])
        elif horizontal:
            ax.barh(where, heights, width, color=colors[h])
        else:
            ax.bar(where, heights, width, color=colors[h])
    names = [str(g) for g in groups]
    if horizontal:
        ax.set_yticks(position, names)
        if not ax.yaxis_inverted():  # the first group on top (once: the axes share y)
            ax.invert_yaxis()
        ax.grid(True, axis="x", alpha=0.3)
    else:
        ax.set_xticks(position, names)
        ax.grid(True, axis="y", alpha=0.3)
    if log:
        (ax.set_xscale if horizontal else ax.set_yscale)("log")
    if zoom and len(hues) > 1:
        _label_changes(ax, groups, hues, value, position, horizontal)


def _label_changes(
    ax: Axes,
    groups: Sequence[Any],
    hues: Sequence[Any],
    value: Mapping[tuple[Any, Any], float],
    position: npt.NDArray[np.float64],
    horizontal: bool,
) -> None:
    """Write the change of the last hue against the first beside each group (``+14.6 %``)."""
    values = np.array([v for v in value.values() if math.isfinite(v)])
    if values.size == 0:
        return
    lo, hi = float(values.min()), float(values.max())
    span = max(hi - lo, 1e-9 * max(abs(hi), 1.0))
    limits = (lo - 0.08 * span, hi + 0.3 * span)
    (ax.set_xlim if horizontal else ax.set_ylim)(*limits)
    for g, p in zip(groups, position, strict=True):
        first, last = value.get((g, hues[0]), math.nan), value.get((g, hues[-1]), math.nan)
        if not (math.isfinite(first) and math.isfinite(last)) or first == 0:
            continue
        text = f"{(last / first - 1) * 100:+.1f} %"
        top = max(first, last) + 0.04 * span
        if horizontal:
            ax.text(top, p, text, va="center", ha="left", fontsize=9)
        else:
            ax.text(p, top, text, va="bottom", ha="center", fontsize=9)


def cell_edges(values: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Cell edges around grid centres (a unit-wide cell around a single value)."""
    if values.size == 1:
        half = 0.05 * values[0]
        return np.array([values[0] - half, values[0] + half])
    mid = 0.5 * (values[1:] + values[:-1])
    return np.concatenate(([2 * values[0] - mid[0]], mid, [2 * values[-1] - mid[-1]]))


# ------------------------------------------------------------------------ realism study
REALISM_METRICS: Final = ("iae", "stick_slip_severity", "stuck_fraction", "torque_at_limit")
"""The metrics of each row of :func:`realism_figure`."""
_REALISM_TITLES: Final = {"torque_at_limit": "share at a torque limit"}
"""Panel titles of the realism figure's own quantities (the metrics take their labels)."""


def realism_figure(
    panels: Mapping[str, Mapping[str, Sequence[Mapping[str, Any]]]],
    value_labels: Sequence[str],
    xlabel: str,
    title: str = "",
    *,
    breaks: Mapping[tuple[str, str], int] | None = None,
    severity_limit: float = STICK_SLIP_SEVERITY,
    metrics: Sequence[str] = REALISM_METRICS,
) -> Figure:
    """Metrics of the controllers against the values of one factor: one row of panels per
    group (env), one panel per metric, one line per controller.

    Args:
        panels: Row title (an env id) -> controller -> one mapping per value of the factor
            (with the ``metrics`` keys, an ``index`` into ``value_labels`` and ``diverged``,
            the number of diverged runs; a ``None`` or NaN metric draws no point).
        value_labels: The factor's values as the x axis shows them, in order.
        xlabel: The factor, with its unit.
        title: Figure title.
        breaks: (row title, controller) -> index of the value at which the controller breaks:
            a ring around that point in every panel.
        severity_limit: A dotted line at this severity (the stick-slip threshold).
        metrics: The metric keys, one panel each.

    Returns:
        The figure.

    Raises:
        ValueError: if ``panels`` is empty or a row has no controller.
    """
    if not panels:
        raise ValueError("panels is empty: nothing to plot")
    empty = [name for name, lines in panels.items() if not lines]
    if empty:
        raise ValueError(f"row(s) {', '.join(map(repr, empty))} have no controller")
    n_rows, n_cols = len(panels), len(metrics)
    fig = new_figure(4.0 * n_cols + 0.6, 3.1 * n_rows + 1.9)
    axes = np.asarray(fig.subplots(n_rows, n_cols, squeeze=False, sharex=True))
    ticks = ["\n".join(textwrap.wrap(str(v), 14)) for v in value_labels]
    position = np.arange(len(value_labels), dtype=float)
    handles: dict[str, Any] = {}  # the controllers' lines
    marks: dict[str, Any] = {}  # the marks, listed after them
    for row, (name, lines) in enumerate(panels.items()):
        for col, metric in enumerate(metrics):
            ax = axes[row, col]
            for k, (label, points) in enumerate(lines.items()):
                color = color_of(label, k)
                style = _DASHES[k % len(_DASHES)]
                x = np.array([float(p["index"]) for p in points])
                y = np.array(
                    [math.nan if p.get(metric) is None else float(p[metric]) for p in points]
                )
                (line,) = ax.plot(
                    x, y, color=color, ls=style[0], lw=style[1],
                    marker=_MARKERS[k % len(_MARKERS)], ms=5, label=label,
                )  # fmt: skip
                handles.setdefault(label, line)
                gone = np.array([bool(p.get("diverged")) for p in points])
                if gone.any():
                    (cross,) = ax.plot(
                        x[gone], y[gone], ls="", marker="x", ms=11, mew=2.0, color="k",
                        label="a run diverged",
                    )  # fmt: skip
                    marks.setdefault("a run diverged", cross)
                where = (breaks or {}).get((name, label))
                if where is not None and np.any(x == where):
                    at = int(np.flatnonzero(x == where)[0])
                    (ring,) = ax.plot(
                        [x[at]], [y[at]], ls="", marker="o", ms=14, mfc="none", mew=1.6,
                        color=color, label="break point (ring, in the controller's colour)",
                    )  # fmt: skip
                    marks.setdefault("break point (ring, in the controller's colour)", ring)
            if metric == "stick_slip_severity":
                limit = ax.axhline(
                    severity_limit, color="0.4", ls=":", lw=1.2,
                    label=f"severity {severity_limit:g}: stick-slip",
                )  # fmt: skip
                marks.setdefault(f"severity {severity_limit:g}: stick-slip", limit)
            ax.set_title(f"{name}: {_REALISM_TITLES.get(metric, key_label(metric))}", fontsize=11)
            ax.grid(True, alpha=0.3)
            ax.set_xticks(position, ticks)
            ax.set_xlim(-0.3, len(value_labels) - 0.7)
            ax.set_ylim(bottom=0.0)  # every metric is >= 0: a ratio reads as one
            if row == n_rows - 1:
                ax.set_xlabel(xlabel)
    handles.update(marks)
    labels = list(handles)
    fig.legend(
        handles=[handles[k] for k in labels],
        labels=labels,
        loc="outside lower center",
        ncol=legend_columns(fig, labels, 10.0, most=5),
        fontsize=10,
    )
    suptitle(fig, title)
    return fig


# ------------------------------------------------------------ the field string's waves
def trace_response_figure(
    traces: Mapping[str, Trace],
    title: str = "",
    *,
    window_s: tuple[float, float] | None = None,
    every: int = 20,
) -> Figure:
    """Bit speed (with the reference), top-drive speed and top-drive torque of several runs of
    one scenario against time, overlaid in three panels sharing the time axis (one colour per
    run, one legend under the panels).

    Args:
        traces: Run label -> trace (the same scenario).
        title: Figure title.
        window_s: Show only ``[t0, t1]`` seconds; the whole run when ``None``.
        every: Plant steps per plotted sample (:func:`downsample`: the torque keeps each bin's
            extremes).

    Raises:
        ValueError: if ``traces`` is empty.
    """
    from matplotlib.lines import Line2D

    if not traces:
        raise ValueError("traces is empty: nothing to plot")
    fig = new_figure(8.5, 7.4)
    ax_bit, ax_top, ax_torque = fig.subplots(3, 1, sharex=True)
    handles: list[Line2D] = [
        Line2D([], [], color="k", ls=(0, (4, 2)), lw=1.0, label="reference bit speed")
    ]
    first = True
    for k, (label, full) in enumerate(traces.items()):
        trace = downsample(full, every)
        t = trace.time_s
        shown = np.ones(t.shape, bool)
        if window_s is not None:
            shown = (t >= window_s[0]) & (t <= window_s[1])
        color = color_of(label, k)
        if first:
            for ax in (ax_bit, ax_top):
                ax.plot(t[shown], trace.reference_rad_s[shown], color="k", ls=(0, (4, 2)), lw=1.0)
            first = False
        ax_bit.plot(t[shown], trace.bit_speed_rad_s[shown], color=color, lw=1.2)
        ax_top.plot(t[shown], trace.top_drive_speed_rad_s[shown], color=color, lw=1.2)
        ax_torque.plot(t[shown], trace.torque_nm[shown] / 1e3, color=color, lw=0.9)
        handles.append(Line2D([], [], color=color, lw=1.6, label=label))
    ax_bit.set_ylabel("bit speed (rad/s)")
    ax_top.set_ylabel("top-drive speed (rad/s)")
    ax_torque.set_ylabel("top-drive torque (kN m)")
    ax_torque.set_xlabel("time (s)")
    for ax in (ax_bit, ax_top, ax_torque):
        ax.grid(True, alpha=0.3)
        ax.ticklabel_format(axis="x", useOffset=False)
    labels = [h.get_label() for h in handles]
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncol=legend_columns(fig, [str(x) for x in labels], 10.0, most=4),
        fontsize=10,
    )
    suptitle(fig, title)
    return fig


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


def learning_curves_figure(
    runs: Mapping[str, str | Path],
    title: str = "",
    *,
    reference: str = "proposed SMC",
    short: str = "proposed",
    goal: float | None = 0.7,
    severity: bool = False,
) -> Figure:
    """Validation mean IAE and RMSD relative to the base controller (the proposed SMC by
    default), and the training return, against decisions, for each run folder.

    Args:
        runs: Label -> run folder (with ``validation.csv`` and ``progress*.csv``).
        title: Figure title.
        reference: The controller the ratios are to, in the legend.
        short: Its name in the axis labels.
        goal: The IAE ratio drawn as the goal (``None``: none).
        severity: Also a panel of the mean stick-slip severity ratio.

    Returns:
        The figure.
    """
    fig = new_figure(8.0, 8.2 if severity else 6.4)
    axes = fig.subplots(4 if severity else 3, 1, sharex=True)
    ax_iae, ax_rmsd = axes[0], axes[1]
    ax_sev = axes[2] if severity else None
    ax_ret = axes[-1]
    for k, (label, folder) in enumerate(runs.items()):
        color = color_of(label, k)
        run = Path(folder)
        validation = run / "validation.csv"
        if validation.is_file():
            v = read_csv_columns(validation)
            steps = [s / 1e6 for s in v["timesteps"]]
            ax_iae.plot(steps, v["iae_ratio"], marker="o", ms=3, color=color, label=label)
            ax_rmsd.plot(steps, v["rmsd_ratio"], marker="o", ms=3, color=color, label=label)
            if ax_sev is not None:
                ax_sev.plot(steps, v["severity_ratio"], marker="o", ms=3, color=color)
        xs: list[float] = []
        ys: list[float] = []
        for progress in sorted(run.glob("progress*.csv")):
            p = read_csv_columns(progress)
            if "rollout/ep_rew_mean" in p:
                xs += [s / 1e6 for s in p["time/total_timesteps"]]
                ys += p["rollout/ep_rew_mean"]
        if xs:
            pairs = sorted(zip(xs, ys, strict=True))
            ax_ret.plot([a for a, _ in pairs], [b for _, b in pairs], lw=1.0, color=color)
    ax_iae.axhline(1.0, color="k", lw=0.8, ls="--", label=f"{reference} (1.0)")
    if goal is not None:
        ax_iae.axhline(goal, color="tab:red", lw=0.8, ls=":", label=f"goal ({goal:g})")
    ax_iae.set_ylabel(f"mean IAE / {short}")
    ax_iae.set_yscale("log")
    ax_rmsd.axhline(1.0, color="k", lw=0.8, ls="--")
    ax_rmsd.set_ylabel(f"mean RMSD / {short}")
    if ax_sev is not None:
        ax_sev.axhline(1.0, color="k", lw=0.8, ls="--")
        ax_sev.set_ylabel(f"mean severity / {short}")
    ax_ret.set_ylabel("training return\n(each run's reward)")
    ax_ret.set_xlabel("decisions (millions)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.legend(*ax_iae.get_legend_handles_labels(), loc="outside right upper", fontsize=10)
    suptitle(fig, title)
    return fig


def plot_learning_curves(
    runs: Mapping[str, str | Path], path: str | Path, title: str = "", **options: Any
) -> Path:
    """:func:`learning_curves_figure` (with its keyword ``options``) written as PNG to
    ``path``; returns the path."""
    return save_figure(learning_curves_figure(runs, title, **options), path)
