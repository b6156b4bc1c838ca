"""Sizes, counts and physical values from the command line and from the files it reads are
range-checked before anything is allocated or created: a log's sample period, ``calibrate
--fix``, the parameters of a ``plant.json``, the counts of ``train`` and ``sweep-train``; a
diverged replay and a sweep whose every trial failed are not successes; ``train --resume``
keeps the run's recorded settings; printed folder names are printable."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agents.config import (
    MAX_TORCH_THREADS,
    MAX_VALIDATION_EPISODES,
    TrainConfig,
    resumed_config,
)
from drill_env.calibrated_plant import (
    PARAMETER_RANGES,
    CalibratedPlant,
    FittedParameter,
    check_parameter,
    parameter_unit,
    plant_from_json,
)
from drill_env.measured_log import MIN_SAMPLE_PERIOD_S, MeasuredLog, write_log_csv
from experiments import sweep_train
from experiments.cli import main as cli_main
from experiments.train import parse_config

PLANT = {"bit_inertia": 0.02, "stiffness": 1.5, "damping": 0.01, "static_friction": 2.5,
         "sliding_friction": 1.5, "stribeck_rate": 0.5}  # fmt: skip
"""A lab-sized karnopp plant (kg m^2, N m/rad, N m s/rad, N m, N m, s/rad)."""


def _error(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    """Run ``drill-gym ARGV`` in-process; the one error line it printed (exit code 2)."""
    code = cli_main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"drill-gym {argv[0]}: error: "), err
    return err


def _log(path: Path, period_s: float, n: int = 200) -> Path:
    t = np.arange(n, dtype=np.float64) * period_s
    speed = 1.0 + 0.1 * np.sin(np.arange(n) / 7.0)
    columns = {"top_speed_rad_s": np.ones(n), "bit_speed_rad_s": speed,
               "bit_torque_nm": np.ones(n), "wob_n": np.full(n, 1000.0)}  # fmt: skip
    if period_s >= MIN_SAMPLE_PERIOD_S:
        return write_log_csv(MeasuredLog(t, columns), path)
    names = ["time_s", *columns]
    table = np.column_stack([t, *columns.values()])
    np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return path


def _plant(path: Path, **values: float) -> Path:
    CalibratedPlant(
        "karnopp",
        False,
        {n: FittedParameter(v, parameter_unit(n, False)) for n, v in PLANT.items()},
    ).save(path)
    data = json.loads(path.read_text())
    for name, value in values.items():
        data["parameters"][name]["value"] = value
    path.write_text(json.dumps(data))
    return path


# ------------------------------------------------------------------------- calibrate, replay
def test_a_log_sampled_faster_than_allowed_is_refused_when_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(ValueError, match=r"column 'time_s': the median sample period 1e-09 s"):
        MeasuredLog(np.arange(10, dtype=np.float64) * 1e-9, {"top_speed_rad_s": np.ones(10)})
    log = _log(tmp_path / "ns.csv", 1e-9)
    out = tmp_path / "out"
    err = _error(capsys, ["calibrate", str(log), "--window", "0:1.5e-7", "--out", str(out)])
    assert "column 'time_s'" in err and f"allowed at least {MIN_SAMPLE_PERIOD_S:g} s" in err
    assert not out.exists()
    # The bound itself is a valid period.
    MeasuredLog(
        np.arange(10, dtype=np.float64) * MIN_SAMPLE_PERIOD_S, {"top_speed_rad_s": np.ones(10)}
    )


@pytest.mark.parametrize(
    ("fix", "message"),
    [
        ("bit_inertia=0", "bit_inertia = 0.0 is out of range: allowed [1e-09, 1e+09] kg m^2"),
        ("stiffness=0", "stiffness = 0.0 is out of range: allowed [1e-09, 1e+12] N m/rad"),
        ("stiffness=1e300", "stiffness = 1e+300 is out of range"),
        ("memory_time=0", "memory_time = 0.0 is out of range"),
        ("damping=-1", "damping = -1.0 is out of range: allowed [0, 1e+12] N m s/rad"),
    ],
)
def test_fix_values_are_checked_against_the_parameter_ranges(
    fix: str, message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = _log(tmp_path / "rig.csv", 1e-3)
    out = tmp_path / "out"
    err = _error(capsys, ["calibrate", str(log), "--window", "0:0.19", "--out", str(out),
                          "--fix", fix])  # fmt: skip
    assert "argument --fix: " + message in err
    assert not out.exists()


def test_the_parameter_ranges_have_one_home() -> None:
    for name, (low, high) in PARAMETER_RANGES.items():
        assert check_parameter(name, low) == low and check_parameter(name, high) == high
        with pytest.raises(ValueError, match=rf"^{name} = .* is out of range"):
            check_parameter(name, high * 10)
    with pytest.raises(ValueError, match=r"parameters.stiffness.value = 0 is out of range"):
        CalibratedPlant(
            "karnopp", False,
            {n: FittedParameter(0 if n == "stiffness" else v, parameter_unit(n, False))
             for n, v in PLANT.items()},
        )  # fmt: skip


@pytest.mark.parametrize("stiffness", [1e300, 1e-300])
def test_a_plant_file_out_of_range_is_refused_with_its_key_path(
    stiffness: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plant = _plant(tmp_path / "plant.json", stiffness=stiffness)
    log = _log(tmp_path / "rig.csv", 1e-3)
    out = tmp_path / "out"
    err = _error(capsys, ["replay", str(plant), str(log), "--window", "0:0.19", "--out", str(out)])
    assert f"plant.json.parameters.stiffness.value = {stiffness:g} is out of range" in err
    assert "allowed [1e-09, 1e+12] N m/rad" in err
    assert not out.exists()


def test_a_missing_parameter_is_named_by_its_key_path(tmp_path: Path) -> None:
    data = json.loads(_plant(tmp_path / "plant.json").read_text())
    del data["parameters"]["stiffness"]["value"]
    with pytest.raises(ValueError, match=r"^plant.parameters.stiffness.value: missing"):
        plant_from_json(data)
    del data["parameters"]["stiffness"]
    with pytest.raises(
        ValueError,
        match=r"^plant.parameters.stiffness: missing \(family 'karnopp': missing \['stiffness'\]",
    ):
        plant_from_json(data)


def test_a_diverged_replay_is_an_error_not_a_table_of_nan(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Within the ranges, but far too stiff and light for a 1 ms sample period.
    plant = _plant(tmp_path / "plant.json", stiffness=1e12, bit_inertia=1e-9)
    log = _log(tmp_path / "rig.csv", 1e-3)
    out = tmp_path / "out"
    err = _error(capsys, ["replay", str(plant), str(log), "--window", "0:0.19", "--out", str(out)])
    assert "diverged: bit_speed_rad_s is not finite from t = " in err
    assert not out.exists()


def test_a_printed_output_folder_has_no_raw_control_characters(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plant = _plant(tmp_path / "plant.json")
    log = _log(tmp_path / "rig.csv", 1e-3)
    out = tmp_path / "o\x1b[31mX"
    code = cli_main(["replay", str(plant), str(log), "--window", "0:0.19", "--out", str(out)])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "\x1b" not in printed.out and "o\\x1b[31mX" in printed.out


# ---------------------------------------------------------------------- train, sweep-train
@pytest.mark.parametrize(
    ("option", "value", "allowed"),
    [
        ("--validation-episodes", str(10**12), f"[1, {MAX_VALIDATION_EPISODES}]"),
        ("--torch-threads", "100000", f"[1, {MAX_TORCH_THREADS}]"),
        ("--torch-threads", "0", f"[1, {MAX_TORCH_THREADS}]"),
        ("--n-epochs", "100000", "[1, 1000]"),
    ],
)
def test_train_counts_are_bounded_before_anything_is_created(
    option: str, value: str, allowed: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    err = _error(capsys, ["train", option, value, "--out", str(run)])
    assert f"{option} = {value} is out of range: allowed an integer in {allowed}" in err
    assert not run.exists()
    assert max(256, os.cpu_count() or 1) <= MAX_TORCH_THREADS


def test_sweep_train_refuses_a_thread_count_before_anything_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "sweep"
    err = _error(capsys, ["sweep-train", "--set", "torch_threads=100000", "--out", str(out)])
    assert "--torch-threads = 100000 is out of range" in err
    assert not out.exists()


def _fake_sweep(errors: list[str | None]) -> Any:
    def run(spec: Any, out: Path, *args: Any, **kwargs: Any) -> dict[str, Any]:
        out.mkdir(parents=True, exist_ok=True)
        (out / "trials.md").write_text("| trial |\n")
        rows = [{"trial": f"t{i}", "error": e} for i, e in enumerate(errors)]
        return {"trials": rows, "best": None, "wall_time_s": 0.0}

    return run


@pytest.mark.parametrize(
    ("errors", "code", "line"),
    [
        (["ValueError: a", "ValueError: b"], 1, "all 2 trial(s) failed"),
        (["ValueError: a", None], 0, "1 of 2 trial(s) failed"),
        ([None, None], 0, None),
    ],
    ids=["all-failed", "one-failed", "none-failed"],
)
def test_sweep_train_exit_code_says_whether_any_trial_ran(
    errors: list[str | None],
    code: int,
    line: str | None,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setattr(sweep_train, "run_training_sweep", _fake_sweep(errors))
    out = tmp_path / "sweep"
    assert cli_main(["sweep-train", "--out", str(out), "--no-progress"]) == code
    err = capsys.readouterr().err
    if line is None:
        assert err == ""
    else:
        assert err.count("\n") == 1 and line in err
        assert "trials.csv" in err and "error.txt" in err and "ValueError: a" in err


# --------------------------------------------------------------------------- train --resume
def _run_folder(tmp_path: Path, **settings: Any) -> Path:
    """A run folder as drill-gym train leaves it: its config.json and one checkpoint."""
    run = tmp_path / "run"
    (run / "checkpoints" / "steps_64").mkdir(parents=True)
    (run / "checkpoints" / "steps_64" / "training.json").write_text("{}")
    config = TrainConfig(run_dir=str(run), **settings)
    (run / "config.json").write_text(config.to_json() + "\n")
    return run


def test_resume_takes_the_runs_recorded_settings(tmp_path: Path) -> None:
    run = _run_folder(tmp_path, gamma=0.9, num_envs=2, n_steps=32, net_arch=[8])
    config = parse_config(["--resume", "--out", str(run), "--total-timesteps", "640"])
    assert (config.gamma, config.num_envs, config.n_steps, config.net_arch) == (0.9, 2, 32, [8])
    assert config.total_timesteps == 640 and config.resume
    same = parse_config(["--resume", "--out", str(run), "--gamma", "0.9", "--num-envs", "2"])
    assert same.gamma == 0.9  # the recorded value given again is no conflict


def test_resume_refuses_an_option_that_differs_from_the_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = _run_folder(tmp_path, gamma=0.9)
    before = (run / "config.json").read_text()
    err = _error(capsys, ["train", "--resume", "--out", str(run), "--gamma", "0.99"])
    assert "--resume: --gamma = 0.99 differs from the run's 0.9" in err
    assert "--total-timesteps" in err  # what may change is listed
    err = _error(capsys, ["train", "--resume", "--out", str(run), "--duration-s", "5"])
    assert "--duration-s/--episode-s = 5.0 differs" in err
    err = _error(capsys, ["train", "--resume", str(run)])
    assert "--resume --out RUN" in err
    assert (run / "config.json").read_text() == before


def test_train_resumed_with_other_settings_is_refused(tmp_path: Path) -> None:
    from agents.train import train

    run = _run_folder(tmp_path, gamma=0.9)
    before = sorted(p.name for p in run.rglob("*"))
    with pytest.raises(ValueError, match=r"--resume: --gamma = 0.995 differs from the run's 0.9"):
        train(TrainConfig(run_dir=str(run), resume=True))
    assert sorted(p.name for p in run.rglob("*")) == before


def test_resumed_config_keeps_what_may_change_only() -> None:
    recorded = json.loads(TrainConfig(learning_rate=1e-3, torch_threads=1).to_json())
    config = resumed_config(recorded, {"torch_threads": 2, "total_timesteps": 10}, "c.json")
    assert (config.learning_rate, config.torch_threads, config.total_timesteps) == (1e-3, 2, 10)
    with pytest.raises(ValueError, match=r"--learning-rate = 0.1 differs .*\(c.json\)"):
        resumed_config(recorded, {"learning_rate": 0.1}, "c.json")
    with pytest.raises(ValueError, match=r"c.json does not hold the settings of a run"):
        resumed_config({"nope": 1}, {}, "c.json")


def test_a_fitted_value_beyond_its_range_is_held_at_the_end_and_said() -> None:
    """An unpinned parameter that the fit drives beyond its allowed range (a stiffness of
    1e13 N m/rad) makes a plant at the range's end, with a note, instead of failing."""
    from drill_env.bit_model import P_K
    from drill_env.calibrated_plant import PARAMETER_RANGES
    from drill_env.measured_log import MeasuredLog
    from experiments.calibration_fit import FamilyFit, _plant_of

    t = np.arange(200) * 1e-2
    ones = np.ones_like(t)
    window = MeasuredLog(
        t, {"top_speed_rad_s": 5 * ones, "bit_speed_rad_s": 5 * ones, "bit_torque_nm": 1e3 * ones}
    )
    p = np.zeros(8)
    p[:6] = 300.0, 1.0, 50.0, 8e3, 5e3, 1.0
    p[P_K] = 1e13
    fit = FamilyFit("karnopp", p, 0.0, 1.0, 200, 200.0, [], {}, {}, {}, 0.0, 1)
    plant = _plant_of(fit, window, False, (0.0, 2.0), "log.csv", {"karnopp": fit}, [],
                      np.ones_like(t))  # fmt: skip
    stiffness = plant.parameters["stiffness"]
    assert stiffness.value == PARAMETER_RANGES["stiffness"][1]
    assert "held at the end of the allowed range" in stiffness.note
    assert plant.parameters["bit_inertia"].value == 300.0
