"""Measured logs of a drill string: the file format, its reader and its defects
(docs/calibration.md section 1).

A log is a table with a header of named columns in SI units, one row per sample:

| column | unit | |
|---|---|---|
| ``time_s`` | s | required, strictly increasing |
| ``top_speed_rad_s`` | rad/s | required: the top drive's (rotary table's) speed |
| ``bit_speed_rad_s`` | rad/s | optional: the bit's speed |
| ``bit_torque_nm`` | N m | optional: the torque on bit (the rock's reaction on the bit) |
| ``wob_n`` | N | optional: the weight on bit |
| ``surface_torque_nm`` | N m | optional: the top drive's torque |

Files are CSV (``.csv``, comma separated, ``#`` comment lines allowed before the header) or
Parquet (``.parquet``, read only where pyarrow is installed). Every file is untrusted: it is
parsed as numbers only, refused when larger than :data:`MAX_LOG_BYTES` before it is read, and a
bad value is reported on one line with its column and its row (data rows count from 1).

Real logs have defects. :func:`find_defects` reports them with their time ranges and never
changes the data: gaps in the clock, single-sample spikes, flat lines (a sensor that holds its
last value or drops out to a constant) and stalls of the top drive.
"""

from __future__ import annotations

import array
import csv
import math
import os
import stat
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final, TextIO

import numpy as np
import numpy.typing as npt

from drill_env.files import replacing
from drill_env.validation import shown

__all__ = [
    "COLUMN_UNITS",
    "MAX_LOG_BYTES",
    "MAX_LOG_ROWS",
    "MIN_SAMPLE_PERIOD_S",
    "OPTIONAL_COLUMNS",
    "REQUIRED_COLUMNS",
    "Defect",
    "MeasuredLog",
    "find_defects",
    "read_log",
    "write_log_csv",
]

REQUIRED_COLUMNS: Final = ("time_s", "top_speed_rad_s")
"""Columns every log has."""
OPTIONAL_COLUMNS: Final = ("bit_speed_rad_s", "bit_torque_nm", "wob_n", "surface_torque_nm")
"""Columns a log may have; a fit uses those that are there."""
COLUMN_UNITS: Final = {
    "time_s": "s",
    "top_speed_rad_s": "rad/s",
    "bit_speed_rad_s": "rad/s",
    "bit_torque_nm": "N m",
    "wob_n": "N",
    "surface_torque_nm": "N m",
}
"""Unit of each column of the format."""
_ENCODING: Final = "utf-8-sig"
"""UTF-8, with or without the byte-order mark some spreadsheets write."""
MAX_LOG_BYTES: Final = 1 << 30
"""Largest log file accepted, bytes (1 GiB: a day at 1 kHz of six columns), checked before
reading."""
MAX_LOG_ROWS: Final = 50_000_000
"""Most data rows accepted."""
MIN_LOG_ROWS: Final = 3
"""Fewest data rows a log can have."""
MIN_SAMPLE_PERIOD_S: Final = 1e-5
"""Shortest median sample period of a log (and of any window of it), s: sampling at up to
100 kHz, above the fastest torsional sensors. The fit's smoothing and stick detection work in
windows of a fixed duration, whose length in samples grows as the period shrinks; a clock in
the wrong unit (ns written as s) is refused here rather than allocated."""
MAX_LINE_CHARS: Final = 64 * 1024
"""Longest line of a CSV log (header, comment or data row), characters."""
MAX_SHOWN_NAMES: Final = 8
"""Most column names a message lists (the others are counted)."""

GAP_FACTOR: Final = 3.0
"""A time step longer than this many median steps is a gap."""
SPIKE_SIGMAS: Final = 8.0
"""A sample further than this many robust standard deviations from the median of its
neighbours, and from both its neighbours, is a spike."""
FLAT_MIN_SAMPLES: Final = 25
"""A run of at least this many exactly equal samples (and :data:`FLAT_MIN_S`) is a flat line."""
FLAT_MIN_S: Final = 0.02
"""Shortest flat line reported, s."""
STALL_FRACTION: Final = 0.05
"""The top drive is stalled while its speed is below this fraction of its median speed..."""
STALL_MIN_S: Final = 0.2
"""... for at least this long, s."""


