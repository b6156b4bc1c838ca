"""``drill-gym map``: the grid validation, the map's numbers against a plain env rollout, and
the command line (bad input, a tiny smoke run that writes CSV and PNG)."""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import ZeroAction, rollout
from experiments.cli import main as cli_main
from experiments.stick_slip_map import (
    CSV_COLUMNS,
    MapSpec,
    MapStudy,
    StickSlipMap,
    compute_map,
    grid_values,
    main,
    write_map_csv,
)
from experiments.sweep import run_sweep

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------------------------------ grid
def test_grid_values_are_evenly_spaced() -> None:
    np.testing.assert_allclose(
        grid_values("wob", 40e3, 200e3, 5, 1e6), [40e3, 80e3, 120e3, 160e3, 200e3]
    )
    np.testing.assert_allclose(grid_values("speed", 3.0, 3.0, 1, 100.0), [3.0])


@pytest.mark.parametrize(
    ("low", "high", "count", "message"),
    [
        (100.0, 50.0, 3, r"--speed-min = 100.0 and --speed-max = 50.0: the range is inverted"),
        (5.0, 5.0, 4, r"--speed-min = --speed-max = 5.0: the range is empty"),
        (0.0, 5.0, 4, r"--speed-min = 0.0 is out of range: allowed \(0, 100\]"),
        (-1.0, 5.0, 4, r"--speed-min = -1.0 is out of range"),
        (1.0, 500.0, 4, r"--speed-max = 500.0 is out of range"),
        (1.0, 5.0, 0, r"--speed-n = 0 is out of range: allowed an integer >= 1"),
        (1.0, float("nan"), 2, r"--speed-max = nan is out of range"),
    ],
)
def test_grid_values_reject_bad_ranges(low: float, high: float, count: int, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        grid_values("speed", low, high, count, 100.0)


# ------------------------------------------------------------------------------ compute_map
@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"controller": "pid"}, r"unknown controller 'pid': valid names are .*stiff_pi"),
        ({"wob_n": [0.0, 1e5]}, r"wob_n = \[0.0, 100000.0\] is out of range"),
        ({"reference_speed_rad_s": []}, r"reference_speed_rad_s must be a non-empty"),
        ({"duration_s": -5.0}, r"duration_s = -5.0 is out of range"),
        ({"duration_s": 1.25}, r"duration_s = 1.25 is out of range: allowed a multiple of 0.1 s"),
        ({"window_s": 20.0}, r"window_s = 20.0 is out of range: allowed \(0, duration_s = 10\]"),
        ({"noise_std_rad_s": -0.1}, r"noise_std_rad_s = -0.1 is out of range"),
        ({"parameters": "nope"}, r"parameters = 'nope' is not a known preset"),
    ],
)
def test_compute_map_rejects_bad_arguments(kwargs: dict[str, Any], message: str) -> None:
    args: dict[str, Any] = {
        "controller": "stiff_pi",
        "wob_n": [1e5],
        "reference_speed_rad_s": [5.0],
        "duration_s": 10.0,
        "window_s": 5.0,
        "progress": False,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        compute_map(**args)


@pytest.mark.parametrize("controller", ["stiff_pi", "proposed"])
def test_map_cell_matches_a_plain_env_rollout(controller: str) -> None:
    """Each cell is the env's run from rest; severity and stuck fraction are computed over the
    window by the formulas of docs/specification.md sections 4 and 14 (here over a window that starts inside a 1 s chunk)."""
    wob, speed = 150e3, 3.0
    result = compute_map(
        controller, [80e3, wob], [speed, 9.0], duration_s=12.0, window_s=7.5, progress=False
    )
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller=controller,
        wob_n=wob,
        reference_speed_rad_s=speed,
        noise_std_rad_s=0.0,
        episode_s=12.0,
        control_dt_s=0.5,
        max_episode_steps=24,
    )
    trace = rollout(env, ZeroAction(), seed=0)
    bit = trace.bit_speed_rad_s[-7500:]
    severity = (bit.max() - bit.min()) / (2 * bit.mean()) if bit.mean() > 0 else 1.0
    assert result.severity[1, 0] == pytest.approx(severity, rel=1e-12)
    assert result.stuck_fraction[1, 0] == pytest.approx(trace.bit_stuck[-7500:].mean(), rel=1e-12)
    assert result.window_s == 7.5 and result.duration_s == 12.0


