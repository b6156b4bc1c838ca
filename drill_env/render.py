"""Frames of a turning drill string, for ``render()``: a short history in, an image out.

The input is the history of one string's state in the alternating layout of the plant,

    ``x = (w_0, phi_0 - phi_1, w_1, phi_1 - phi_2, ..., w_{n-1})``   (``2 n - 1`` entries)

speeds ``w_k`` in rad/s and twists ``phi_k - phi_{k+1}`` in rad, node 0 the top drive and node
``n - 1`` the bit (the 4-DOF plant: top drive, pipes, collars/BHA, bit), with the top-drive
torque, the reference bit speed, the weight on bit and the bit's stuck flag at each sample.
:class:`History` keeps the last samples in a ring buffer; :class:`StringRenderer` draws them
as an ``H x W x 3`` uint8 frame:

* left, the string: one dial per element, its pointer at the element's absolute angle
  ``phi_k = phi_0 - sum_{j<k} (phi_j - phi_{j+1})`` (``phi_0`` integrates the top-drive speed,
  trapezoidal rule between samples), seen from above with the string turning clockwise; on
  each dial a dashed pointer shows the element above and the shaded ring sector between the
  two is the twist (modulo one turn; the label gives the whole twist in rad and turns). The bit's dial
  is red and labelled STUCK while the bit sticks, green and SLIPPING while it turns. With more
  than :data:`MAX_DIALS` nodes (a distributed string) a subset is drawn, evenly spread in depth;
* right, traces of the last ``window_s`` seconds against time before now: bit, top-drive and
  reference speed (rad/s, stuck intervals shaded red), top-drive torque (kN m), and a
  space-time strip of every twist along the string (rows: segments from the top drive down to
  the bit; colour: twist in rad), which shows torsional waves and the wind-up before
  break-away for any number of nodes;
* on top, the current time, WOB, reference and bit state.

Drawing uses matplotlib's object-oriented API on the Agg canvas (no ``pyplot``, no global
state); matplotlib is imported only when a renderer or a window is created, so that neither
``import drill_env`` nor an env without a ``render_mode`` imports it. The figure's artists are
built once and updated per frame. :class:`HumanWindow` shows frames in a live window through
an interactive matplotlib back-end (``render_mode="human"``).
"""

from __future__ import annotations

import contextlib
import importlib
import math
import os
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from drill_env.ids import ENV_ID
from drill_env.validation import shown

__all__ = [
    "MAX_DIALS",
    "RENDER_MODES",
    "WINDOW_S",
    "EnvRendering",
    "History",
    "HistoryArrays",
    "HumanWindow",
    "StringRenderer",
    "available_render_modes",
    "check_render_mode",
    "dial_nodes",
    "history_capacity",
    "human_mode_problem",
    "node_angles",
]

RENDER_MODES: Final = ("human", "rgb_array")
"""The render modes of ``DrillString-v0``."""
WINDOW_S: Final = 20.0
"""Length of the traces, s."""
MAX_DIALS: Final = 6
"""Most dials drawn; a string with more nodes shows this many, evenly spread in depth."""
FOUR_DOF_LABELS: Final = ("top drive", "pipes", "collars (BHA)", "bit")
"""Element names of the 4-DOF plant, top to bottom."""

_NON_INTERACTIVE: Final = frozenset({"agg", "cairo", "pdf", "pgf", "ps", "svg", "template"})
_GUI_BACKENDS: Final = ("macosx", "qtagg", "gtk4agg", "gtk3agg", "tkagg", "wxagg")
_STUCK_COLOUR: Final = "#d62728"
_SLIP_COLOUR: Final = "#2ca02c"