@dataclass(frozen=True)
class Defect:
    """One defect of a log: its kind, the column, the time range and what was seen.

    Attributes:
        kind: ``gap``, ``spike``, ``flat_line`` or ``stall``.
        column: The column it is in (``time_s`` for a gap).
        start_s: First time of the defect, s.
        end_s: Last time of the defect, s.
        rows: Data rows (counted from 1) of its first and last sample.
        detail: One line saying what was seen.
    """

    kind: str
    column: str
    start_s: float
    end_s: float
    rows: tuple[int, int]
    detail: str

    def overlaps(self, start_s: float, end_s: float) -> bool:
        """Whether the defect touches the time window ``[start_s, end_s]``, s."""
        return self.start_s <= end_s and self.end_s >= start_s


@dataclass(frozen=True)
class MeasuredLog:
    """A validated log: its clock and its columns, float64 arrays of one length.

    Attributes:
        time_s: Sample times, s, strictly increasing, shape ``(n,)``.
        columns: Every other column of the file by name (units in the names), shape ``(n,)``.
        source: Where it was read from (for reports).
    """

    time_s: npt.NDArray[np.float64]
    columns: Mapping[str, npt.NDArray[np.float64]] = field(default_factory=dict)
    source: str = ""

    def __post_init__(self) -> None:
        check_log_arrays(self.time_s, self.columns)

    def has(self, name: str) -> bool:
        """Whether the log has the column ``name``."""
        return name in self.columns

    def column(self, name: str) -> npt.NDArray[np.float64]:
        """The column ``name``; ``ValueError`` naming the columns there are if it is missing."""
        if name == "time_s":
            return self.time_s
        if name not in self.columns:
            raise ValueError(
                f"the log {self.source or ''} has no column {shown(name)}: it has "
                f"{', '.join(['time_s', *self.columns])}"
            )
        return self.columns[name]

    @property
    def sample_period_s(self) -> float:
        """Median time between samples, s."""
        return float(np.median(np.diff(self.time_s)))

    def window_indices(self, start_s: float, end_s: float) -> tuple[int, int]:
        """``(i0, i1)`` such that ``time_s[i0:i1]`` is the window ``[start_s, end_s]``;
        ``ValueError`` if the window is not inside the log or holds fewer than 3 samples."""
        t0, t1 = float(self.time_s[0]), float(self.time_s[-1])
        if not (math.isfinite(start_s) and math.isfinite(end_s) and start_s < end_s):
            raise ValueError(f"window = {start_s:g}:{end_s:g} s is empty: allowed A:B with A < B")
        if start_s < t0 - 1e-9 or end_s > t1 + 1e-9:
            raise ValueError(
                f"window = {start_s:g}:{end_s:g} s is out of range: allowed inside the log's "
                f"time [{t0:g}, {t1:g}] s"
            )
        i0 = int(np.searchsorted(self.time_s, start_s - 1e-9, side="left"))
        i1 = int(np.searchsorted(self.time_s, end_s + 1e-9, side="right"))
        if i1 - i0 < MIN_LOG_ROWS:
            raise ValueError(
                f"window = {start_s:g}:{end_s:g} s holds {i1 - i0} samples: allowed at least "
                f"{MIN_LOG_ROWS}"
            )
        return i0, i1

    def window(self, start_s: float, end_s: float) -> MeasuredLog:
        """The samples of ``[start_s, end_s]`` as a log (copies)."""
        i0, i1 = self.window_indices(start_s, end_s)
        return MeasuredLog(
            self.time_s[i0:i1].copy(),
            {k: v[i0:i1].copy() for k, v in self.columns.items()},
            f"{self.source}[{start_s:g}:{end_s:g} s]",
        )


def check_log_arrays(
    time_s: npt.NDArray[np.float64], columns: Mapping[str, npt.NDArray[np.float64]]
) -> None:
    """Check a log's arrays: known names, the required ones there, one length, finite values,
    a strictly increasing clock with a median step of at least :data:`MIN_SAMPLE_PERIOD_S`;
    ``ValueError`` naming the column and the row otherwise."""
    names = ["time_s", *columns]
    _check_names(names)
    _check_rows(time_s, columns)


def _listed(names: list[str]) -> str:
    """At most :data:`MAX_SHOWN_NAMES` names, each shown escaped and bounded."""
    text = ", ".join(shown(n) for n in names[:MAX_SHOWN_NAMES])
    more = len(names) - MAX_SHOWN_NAMES
    return text + (f" and {more} more" if more > 0 else "")


