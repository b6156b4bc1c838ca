"""The studies' one table writer (:mod:`experiments.tables`)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from experiments.tables import Column, markdown_table, write_csv, write_json

ROWS = [
    {"name": "a", "x": 1.23456, "y": None},
    {"name": "b", "x": math.nan, "y": 2},
]


def test_markdown_table() -> None:
    columns = (Column("name", "name", align="left"), Column("x", "x (m)", "{:.2f}"),
               Column("y", "y", missing="never"))  # fmt: skip
    text = markdown_table(ROWS, columns)
    assert text.splitlines() == [
        "| name | x (m) | y |",
        "|---|---:|---:|",
        "| a | 1.23 | never |",
        "| b | nan | 2 |",
    ]
    custom = markdown_table(ROWS, columns, lambda r, c: "!" if c.key == "y" else None)
    assert custom.splitlines()[2] == "| a | 1.23 | ! |"


def test_csv_and_json(tmp_path: Path) -> None:
    path = write_csv(ROWS, tmp_path / "sub" / "t.csv", ("name", "y"))
    with path.open() as f:
        assert list(csv.DictReader(f)) == [{"name": "a", "y": ""}, {"name": "b", "y": "2"}]
    data = json.loads(write_json({"rows": ROWS}, tmp_path / "t.json").read_text())
    assert data["rows"][1]["x"] is None  # NaN is not JSON: null
