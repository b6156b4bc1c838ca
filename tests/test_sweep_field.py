"""The sweep runner on the field string (``DrillStringField-v0``), serially: a map, a
comparison and a held-out evaluation on the runner equal the plain serial functions (every
row, in order, every float bit for bit), a resume after an interrupted sweep gives the same
result, a study with other field settings reads none of the rows, and the commands with
``--task-size``/``--results``/``--resume`` write the files of the plain run."""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
import sqlite3
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

from experiments import compare, evaluate, stick_slip_map
from experiments.cli import main as cli_main
from experiments.compare import CompareStudy
from experiments.evaluate import EvaluateStudy
from experiments.field import FIELD_ENV, PAPER_ENV
from experiments.stick_slip_map import MapStudy, StickSlipMap, compute_map
from experiments.sweep import read_results, run_sweep, spec_hash

WOBS = (60e3, 120e3, 180e3)
SPEEDS = (6.0, 12.0)
SHORT: dict[str, Any] = {"duration_s": 2.0, "window_s": 1.0, "noise_std_rad_s": 0.05, "seed": 5}


def field_map(**kwargs: Any) -> MapStudy:
    settings: dict[str, Any] = {
        "env_id": FIELD_ENV,
        "depths_m": (1500.0,),
        "observations": ("state", "surface"),
        "task_cells": 2,
        **SHORT,
    }
    settings.update(kwargs)
    return MapStudy(("soft_speed", "csmc"), WOBS, SPEEDS, **settings)


def assert_same_map(swept: StickSlipMap, plain: StickSlipMap) -> None:
    """Every field equal (arrays bit for bit, scalars of the same type) but the wall time."""
    for f in dataclasses.fields(plain):
        if f.name == "wall_time_s":
            continue
        a, b = getattr(swept, f.name), getattr(plain, f.name)
        if isinstance(b, np.ndarray):
            assert a.shape == b.shape and a.tobytes() == b.tobytes(), f.name
        else:
            assert a == b and type(a) is type(b), f.name


def drop_last_task(path: Path) -> int:
    """Delete the rows of the results database's last task (as if the sweep had been
    interrupted before it); returns the number of tasks left."""
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        (last,) = db.execute("SELECT task FROM results ORDER BY rowid DESC LIMIT 1").fetchone()
        db.execute("DELETE FROM results WHERE task = ?", (last,))
        (left,) = db.execute("SELECT count(DISTINCT task) FROM results").fetchone()
    assert left >= 1, "at least two tasks"
    return int(left)


# ----------------------------------------------------------------------------------- maps
def test_field_map_study_runs_are_those_of_the_map_command() -> None:
    study = field_map(depths_m=(1500.0, 2500.0))
    assert study.runs() == [
        ("soft_speed", "state", 1500.0),
        ("soft_speed", "surface", 1500.0),
        ("soft_speed", "state", 2500.0),
        ("soft_speed", "surface", 2500.0),
        ("csmc", "state", 1500.0),  # the paper's SMCs need the whole state
        ("csmc", "state", 2500.0),
    ]
    assert study.items()[:4] == [
        "soft_speed/state/1500.0m/row0",
        "soft_speed/state/1500.0m/row1",
        "soft_speed/state/1500.0m/row2",
        "soft_speed/surface/1500.0m/row0",
    ]
    tasks = study.tasks(study.items())
    assert tasks[0].key == "soft_speed/state/1500.0m/rows0-0"  # 2 cells: one row of 2 speeds
    assert tasks[0].kwargs["measured_depth_m"] == 1500.0
    assert tasks[0].kwargs["parameters"] == "field_2500m"
    assert field_map(depths_m=()).runs()[0] == ("soft_speed", "state", 2500.0)  # the preset's


def test_field_maps_on_the_runner_equal_compute_map() -> None:
    study = field_map(task_cells=4)
    maps = study.maps(run_sweep(study, progress=False))
    assert [(m.controller, m.observation, m.measured_depth_m) for m in maps] == study.runs()
    for swept, (controller, observation, depth) in zip(maps, study.runs(), strict=True):
        plain = compute_map(
            controller, list(WOBS), list(SPEEDS), progress=False, env_id=FIELD_ENV,
            observation=observation, measured_depth_m=depth, **SHORT,
        )  # fmt: skip
        assert_same_map(swept, plain)
        assert swept.file_stem() == plain.file_stem()
    assert maps[1].file_stem() == "stick_slip_map_soft_speed_surface_1500m"


