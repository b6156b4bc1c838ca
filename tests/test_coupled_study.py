"""``drill-gym coupled``: the standard-run table, the critical speeds, the maps and the files,
on a short run and a small grid; and its user errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drill_env.coupled import critical_speed_rad_s, run_features, simulate
from experiments.cli import main


def test_short_run_prints_the_tables_and_writes_the_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["coupled", "--points", "P1", "P3", "--duration-s", "4", "--window", "2", "4"]
    argv += ["--forces", "60", "--speeds", "4", "20", "--map-duration", "2"]
    argv += ["--out", str(tmp_path), "--no-progress"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "| P1 |" in out and "| P3 |" in out and "critical Om0" in out
    data = json.loads((tmp_path / "coupled.json").read_text())
    rows = {row["point"]: row for row in data["standard_run"]}
    expected = run_features(simulate("rgd_a", 4.0, 60e3, 4.0), (2.0, 4.0))
    assert rows["P3"]["frac_stick"] == pytest.approx(expected.frac_stick, rel=1e-12)
    assert rows["P3"]["rop_mm_s"] == pytest.approx(expected.rop_m_s * 1e3, rel=1e-12)
    critical = data["critical_speeds"][0]["critical_speed_rad_s"]
    assert critical == pytest.approx(
        critical_speed_rad_s("rgd_a", 60e3, speed_range_rad_s=(1.0, 60.0), grid=30), rel=1e-9
    )
    assert len(data["rightmost_root_real"]) == 1 and len(data["simulated"]["frac_stick"][0]) == 2
    assert (tmp_path / "figures" / "coupled_stability_map.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--forces", "20"], "--forces: 20 is out of range: allowed > W_f_bar"),
        (["--window", "300", "200"], "--window: 300 200 is out of range"),
        (["--window", "300"], "--window: 300: allowed two values, START END"),
        (
            ["--duration", "150"],
            "--window: 100 400 is out of range: allowed START < END <= --duration-s",
        ),
        (["--step", "0.001"], "argument --step: 0.001 is out of range"),
        (["--points", "P7"], "argument --points: invalid choice: 'P7'"),
    ],
)
def test_user_errors_are_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code = main(["coupled", *argv, "--out", str(tmp_path / "new")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err
    assert not (tmp_path / "new").exists()