def test_map_shapes_rows_and_csv(tmp_path: Path) -> None:
    result = compute_map(
        "soft_speed", [60e3, 120e3, 180e3], [4.0, 12.0], duration_s=3.0, window_s=1.0,
        progress=False,
    )  # fmt: skip
    assert isinstance(result, StickSlipMap)
    assert result.severity.shape == result.stuck_fraction.shape == (3, 2)
    assert result.cells == 6 and not result.diverged.any()
    rows = result.rows()
    assert [r[:2] for r in rows[:3]] == [(60e3, 4.0), (60e3, 12.0), (120e3, 4.0)]  # WOB-major
    path = write_map_csv(result, tmp_path / "sub" / "map.csv")
    with path.open() as f:
        table = list(csv.reader(f))
    assert tuple(table[0]) == CSV_COLUMNS
    assert len(table) == 7
    np.testing.assert_allclose([float(r[2]) for r in table[1:]], result.severity.ravel(), rtol=1e-5)


def test_map_is_deterministic_without_noise_and_seeded_with_noise() -> None:
    args = ("stiff_pi", [150e3], [3.0, 6.0])
    kw: dict[str, Any] = {"duration_s": 5.0, "window_s": 2.0, "progress": False}
    a = compute_map(*args, **kw)
    b = compute_map(*args, seed=7, **kw)
    np.testing.assert_array_equal(a.severity, b.severity)
    c = compute_map(*args, noise_std_rad_s=0.1, seed=1, **kw)
    d = compute_map(*args, noise_std_rad_s=0.1, seed=1, **kw)
    np.testing.assert_array_equal(c.severity, d.severity)


# ------------------------------------------------------------------------------ command line
@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--controller", "pid"], r"argument --controller: unknown controller 'pid': allowed csmc, .*z_torque"),
        (["--wob-min", "-1"], r"argument --wob-min: -1 is out of range: allowed \(0, 1e\+06\] N"),
        (["--wob-min", "0"], r"argument --wob-min: 0 is out of range"),
        (["--wob-min", "2e5", "--wob-max", "1e5"], r"--wob-min = 200000.0 and --wob-max = 100000.0: the range is inverted"),
        (["--wob-min", "5e4", "--wob-max", "5e4"], r"the range is empty"),
        (["--wob-n", "0"], r"argument --wob-n: 0 is out of range: allowed \[1, 10000\]"),
        (["--speed-min", "0"], r"argument --speed-min: 0 is out of range: allowed \(0, 100\] rad/s"),
        (["--speed-max", "-3"], r"argument --speed-max: -3 is out of range"),
        (["--speed-min", "9", "--speed-max", "2"], r"--speed-min = 9.0 and --speed-max = 2.0: the range is inverted"),
        (["--speed-n", "-2"], r"argument --speed-n: -2 is out of range"),
        (["--duration-s", "0"], r"argument --duration-s: 0 is out of range: allowed \(0, 10000\] s"),
        (["--duration", "0"], r"argument --duration: 0 is out of range: allowed \(0, 10000\] s"),
        (["--duration-s", "10", "--window-s", "20"], r"argument --window-s: 20 is out of range: allowed \(0, --duration-s = 10\] s"),
        (["--duration-s", "10.05", "--window-s", "5"], r"argument --duration-s: 10.05 is not a multiple of 0.1 s"),
        (["--depths", "1500"], r"argument --depths: is an option of the field string"),
        (["--parameters", "field_2500m"], r"argument --parameters: field_2500m is not a preset of DrillString-v0: allowed navarro_lopez2007, zribi2024"),
        (["--noise", "-1"], r"argument --noise: -1 is out of range: allowed \[0, 10\] rad/s"),
        (["--wob-n", "two"], r"argument --wob-n: 'two' is not an integer"),
        (["--parameters", "nope"], r"argument --parameters: invalid choice: 'nope'"),
    ],
)  # fmt: skip
def test_cli_bad_input_names_the_argument(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("drill-gym map: error: ") and err.count("\n") == 1, err
    assert err.endswith(" (see drill-gym map --help)\n") and "usage:" not in err
    assert re.search(message, err), err


def test_cli_smoke_run_writes_csv_and_png(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "map",
        "--controllers", "stiff_pi", "z_torque",
        "--wob-min", "60000", "--wob-max", "180000", "--wob-n", "2",
        "--speed-min", "3", "--speed-max", "12", "--speed-n", "2",
        "--duration-s", "2", "--window-s", "1",
        "--out", str(tmp_path),
        "--no-progress",
    ]  # fmt: skip
    assert cli_main(argv) == 0
    out = capsys.readouterr().out
    assert "stiff_pi: 4 cells x 2 s" in out and "simulated s per wall s" in out
    for name in ("stiff_pi", "z_torque"):
        with (tmp_path / f"stick_slip_map_{name}.csv").open() as f:
            table = list(csv.reader(f))
        assert tuple(table[0]) == CSV_COLUMNS and len(table) == 5
        assert {float(r[0]) for r in table[1:]} == {60e3, 180e3}
        assert (tmp_path / f"stick_slip_map_{name}.png").read_bytes()[:8] == PNG_MAGIC
    assert (tmp_path / "stick_slip_maps.png").read_bytes()[:8] == PNG_MAGIC


def test_cli_single_cell_grid(tmp_path: Path) -> None:
    argv = [
        "--wob-min", "1e5", "--wob-max", "1e5", "--wob-n", "1",
        "--speed-min", "5", "--speed-max", "5", "--speed-n", "1",
        "--duration-s", "1", "--window-s", "0.5", "--out", str(tmp_path), "--no-progress",
    ]  # fmt: skip
    assert main(argv) == 0
    assert (tmp_path / "stick_slip_map_stiff_pi.png").exists()
    assert not (tmp_path / "stick_slip_maps.png").exists()


def test_cli_no_plots_writes_only_csv(tmp_path: Path) -> None:
    argv = [
        "--controller", "soft_speed", "csmc", "--wob-n", "2", "--speed-n", "2",
        "--duration-s", "1", "--window-s", "0.5", "--out", str(tmp_path), "--no-progress", "--no-plots",
    ]  # fmt: skip
    assert main(argv) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "stick_slip_map_csmc.csv",
        "stick_slip_map_soft_speed.csv",
    ]