@pytest.fixture(scope="module")
def map_results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The results database of :func:`field_map` (one row per task)."""
    path = tmp_path_factory.mktemp("map") / "map.sqlite"
    run_sweep(field_map(), results_path=path, progress=False)
    return path


def test_field_map_resumes_after_an_interruption(map_results: Path, tmp_path: Path) -> None:
    clean = field_map().maps(run_sweep(field_map(), progress=False))
    path = tmp_path / "map.sqlite"
    shutil.copy(map_results, path)
    kept = drop_last_task(path)
    resumed = run_sweep(field_map(task_cells=6), results_path=path, resume=True, progress=False)
    assert resumed.loaded == kept and resumed.ran == ["csmc/state/1500.0m/rows2-2"]
    for a, b in zip(field_map().maps(resumed), clean, strict=True):
        assert_same_map(a, b)


@pytest.mark.parametrize(
    "other",
    [
        {"depths_m": (1600.0,)},
        {"observations": ("state",)},
        {"noise_std_rad_s": 0.0},
        {"parameters": "deep_5000m"},
        {"env_id": PAPER_ENV, "depths_m": ()},
    ],
)
def test_field_map_with_other_settings_reads_none_of_the_rows(
    other: dict[str, Any], map_results: Path
) -> None:
    assert read_results(map_results, field_map())  # the same settings read them
    study = field_map(**other)
    assert spec_hash("map", study.spec()) != spec_hash("map", field_map().spec())
    assert read_results(map_results, study) == {}


def test_map_study_passes_further_compute_map_keywords_through(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A keyword compute_map accepts beyond those the study sets (``keywords``) reaches every
    call and is part of the spec; one the study sets itself, or one compute_map does not
    take, is refused."""
    seen: list[Any] = []

    def with_level(*args: Any, level: str = "ideal", **kwargs: Any) -> StickSlipMap:
        seen.append(level)
        return compute_map(*args, **kwargs)

    monkeypatch.setattr(stick_slip_map, "compute_map", with_level)
    study = field_map(keywords={"level": "rough"}, task_cells=6)
    assert study.spec()["keywords"] == {"level": "rough"}
    assert study.spec() != field_map(keywords={"level": "smooth"}).spec()
    run_sweep(study, progress=False)
    assert seen == ["rough"] * len(study.runs())
    with pytest.raises(
        ValueError, match=r"keywords: 'seed' is not a further keyword of compute_map"
    ):
        field_map(keywords={"seed": 3})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"env_id": PAPER_ENV}, r"depths_m = \[1500.0\]: measured depths are a setting of the field"),
        ({"observations": ()}, r"observations = \[\] is empty: allowed one or more of state, surface"),
        ({"observations": ("wired",)}, r"observation = 'wired' is not valid: allowed state, surface"),
        ({"parameters": "zribi2024"}, r"parameters = 'zribi2024' is not a preset of DrillStringField-v0"),
        ({"env_id": "CartPole-v1"}, r"env = 'CartPole-v1' is not a known env"),
        ({"depths_m": (10.0,)}, r"measured_depth_m = 10.0 is out of range: allowed > BHA length"),
        ({"keywords": {"pid": 1}}, r"keywords: 'pid' is not a further keyword of compute_map"),
    ],
)  # fmt: skip
def test_bad_field_map_study(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        field_map(**kwargs)


# ----------------------------------------------------------------------------- compare
def field_compare(**kwargs: Any) -> CompareStudy:
    settings: dict[str, Any] = {
        "duration_s": 2.0,
        "seed": 2,
        "env_id": FIELD_ENV,
        "depths_m": (1500.0,),
        "keep_traces": True,
    }
    settings.update(kwargs)
    conditions = settings.pop("conditions", ("nominal",))
    return CompareStudy(("stiff_pi", "csmc"), conditions, (0.0, 0.05), **settings)


PAPER_AGENT = SimpleNamespace(name="paper_agent", env_id=PAPER_ENV, env_kwargs={})
"""An agent of the other env: the comparison does not run it on the field."""


def test_field_compare_does_not_depend_on_the_task_size() -> None:
    """Three runs per task, or one (``run_comparison``): the same rows and traces."""
    study = field_compare(agent=PAPER_AGENT, task_runs=3)
    assert not study.agent_runs and study.spec()["agent"] is None
    outcome = run_sweep(study, progress=False)
    swept, traces = study.results(outcome)
    cases = compare.comparison_cases(FIELD_ENV, ["nominal"], depths_m=[1500.0])
    rows, plain_traces = compare.run_comparison(
        ["stiff_pi", "csmc"], ["nominal"], [0.0, 0.05], duration_s=2.0, seed=2, env_id=FIELD_ENV,
        cases=cases, agent=PAPER_AGENT, progress=False,
    )  # fmt: skip
    assert [
        (r["controller"], r["observation"], r["scenario"], r["noise_std_rad_s"]) for r in swept
    ][:3] == [
        ("stiff_pi", "state", "1.5km-150kN-60rpm-nominal", 0.0),
        ("stiff_pi", "state", "1.5km-150kN-60rpm-nominal", 0.05),
        ("stiff_pi", "state", "1.5km-100kN-120rpm-nominal", 0.0),
    ]
    assert len(swept) == 12  # (stiff_pi x 2 modes + csmc) x 2 cases x 2 noises
    assert swept == rows  # every float bit for bit, in order
    assert compare.markdown_table(swept) == compare.markdown_table(rows)
    assert set(traces) == set(plain_traces)
    key = ("stiff_pi (surface)", "1.5km-150kN-60rpm-nominal", 0.05)
    assert traces[key].overview.bit_speed_rad_s.tobytes() == (
        plain_traces[key].overview.bit_speed_rad_s.tobytes()
    )


@pytest.fixture(scope="module")
def compare_results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The results database of :func:`field_compare` (four runs per task)."""
    path = tmp_path_factory.mktemp("compare") / "compare.sqlite"
    run_sweep(field_compare(task_runs=4), results_path=path, progress=False)
    return path


def test_field_compare_resumes_after_an_interruption(compare_results: Path, tmp_path: Path) -> None:
    clean, _ = field_compare().results(run_sweep(field_compare(), progress=False))
    path = tmp_path / "compare.sqlite"
    shutil.copy(compare_results, path)
    kept = drop_last_task(path)
    resumed = run_sweep(field_compare(task_runs=1), results_path=path, resume=True, progress=False)
    assert resumed.loaded == 4 * kept and len(resumed.ran) == 12 - 4 * kept
    rows, _ = field_compare().results(resumed)
    assert rows == clean


@pytest.mark.parametrize(
    "other",
    [
        {"depths_m": (2500.0,)},
        {"controller_model": "exact"},
        {"observations": ("surface",)},
        {"conditions": ("severe",)},
        {"env_id": PAPER_ENV},
    ],
)
def test_field_compare_with_other_settings_reads_none_of_the_rows(
    other: dict[str, Any], compare_results: Path
) -> None:
    assert read_results(compare_results, field_compare())  # the same settings read them
    study = field_compare(**other)
    assert spec_hash("compare", study.spec()) != spec_hash("compare", field_compare().spec())
    assert read_results(compare_results, study) == {}


def test_bad_field_compare_study() -> None:
    with pytest.raises(ValueError, match=r"condition = 'condition1' is not a field condition"):
        field_compare(conditions=("condition1",))
    with pytest.raises(ValueError, match=r"controller_model = 'true' is not valid"):
        field_compare(controller_model="true")
    with pytest.raises(ValueError, match=r"depths_m = \[\] is empty"):
        field_compare(depths_m=())
    with pytest.raises(ValueError, match=r"observation = 'wired' is not valid"):
        field_compare(observations=("wired",))


# ----------------------------------------------------------------------------- evaluate
SCENARIOS = tuple(s for s in evaluate.FIELD_HELD_OUT if s.id in ("f01", "f14"))


def field_evaluate(**kwargs: Any) -> EvaluateStudy:
    settings: dict[str, Any] = {
        "env_id": FIELD_ENV,
        "keep_traces": ("soft_speed (surface)",),
        "controllers": ("soft_speed",),
        "scenarios": SCENARIOS,
    }
    settings.update(kwargs)
    return EvaluateStudy((), **settings)


def test_field_evaluation_on_the_runner_equals_evaluate() -> None:
    outcome = run_sweep(field_evaluate(), progress=False)
    swept, traces = field_evaluate().results(outcome)
    rows, plain_traces = evaluate.evaluate(
        [], ["soft_speed"], list(SCENARIOS), keep_traces=["soft_speed (surface)"], env_id=FIELD_ENV
    )
    assert [(r["scenario"], r["controller"], r["observation"]) for r in swept] == [
        ("f01", "soft_speed", "state"),
        ("f01", "soft_speed", "surface"),
        ("f14", "soft_speed", "state"),
        ("f14", "soft_speed", "surface"),
    ]
    assert swept == rows
    assert (
        set(traces)
        == set(plain_traces)
        == {("f01", "soft_speed (surface)"), ("f14", "soft_speed (surface)")}
    )
    assert evaluate.summarize(swept, "soft_speed (state)") == evaluate.summarize(
        rows, "soft_speed (state)"
    )


def test_field_evaluation_resumes_after_an_interruption(tmp_path: Path) -> None:
    """Interrupted (the second scenario's row lost), resumed with another task size; then
    studies with other settings read none of the rows."""
    clean, _ = field_evaluate().results(run_sweep(field_evaluate(), progress=False))
    path = tmp_path / "heldout.sqlite"
    run_sweep(field_evaluate(), results_path=path, progress=False)
    assert drop_last_task(path) == 1
    resumed = run_sweep(
        field_evaluate(task_scenarios=2), results_path=path, resume=True, progress=False
    )
    assert resumed.loaded == 1 and resumed.ran == ["f14"]
    assert field_evaluate().results(resumed)[0] == clean
    for other in (
        field_evaluate(observations=("surface",)),
        field_evaluate(controllers=("stiff_pi",)),
        field_evaluate(scenarios=SCENARIOS[:1]),
    ):
        assert read_results(path, other) == {}


def test_bad_field_evaluate_study() -> None:
    with pytest.raises(
        ValueError, match=r"scenario 'h01' is not a held-out scenario of DrillStringField-v0"
    ):
        field_evaluate(scenarios=tuple(evaluate.HELD_OUT[:1]))
    with pytest.raises(ValueError, match=r"observations = \[\] is empty"):
        field_evaluate(observations=())
    with pytest.raises(ValueError, match=r"each held-out scenario at most once"):
        field_evaluate(scenarios=SCENARIOS[:1] * 2)


# ------------------------------------------------------------------------- command lines
def _same_files(a: Path, b: Path, names: list[str]) -> None:
    for name in names:
        assert (a / name).read_text() == (b / name).read_text(), name


def test_field_map_command_on_the_runner_writes_the_plain_files(tmp_path: Path) -> None:
    base = ["map", "--env", FIELD_ENV, "--controllers", "soft_speed", "csmc", "--depths", "1500"]
    base += ["--wob-n", "3", "--speed-n", "1", "--duration-s", "2", "--window-s", "1"]
    base += ["--noise", "0.05", "--no-plots", "--no-progress"]
    assert cli_main([*base, "--out", str(tmp_path / "plain")]) == 0
    swept = tmp_path / "swept"
    assert cli_main([*base, "--out", str(swept), "--task-size", "1", "--resume"]) == 0
    path = swept / "stick_slip_map.sqlite"
    drop_last_task(path)
    assert cli_main([*base, "--out", str(swept), "--resume"]) == 0
    names = sorted(p.name for p in (tmp_path / "plain").iterdir())
    assert names == [
        "stick_slip_map_csmc_state_1500m.csv",
        "stick_slip_map_soft_speed_state_1500m.csv",
        "stick_slip_map_soft_speed_surface_1500m.csv",
    ]
    assert sorted(p.name for p in swept.iterdir()) == sorted([*names, "stick_slip_map.sqlite"])
    _same_files(tmp_path / "plain", swept, names)


def test_field_compare_command_on_the_runner_writes_the_plain_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    base = ["compare", "--env", FIELD_ENV, "--controllers", "stiff_pi", "proposed", "--depths"]
    base += ["1500", "--conditions", "nominal", "--observations", "surface", "--noise", "0.05"]
    base += ["--duration-s", "2", "--no-agent", "--no-progress", "--no-plots"]
    assert cli_main([*base, "--out", str(tmp_path / "plain")]) == 0
    plain = capsys.readouterr().out
    assert cli_main([*base, "--out", str(tmp_path / "swept"), "--task-size", "3", "--results",
                     str(tmp_path / "c.sqlite")]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "sweep compare on serial: 2 tasks run" in out
    table = plain[plain.index("| controller") : plain.index("\n\n4 runs")]
    assert table in out
    _same_files(tmp_path / "plain", tmp_path / "swept", ["compare.csv", "compare.json"])
    # The options that change the numbers make another study: it reads none of the rows.
    other = [*base, "--controller-model", "exact", "--resume", "--results"]
    assert cli_main([*other, str(tmp_path / "c.sqlite"), "--out", str(tmp_path / "other")]) == 0
    printed = capsys.readouterr().out
    assert "sweep compare on serial: 4 tasks run" in printed and "items read" not in printed
    with contextlib.closing(sqlite3.connect(tmp_path / "c.sqlite")) as db:
        assert db.execute("SELECT count(DISTINCT settings_hash) FROM results").fetchone() == (2,)


def test_field_evaluate_command_on_the_runner_writes_the_plain_files(tmp_path: Path) -> None:
    base = ["evaluate", "--env", FIELD_ENV, "--controllers", "stiff_pi", "--observations"]
    base += ["surface", "--scenarios", "f01", "f14", "--no-plots", "--no-progress"]
    assert cli_main([*base, "--out", str(tmp_path / "plain")]) == 0
    swept = tmp_path / "swept"
    assert cli_main([*base, "--out", str(swept), "--resume"]) == 0
    with contextlib.closing(sqlite3.connect(swept / "heldout.sqlite")) as db:
        rows = db.execute("SELECT item, task FROM results ORDER BY rowid").fetchall()
    assert rows == [("f01", "f01"), ("f14", "f14")]  # one task per scenario
    _same_files(tmp_path / "plain", swept, ["heldout.csv", "heldout.json"])