def check_render_mode(render_mode: object) -> None:
    """Raise ``ValueError`` naming ``render_mode`` unless it is None or one of
    :data:`RENDER_MODES`."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(
            f"render_mode = {shown(render_mode)} is not valid: allowed None, "
            + ", ".join(repr(m) for m in RENDER_MODES)
        )


def human_mode_problem() -> str | None:
    """Why ``render_mode="human"`` cannot open a window here, or None when it may.

    Cheap (environment variables only, no import): a Linux or BSD session needs ``DISPLAY`` or
    ``WAYLAND_DISPLAY``, and ``MPLBACKEND``, when set, must not name a non-interactive
    matplotlib back-end. Whether a GUI toolkit is installed is found out by
    :class:`HumanWindow`.
    """
    backend = os.environ.get("MPLBACKEND", "").strip().lower()
    if backend in _NON_INTERACTIVE:
        return (
            f"render_mode='human' needs an interactive matplotlib back-end, but MPLBACKEND = "
            f"{shown(backend)} is non-interactive; unset it, or use render_mode='rgb_array' (frames as "
            "arrays, e.g. for gymnasium.wrappers.RecordVideo)"
        )
    headless_platform = not (sys.platform.startswith(("win", "darwin", "cygwin")))
    if headless_platform and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return (
            "render_mode='human' needs a display, but neither DISPLAY nor WAYLAND_DISPLAY is set "
            "(a headless machine?); use render_mode='rgb_array' (frames as arrays, e.g. for "
            "gymnasium.wrappers.RecordVideo), or run under a virtual display such as xvfb-run"
        )
    return None


def available_render_modes() -> list[str]:
    """The render modes usable on this machine: ``rgb_array`` always, ``human`` only where
    :func:`human_mode_problem` finds nothing against it."""
    return [m for m in RENDER_MODES if m != "human" or human_mode_problem() is None]


def history_capacity(window_s: float, sample_dt_s: float) -> int:
    """Samples a :class:`History` needs to span ``window_s`` seconds at one sample per
    ``sample_dt_s`` seconds (plus the two ends)."""
    if not (math.isfinite(sample_dt_s) and sample_dt_s > 0):
        raise ValueError(f"sample_dt_s = {shown(sample_dt_s)} is out of range: allowed > 0")
    if not (math.isfinite(window_s) and window_s > 0):
        raise ValueError(f"window_s = {shown(window_s)} is out of range: allowed > 0")
    return math.ceil(window_s / sample_dt_s - 1e-9) + 2


def node_angles(
    states: npt.ArrayLike, top_drive_angle_rad: npt.ArrayLike
) -> npt.NDArray[np.float64]:
    """Absolute angle of every node: ``phi_k = phi_0 - sum_{j<k} (phi_j - phi_{j+1})``.

    Args:
        states: States in the alternating layout, ``(..., 2 n - 1)``, rad/s and rad.
        top_drive_angle_rad: ``phi_0``, shape ``(...)``, rad.

    Returns:
        Angles ``(..., n)``, rad; column 0 is ``phi_0``.
    """
    x = np.asarray(states, dtype=np.float64)
    phi0 = np.asarray(top_drive_angle_rad, dtype=np.float64)
    if x.shape[-1] % 2 != 1 or x.shape[-1] < 3:
        raise ValueError(
            f"states have {x.shape[-1]} entries per sample: allowed 2 n - 1 with n >= 2 nodes"
        )
    twists = x[..., 1::2]
    out = np.empty((*x.shape[:-1], twists.shape[-1] + 1))
    out[..., 0] = phi0
    out[..., 1:] = phi0[..., None] - np.cumsum(twists, axis=-1)
    return out


def dial_nodes(n_nodes: int, max_dials: int = MAX_DIALS) -> list[int]:
    """The nodes that get a dial: all of them up to ``max_dials``, else ``max_dials`` evenly
    spread from the top drive (0) to the bit (``n_nodes - 1``)."""
    if n_nodes <= max_dials:
        return list(range(n_nodes))
    return sorted({round(v) for v in np.linspace(0, n_nodes - 1, max_dials)})


@dataclass(frozen=True)
class HistoryArrays:
    """The samples of a :class:`History`, oldest first (copies); ``m`` samples, ``n`` nodes.

    Attributes:
        time_s: Sample times, (m,), s.
        states: States in the alternating layout, (m, 2 n - 1), rad/s and rad.
        top_drive_angle_rad: Integrated top-drive angle ``phi_0``, (m,), rad.
        torque_nm: Top-drive torque, (m,), N m.
        reference_rad_s: Reference bit speed, (m,), rad/s.
        wob_n: Weight on bit, (m,), N.
        bit_stuck: Whether the bit sticks, (m,), bool.
    """

    time_s: npt.NDArray[np.float64]
    states: npt.NDArray[np.float64]
    top_drive_angle_rad: npt.NDArray[np.float64]
    torque_nm: npt.NDArray[np.float64]
    reference_rad_s: npt.NDArray[np.float64]
    wob_n: npt.NDArray[np.float64]
    bit_stuck: npt.NDArray[np.bool_]


class History:
    """The last ``capacity`` samples of one string (a ring buffer; appending is O(1)).

    The top-drive angle ``phi_0`` is integrated from the speeds with the trapezoidal rule
    between consecutive samples and starts at 0 rad after :meth:`clear`.
    """

    def __init__(self, n_nodes: int, capacity: int) -> None:
        if isinstance(n_nodes, bool) or not isinstance(n_nodes, int) or n_nodes < 2:
            raise ValueError(f"n_nodes = {shown(n_nodes)} is out of range: allowed an integer >= 2")
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 2:
            raise ValueError(
                f"capacity = {shown(capacity)} is out of range: allowed an integer >= 2"
            )
        self.n_nodes = n_nodes
        self.capacity = capacity
        self.n_state = 2 * n_nodes - 1
        self._time = np.zeros(capacity)
        self._states = np.zeros((capacity, self.n_state))
        self._angle = np.zeros(capacity)
        self._torque = np.zeros(capacity)
        self._reference = np.zeros(capacity)
        self._wob = np.zeros(capacity)
        self._stuck = np.zeros(capacity, dtype=bool)
        self._count = 0
        self._last = -1  # index of the newest sample
        self._state_shape = (self.n_state,)
        self._previous = (0.0, 0.0, 0.0)  # time, top-drive speed and angle of the newest sample

    def __len__(self) -> int:
        return self._count

    def clear(self) -> None:
        """Forget every sample (a new episode: the angle restarts at 0)."""
        self._count = 0
        self._last = -1

    def append(
        self,
        time_s: float,
        state: npt.ArrayLike,
        torque_nm: float,
        reference_rad_s: float,
        wob_n: float,
        bit_stuck: bool,
    ) -> None:
        """Add one sample; ``state`` has ``2 n - 1`` entries (rad/s, rad), the rest are
        scalars in s, N m, rad/s, N."""
        x = state if type(state) is np.ndarray else np.asarray(state, dtype=np.float64)
        if x.shape != self._state_shape:
            raise ValueError(
                f"state has shape {x.shape}: allowed ({self.n_state},) for {self.n_nodes} nodes"
            )
        w0 = float(x[0])
        if self._count:
            t0, w_prev, a_prev = self._previous
            angle = a_prev + 0.5 * (w_prev + w0) * (time_s - t0)
        else:
            angle = 0.0
        self._previous = (time_s, w0, angle)
        i = self._last + 1
        if i == self.capacity:
            i = 0
        self._time[i] = time_s
        self._states[i] = x
        self._angle[i] = angle
        self._torque[i] = torque_nm
        self._reference[i] = reference_rad_s
        self._wob[i] = wob_n
        self._stuck[i] = bit_stuck
        self._last = i
        if self._count < self.capacity:
            self._count += 1

    def arrays(self) -> HistoryArrays:
        """The samples, oldest first."""
        order = (np.arange(self._count) + self._last + 1 - self._count) % self.capacity
        return HistoryArrays(
            time_s=self._time[order],
            states=self._states[order],
            top_drive_angle_rad=self._angle[order],
            torque_nm=self._torque[order],
            reference_rad_s=self._reference[order],
            wob_n=self._wob[order],
            bit_stuck=self._stuck[order],
        )


def _nice_ceiling(value: float) -> float:
    """The smallest of 1, 2, 5 x 10^k at or above ``value`` (> 0), for stable axes."""
    if not (math.isfinite(value) and value > 0):
        return 1.0
    exponent = 10.0 ** math.floor(math.log10(value))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * exponent >= value * (1 - 1e-12):
            return m * exponent
    return 10.0 * exponent


def _stable_range(
    lo: float, hi: float, current: tuple[float, float] | None, floor: float, headroom: float
) -> tuple[float, float]:
    """Axis limits for data in ``[lo, hi]``: 0 included, rounded to 1, 2, 5 x 10^k, the top
    at least ``floor``; the ``current`` limits stay while they hold the data and the data
    (with its headroom) spans at least 40 % of each side (so that axes seldom change)."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        lo, hi = 0.0, floor
    top = max(_nice_ceiling(hi * headroom) if hi > 0 else 0.0, floor)
    bottom = -_nice_ceiling(-lo * headroom) if lo < 0 else 0.0
    if current is not None:
        c_lo, c_hi = current
        keep_top = c_hi == top or 2.5 * headroom * hi >= c_hi
        keep_bottom = c_lo == bottom or 2.5 * headroom * lo <= c_lo
        if c_lo <= lo and hi <= c_hi and keep_top and keep_bottom:
            return current
    return bottom, top


