"""``drill-gym coupled``: the standard-run table, the critical speeds, the maps and the files,
on a short run and a small grid; and its user errors."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drill_env.coupled import (
    SURFACE_RULES,
    critical_speed_rad_s,
    run_features,
    simulate,
    simulated_map,
)
from experiments.cli import main
from experiments.coupled import CoupledSpec, CoupledStudy
from experiments.sweep import Backend, read_results, run_sweep, spec_hash


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


# ------------------------------------------------------------------------ on the runner
def small_study(**changes: Any) -> CoupledStudy:
    settings = {
        "points": ("P3",),
        "duration_s": 4.0,
        "window_s": (2.0, 4.0),
        "forces_kn": (60.0, 90.0),
        "speeds_rad_s": (4.0, 20.0),
        "map_duration_s": 2.0,
        **changes,
    }
    return CoupledStudy(CoupledSpec(**settings))


def test_study_items_and_cells_are_the_simulated_map() -> None:
    study = small_study()
    assert study.items() == ["point/P3", "cell/0/0", "cell/0/1", "cell/1/0", "cell/1/1"]
    assert small_study(no_simulated_map=True).items() == ["point/P3"]
    assert small_study(no_map=True).items() == ["point/P3"]
    outcome = run_sweep(study, progress=False)
    whole = simulated_map(
        "rgd_a", [60e3, 90e3], [4.0, 20.0], duration_s=2.0, window_s=(1.0, 2.0)
    )  # one call over the whole grid, as before the runner
    maps = study.simulated(outcome.records)
    for name, values in whole.items():
        np.testing.assert_array_equal(maps[name], values)
    features = run_features(simulate("rgd_a", 4.0, 60e3, 4.0), (2.0, 4.0))
    assert outcome.records["point/P3"]["frac_stick"] == features.frac_stick


def test_database_and_resume_write_the_serial_file(tmp_path: Path) -> None:
    argv = ["coupled", "--points", "P3", "--duration-s", "4", "--window", "2", "4"]
    argv += ["--forces", "60", "--speeds", "4", "20", "--map-duration", "2"]
    argv += ["--no-progress", "--no-plots"]
    results = str(tmp_path / "results.sqlite")
    assert main([*argv, "--out", str(tmp_path / "serial")]) == 0
    assert main([*argv, "--out", str(tmp_path / "db"), "--results", results]) == 0
    assert main([*argv, "--out", str(tmp_path / "again"), "--results", results, "--resume"]) == 0

    def read(name: str) -> dict[str, Any]:
        data: dict[str, Any] = json.loads((tmp_path / name / "coupled.json").read_text())
        for row in data["standard_run"]:
            row.pop("cpu_s")  # a timing
        return data

    assert read("serial") == read("db")
    assert (tmp_path / "db" / "coupled.json").read_text() == (
        tmp_path / "again" / "coupled.json"
    ).read_text()  # nothing recomputed: even the CPU times are the stored ones
    study = small_study(forces_kn=(60.0,), out=tmp_path / "again")
    assert set(read_results(Path(results), study)) == {"point/P3", *(c[0] for c in study.cells())}


def test_settings_hash_changes_with_every_setting_of_the_numbers() -> None:
    base = small_study()
    changes: dict[str, Any] = {
        "points": ("P4",),
        "duration_s": 5.0,
        "window_s": (1.0, 4.0),
        "step_s": 5e-5,
        "surface": next(s for s in SURFACE_RULES if s != "max"),
        "forces_kn": (60.0, 95.0),
        "speeds_rad_s": (4.0, 21.0),
        "map_duration_s": 3.0,
        "no_simulated_map": True,
    }
    hashes = {spec_hash(base.name, base.spec())}
    for key, value in changes.items():
        study = small_study(**{key: value})
        hashes.add(spec_hash(study.name, study.spec()))
    assert len(hashes) == 1 + len(changes)
    same = small_study(out=Path("elsewhere"), no_plots=True, no_progress=True)
    assert spec_hash(same.name, same.spec()) == spec_hash(base.name, base.spec())
    roots_only, no_map = small_study(no_simulated_map=True), small_study(no_map=True)
    assert spec_hash("coupled", roots_only.spec()) == spec_hash("coupled", no_map.spec())


def test_on_ray_equals_the_serial_run() -> None:
    pytest.importorskip("ray")
    study = small_study(no_simulated_map=False)
    serial = run_sweep(study, progress=False)
    swept = run_sweep(study, Backend(workers=2), progress=False)
    assert swept.records.keys() == serial.records.keys()
    for item, record in serial.records.items():
        other = swept.records[item]
        if item.startswith("point/"):
            record, other = dict(record, cpu_s=0), dict(other, cpu_s=0)
        assert other == record, item