def _check_names(names: list[str]) -> None:
    unknown = [n for n in names if n not in COLUMN_UNITS]
    if unknown:
        raise ValueError(f"unknown column(s) {_listed(unknown)}: allowed {', '.join(COLUMN_UNITS)}")
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise ValueError(f"column(s) {_listed(duplicated)} appear twice or more")
    missing = [n for n in REQUIRED_COLUMNS if n not in names]
    if missing:
        raise ValueError(
            f"missing required column(s) {', '.join(repr(n) for n in missing)} "
            f"(required: {', '.join(REQUIRED_COLUMNS)})"
        )


def _check_rows(
    time_s: npt.NDArray[np.float64], columns: Mapping[str, npt.NDArray[np.float64]]
) -> None:
    names = ["time_s", *columns]
    n = len(time_s)
    if n < MIN_LOG_ROWS:
        raise ValueError(f"the log has {n} data rows: allowed at least {MIN_LOG_ROWS}")
    for name in names:
        values = time_s if name == "time_s" else columns[name]
        if values.shape != (n,):
            raise ValueError(f"column {shown(name)} has shape {values.shape}, expected ({n},)")
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ValueError(
                f"column {shown(name)}, row {bad[0] + 1}: {shown(float(values[bad[0]]))} is not finite "
                f"({bad.size} such row(s))"
            )
    steps = np.diff(time_s)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise ValueError(
            f"column 'time_s', row {i + 1}: {shown(float(time_s[i]))} s is not after row {i}'s "
            f"{shown(float(time_s[i - 1]))} s: time must be strictly increasing"
        )
    period = float(np.median(steps))
    if not period >= MIN_SAMPLE_PERIOD_S * (1 - 1e-6):  # a clock's rounding is no excess
        raise ValueError(
            f"column 'time_s': the median sample period {period:.3g} s is out of range: allowed "
            f"at least {MIN_SAMPLE_PERIOD_S:g} s (at most {1 / MIN_SAMPLE_PERIOD_S:.0f} samples "
            "per second; is the clock in seconds?)"
        )


def _check_size(path: Path) -> None:
    """Refuse anything but a regular file of at most :data:`MAX_LOG_BYTES` (a FIFO, a device
    such as ``/dev/zero`` or a folder is never opened)."""
    status = os.stat(path)
    if not stat.S_ISREG(status.st_mode):
        kind = "a folder" if stat.S_ISDIR(status.st_mode) else "not a regular file"
        raise ValueError(
            f"log {str(path)!r} is {kind} (a FIFO, a device or a socket is never opened): "
            "expected a CSV or Parquet file"
        )
    size = status.st_size
    if size > MAX_LOG_BYTES:
        raise ValueError(
            f"log {str(path)!r} is {size} bytes: allowed at most {MAX_LOG_BYTES} bytes"
        )


def _line(f: TextIO, path: Path, line_number: int) -> str:
    """The next line of ``f`` (empty at the end), refused beyond :data:`MAX_LINE_CHARS`."""
    line = f.readline(MAX_LINE_CHARS + 1)
    if len(line) > MAX_LINE_CHARS:
        raise ValueError(
            f"log {str(path)!r}, line {line_number}: longer than {MAX_LINE_CHARS} characters"
        )
    return line


def _header(path: Path) -> tuple[list[str], int]:
    """The header's names and the number of lines before the first data row."""
    with open(path, encoding=_ENCODING, newline="") as f:
        skipped = 0
        while line := _line(f, path, skipped + 1):
            skipped += 1
            text = line.strip()
            if not text or text.startswith("#"):
                continue
            names = [c.strip() for c in next(csv.reader([text]))]
            return names, skipped
    raise ValueError(f"log {str(path)!r} has no header line: expected e.g. time_s,top_speed_rad_s")