def _segment_labels(n_nodes: int, labels: Sequence[str]) -> list[str]:
    if n_nodes == len(FOUR_DOF_LABELS) and tuple(labels) == FOUR_DOF_LABELS:
        return ["TD-pipes", "pipes-BHA", "BHA-bit"]
    return [f"{k}-{k + 1}" for k in range(n_nodes - 1)]


class StringRenderer:
    """Draws :class:`History` samples of an ``n_nodes`` string as ``H x W x 3`` uint8 frames.

    The figure is built once. Axes, ticks, labels and the colour bar form a background that is
    drawn again only when an axis range changes (the ranges are rounded to 1, 2 or 5 x 10^k and
    kept while they fit, so that happens seldom); every frame restores it and draws only the
    moving artists.

    Args:
        n_nodes: Nodes of the string (4 for the 4-DOF plant).
        width_px, height_px: Frame size, pixels (even numbers suit video encoders).
        window_s: Length of the traces, s.
        labels: Names of the nodes, top to bottom; default: top drive, pipes, collars (BHA),
            bit for 4 nodes, else ``top drive``, ``node k``, ``bit``.
    """

    def __init__(
        self,
        n_nodes: int,
        width_px: int = 800,
        height_px: int = 480,
        window_s: float = WINDOW_S,
        labels: Sequence[str] | None = None,
    ) -> None:
        if isinstance(n_nodes, bool) or not isinstance(n_nodes, int) or n_nodes < 2:
            raise ValueError(f"n_nodes = {shown(n_nodes)} is out of range: allowed an integer >= 2")
        for name, value in (("width_px", width_px), ("height_px", height_px)):
            if isinstance(value, bool) or not isinstance(value, int) or not 64 <= value <= 8192:
                raise ValueError(
                    f"{name} = {shown(value)} is out of range: allowed 64..8192 pixels"
                )
        if not (math.isfinite(window_s) and window_s > 0):
            raise ValueError(f"window_s = {shown(window_s)} is out of range: allowed > 0")
        if labels is None:
            if n_nodes == len(FOUR_DOF_LABELS):
                labels = FOUR_DOF_LABELS
            else:
                labels = ["top drive", *(f"node {k}" for k in range(1, n_nodes - 1)), "bit"]
        if len(labels) != n_nodes:
            raise ValueError(f"labels has {len(labels)} names: allowed one per node ({n_nodes})")
        self.n_nodes = n_nodes
        self.width_px = width_px
        self.height_px = height_px
        self.window_s = float(window_s)
        self.labels = list(labels)
        self.dials = dial_nodes(n_nodes)
        # Axis ranges of the saved background: speed, torque (low, high) and twist colours.
        self._layout: tuple[float, float, float, float, float, float] | None = None
        self._background: Any = None
        self._build()

    # ------------------------------------------------------------------ figure
    def _build(self) -> None:
        """Create the figure and every artist once; :meth:`frame` only updates them."""
        from matplotlib import colormaps
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.colors import Normalize
        from matplotlib.figure import Figure
        from matplotlib.patches import Circle, Wedge

        dpi = 100
        fig = Figure(figsize=(self.width_px / dpi, self.height_px / dpi), dpi=dpi)
        fig.patch.set_facecolor("white")
        self._canvas = FigureCanvasAgg(fig)
        self._fig = fig
        self._cmap = colormaps["viridis"]
        self._norm = Normalize(0.0, 1.0)
        small = 7.5
        moving: list[Any] = []  # drawn at every frame, in this order

        # Header: time, WOB, reference; the bit state in a coloured box.
        self._header = fig.text(
            0.01, 0.975, "", ha="left", va="top", fontsize=10, family="monospace"
        )
        self._state_text = fig.text(
            0.99, 0.975, "", ha="right", va="top", fontsize=10, weight="bold", color="white",
            bbox={"boxstyle": "round,pad=0.25", "facecolor": _STUCK_COLOUR, "edgecolor": "none"},
        )  # fmt: skip
        moving += [self._header, self._state_text]

        # Left: the string, one dial per shown node, the top drive at the top.
        k = len(self.dials)
        ax = fig.add_axes((0.0, 0.03, 0.34, 0.87))
        ax.set_axis_off()
        ax.set_xlim(-0.5, 2.4)
        ax.set_ylim(-0.75, k - 0.45)
        ax.set_aspect("equal", adjustable="box", anchor="C")
        radius = 0.36
        self._radius = radius
        self._centres = [(0.0, float(k - 1 - d)) for d in range(k)]
        self._connectors: list[Any] = []
        self._twist_texts: list[Any] = []
        for d in range(1, k):
            top, bottom = k - d - radius, k - 1 - d + radius  # from dial d - 1 down to dial d
            (line,) = ax.plot([0.0, 0.0], [top, bottom], lw=5, solid_capstyle="butt")
            text = ax.text(0.1, k - d - 0.5, "", fontsize=small, va="center", ha="left")
            self._connectors.append(line)
            self._twist_texts.append(text)
        moving += self._connectors + self._twist_texts
        self._pointers: list[Any] = []
        self._ghosts: list[Any] = []
        self._wedges: list[Any] = []
        self._speed_texts: list[Any] = []
        for d, node in enumerate(self.dials):
            cx, cy = self._centres[d]
            face = Circle((cx, cy), radius, facecolor="#d0d7de", edgecolor="#333333", lw=1.2)
            ax.add_patch(face)
            if d == k - 1:
                self._bit_face = face
                moving.append(face)
            ax.text(
                cx + radius + 0.1, cy + 0.12, self.labels[node], fontsize=8.5, weight="bold",
                va="center",
            )  # fmt: skip
            self._speed_texts.append(
                ax.text(cx + radius + 0.1, cy - 0.13, "", fontsize=small, va="center")
            )
            # The twist to the element above: a ring sector between its pointer and this one.
            wedge = Wedge((cx, cy), radius, 0.0, 0.0, width=0.3 * radius, facecolor="#ff7f0e")
            wedge.set_alpha(0.8)
            ax.add_patch(wedge)
            (ghost,) = ax.plot([cx, cx], [cy, cy], ls="--", lw=1.0, color="#444444")
            (pointer,) = ax.plot([cx, cx], [cy, cy], lw=2.2, color="black", solid_capstyle="round")
            (hub,) = ax.plot([cx], [cy], "o", ms=3, color="black")
            self._wedges.append(wedge)
            self._ghosts.append(ghost)
            self._pointers.append(pointer)
            moving += [wedge, ghost, pointer, hub]
            if d == 0:
                ghost.set_visible(False)
                wedge.set_visible(False)
        moving += self._speed_texts
        self._bit_label = ax.text(
            self._centres[-1][0], self._centres[-1][1] - radius - 0.08, "", ha="center",
            va="top", fontsize=9, weight="bold",
        )  # fmt: skip
        moving.append(self._bit_label)

        # Right: traces against time before now.
        left, width = 0.42, 0.50
        axes_s = fig.add_axes((left, 0.62, width, 0.26))
        axes_t = fig.add_axes((left, 0.36, width, 0.22), sharex=axes_s)
        axes_w = fig.add_axes((left, 0.1, width, 0.22), sharex=axes_s)
        for a in (axes_s, axes_t, axes_w):
            a.tick_params(labelsize=small)
        axes_s.set_xlim(-self.window_s, 0.0)
        for a in (axes_s, axes_t):
            a.grid(True, lw=0.4, alpha=0.5)
            a.tick_params(labelbottom=False)
        (self._line_ref,) = axes_s.plot([], [], "k--", lw=1.0, label="reference")
        (self._line_td,) = axes_s.plot([], [], color="#7f7f7f", lw=1.2, label="top drive")
        (self._line_bit,) = axes_s.plot([], [], color="#1f77b4", lw=1.4, label="bit")
        axes_s.fill_between([], [], color=_STUCK_COLOUR, alpha=0.15, lw=0, label="bit stuck")
        axes_s.set_ylabel("speed (rad/s)", fontsize=small)
        axes_s.legend(
            loc="lower left", bbox_to_anchor=(0.0, 1.0), fontsize=7, ncol=4, frameon=False,
            borderaxespad=0.1, handlelength=1.6,
        )  # fmt: skip
        (self._line_torque,) = axes_t.plot([], [], color="#9467bd", lw=1.2)
        axes_t.set_ylabel("torque (kN m)", fontsize=small)
        self._torque_text = axes_t.text(
            0.01, 0.95, "", transform=axes_t.transAxes, fontsize=small, va="top"
        )
        n_seg = self.n_nodes - 1
        self._strip = axes_w.imshow(
            np.full((n_seg, 2), np.nan), aspect="auto", interpolation="nearest",
            cmap=self._cmap, norm=self._norm, extent=(-self.window_s, 0.0, n_seg - 0.5, -0.5),
        )  # fmt: skip
        axes_w.set_ylim(n_seg - 0.5, -0.5)
        if n_seg <= 8:
            axes_w.set_yticks(range(n_seg), _segment_labels(self.n_nodes, self.labels))
        else:
            axes_w.set_ylabel("segment (top to bit)", fontsize=small)
        axes_w.set_xlabel("time before now (s)", fontsize=small)
        cax = fig.add_axes((left + width + 0.012, 0.1, 0.014, 0.22))
        bar = fig.colorbar(self._strip, cax=cax)
        bar.set_label("twist (rad)", fontsize=small)
        bar.ax.tick_params(labelsize=6.5)
        self._axes_s, self._axes_t, self._axes_w = axes_s, axes_t, axes_w
        self._stuck_fill: Any = None
        moving += [
            self._strip, self._line_ref, self._line_td, self._line_bit, self._line_torque,
            self._torque_text,
        ]  # fmt: skip
        for artist in moving:
            artist.set_animated(True)
        self._moving = moving

    # ------------------------------------------------------------------- frame
    def frame(self, history: History) -> npt.NDArray[np.uint8]:
        """Draw the samples of ``history`` (the last one is "now"); ``(H, W, 3)`` uint8."""
        if history.n_nodes != self.n_nodes:
            raise ValueError(
                f"history has {history.n_nodes} nodes: allowed {self.n_nodes} for this renderer"
            )
        h = history.arrays()
        if h.time_s.size:
            layout = self._update(h)
        else:
            self._header.set_text("no samples yet: reset() the env")
            self._state_text.set_visible(False)
            layout = (0.0, 1.0, 0.0, 1.0, 0.0, 1.0)
        if layout != self._layout or self._background is None:
            s_lo, s_hi, t_lo, t_hi, w_lo, w_hi = layout
            self._axes_s.set_ylim(s_lo, s_hi)
            self._axes_t.set_ylim(t_lo, t_hi)
            self._strip.set_clim(w_lo, w_hi)  # also the norm of the connectors' colours
            self._canvas.draw()  # everything but the moving artists
            self._background = self._canvas.copy_from_bbox(self._fig.bbox)
            self._layout = layout
        else:
            self._canvas.restore_region(self._background)
        for artist in self._moving:
            self._fig.draw_artist(artist)
        if self._stuck_fill is not None:
            self._fig.draw_artist(self._stuck_fill)
        rgba = np.asarray(self._canvas.buffer_rgba())
        return np.ascontiguousarray(rgba[:, :, :3])

    def _update(self, h: HistoryArrays) -> tuple[float, float, float, float, float, float]:
        """Set the moving artists from ``h``; returns the axis ranges the frame needs."""
        now = float(h.time_s[-1])
        keep = h.time_s >= now - self.window_s - 1e-9
        t = h.time_s[keep] - now
        states = h.states[keep]
        angles = node_angles(states[-1], h.top_drive_angle_rad[-1])
        stuck_now = bool(h.bit_stuck[-1])
        state_colour = _STUCK_COLOUR if stuck_now else _SLIP_COLOUR
        state_word = "STUCK" if stuck_now else "SLIPPING"

        self._header.set_text(
            f"t = {now:7.2f} s   WOB = {h.wob_n[-1] / 1e3:6.1f} kN   "
            f"V_ref = {h.reference_rad_s[-1]:5.2f} rad/s"
        )
        self._state_text.set_visible(True)
        self._state_text.set_text(f"bit {state_word}")
        self._state_text.get_bbox_patch().set_facecolor(state_colour)  # type: ignore[union-attr]

        # Axis ranges, rounded so that they change seldom.
        twists = states[:, 1::2]
        bit = states[:, -1]
        td = states[:, 0]
        ref = h.reference_rad_s[keep]
        torque_kn = h.torque_nm[keep] / 1e3
        speeds = np.concatenate((bit, td, ref))
        old = self._layout
        s_lim = _stable_range(
            float(np.min(speeds)), float(np.max(speeds)), old and old[0:2], 10.0, 1.1
        )
        t_lim = _stable_range(
            float(np.min(torque_kn)), float(np.max(torque_kn)), old and old[2:4], 10.0, 1.1
        )
        w_lim = _stable_range(
            float(np.min(twists)), float(np.max(twists)), old and old[4:6], 1.0, 1.0
        )
        layout = (*s_lim, *t_lim, *w_lim)
        self._norm.vmin, self._norm.vmax = layout[4], layout[5]

        # Dials: pointer at the absolute angle (clockwise from 12 o'clock), the element above
        # dashed, the twist between them shaded.
        r = self._radius
        screen = [math.pi / 2 - float(angles[node]) for node in self.dials]
        for d, node in enumerate(self.dials):
            cx, cy = self._centres[d]
            a = screen[d]
            self._pointers[d].set_data([cx, cx + r * math.cos(a)], [cy, cy + r * math.sin(a)])
            self._speed_texts[d].set_text(f"{states[-1, 2 * node]:6.2f} rad/s")
            if d == 0:
                continue
            above = screen[d - 1]
            self._ghosts[d].set_data([cx, cx + r * math.cos(above)], [cy, cy + r * math.sin(above)])
            twist = float(angles[self.dials[d - 1]] - angles[node])  # phi_above - phi_here
            span = math.degrees(math.fmod(twist, 2 * math.pi))
            start = math.degrees(above)
            # The string turns clockwise (screen angles fall as phi grows): an element that
            # lags the one above by the twist sits the twist counter-clockwise of it.
            self._wedges[d].set_theta1(min(start, start + span))
            self._wedges[d].set_theta2(max(start, start + span))
            self._connectors[d - 1].set_color(self._cmap(self._norm(twist)))
            self._twist_texts[d - 1].set_text(
                f"twist {twist:.2f} rad ({twist / (2 * math.pi):.2f} turns)"
            )
        self._bit_face.set_facecolor(state_colour)
        self._bit_label.set_text(state_word)
        self._bit_label.set_color(state_colour)

        # Traces.
        self._line_bit.set_data(t, bit)
        self._line_td.set_data(t, td)
        self._line_ref.set_data(t, ref)
        self._line_torque.set_data(t, torque_kn)
        self._torque_text.set_text(f"now {torque_kn[-1]:.2f} kN m")
        if self._stuck_fill is not None:
            self._stuck_fill.remove()
        self._stuck_fill = self._axes_s.fill_between(
            t, 0.0, 1.0, where=h.bit_stuck[keep], transform=self._axes_s.get_xaxis_transform(),
            color=_STUCK_COLOUR, alpha=0.15, lw=0, step="mid", animated=True,
        )  # fmt: skip

        # Space-time strip of the twists: one column per sample.
        half = 0.5 * (t[-1] - t[0]) / max(t.size - 1, 1)
        self._strip.set_data(twists.T)
        n_seg = self.n_nodes - 1
        self._strip.set_extent((t[0] - half, t[-1] + half, n_seg - 0.5, -0.5))
        self._axes_w.set_xlim(-self.window_s, 0.0)  # set_extent autoscales: undo it
        return layout


