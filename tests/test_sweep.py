"""The sweep runner on its serial path (no Ray needed): tasks and items, the results database
(one row per item, studies sharing a file, two processes writing at once), resuming an
interrupted sweep (a SIGKILL included), and bad sweep specs failing on one line before anything
runs."""

from __future__ import annotations

import contextlib
import json
import re
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from drill_env import __version__
from experiments.cli import main as cli_main
from experiments.compare import CompareStudy
from experiments.evaluate import EvaluateStudy
from experiments.results_db import Fields, Flag, Number
from experiments.stick_slip_map import MapStudy, compute_map
from experiments.sweep import Backend, Task, TaskResult, read_results, run_sweep, spec_hash

WOBS = (60e3, 110e3, 160e3)
SPEEDS = (3.0, 7.0)
SHORT: dict[str, Any] = {"duration_s": 4.0, "window_s": 2.0, "noise_std_rad_s": 0.1, "seed": 5}


def small_map(task_cells: int = 2, controllers: tuple[str, ...] = ("stiff_pi",)) -> MapStudy:
    return MapStudy(controllers, WOBS, SPEEDS, task_cells=task_cells, **SHORT)


# ----------------------------------------------------------------------- tasks and items
def test_map_study_splits_rows_into_tasks_and_covers_every_item() -> None:
    study = small_map(task_cells=4, controllers=("stiff_pi", "soft_speed"))
    assert study.items() == [f"{c}/row{r}" for c in ("stiff_pi", "soft_speed") for r in range(3)]
    tasks = study.tasks(study.items())
    assert [t.items for t in tasks] == [
        ("stiff_pi/row0", "stiff_pi/row1"),
        ("stiff_pi/row2",),
        ("soft_speed/row0", "soft_speed/row1"),
        ("soft_speed/row2",),
    ]
    # Missing rows that are not consecutive make separate tasks (a task is one compute_map).
    gaps = study.tasks(["stiff_pi/row0", "stiff_pi/row2"])
    assert [t.kwargs["rows"] for t in gaps] == [[0], [2]]


def test_serial_sweep_equals_one_map_over_the_whole_grid() -> None:
    """Row blocks keep every cell's reset seed (seed + cell index): the map is the same as one
    compute_map over the grid, whatever the task size."""
    whole = compute_map("stiff_pi", list(WOBS), list(SPEEDS), progress=False, **SHORT)
    for task_cells in (1, 2, 6):
        study = small_map(task_cells)
        result = study.maps(run_sweep(study, progress=False))[0]
        np.testing.assert_array_equal(result.severity, whole.severity)
        np.testing.assert_array_equal(result.stuck_fraction, whole.stuck_fraction)
        assert result.window_s == whole.window_s and result.duration_s == whole.duration_s


# ----------------------------------------------------------------------- results database
def rows_of(path: Path) -> list[tuple[str, str, str, str]]:
    """(settings hash, version, item, task) of every row of a results database."""
    with contextlib.closing(sqlite3.connect(path)) as db:
        return db.execute(
            "SELECT settings_hash, version, item, task FROM results ORDER BY rowid"
        ).fetchall()


def drop_rows(path: Path, where: str, *args: Any) -> int:
    """Delete the rows ``where`` says (an interrupted sweep); returns how many."""
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        return db.execute(f"DELETE FROM results WHERE {where}", args).rowcount


def test_results_database_has_one_row_per_item_keyed_by_settings_and_version(
    tmp_path: Path,
) -> None:
    study = small_map(task_cells=2)
    path = tmp_path / "map.sqlite"
    outcome = run_sweep(study, results_path=path, progress=False)
    rows = rows_of(path)
    assert [item for _, _, item, _ in rows] == study.items()  # every item once, in order
    assert {(h, v) for h, v, _, _ in rows} == {(spec_hash("map", study.spec()), __version__)}
    assert list(dict.fromkeys(task for *_, task in rows)) == outcome.ran
    assert read_results(path, study) == outcome.records
    with contextlib.closing(sqlite3.connect(path)) as db:
        assert db.execute("PRAGMA journal_mode").fetchone() == ("wal",)
        (settings,) = db.execute("SELECT settings FROM studies WHERE sweep = 'map'").fetchone()
    assert json.loads(settings) == json.loads(json.dumps(study.spec()))