def _read_csv(path: Path) -> tuple[npt.NDArray[np.float64], dict[str, npt.NDArray[np.float64]]]:
    try:
        names, skipped = _header(path)
    except UnicodeDecodeError as exc:
        raise ValueError(f"log {str(path)!r} is not UTF-8 text: {exc.reason}") from None
    _check_names(names)  # unknown, repeated and missing columns before any number is read
    values = array.array("d")  # 8 bytes a value, whatever the row count
    rows = 0
    try:
        with open(path, encoding=_ENCODING, newline="") as f:
            for _ in range(skipped):
                f.readline(MAX_LINE_CHARS + 1)
            row_number = 0
            while line := _line(f, path, skipped + row_number + 1):
                row_number += 1
                row = next(csv.reader([line]), [])
                if not row or (len(row) == 1 and not row[0].strip()):
                    continue
                if row_number > MAX_LOG_ROWS:
                    raise ValueError(f"log {str(path)!r} has more than {MAX_LOG_ROWS} data rows")
                if len(row) != len(names):
                    raise ValueError(
                        f"row {row_number}: {len(row)} values for {len(names)} columns "
                        f"({', '.join(names)})"
                    )
                for name, text in zip(names, row, strict=True):
                    try:
                        values.append(float(text))
                    except ValueError:
                        raise ValueError(
                            f"column {shown(name)}, row {row_number}: {shown(text.strip())} is not a "
                            "number"
                        ) from None
                rows += 1
    except UnicodeDecodeError as exc:
        raise ValueError(f"log {str(path)!r} is not UTF-8 text: {exc.reason}") from None
    except csv.Error as exc:
        raise ValueError(f"log {str(path)!r} is not valid CSV: {shown(str(exc))}") from None
    table = np.frombuffer(values, dtype=np.float64).reshape(rows, len(names))
    data = {name: np.ascontiguousarray(table[:, j]) for j, name in enumerate(names)}
    time_s = data.pop("time_s")
    return time_s, data


def _read_parquet(
    path: Path,
) -> tuple[npt.NDArray[np.float64], dict[str, npt.NDArray[np.float64]]]:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ModuleNotFoundError:
        raise ValueError(
            f"log {str(path)!r} is Parquet, which needs the package pyarrow (pip install pyarrow); "
            "or write the log as CSV"
        ) from None
    meta = pq.read_metadata(path)
    if meta.num_rows > MAX_LOG_ROWS:
        raise ValueError(f"log {str(path)!r} has {meta.num_rows} rows: allowed {MAX_LOG_ROWS}")
    _check_names(list(meta.schema.names))  # before any column is read
    table = pq.read_table(path)
    names = list(table.column_names)
    _check_names(names)
    data: dict[str, npt.NDArray[np.float64]] = {}
    for name in names:
        column = table.column(name)
        kind = column.type
        if not (pa.types.is_floating(kind) or pa.types.is_integer(kind)):
            # bools, times and dates, text: not a number in the column's SI unit
            raise ValueError(
                f"column {shown(name)} is not numeric ({kind}): expected float or integer"
            )
        if column.null_count:
            first = int(np.flatnonzero(np.asarray(column.is_null()))[0]) + 1
            raise ValueError(f"column {shown(name)}, row {first}: empty value is not a number")
        try:
            data[name] = np.asarray(column.to_numpy(), dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"column {shown(name)} is not numeric ({column.type})") from None
    return data.pop("time_s"), data


def read_log(path: str | os.PathLike[str]) -> MeasuredLog:
    """Read and validate a log file (CSV, or Parquet where pyarrow is installed).

    Raises:
        OSError: The file cannot be opened.
        ValueError: One line naming the column and the row of the first bad value, an unknown
            or missing column, a clock that does not increase, or a file too large.
    """
    p = Path(path)
    _check_size(p)
    if p.suffix.lower() in (".parquet", ".pq"):
        time_s, columns = _read_parquet(p)
    else:
        time_s, columns = _read_csv(p)
    return MeasuredLog(time_s, columns, str(p))


def write_log_csv(log: MeasuredLog, path: str | os.PathLike[str]) -> Path:
    """Write ``log`` as a CSV file of the format (17 significant digits), returns the path."""
    p = Path(path)
    names = ["time_s", *log.columns]
    table = np.column_stack([log.column(n) for n in names])
    with replacing(p, "w") as f:
        np.savetxt(f, table, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return p


def _runs(mask: npt.NDArray[np.bool_]) -> list[tuple[int, int]]:
    """``(first, last)`` index of every run of True in ``mask``."""
    if not mask.any():
        return []
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2], strict=False)]