class HumanWindow:
    """A live window that shows frames (``render_mode="human"``), through an interactive
    matplotlib back-end: the one ``MPLBACKEND`` names, else the first that loads of macosx,
    qtagg, gtk4agg, gtk3agg, tkagg, wxagg (matplotlib's own order).

    Frames are shown no faster than ``fps`` (real time at one frame per decision). The window
    opens at the first :meth:`show`; once the user closes it, later frames are dropped.

    Raises:
        RuntimeError: when there is no display or no interactive back-end (the message says
            which, and suggests ``render_mode="rgb_array"``).
    """

    def __init__(self, fps: float, title: str = ENV_ID) -> None:
        problem = human_mode_problem()
        if problem is not None:
            raise RuntimeError(problem)
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"fps = {shown(fps)} is out of range: allowed > 0")
        self.fps = float(fps)
        self.title = title
        self._module = _interactive_backend()
        self._manager: Any = None
        self._image: Any = None
        self._closed = False
        self._last_show = -math.inf

    @property
    def closed(self) -> bool:
        """Whether the user closed the window (or :meth:`close` was called)."""
        return self._closed

    def show(self, frame: npt.NDArray[np.uint8]) -> None:
        """Show ``frame`` ``(H, W, 3)`` uint8, waiting so that frames come at most at ``fps``."""
        if self._closed:
            return
        if self._manager is None:
            self._open(frame)
        else:
            self._image.set_data(frame)
        canvas = self._manager.canvas
        canvas.draw_idle()
        wait = self._last_show + 1.0 / self.fps - time.perf_counter()
        if wait > 0:
            canvas.start_event_loop(wait)
        else:
            canvas.flush_events()
        self._last_show = time.perf_counter()

    def _open(self, frame: npt.NDArray[np.uint8]) -> None:
        import matplotlib
        from matplotlib.figure import Figure

        dpi = 100
        figure = Figure(figsize=(frame.shape[1] / dpi, frame.shape[0] / dpi), dpi=dpi)
        self._image = figure.figimage(frame, origin="upper")  # pixel for pixel, no resampling
        with matplotlib.rc_context({"toolbar": "None"}):  # no zoom or pan for a picture
            self._manager = self._module.FigureCanvas.new_manager(figure, 1)
        self._manager.set_window_title(self.title)
        self._manager.canvas.mpl_connect("close_event", self._on_close)
        self._manager.show()

    def _on_close(self, _event: object) -> None:
        self._closed = True

    def close(self) -> None:
        """Close the window (idempotent)."""
        manager, self._manager = self._manager, None
        self._closed = True
        if manager is not None:
            with contextlib.suppress(Exception):  # a window that the user closed already
                manager.destroy()