def test_resume_runs_only_the_missing_items_and_gives_the_clean_table(tmp_path: Path) -> None:
    """An interrupted sweep (two of three rows written) resumes: only the missing row runs,
    with another task size even, and the map equals a clean run."""
    clean_study = small_map(task_cells=2)
    clean = clean_study.maps(run_sweep(clean_study, progress=False))[0]
    path = tmp_path / "map.sqlite"
    run_sweep(small_map(task_cells=1), results_path=path, progress=False)
    assert drop_rows(path, "item = ?", "stiff_pi/row2") == 1
    resumed = run_sweep(small_map(task_cells=6), results_path=path, resume=True, progress=False)
    assert resumed.loaded == 2 and resumed.ran == ["stiff_pi/rows2-2"]
    result = small_map().maps(resumed)[0]
    np.testing.assert_array_equal(result.severity, clean.severity)
    np.testing.assert_array_equal(result.stuck_fraction, clean.stuck_fraction)
    assert [task for *_, task in rows_of(path)] == [
        "stiff_pi/rows0-0",
        "stiff_pi/rows1-1",
        "stiff_pi/rows2-2",
    ]
    # Nothing left to run: a second resume runs no task and gives the same map.
    again = run_sweep(small_map(), results_path=path, resume=True, progress=False)
    assert again.ran == [] and again.loaded == 3
    np.testing.assert_array_equal(small_map().maps(again)[0].severity, clean.severity)


def test_a_duration_that_is_not_a_whole_float_of_steps_resumes(tmp_path: Path) -> None:
    """2.3 s is 23 steps of 0.1 s, which the map reports as 23 * 0.1 = 2.3000000000000003 s:
    its rows fit the study's schema, are written and read back to the plain map."""
    kw: dict[str, Any] = {**SHORT, "duration_s": 2.3, "window_s": 1.3}
    study = MapStudy(("stiff_pi",), WOBS, SPEEDS, task_cells=2, **kw)
    plain = compute_map("stiff_pi", list(WOBS), list(SPEEDS), progress=False, **kw)
    assert plain.duration_s != 2.3  # the case this is about
    path = tmp_path / "map.sqlite"
    run_sweep(study, results_path=path, progress=False)
    (resumed,) = study.maps(run_sweep(study, results_path=path, resume=True, progress=False))
    assert resumed.severity.tobytes() == plain.severity.tobytes()
    assert (resumed.duration_s, resumed.window_s) == (plain.duration_s, plain.window_s)


def test_studies_share_a_database_and_never_read_each_others_rows(tmp_path: Path) -> None:
    """Two maps of other settings, and a comparison, in one file: each resume reads only its
    own rows, and a row of the same settings written by another version is not used."""
    path = tmp_path / "shared.sqlite"
    first = run_sweep(small_map(), results_path=path, progress=False)
    other = MapStudy(("stiff_pi",), WOBS, SPEEDS, **{**SHORT, "seed": 6})
    assert read_results(path, other) == {}  # none of the rows is the other study's
    second = run_sweep(other, results_path=path, resume=True, progress=False)
    assert second.loaded == 0 and second.ran == ["stiff_pi/rows0-2"] and second.other_rows == 3
    compare = CompareStudy(("stiff_pi",), ("nominal",), (0.0,), duration_s=2.0)
    run_sweep(compare, results_path=path, progress=False)
    assert len(rows_of(path)) == 3 + 3 + 1
    assert read_results(path, small_map()) == first.records
    assert read_results(path, other) == second.records
    assert list(read_results(path, compare)) == compare.items()
    # The rows of an older version are another study's: the item runs again.
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        db.execute("UPDATE results SET version = '0.0.1' WHERE item = 'stiff_pi/row1'")
    resumed = run_sweep(small_map(), results_path=path, resume=True, progress=False)
    assert resumed.loaded == 2 and resumed.ran == ["stiff_pi/rows1-1"]
    assert resumed.records == first.records