def _running_median(x: npt.NDArray[np.float64], half: int) -> npt.NDArray[np.float64]:
    padded = np.pad(x, half, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    return np.asarray(np.median(windows, axis=1))


def spike_mask(values: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """Samples that are isolated spikes (a Hampel test on 7 samples, with the noise scale the
    larger of the median absolute deviations of the signal from its running median and of its
    sample-to-sample steps, over the whole signal), outside the signal's 0.5-99.5 % range
    widened by 10 % or three times beyond the threshold."""
    if values.size < 7:
        return np.zeros(values.shape, dtype=bool)
    deviation = values - _running_median(values, 3)
    scale = 1.4826 * float(np.median(np.abs(deviation - np.median(deviation))))
    # A signal sampled coarsely against its own changes (field telemetry) deviates from a
    # running median by its trend too: the spread of the sample-to-sample steps bounds it.
    steps = np.diff(values)
    scale = max(scale, 1.4826 * float(np.median(np.abs(steps - np.median(steps)))) / math.sqrt(2))
    spread = float(np.percentile(values, 99) - np.percentile(values, 1))
    scale = max(scale, 1e-3 * spread, 1e-12)
    far = np.abs(deviation) > SPIKE_SIGMAS * scale
    # A spike also jumps from both of its neighbours (a steep front does not).
    prev = np.abs(values - np.roll(values, 1)) > 0.5 * SPIKE_SIGMAS * scale
    after = np.abs(values - np.roll(values, -1)) > 0.5 * SPIKE_SIGMAS * scale
    # A coarse log samples a real peak (a break-away torque) once: such a sample stays within
    # the signal's range; a spike is outside it or far beyond the threshold.
    low, high = np.percentile(values, [0.5, 99.5])
    margin = 0.1 * (high - low)
    outside = (values < low - margin) | (values > high + margin)
    mask = far & prev & after & (outside | (np.abs(deviation) > 3 * SPIKE_SIGMAS * scale))
    mask[0] = mask[-1] = False
    return np.asarray(mask)


def flat_mask(
    values: npt.NDArray[np.float64], time_s: npt.NDArray[np.float64]
) -> list[tuple[int, int]]:
    """Runs of exactly equal samples at least :data:`FLAT_MIN_SAMPLES` long and
    :data:`FLAT_MIN_S` seconds, as ``(first, last)`` indices."""
    same = np.concatenate(([False], values[1:] == values[:-1]))
    out = []
    for a, b in _runs(same):
        first = a - 1
        if b - first + 1 >= FLAT_MIN_SAMPLES and time_s[b] - time_s[first] >= FLAT_MIN_S:
            out.append((first, b))
    return out


def find_defects(log: MeasuredLog) -> list[Defect]:
    """Every defect of ``log`` with its time range, in order of time; the log is not changed.

    * ``gap``: a time step longer than :data:`GAP_FACTOR` median steps.
    * ``spike``: an isolated sample far from its neighbours (:func:`spike_mask`).
    * ``flat_line``: a sensor that repeats one value exactly (:func:`flat_mask`): a dropout
      or a held value. A bit that really sticks reads noise around 0, not one number.
    * ``stall``: the top drive below :data:`STALL_FRACTION` of its median speed for
      :data:`STALL_MIN_S` or longer.
    """
    t = log.time_s
    defects: list[Defect] = []
    steps = np.diff(t)
    median_step = float(np.median(steps))
    for i in np.flatnonzero(steps > GAP_FACTOR * median_step):
        defects.append(
            Defect(
                "gap",
                "time_s",
                float(t[i]),
                float(t[i + 1]),
                (int(i) + 1, int(i) + 2),
                f"{steps[i]:.4g} s without samples ({steps[i] / median_step:.0f} median steps)",
            )
        )
    for name, values in log.columns.items():
        for a, b in _runs(spike_mask(values)):
            defects.append(
                Defect(
                    "spike",
                    name,
                    float(t[a]),
                    float(t[b]),
                    (a + 1, b + 1),
                    f"{b - a + 1} sample(s) up to {values[a : b + 1][np.argmax(np.abs(values[a : b + 1]))]:.4g}",
                )
            )
        for a, b in flat_mask(values, t):
            defects.append(
                Defect(
                    "flat_line",
                    name,
                    float(t[a]),
                    float(t[b]),
                    (a + 1, b + 1),
                    f"{b - a + 1} samples all equal to {values[a]:.6g}",
                )
            )
    top = np.abs(log.column("top_speed_rad_s"))
    level = float(np.median(top))
    if level > 0:
        for a, b in _runs(top < STALL_FRACTION * level):
            if t[b] - t[a] >= STALL_MIN_S:
                defects.append(
                    Defect(
                        "stall",
                        "top_speed_rad_s",
                        float(t[a]),
                        float(t[b]),
                        (a + 1, b + 1),
                        f"top drive below {STALL_FRACTION * level:.3g} rad/s for "
                        f"{t[b] - t[a]:.3g} s",
                    )
                )
    defects.sort(key=lambda d: (d.start_s, d.kind, d.column))
    return defects
