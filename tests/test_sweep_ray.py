"""The sweep runner on a local Ray cluster (the scale extra): the same numbers as the serial
path, bit for bit, for a map (of either env), a held-out evaluation and a comparison table;
a worker that dies mid-sweep has its task retried, with nothing lost and nothing counted
twice; the driver shares its results database with a sweep in another process.

One local cluster of two CPUs serves the whole module (the runner joins a running session).
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

ray = pytest.importorskip("ray")

from agents import load_default_policy  # noqa: E402
from experiments import compare  # noqa: E402
from experiments.cli import main as cli_main  # noqa: E402
from experiments.compare import CompareStudy  # noqa: E402
from experiments.evaluate import (  # noqa: E402
    HELD_OUT,
    EvaluateStudy,  # noqa: E402
    evaluate,
)
from experiments.field import FIELD_ENV  # noqa: E402
from experiments.stick_slip_map import MapStudy, compute_map  # noqa: E402
from experiments.sweep import (  # noqa: E402
    Backend,
    Task,
    TaskResult,
    ray_session,
    read_results,
    run_sweep,
)

RAY = Backend(workers=2)


@pytest.fixture(scope="module", autouse=True)
def cluster() -> Iterator[Any]:
    """A local Ray cluster of 2 CPUs for the module; this module's functions travel to the
    workers by value (the workers cannot import the tests)."""
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    with ray_session(RAY) as session:
        yield session
    assert not ray.is_initialized()


def test_map_on_ray_equals_the_serial_map_bit_for_bit() -> None:
    wobs, speeds = [50e3, 90e3, 130e3, 170e3], [2.0, 6.0, 10.0]
    kw: dict[str, Any] = {"duration_s": 6.0, "window_s": 3.0, "noise_std_rad_s": 0.1, "seed": 11}
    serial = compute_map("stiff_pi", wobs, speeds, progress=False, **kw)
    study = MapStudy(("stiff_pi",), tuple(wobs), tuple(speeds), task_cells=3, **kw)
    outcome = run_sweep(study, RAY, progress=False)
    assert len(outcome.ran) == 4  # one row per task, scheduled on two workers
    swept = study.maps(outcome)[0]
    assert swept.severity.tobytes() == serial.severity.tobytes()
    assert swept.stuck_fraction.tobytes() == serial.stuck_fraction.tobytes()


def test_ray_driver_and_another_process_write_one_database_at_once(tmp_path: Path) -> None:
    """While a map runs on Ray (its driver writing each finished task), a serial sweep in
    another process writes its own rows to the same file: both complete, each reads back
    exactly its rows."""
    from test_sweep import EchoStudy, sweep_process

    path = tmp_path / "shared.sqlite"
    other = sweep_process("fresh", path, 60, 0.02)
    wobs, speeds = (50e3, 90e3, 130e3, 170e3), (2.0, 6.0)
    kw: dict[str, Any] = {"duration_s": 4.0, "window_s": 2.0, "noise_std_rad_s": 0.1, "seed": 3}
    study = MapStudy(("stiff_pi",), wobs, speeds, task_cells=2, **kw)
    outcome = run_sweep(study, RAY, path, progress=False)
    out, err = other.communicate(timeout=120)
    assert other.returncode == 0, err
    assert out.split() == ["60", "0"]
    assert read_results(path, study) == outcome.records
    assert read_results(path, EchoStudy(60)) == run_sweep(EchoStudy(60), progress=False).records
    serial = compute_map("stiff_pi", list(wobs), list(speeds), progress=False, **kw)
    assert study.maps(outcome)[0].severity.tobytes() == serial.severity.tobytes()


def test_field_map_on_ray_equals_the_serial_map_bit_for_bit() -> None:
    """A map of the field string (both observation modes of a speed loop at one depth) on
    two workers: the cells equal compute_map's bit for bit, with the same observation mode,
    depth and file name."""
    wobs, speeds = [60e3, 120e3, 180e3], [6.0, 12.0]
    kw: dict[str, Any] = {"duration_s": 2.0, "window_s": 1.0, "noise_std_rad_s": 0.05, "seed": 7}
    study = MapStudy(
        ("soft_speed",), tuple(wobs), tuple(speeds), task_cells=2, env_id=FIELD_ENV,
        depths_m=(1500.0,), **kw,
    )  # fmt: skip
    outcome = run_sweep(study, RAY, progress=False)
    assert len(outcome.ran) == 6  # one row per task, two maps
    for swept, (controller, observation, depth) in zip(
        study.maps(outcome), study.runs(), strict=True
    ):
        serial = compute_map(
            controller, wobs, speeds, progress=False, env_id=FIELD_ENV, observation=observation,
            measured_depth_m=depth, **kw,
        )  # fmt: skip
        assert swept.severity.tobytes() == serial.severity.tobytes()
        assert swept.stuck_fraction.tobytes() == serial.stuck_fraction.tobytes()
        assert (swept.observation, swept.measured_depth_m, swept.file_stem()) == (
            serial.observation, serial.measured_depth_m, serial.file_stem(),
        )  # fmt: skip


def test_heldout_evaluation_on_ray_equals_the_serial_one() -> None:
    agent = load_default_policy()
    assert agent is not None
    scenarios = [s for s in HELD_OUT if s.id in ("h01", "h08")]
    rows, _ = evaluate([agent], ["proposed"], scenarios)
    study = EvaluateStudy((agent,), ("proposed",), tuple(scenarios), task_scenarios=1)
    outcome = run_sweep(study, RAY, progress=False)
    assert sorted(outcome.ran) == ["h01", "h08"]  # one task per scenario
    swept, _ = study.results(outcome)
    assert [(r["scenario"], r["controller"]) for r in swept] == [
        ("h01", "proposed"), ("h01", agent.name), ("h08", "proposed"), ("h08", agent.name),
    ]  # fmt: skip
    assert swept == rows  # every float bit for bit (== on floats), every flag and None


def test_compare_table_on_ray_equals_the_serial_one() -> None:
    args = (["csmc", "proposed"], ["nominal", "condition3"], [0.1])
    rows, _ = compare.run_comparison(
        *args, duration_s=3.0, seed=4, keep_traces=False, progress=False
    )
    study = CompareStudy(*map(tuple, args), duration_s=3.0, seed=4)  # type: ignore[arg-type]
    swept, _ = study.results(run_sweep(study, RAY, progress=False))
    assert swept == rows
    assert compare.markdown_table(swept) == compare.markdown_table(rows)


def test_map_command_with_workers_writes_the_serial_csv(tmp_path: Path) -> None:
    base = ["map", "--controllers", "z_torque", "--wob-n", "3", "--speed-n", "2"]
    base += ["--duration-s", "2", "--window-s", "1", "--noise", "0.1"]
    base += ["--no-plots", "--no-progress"]
    assert cli_main([*base, "--out", str(tmp_path / "serial")]) == 0
    assert (
        cli_main([*base, "--out", str(tmp_path / "ray"), "--workers", "2", "--task-size", "2"]) == 0
    )
    name = "stick_slip_map_z_torque.csv"
    assert (tmp_path / "ray" / name).read_text() == (tmp_path / "serial" / name).read_text()
    assert (tmp_path / "ray" / "stick_slip_map.sqlite").is_file()  # the results, as they came


def die_once(marker: str, function: Any, **kwargs: Any) -> TaskResult:
    """Kill this worker process the first time (the marker file records it), then run."""
    path = Path(marker)
    if not path.exists():
        path.write_text(str(os.getpid()))
        os._exit(1)
    with Path(marker + ".runs").open("a") as f:
        f.write(f"{kwargs['rows']}\n")
    return function(**kwargs)  # type: ignore[no-any-return]


def counted(marker: str, function: Any, **kwargs: Any) -> TaskResult:
    with Path(marker + ".runs").open("a") as f:
        f.write(f"{kwargs['rows']}\n")
    return function(**kwargs)  # type: ignore[no-any-return]


def test_a_worker_that_dies_has_its_task_retried(tmp_path: Path) -> None:
    """One task kills its worker process (os._exit) the first time it runs; Ray runs it
    again in a new worker, and the sweep ends with every cell exactly once."""
    wobs, speeds = (60e3, 100e3, 140e3, 180e3), (3.0, 8.0)
    kw: dict[str, Any] = {"duration_s": 3.0, "window_s": 1.0, "seed": 2}
    study = MapStudy(("soft_speed",), wobs, speeds, task_cells=2, **kw)
    marker = str(tmp_path / "died")
    tasks = study.tasks(study.items())
    wrapped = [
        Task(t.key, die_once if k == 1 else counted, {"marker": marker, "function": t.function, **t.kwargs}, t.items)
        for k, t in enumerate(tasks)
    ]  # fmt: skip

    class Faulty:
        name = study.name
        spec = study.spec
        items = study.items
        record_schema = study.record_schema

        def tasks(self, missing: Any) -> list[Task]:
            return wrapped

    path = tmp_path / "map.sqlite"
    outcome = run_sweep(Faulty(), Backend(workers=2, max_retries=2), path, progress=False)
    assert Path(marker).read_text().isdigit()  # the worker did die once
    runs = sorted(Path(marker + ".runs").read_text().split("\n")[:-1])
    assert runs == ["[0]", "[1]", "[2]", "[3]"]  # each task completed exactly once
    assert sorted(outcome.ran) == sorted(t.key for t in tasks)
    with contextlib.closing(sqlite3.connect(path)) as db:
        items = [item for (item,) in db.execute("SELECT item FROM results")]
    assert sorted(items) == sorted(study.items())  # nothing lost, nothing twice
    assert read_results(path, study) == outcome.records
    serial = compute_map("soft_speed", list(wobs), list(speeds), progress=False, **kw)
    np.testing.assert_array_equal(study.maps(outcome)[0].severity, serial.severity)


def test_probability_map_on_ray_equals_the_serial_one() -> None:
    from experiments.probability_map import ProbabilityStudy

    study = ProbabilityStudy(
        env_id="DrillString-v0", controllers=("stiff_pi",), row_axis="wob",
        rows=(70e3, 150e3), reference_speed_rad_s=(3.0, 9.0), draws=3,
        duration_s=4.0, window_s=2.0, noise_std_rad_s=0.1, seed=3, task_cells=1,
    )  # fmt: skip
    serial = study.maps(run_sweep(study, progress=False))[0]
    swept = study.maps(run_sweep(study, RAY, progress=False))[0]
    assert swept.severity.tobytes() == serial.severity.tobytes()
    assert swept.stuck_fraction.tobytes() == serial.stuck_fraction.tobytes()
    np.testing.assert_array_equal(swept.probability, serial.probability)


def test_compare_and_evaluate_commands_with_workers_write_the_serial_files(tmp_path: Path) -> None:
    """Through the command line: the same CSV as the serial run, and the figures drawn from
    the traces that came back from the workers."""
    base = ["compare", "--controllers", "csmc", "proposed", "--conditions", "nominal"]
    base += ["--noise", "0.1", "--duration-s", "2", "--no-agent", "--no-progress"]
    assert cli_main([*base, "--no-plots", "--out", str(tmp_path / "c1")]) == 0
    assert cli_main([*base, "--workers", "2", "--out", str(tmp_path / "c2")]) == 0
    assert (tmp_path / "c2" / "compare.csv").read_text() == (
        tmp_path / "c1" / "compare.csv"
    ).read_text()
    assert (tmp_path / "c2" / "figures" / "speed_torque_proposed.png").is_file()
    base = ["evaluate", "--controllers", "proposed", "--scenarios", "h01", "h14", "--no-plots"]
    base += ["--no-progress"]
    assert cli_main([*base, "--out", str(tmp_path / "e1")]) == 0
    assert cli_main([*base, "--workers", "2", "--out", str(tmp_path / "e2")]) == 0
    assert (tmp_path / "e2" / "heldout.csv").read_text() == (
        tmp_path / "e1" / "heldout.csv"
    ).read_text()
    with contextlib.closing(sqlite3.connect(tmp_path / "e2" / "heldout.sqlite")) as db:
        assert db.execute("SELECT count(*) FROM results").fetchone() == (2,)  # 2 scenarios