def test_rows_of_the_same_settings_are_refused_without_resume_or_overwrite(
    tmp_path: Path,
) -> None:
    path = tmp_path / "map.sqlite"
    run_sweep(small_map(), results_path=path, progress=False)
    other = MapStudy(("stiff_pi",), WOBS, SPEEDS, **{**SHORT, "seed": 6})
    run_sweep(other, results_path=path, progress=False)  # other settings: no conflict
    before = rows_of(path)
    with pytest.raises(
        ValueError,
        match=r"already holds 3 results of these settings \(sweep 'map', version .*\): add "
        r"--resume to keep them and run only the missing items, or --overwrite",
    ):
        run_sweep(small_map(task_cells=6), results_path=path, progress=False)
    assert rows_of(path) == before  # nothing written
    outcome = run_sweep(small_map(task_cells=6), results_path=path, overwrite=True, progress=False)
    assert outcome.loaded == 0 and outcome.ran == ["stiff_pi/rows0-2"]
    mine = spec_hash("map", small_map().spec())
    after = rows_of(path)
    assert [r for r in after if r[0] != mine] == before[3:]  # the other study's rows stay
    assert [r[2:] for r in after if r[0] == mine] == [
        (f"stiff_pi/row{k}", "stiff_pi/rows0-2") for k in range(3)
    ]
    with pytest.raises(ValueError, match=r"--resume and --overwrite exclude each other"):
        run_sweep(small_map(), results_path=path, resume=True, overwrite=True, progress=False)


def echo_task(keys: list[str], value: float, pause_s: float = 0.0) -> TaskResult:
    time.sleep(pause_s)
    return TaskResult({k: {"value": value, "nan": float("nan")} for k in keys})


class EchoStudy:
    """Items ``e0``..``e{n-1}``, one task each (sleeping ``pause_s``)."""

    name = "echo"

    def __init__(self, n: int = 3, pause_s: float = 0.0) -> None:
        self.n, self.pause_s = n, pause_s

    def spec(self) -> dict[str, Any]:
        return {"n": self.n}

    def items(self) -> list[str]:
        return [f"e{i}" for i in range(self.n)]

    def record_schema(self, item: str) -> Fields:
        return Fields({"value": Number(nullable=False), "nan": Number()})

    def tasks(self, missing: Sequence[str]) -> list[Task]:
        index = {k: i for i, k in enumerate(self.items())}
        return [
            Task(
                k, echo_task, {"keys": [k], "value": 0.1 + index[k], "pause_s": self.pause_s}, (k,)
            )
            for k in missing
        ]


def test_records_read_back_as_from_json_on_every_path(tmp_path: Path) -> None:
    """A record is what its JSON says (NaN as null), written or not, so a resumed sweep
    assembles the same numbers as a fresh one."""
    fresh = run_sweep(EchoStudy(), progress=False)
    assert fresh.records["e0"] == {"value": 0.1, "nan": None}
    written = run_sweep(EchoStudy(), results_path=tmp_path / "e.sqlite", progress=False)
    assert written.records == fresh.records
    assert read_results(tmp_path / "e.sqlite", EchoStudy()) == fresh.records


def test_a_task_whose_record_does_not_fit_the_schema_is_an_error(tmp_path: Path) -> None:
    class Loose(EchoStudy):
        def record_schema(self, item: str) -> Fields:
            return Fields({"value": Flag(), "nan": Number()})

    with pytest.raises(ValueError, match=r"task 'e0' made a record of item 'e0' that does not"):
        run_sweep(Loose(), results_path=tmp_path / "e.sqlite", progress=False)
    assert rows_of(tmp_path / "e.sqlite") == []


SWEEP_SCRIPT = """
import sys
sys.path.insert(0, sys.argv[1])
from pathlib import Path
from test_sweep import EchoStudy
from experiments.sweep import run_sweep
mode, path, n, pause = sys.argv[2], Path(sys.argv[3]), int(sys.argv[4]), float(sys.argv[5])
outcome = run_sweep(EchoStudy(n, pause), results_path=path, resume=mode == "resume", progress=False)
print(len(outcome.ran), outcome.loaded)
"""