# ---------------------------------------------------------------------------- learned models
class _ZeroResidual:
    """A policy that adds nothing to its base controller: its map is the base's map."""

    name = "zero_residual"
    env_kwargs = {"base_controller": "proposed", "control_dt_s": 0.1, "residual_scale_nm": 1e4}

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:  # fmt: skip
        return np.zeros((len(observation), 1), dtype=np.float32), state


def test_a_zero_residual_policy_maps_like_its_base_controller() -> None:
    grid = ([60e3, 170e3], [2.0, 10.0])
    base = compute_map("proposed", *grid, duration_s=6.0, window_s=3.0, progress=False)
    learned = compute_map(_ZeroResidual(), *grid, duration_s=6.0, window_s=3.0, progress=False)
    assert learned.controller == "zero_residual"
    # the same trajectories, summed over the window in other chunks (0.1 s instead of 1 s)
    np.testing.assert_allclose(learned.severity, base.severity, rtol=1e-12)
    np.testing.assert_array_equal(learned.stuck_fraction, base.stuck_fraction)


def test_the_shipped_agent_maps_as_its_own_env_rollout() -> None:
    """A map cell of the shipped agent is its env run from rest with the policy's action at
    every decision (``rollout`` of a plain env with the policy's keywords)."""
    from agents import load_default_policy

    policy = load_default_policy()
    assert policy is not None
    wob, speed = 160e3, 4.0
    result = compute_map(policy, [wob], [speed], duration_s=8.0, window_s=5.0, progress=False)
    env = gym.make(
        "DrillString-v0", randomize=False, wob_n=wob, reference_speed_rad_s=speed,
        noise_std_rad_s=0.0, episode_s=8.0, max_episode_steps=80, **policy.env_kwargs,
    )  # fmt: skip
    trace = rollout(env, policy, seed=0)
    bit = trace.bit_speed_rad_s[-5000:]
    assert trace.bit_speed_rad_s.size == 8000
    severity = (bit.max() - bit.min()) / (2 * bit.mean()) if bit.mean() > 0 else 1.0
    assert result.severity[0, 0] == pytest.approx(severity, rel=1e-12)
    assert result.stuck_fraction[0, 0] == pytest.approx(trace.bit_stuck[-5000:].mean(), rel=1e-12)


