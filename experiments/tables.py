"""The one table writer of the studies: rows of results as a markdown table, CSV and JSON.

A row is a mapping of column keys to values; ``None`` (and a non-finite float in JSON) means
"no value". Every study (``compare``, ``map``, ``evaluate``) writes its tables through these
functions, so their files read alike. Names in the rows may come from files (a model's name, a
controller's): a Markdown cell shows them through :func:`drill_env.validation.printable`, so a
newline, a ``|`` or an escape sequence can neither break the table nor reach the terminal raw.
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Final, NamedTuple

from drill_env.files import replacing, write_text
from drill_env.validation import printable

__all__ = ["MAX_CELL_CHARS", "Column", "json_clean", "markdown_table", "write_csv", "write_json"]

MAX_CELL_CHARS: Final = 200
"""Longest text of a Markdown cell (longer is cut with ...)."""


class Column(NamedTuple):
    """One column of a markdown table.

    Attributes:
        key: The row key it shows.
        title: Its heading (with the unit).
        fmt: A ``str.format`` pattern for the value (``"{}"`` for text).
        missing: What a ``None`` value shows.
        align: ``"left"`` or ``"right"``.
    """

    key: str
    title: str
    fmt: str = "{}"
    missing: str = "-"
    align: str = "right"


def markdown_table(
    rows: Sequence[Mapping[str, Any]],
    columns: Sequence[Column],
    cell: Callable[[Mapping[str, Any], Column], str | None] | None = None,
) -> str:
    """``rows`` as a markdown table of ``columns``; ``cell(row, column)`` may return the text
    of a cell itself (``None``: the default formatting)."""
    head = "| " + " | ".join(c.title for c in columns) + " |"
    rule = "|" + "|".join("---" if c.align == "left" else "---:" for c in columns) + "|"
    lines = [head, rule]
    for row in rows:
        cells = []
        for column in columns:
            text = cell(row, column) if cell is not None else None
            if text is None:
                value = row.get(column.key)
                text = column.missing if value is None else column.fmt.format(value)
            cells.append(printable(text, MAX_CELL_CHARS, cell=True))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_csv(rows: Sequence[Mapping[str, Any]], path: Path, keys: Sequence[str]) -> Path:
    """``rows`` as CSV with the columns ``keys`` (an empty cell for ``None``); returns ``path``.

    Written whole or not at all, never through a symbolic link (:func:`drill_env.files.replacing`).
    """
    with replacing(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(keys))
        writer.writeheader()
        for r in rows:
            writer.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in keys})
    return path


def json_clean(value: Any) -> Any:
    """``value`` with non-finite floats replaced by ``None`` (JSON has no NaN), recursively."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {k: json_clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_clean(v) for v in value]
    return value


def write_json(data: Any, path: Path, indent: int = 1) -> Path:
    """``data`` (rows or any JSON-able object) as JSON, non-finite numbers as ``null``.

    Written whole or not at all, never through a symbolic link (:func:`drill_env.files.replacing`).
    """
    return write_text(path, json.dumps(json_clean(data), indent=indent) + "\n")
