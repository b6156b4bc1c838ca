"""``drill-gym probability-map``: each draw is the env's own randomised run from rest, scored
by the map's stick-slip criterion; the command writes CSV and PNG for both envs."""

from __future__ import annotations

import csv
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from drill_env.evaluation import ZeroAction, rollout
from drill_env.scenarios import Randomization
from experiments.cli import main as cli_main
from experiments.plots import text_problems
from experiments.probability_map import (
    CSV_COLUMNS,
    ProbabilityStudy,
    probability_cells_task,
    probability_figure,
)
from experiments.stick_slip_map import stick_slip
from experiments.sweep import run_sweep

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_each_draw_is_a_randomised_run_from_rest_scored_by_the_map_criterion() -> None:
    """Draw k of a cell is DrillString-v0 with the cell's WOB and reference, Deltas drawn by
    its Randomization from reset seed seed + k: the same severity and stuck fraction as a
    plain rollout of that env, computed here from the trace."""
    wob, speed, draws, seed = 150e3, 4.0, 4, 7
    result = probability_cells_task(
        env_id="DrillString-v0", controller="stiff_pi", cells=[("c", wob, speed, None)],
        draws=draws, duration_s=6.0, window_s=3.0, noise_std_rad_s=0.0, seed=seed,
        parameters="zribi2024", delta_range=(0.0, 0.75), depth_span_m=None,
    )  # fmt: skip
    record = result.records["c"]
    randomization = Randomization(
        wob_range_n=(wob, wob), wob_step_probability=0.0, reference_range_rad_s=(speed, speed)
    )
    deltas = []
    for k in range(draws):
        env = gym.make(
            "DrillString-v0", randomize=True, randomization=randomization,
            base_controller="stiff_pi", noise_std_rad_s=0.0, episode_s=6.0, control_dt_s=0.5,
        )  # fmt: skip
        trace = rollout(env, ZeroAction(), seed=seed + k)
        deltas.append(env.unwrapped.batch.episodes[0].scenario.uncertainty)  # type: ignore[attr-defined]
        assert np.all(trace.wob_n == wob) and np.all(trace.reference_rad_s == speed)
        bit = trace.bit_speed_rad_s[-3000:]
        severity = (bit.max() - bit.min()) / (2 * bit.mean()) if bit.mean() > 0 else 1.0
        assert record["severity"][k] == pytest.approx(severity, rel=1e-12)
        assert record["stuck_fraction"][k] == pytest.approx(
            trace.bit_stuck[-3000:].mean(), rel=1e-12
        )
    assert len(set(deltas)) == draws  # a new plant every draw
    assert all(0.0 <= d <= 0.75 for draw in deltas for d in draw)
    flags = stick_slip(record["severity"], record["stuck_fraction"])
    assert flags.dtype == bool and flags.shape == (draws,)


def test_probability_is_the_share_of_draws_in_stick_slip() -> None:
    study = ProbabilityStudy(
        env_id="DrillString-v0", controllers=("stiff_pi",), row_axis="wob",
        rows=(60e3, 180e3), reference_speed_rad_s=(2.0, 12.0), draws=3,
        duration_s=4.0, window_s=2.0, seed=1, task_cells=3,
    )  # fmt: skip
    result = study.maps(run_sweep(study, progress=False))[0]
    assert result.severity.shape == (2, 2, 3)
    expected = stick_slip(result.severity, result.stuck_fraction).mean(axis=2)
    np.testing.assert_array_equal(result.probability, expected)
    assert set(np.unique(result.probability * 3)) <= {0.0, 1.0, 2.0, 3.0}
    assert not text_problems(probability_figure(result))


def test_command_writes_csv_and_png(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = [
        "probability-map", "--wob-n", "2", "--speed-n", "3", "--draws", "3", "--duration-s", "3",
        "--window-s", "1.5", "--out", str(tmp_path), "--no-progress",
    ]  # fmt: skip
    assert cli_main(argv) == 0
    assert "probability-map on serial: 6 cells x 3 draws x 3 s" in capsys.readouterr().out
    with (tmp_path / "stick_slip_probability_stiff_pi.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == CSV_COLUMNS["wob"] and len(rows) == 6
    assert all(r["draws"] == "3" and 0 <= float(r["stick_slip_probability"]) <= 1 for r in rows)
    png = tmp_path / "stick_slip_probability_stiff_pi.png"
    assert png.read_bytes()[:8] == PNG_MAGIC


def test_field_string_over_measured_depth(tmp_path: Path) -> None:
    """On DrillStringField-v0 the rows can be measured depths at a fixed WOB; friction and
    damping are drawn (FieldRandomization), the depth is the cell's."""
    argv = [
        "probability-map", "--env", "DrillStringField-v0", "--rows", "depth",
        "--depth-min", "1500", "--depth-max", "4000", "--depth-n", "2", "--wob", "120000",
        "--speed-min", "4", "--speed-max", "12", "--speed-n", "2", "--draws", "2",
        "--duration-s", "3", "--window-s", "1.5", "--out", str(tmp_path), "--no-progress",
    ]  # fmt: skip
    assert cli_main(argv) == 0
    with (tmp_path / "stick_slip_probability_stiff_pi.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == CSV_COLUMNS["depth"]
    assert [r["measured_depth_m"] for r in rows] == ["1500", "1500", "4000", "4000"]
    assert (tmp_path / "stick_slip_probability_stiff_pi.png").read_bytes()[:8] == PNG_MAGIC