def test_a_model_of_another_env_or_period_is_refused() -> None:
    field = _ZeroResidual()
    field.env_kwargs = {**field.env_kwargs, "env_id": "DrillStringField-v0"}
    with pytest.raises(ValueError, match="trained on DrillStringField-v0: map it with env_id"):
        compute_map(field, [1e5], [5.0], duration_s=2.0, window_s=1.0, progress=False)
    with pytest.raises(ValueError, match="was trained on 'state' ones: map it at a level that"):
        compute_map(
            _ZeroResidual(), [1e5], [5.0], duration_s=2.0, window_s=1.0, progress=False,
            realism="surface_only",
        )  # fmt: skip
    slow = _ZeroResidual()
    slow.env_kwargs = {**slow.env_kwargs, "control_dt_s": 0.5}
    with pytest.raises(ValueError, match="multiple of the policy's decision period 0.5 s"):
        compute_map(slow, [1e5], [5.0], duration_s=2.2, window_s=1.0, progress=False)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--models", "no/such/model"], r"argument --models: no/such/model: "),
    ],
)  # fmt: skip
def test_cli_bad_models_name_the_argument(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("drill-gym map: error: ") and err.count("\n") == 1, err
    assert re.search(message, err), err


def test_a_model_map_on_the_runner_is_its_compute_map(tmp_path: Path) -> None:
    """A model's map is one task over the whole grid: the cells of compute_map, bit for bit,
    written to the results database and read back on resume; the model is part of the
    settings."""
    grid = ((60e3, 170e3), (2.0, 10.0))
    study = MapStudy(("proposed",), *grid, duration_s=3.0, window_s=1.0, models=(_ZeroResidual(),))
    assert [run[0] for run in study.runs()] == ["proposed", "zero_residual"]
    assert [t.key for t in study.tasks(study.items())] == [
        "proposed/rows0-1",
        "zero_residual/rows0-1",
    ]
    path = tmp_path / "map.sqlite"
    maps = study.maps(run_sweep(study, results_path=path, progress=False))
    plain = compute_map(_ZeroResidual(), *grid, duration_s=3.0, window_s=1.0, progress=False)
    assert maps[1].severity.tobytes() == plain.severity.tobytes()
    assert maps[1].stuck_fraction.tobytes() == plain.stuck_fraction.tobytes()
    resumed = run_sweep(study, results_path=path, resume=True, progress=False)
    assert resumed.loaded == 4 and not resumed.ran
    without = MapStudy(("proposed",), *grid, duration_s=3.0, window_s=1.0)
    assert "models" not in without.spec() and "models" in study.spec()
    with pytest.raises(ValueError, match="each model needs a name of its own"):
        MapStudy(("proposed",), *grid, models=(_ZeroResidual(), _ZeroResidual()))


class _FieldModel(_ZeroResidual):
    """A model of the field string: its env is an attribute, not one of its env keywords."""

    name = "field_model"
    env_id = "DrillStringField-v0"
    env_kwargs = {"base_controller": "stiff_pi", "control_dt_s": 0.1, "observation": "surface"}


def test_a_model_is_mapped_on_the_env_it_was_trained_on() -> None:
    cells: dict[str, Any] = {"duration_s": 2.0, "window_s": 1.0}
    field = MapStudy((), (1e5,), (5.0,), env_id="DrillStringField-v0", depths_m=(1500.0,),
                     models=(_FieldModel(),), **cells)  # fmt: skip
    assert field.runs() == [("field_model", "surface", 1500.0)]
    with pytest.raises(ValueError, match="was trained on DrillStringField-v0"):
        MapStudy((), (1e5,), (5.0,), models=(_FieldModel(),), **cells)


def test_the_command_settings_make_the_study() -> None:
    """``MapSpec`` (the options of ``drill-gym map``) resolves each env's defaults."""
    paper = MapSpec(wob_n=2, speed_n=3, duration_s=2.0, window_s=1.0).study()
    assert paper.controllers == ("stiff_pi",) and paper.preset == "zribi2024"
    assert paper.wob_n == (40e3, 200e3) and paper.reference_speed_rad_s == (1.0, 8.5, 16.0)
    assert paper.items() == ["stiff_pi/row0", "stiff_pi/row1"]
    field = MapSpec(env_id="DrillStringField-v0", controllers=("csmc",), wob_n=1).study()
    assert field.window_s == 50.0 and field.preset == "field_2500m"
    assert field.runs() == [("csmc", "state", 2500.0)]  # the preset's depth, state only
    assert MapSpec(realism="field").study().keywords == {"realism": "field"}
    assert MapSpec(realism="ideal").study().keywords == {}  # the env's own level