def _interactive_backend() -> ModuleType:
    """The module of the first interactive matplotlib back-end that loads."""
    requested = os.environ.get("MPLBACKEND", "").strip()
    if requested:
        name = requested.lower()
        candidates = [requested if name.startswith("module://") else name]
    else:
        candidates = list(_GUI_BACKENDS)
    failures = []
    for name in candidates:
        if name.startswith("module://"):
            module_name = name[len("module://") :]
        else:
            module_name = f"matplotlib.backends.backend_{name}"
        try:
            module = importlib.import_module(module_name)
        except ImportError as error:  # the toolkit is not installed
            failures.append(f"{name}: {error}")
            continue
        canvas = getattr(module, "FigureCanvas", None)
        if canvas is None or getattr(canvas, "required_interactive_framework", None) is None:
            failures.append(f"{name}: not an interactive back-end")
            continue
        return module
    raise RuntimeError(
        "render_mode='human' found no interactive matplotlib back-end ("
        + "; ".join(failures)
        + "); install a GUI toolkit (Tk for Python, or PyQt/PySide), or use "
        "render_mode='rgb_array' (frames as arrays, e.g. for gymnasium.wrappers.RecordVideo)"
    )


class EnvRendering:
    """The rendering state of one env (created only when its ``render_mode`` is not None):
    the history of the last :data:`WINDOW_S` seconds, the renderer and, in ``human`` mode, the
    window (which then shows a frame after every reset and step).

    Args:
        render_mode: ``"rgb_array"`` or ``"human"``.
        n_nodes: Nodes of the string.
        sample_dt_s: Time between samples (the decision period), s.
    """

    def __init__(self, render_mode: str, n_nodes: int, sample_dt_s: float) -> None:
        check_render_mode(render_mode)
        if render_mode is None:
            raise ValueError("render_mode = None: EnvRendering needs a render mode")
        self.render_mode = render_mode
        self.history = History(n_nodes, history_capacity(WINDOW_S, sample_dt_s))
        self.window = HumanWindow(1.0 / sample_dt_s) if render_mode == "human" else None
        self._renderer: StringRenderer | None = None

    def record(
        self,
        time_s: float,
        state: npt.ArrayLike,
        torque_nm: float,
        reference_rad_s: float,
        wob_n: float,
        bit_stuck: bool,
        new_episode: bool = False,
    ) -> None:
        """Append one sample (after ``new_episode``, the history restarts); in human mode,
        show the frame."""
        if new_episode:
            self.history.clear()
        self.history.append(time_s, state, torque_nm, reference_rad_s, wob_n, bit_stuck)
        if self.window is not None:
            self.render()

    def render(self) -> npt.NDArray[np.uint8] | None:
        """The frame in rgb_array mode; in human mode the frame goes to the window (None)."""
        if self._renderer is None:
            self._renderer = StringRenderer(self.history.n_nodes)
        frame = self._renderer.frame(self.history)
        if self.window is None:
            return frame
        self.window.show(frame)
        return None

    def close(self) -> None:
        """Close the window, if any."""
        if self.window is not None:
            self.window.close()