def sweep_process(mode: str, path: Path, n: int, pause_s: float) -> subprocess.Popen[str]:
    """A sweep of :class:`EchoStudy` in another process."""
    argv = [sys.executable, "-c", SWEEP_SCRIPT, str(Path(__file__).parent), mode, str(path)]
    return subprocess.Popen(
        [*argv, str(n), str(pause_s)],
        cwd=Path(__file__).resolve().parents[1],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def test_two_processes_write_one_database_at_once(tmp_path: Path) -> None:
    """Two sweeps of other settings start together on a new file: both end, every row of
    each is there once."""
    path = tmp_path / "shared.sqlite"
    runs = [sweep_process("fresh", path, n, 0.005) for n in (40, 41)]
    for n, process in zip((40, 41), runs, strict=True):
        out, err = process.communicate(timeout=120)
        assert process.returncode == 0, err
        assert out.split() == [str(n), "0"]  # every task run, none read
    rows = rows_of(path)
    assert len(rows) == 81
    for n in (40, 41):
        assert read_results(path, EchoStudy(n)) == run_sweep(EchoStudy(n), progress=False).records


def test_kill_9_mid_sweep_then_resume_gives_every_item_once(tmp_path: Path) -> None:
    """A serial sweep killed with SIGKILL between tasks (or in one) resumes: the tasks that
    finished are kept, the rest run, and every item is in the file exactly once."""
    path, n = tmp_path / "killed.sqlite", 30
    process = sweep_process("fresh", path, n, 0.05)
    deadline = time.monotonic() + 120
    done = 0
    while time.monotonic() < deadline and done < 5:
        time.sleep(0.02)
        if path.is_file():
            with contextlib.suppress(sqlite3.Error):
                done = len(rows_of(path))
    process.kill()
    process.communicate(timeout=60)
    assert process.returncode == -signal.SIGKILL
    kept = len(rows_of(path))
    assert 5 <= kept < n, kept
    resumed = run_sweep(EchoStudy(n), results_path=path, resume=True, progress=False)
    assert resumed.loaded == kept and len(resumed.ran) == n - kept
    items = [item for _, _, item, _ in rows_of(path)]
    assert sorted(items) == sorted(EchoStudy(n).items())  # each once
    assert resumed.records == run_sweep(EchoStudy(n), progress=False).records


def test_map_command_killed_mid_sweep_resumes_to_the_plain_csv(tmp_path: Path) -> None:
    """``drill-gym map --resume`` in a process killed with SIGKILL after a few of its tasks,
    then run again: every WOB row once in the database, the CSV of a plain run."""
    base = ["map", "--controllers", "soft_speed", "--wob-n", "30", "--speed-n", "2"]
    base += ["--duration-s", "4", "--window-s", "2", "--noise", "0.1"]
    base += ["--no-plots", "--no-progress"]
    swept = tmp_path / "swept"
    path = swept / "stick_slip_map.sqlite"
    argv = [sys.executable, "-m", "experiments.cli", *base, "--task-size", "2", "--resume"]
    process = subprocess.Popen(
        [*argv, "--out", str(swept)],
        cwd=Path(__file__).resolve().parents[1],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline, done = time.monotonic() + 180, 0
    while time.monotonic() < deadline and done < 3 and process.poll() is None:
        time.sleep(0.01)
        if path.is_file():
            with contextlib.suppress(sqlite3.Error):
                done = len(rows_of(path))
    process.kill()
    process.communicate(timeout=60)
    assert process.returncode == -signal.SIGKILL
    kept = len(rows_of(path))
    assert 3 <= kept < 30, kept
    assert cli_main([*base, "--out", str(swept), "--resume"]) == 0
    items = sorted(item for _, _, item, _ in rows_of(path))
    assert items == sorted(f"soft_speed/row{r}" for r in range(30))  # each row once
    assert cli_main([*base, "--out", str(tmp_path / "plain")]) == 0
    name = "stick_slip_map_soft_speed.csv"
    assert (swept / name).read_text() == (tmp_path / "plain" / name).read_text()


# -------------------------------------------------------------------------- bad sweep specs
@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"controllers": ()}, r"controllers = \[\] is empty"),
        ({"controllers": ("pid",)}, r"unknown controller 'pid': valid names are .*stiff_pi"),
        ({"wob_n": ()}, r"wob_n = \[\] is empty: the grid needs at least one value"),
        ({"task_cells": 0}, r"task_cells = 0 is out of range: allowed an integer >= 1"),
    ],
)
def test_bad_map_study(kwargs: dict[str, Any], message: str) -> None:
    args: dict[str, Any] = {
        "controllers": ("stiff_pi",),
        "wob_n": WOBS,
        "reference_speed_rad_s": SPEEDS,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        MapStudy(**args)


def test_bad_compare_and_evaluate_studies() -> None:
    with pytest.raises(ValueError, match=r"conditions = \[\] is empty"):
        CompareStudy(("csmc",), (), (0.0,), duration_s=2.0)
    with pytest.raises(ValueError, match=r"unknown controller 'pid'"):
        CompareStudy(("pid",), ("nominal",), (0.0,), duration_s=2.0)
    with pytest.raises(ValueError, match=r"scenarios = \[\] is empty"):
        EvaluateStudy((), ("proposed",), ())


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"workers": 0}, r"workers = 0 is out of range: allowed an integer >= 1"),
        ({"workers": 1.5}, r"workers = 1.5 is out of range"),
        ({"max_retries": -1}, r"max_retries = -1 is out of range: allowed an integer >= 0"),
        ({"address": " "}, r"address = '' is not valid"),
    ],
)
def test_bad_backend(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Backend(**kwargs)


def test_resume_needs_a_results_file() -> None:
    with pytest.raises(ValueError, match=r"resume needs a results file \(--results\)"):
        run_sweep(small_map(), resume=True, progress=False)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["map", "--workers", "0"], r"drill-gym map: error: argument --workers: 0 is out of range: allowed \[1, 4096\]"),
        (["map", "--task-size", "0"], r"argument --task-size: 0 is out of range"),
        (["map", "--max-retries", "-1"], r"argument --max-retries: -1 is out of range"),
        (["map", "--controllers", "pid", "--workers", "2"], r"argument --controllers: unknown controller 'pid'"),
        (["map", "--wob-n", "0", "--workers", "2"], r"argument --wob-n: 0 is out of range"),
        (["compare", "--workers", "0"], r"drill-gym compare: error: argument --workers: 0 is out of range"),
        (["compare", "--controllers", "nope", "--ray"], r"argument --controllers: unknown controller 'nope'"),
        (["evaluate", "--workers", "-2"], r"drill-gym evaluate: error: argument --workers: -2 is out of range"),
        (["probability-map", "--draws", "-3"], r"drill-gym probability-map: error: argument --draws: -3 is out of range: allowed \[1, 100000\]"),
        (["probability-map", "--draws", "0"], r"argument --draws: 0 is out of range"),
        (["probability-map", "--controllers", "pid"], r"argument --controllers: unknown controller 'pid'"),
        (["probability-map", "--workers", "0"], r"argument --workers: 0 is out of range"),
        (["probability-map", "--speed-min", "5", "--speed-max", "5"], r"--speed-min = --speed-max = 5.0: the range is empty"),
        (["probability-map", "--rows", "depth"], r"argument --rows: depth needs the distributed string: add --env DrillStringField-v0"),
        (["probability-map", "--depth", "2000"], r"argument --depth: is for the distributed string"),
        (["probability-map", "--parameters", "field_2500m"], r"argument --parameters: 'field_2500m' is not a preset of DrillString-v0"),
        (["probability-map", "--delta-min", "0.5", "--delta-max", "0.1"], r"argument --delta-max: 0.1 is below --delta-min = 0.5"),
        (["probability-map", "--duration-s", "10", "--window-s", "20"], r"argument --window-s: 20 is out of range: allowed \(0, --duration-s = 10\] s"),
        (["probability-map", "--duration", "10.05", "--window", "5"], r"argument --duration-s: 10.05 is not a multiple of 0.1 s"),
        (["probability-map", "--env", "CartPole-v1"], r"argument --env: invalid choice: 'CartPole-v1'"),
    ],
)  # fmt: skip
def test_bad_sweep_spec_is_one_line_and_exit_code_2(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("--help)\n"), err
    assert re.search(message, err), err
    assert not (tmp_path / "out").exists()  # nothing started


def test_results_of_the_same_settings_on_the_command_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A second run of the same settings into one database is refused (one line naming
    --resume and --overwrite); other settings share the file."""
    base = ["map", "--wob-n", "2", "--speed-n", "2", "--duration-s", "2", "--window-s", "1"]
    base += ["--no-plots", "--no-progress", "--out", str(tmp_path)]
    results = ["--results", str(tmp_path / "r.sqlite")]
    assert cli_main([*base, *results]) == 0
    capsys.readouterr()
    assert cli_main([*base, *results]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "already holds 2 results of these settings" in err, err
    assert "--resume" in err and "--overwrite" in err
    assert cli_main([*base, "--seed", "3", "--resume", *results]) == 0
    assert "0 tasks run" not in capsys.readouterr().out
    assert cli_main([*base, *results, "--resume", "--overwrite"]) == 2
    assert "--resume and --overwrite exclude each other" in capsys.readouterr().err
    assert cli_main([*base, *results, "--overwrite"]) == 0
    assert len(rows_of(tmp_path / "r.sqlite")) == 4  # two maps of two rows


def test_map_command_resumes_to_the_same_csv(tmp_path: Path) -> None:
    base = ["map", "--controllers", "soft_speed", "--wob-n", "3", "--speed-n", "2"]
    base += ["--duration-s", "2", "--window-s", "1", "--noise", "0.1"]
    base += ["--no-plots", "--no-progress"]
    assert cli_main([*base, "--out", str(tmp_path / "plain")]) == 0
    path = tmp_path / "swept" / "stick_slip_map.sqlite"
    assert cli_main([*base, "--out", str(tmp_path / "swept"), "--task-size", "2", "--resume"]) == 0
    assert drop_rows(path, "task != ?", "soft_speed/rows0-0") == 2  # the first task only
    assert cli_main([*base, "--out", str(tmp_path / "swept"), "--resume"]) == 0
    name = "stick_slip_map_soft_speed.csv"
    assert (tmp_path / "swept" / name).read_text() == (tmp_path / "plain" / name).read_text()


def test_bad_map_durations_fail_before_anything_runs() -> None:
    with pytest.raises(
        ValueError, match=r"window_s = 40.0 is out of range: allowed \(0, duration_s = 1\]"
    ):
        MapStudy(("stiff_pi",), WOBS, SPEEDS, duration_s=1.0)
    with pytest.raises(ValueError, match=r"duration_s = 1.25 is out of range"):
        MapStudy(("stiff_pi",), WOBS, SPEEDS, duration_s=1.25, window_s=1.0)


def test_a_sweep_on_ray_without_the_scale_extra_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without Ray installed (simulated: its import fails), --workers 2 says which extra."""
    import builtins

    real_import = builtins.__import__

    def no_ray(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "ray" or name.startswith("ray."):
            raise ModuleNotFoundError("No module named 'ray'", name="ray")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    argv = ["map", "--wob-n", "1", "--speed-n", "1", "--duration-s", "1", "--window-s", "1"]
    assert cli_main([*argv, "--workers", "2", "--no-progress", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err == (
        "drill-gym map: error: needs the package 'ray', which is not installed (the scale "
        "extra has Ray and Optuna: pip install -e '.[scale]')\n"
    )
    assert not tmp_path.exists() or not any(tmp_path.iterdir())  # nothing written


def test_ray_is_imported_only_when_a_sweep_runs_on_it() -> None:
    """The core, the controllers and the agents never import Ray; the studies import it only
    inside the functions that run on it."""
    import ast
    import subprocess
    import sys
    import tempfile

    root = Path(__file__).resolve().parents[1]
    for package in ("drill_env", "baselines", "agents"):
        for path in (root / package).rglob("*.py"):
            tree = ast.parse(path.read_text())
            names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
            names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
            assert not [n for n in names if n.split(".")[0] in ("ray", "optuna")], path
    code = (
        "import sys\n"
        "import experiments.cli, experiments.sweep, experiments.compare, experiments.evaluate\n"
        "import experiments.probability_map, experiments.sweep_train, experiments.stick_slip_map\n"
        "from experiments.stick_slip_map import main\n"
        "main(['--wob-n', '1', '--speed-n', '1', '--duration', '1', '--window', '1', '--no-plots',"
        " '--no-progress', '--out', sys.argv[1], '--resume'])\n"
        "print(sorted(m for m in ('ray', 'optuna') if m in sys.modules))\n"
    )
    with tempfile.TemporaryDirectory() as out:
        result = subprocess.run(
            [sys.executable, "-c", code, out], cwd=root, capture_output=True, text=True, check=True
        )
    assert result.stdout.strip().splitlines()[-1] == "[]"
