"""The log format: reading, one-line errors naming the column and row, and defect detection."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import drill_env.measured_log as measured_log
from drill_env.measured_log import MeasuredLog, find_defects, read_log, write_log_csv


def _clean_log(n: int = 4000, dt: float = 1e-3, seed: int = 0) -> MeasuredLog:
    """A noisy oscillating log without defects."""
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=np.float64) * dt
    top = 5.0 + 0.2 * np.sin(2 * np.pi * 1.3 * t) + rng.normal(0, 0.02, n)
    bit = 5.0 + 3.0 * np.sin(2 * np.pi * 1.3 * t) + rng.normal(0, 0.05, n)
    torque = 2.0 + 0.5 * np.cos(2 * np.pi * 1.3 * t) + rng.normal(0, 0.02, n)
    return MeasuredLog(t, {"top_speed_rad_s": top, "bit_speed_rad_s": bit, "bit_torque_nm": torque})


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_round_trip(tmp_path: Path) -> None:
    log = _clean_log(100)
    back = read_log(write_log_csv(log, tmp_path / "log.csv"))
    assert np.array_equal(back.time_s, log.time_s)
    for name, values in log.columns.items():
        assert np.array_equal(back.column(name), values)


def test_comments_and_blank_lines_before_the_header(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "log.csv",
        "# rig 3, run 7\n\ntime_s,top_speed_rad_s\n0,1\n0.001,1.1\n0.002,1.2\n",
    )
    log = read_log(path)
    assert log.time_s.tolist() == [0, 0.001, 0.002]
    assert log.column("top_speed_rad_s").tolist() == [1, 1.1, 1.2]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "time_s,top_speed_rad_s\n0,1\n0.001,abc\n0.002,1\n",
            r"column 'top_speed_rad_s', row 2: 'abc' is not a number",
        ),
        (
            "time_s,top_speed_rad_s\n0,1\n0.001,nan\n0.002,1\n",
            r"column 'top_speed_rad_s', row 2: nan is not finite",
        ),
        (
            "time_s,top_speed_rad_s\n0,1\n0.001,inf\n0.002,1\n",
            r"column 'top_speed_rad_s', row 2: inf is not finite",
        ),
        (
            "time_s,top_speed_rad_s\n0,1\n0.002,1\n0.001,1\n",
            r"column 'time_s', row 3: 0.001 s is not after row 2's 0.002 s",
        ),
        ("time_s,top_speed_rad_s\n0,1\n0,1\n0.001,1\n", r"column 'time_s', row 2"),
        (
            "time_s,bit_speed_rad_s\n0,1\n0.001,1\n0.002,1\n",
            r"missing required column\(s\) 'top_speed_rad_s'",
        ),
        (
            "time_s,top_speed_rad_s,rpm,torque\n0,1,2,3\n",
            r"unknown column\(s\) 'rpm', 'torque': allowed time_s, top_speed_rad_s",
        ),
        ("time_s,top_speed_rad_s,top_speed_rad_s\n0,1,1\n", r"'top_speed_rad_s' appear twice"),
        ("time_s,top_speed_rad_s\n0,1\n0.001\n0.002,1\n", r"row 2: 1 values for 2 columns"),
        (
            "time_s,top_speed_rad_s\n0,1\n0.001,\n0.002,1\n",
            r"column 'top_speed_rad_s', row 2: '' is not a number",
        ),
        ("time_s,top_speed_rad_s\n0,1\n", r"the log has 1 data rows: allowed at least 3"),
        ("# only a comment\n", r"has no header line"),
    ],  # fmt: skip
    ids=[
        "non-numeric",
        "nan",
        "inf",
        "time-decreasing",
        "time-repeated",
        "missing-column",
        "unknown-columns",
        "duplicate-column",
        "short-row",
        "empty-value",
        "too-short",
        "no-header",
    ],  # fmt: skip
)
def test_bad_logs_get_one_line_naming_column_and_row(tmp_path: Path, text: str, match: str) -> None:
    path = _write(tmp_path / "bad.csv", text)
    with pytest.raises(ValueError, match=match) as info:
        read_log(path)
    assert "\n" not in str(info.value)


def test_an_absurd_file_is_refused_before_it_is_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = write_log_csv(_clean_log(100), tmp_path / "log.csv")
    monkeypatch.setattr(measured_log, "MAX_LOG_BYTES", 100)

    def fail(*args: object, **kwargs: object) -> None:
        raise AssertionError("the file was opened")

    monkeypatch.setattr(measured_log, "_read_csv", fail)
    with pytest.raises(ValueError, match=r"bytes: allowed at most 100 bytes"):
        read_log(path)


def test_parquet_needs_pyarrow_or_reads(tmp_path: Path) -> None:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ModuleNotFoundError:
        path = _write(tmp_path / "log.parquet", "not parquet")
        with pytest.raises(ValueError, match="needs the package pyarrow"):
            read_log(path)
        return
    log = _clean_log(50)
    table = pa.table({"time_s": log.time_s, **log.columns})
    pq.write_table(table, tmp_path / "log.parquet")
    back = read_log(tmp_path / "log.parquet")
    assert np.array_equal(back.column("bit_speed_rad_s"), log.column("bit_speed_rad_s"))


def test_window_bounds_are_checked() -> None:
    log = _clean_log(1000)
    with pytest.raises(ValueError, match=r"window = 0.5:3 s is out of range: allowed inside"):
        log.window(0.5, 3.0)
    with pytest.raises(ValueError, match=r"window = 0.5:0.2 s is empty"):
        log.window(0.5, 0.2)
    assert log.window(0.1, 0.2).time_s.size == 101


def test_a_clean_log_has_no_defects() -> None:
    assert find_defects(_clean_log()) == []


def test_every_kind_of_defect_is_found_with_its_time_range_and_the_data_unchanged() -> None:
    base = _clean_log(8000)
    t = base.time_s.copy()
    cols = {k: v.copy() for k, v in base.columns.items()}
    cols["bit_speed_rad_s"][1500] += 40.0  # spike at 1.5 s
    cols["bit_torque_nm"][3000:3100] = cols["bit_torque_nm"][3000]  # flat line 3.0-3.099 s
    cols["top_speed_rad_s"][5000:5600] = 0.01  # stall 5.0-5.599 s
    keep = (t <= 6.5) | (t >= 6.6)  # gap 6.5-6.6 s
    log = MeasuredLog(t[keep], {k: v[keep] for k, v in cols.items()})
    before = {k: v.copy() for k, v in log.columns.items()}
    found = {(d.kind, d.column): d for d in find_defects(log)}
    assert set(found) >= {
        ("spike", "bit_speed_rad_s"),
        ("flat_line", "bit_torque_nm"),
        ("stall", "top_speed_rad_s"),
        ("gap", "time_s"),
    }
    assert found["spike", "bit_speed_rad_s"].start_s == pytest.approx(1.5)
    flat = found["flat_line", "bit_torque_nm"]
    assert (flat.start_s, flat.end_s) == pytest.approx((3.0, 3.099))
    stall = found["stall", "top_speed_rad_s"]
    assert (stall.start_s, stall.end_s) == pytest.approx((5.0, 5.599))
    gap = found["gap", "time_s"]
    assert (gap.start_s, gap.end_s) == pytest.approx((6.5, 6.6))
    for name, values in before.items():
        assert np.array_equal(log.column(name), values)


def test_a_steep_stick_slip_front_is_not_a_spike() -> None:
    t = np.arange(4000, dtype=np.float64) * 1e-3
    bit = np.where((t % 0.8) < 0.3, 0.0, 8.0 * np.sin(np.pi * ((t % 0.8) - 0.3) / 0.5))
    bit = bit + np.random.default_rng(1).normal(0, 0.05, t.size)
    log = MeasuredLog(t, {"top_speed_rad_s": np.full(t.size, 3.0), "bit_speed_rad_s": bit})
    assert [d for d in find_defects(log) if d.kind == "spike"] == []
