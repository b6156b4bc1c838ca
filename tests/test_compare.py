"""``drill-gym compare`` (``experiments.compare``): a short smoke run and the files it writes."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.metrics import METRIC_KEYS
from experiments import compare
from experiments.cli import main as cli_main
from experiments.compare import ROW_KEYS, decision_period, default_controllers, main

SHORT = ["--duration-s", "2", "--conditions", "nominal", "--no-agent", "--no-progress"]

FIGURES = (
    "speed_torque_csmc.png",
    "speed_torque_proposed.png",
    "noise_speed_torque.png",
    "noise_torque_zoom.png",
    "bars_rmse.png",
    "bars_ise_iae.png",
    "bars_rmsd.png",
    "bars_chattering.png",
    "adaptive_gains.png",
)


@pytest.fixture(scope="module")
def smoke(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("compare")
    argv = ["--controllers", "csmc", "proposed", "--noise", "0", *SHORT, "--out", str(out)]
    assert main(argv) == 0
    return out


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


class TestSmokeRun:
    def test_csv(self, smoke: Path) -> None:
        rows = read_csv(smoke / "compare.csv")
        assert [(r["controller"], r["condition"], r["noise_std_rad_s"]) for r in rows] == [
            ("csmc", "nominal", "0.0"),
            ("proposed", "nominal", "0.0"),
        ]
        assert tuple(rows[0]) == ROW_KEYS
        assert float(rows[0]["rmsd_nm"]) > 5_000
        assert rows[0]["settling_time_s"] == ""  # never settles within 2 s: empty cell

    def test_json(self, smoke: Path) -> None:
        rows = json.loads((smoke / "compare.json").read_text())
        assert len(rows) == 2
        for row in rows:
            assert tuple(row) == ROW_KEYS
            assert set(METRIC_KEYS) <= set(row)
            assert row["settling_time_s"] is None  # JSON null
            assert row["diverged"] is False
            assert row["gains"] == "paper"
            assert row["uncertainty_reading"] == "plant"
            assert row["duration_s"] == 2.0

    def test_figures(self, smoke: Path) -> None:
        for name in FIGURES:
            path = smoke / "figures" / name
            assert path.is_file(), name
            assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
            assert path.stat().st_size > 1000, name

    def test_same_numbers_as_one_rollout(self, smoke: Path) -> None:
        # compare runs the one scoring path: rollout + episode_metrics of a DrillString-v0.
        env = gym.make(
            "DrillString-v0",
            randomize=False,
            base_controller="proposed",
            noise_std_rad_s=0.0,
            episode_s=2.0,
            control_dt_s=0.05,
            max_episode_steps=-1,
        )
        expected = episode_metrics(rollout(env, ZeroAction(), seed=0))
        row = json.loads((smoke / "compare.json").read_text())[1]
        for key in METRIC_KEYS:
            assert row[key] == expected[key], key


def test_table_and_noise_levels(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--controllers", "asmc", "--noise", "0", "0.1", "--no-plots", *SHORT]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    # The terminal gets the ranked summary: one line per controller, means over its 2 runs.
    assert "| rank | controller | runs | ISE | IAE |" in text
    assert "| 1 | asmc | 2 |" in text
    assert "| asmc | nominal |" not in text
    # Every run goes to the files, compare.md as the readable table.
    table = (tmp_path / "compare.md").read_text()
    assert "| controller | condition | noise (rad/s) | ISE | IAE |" in table
    assert "| asmc | nominal | 0.1 |" in table
    rows = json.loads((tmp_path / "compare.json").read_text())
    assert [r["noise_std_rad_s"] for r in rows] == [0.0, 0.1]
    assert rows[1]["chattering_nm_per_s"] > 20 * rows[0]["chattering_nm_per_s"]
    assert not (tmp_path / "figures").exists()


def test_through_the_cli(tmp_path: Path) -> None:
    argv = ["compare", "--controllers", "msmc", "--noise", "0", "--no-plots", *SHORT]
    assert cli_main([*argv, "--out", str(tmp_path)]) == 0
    assert len(read_csv(tmp_path / "compare.csv")) == 1


def test_rescaled_gains(tmp_path: Path) -> None:
    argv = ["--controllers", "csmc", "--noise", "0", "--gains", "rescaled", "--no-plots", *SHORT]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    row = json.loads((tmp_path / "compare.json").read_text())[0]
    assert row["gains"] == "rescaled"
    assert compare.RESCALED_GAINS["csmc"] == {"k1": pytest.approx(3.0 * 930.0)}


def test_controller_reading(tmp_path: Path) -> None:
    argv = ["--controllers", "csmc", "--noise", "0", "--reading", "controller", "--no-plots"]
    assert main([*argv, *SHORT, "--conditions", "condition3", "--out", str(tmp_path)]) == 0
    row = json.loads((tmp_path / "compare.json").read_text())[-1]
    assert (row["condition"], row["uncertainty_reading"]) == ("condition3", "controller")


class FakeAgent:
    """Stands in for ``agents.load_default_policy()``: a zero residual on the proposed SMC."""

    name = "fake_agent"
    env_kwargs: dict[str, Any] = {"base_controller": "proposed", "control_dt_s": 0.05}

    def predict(self, observation, state=None, episode_start=None, deterministic=True):  # type: ignore[no-untyped-def]
        assert np.asarray(observation).shape == (11,)
        return np.zeros(1, dtype=np.float32), state


def test_agent_row(tmp_path: Path) -> None:
    argv = ["--controllers", "proposed", "--noise", "0", "--no-plots", "--duration-s", "2"]
    argv += ["--conditions", "nominal", "--out", str(tmp_path)]
    assert main(argv, agent_loader=FakeAgent) == 0
    rows = json.loads((tmp_path / "compare.json").read_text())
    assert [r["controller"] for r in rows] == ["proposed", "fake_agent"]
    assert rows[1]["gains"] == "agent"
    # A zero residual on the proposed SMC is the proposed SMC.
    for key in METRIC_KEYS:
        assert rows[1][key] == rows[0][key], key


def test_no_agent_when_none_shipped(tmp_path: Path) -> None:
    argv = ["--controllers", "csmc", "--noise", "0", "--no-plots", "--duration-s", "1"]
    argv += ["--conditions", "nominal", "--out", str(tmp_path)]
    assert main(argv, agent_loader=lambda: None) == 0
    assert len(json.loads((tmp_path / "compare.json").read_text())) == 1


def test_command_line_passes_the_agent_loader(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``drill-gym compare`` looks the agent up in ``agents`` (baselines does not)."""
    asked: list[str] = []

    def shipped(env_id: str) -> FakeAgent:
        asked.append(env_id)
        return FakeAgent()

    monkeypatch.setattr(compare, "shipped_agent", shipped)
    argv = ["compare", "--controllers", "proposed", "--noise", "0", "--no-plots"]
    argv += ["--duration-s", "1", "--conditions", "nominal", "--out", str(tmp_path)]
    assert cli_main(argv) == 0
    rows = json.loads((tmp_path / "compare.json").read_text())
    assert [r["controller"] for r in rows] == ["proposed", "fake_agent"]
    assert asked == ["DrillString-v0"]


@pytest.mark.parametrize(
    ("env_id", "name"),
    [("DrillString-v0", "residual_ppo"), ("DrillStringField-v0", "field_agent")],
)
def test_the_shipped_agent_of_each_env(env_id: str, name: str) -> None:
    agent = compare.shipped_agent(env_id)
    assert agent is not None and agent.name == name and agent.env_id == env_id


def _row(controller: str, iae: float, diverged: bool = False, settling: Any = 5.0) -> dict:
    row: dict[str, Any] = {key: 1.0 for key in compare.SUMMARY_METRICS}
    row.update(controller=controller, iae=iae, diverged=diverged, settling_time_s=settling)
    return row


def test_ranked_summary() -> None:
    rows = [
        _row("a", 30.0),
        _row("b", 10.0, settling=None),
        _row("a", 10.0),
        _row("b", 20.0),
        _row("c", 1.0, diverged=True),
        {**_row("d", 40.0), "observation": "surface"},
    ]
    summary = compare.ranked_summary(rows)
    assert [(e["rank"], e["label"]) for e in summary] == [
        (1, "b"),
        (2, "a"),
        (3, "d (surface)"),
        (4, "c"),  # a diverged run ranks last, whatever its IAE
    ]
    assert summary[0]["iae"] == 15.0 and summary[0]["runs"] == 2
    assert summary[0]["unsettled"] == 1 and summary[0]["settling_time_s"] == 5.0
    assert summary[3]["diverged"] == 1
    lines = compare.summary_table(rows).splitlines()
    assert len(lines) == 2 + 4 and lines[2].startswith("| 1 | b | 2 |")


class TestArguments:
    def test_default_controllers(self) -> None:
        names = default_controllers()
        assert names[:4] == ["csmc", "msmc", "asmc", "proposed"]
        assert len(names) == len(set(names))

    @pytest.mark.parametrize(
        ("argv", "message"),
        [
            (["--controllers", "pid"], "argument --controllers: unknown controller 'pid': allowed csmc, msmc, asmc, proposed"),
            (["--conditions", "condition4"], "argument --conditions: unknown condition 'condition4': allowed nominal, condition1"),
            (["--conditions", "severe"], "argument --conditions: severe is not a condition of DrillString-v0: allowed nominal, condition1"),
            (["--noise", "-0.1"], "argument --noise: -0.1 is out of range: allowed [0, 10] rad/s"),
            (["--noise", "nan"], "argument --noise: nan is out of range"),
            (["--duration-s", "0"], "argument --duration-s: 0 is out of range: allowed (0, 100000] s"),
            (["--duration", "0"], "argument --duration: 0 is out of range: allowed (0, 100000] s"),
            (["--duration-s", "-5"], "argument --duration-s: -5 is out of range"),
            (["--duration-s", "0.0005"], "argument --duration-s: 0.0005 is not a multiple of the 0.001 s plant step"),
            (["--seed", "-1"], "argument --seed: -1 is out of range: allowed [0, 4294967295]"),
        ],
    )  # fmt: skip
    def test_bad_arguments(
        self, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
    ) -> None:
        with pytest.raises(SystemExit) as exc:
            main([*argv, "--no-agent"])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith(f"drill-gym compare: error: {message}"), err
        assert err.count("\n") == 1 and err.endswith(" (see drill-gym compare --help)\n")

    @pytest.mark.parametrize(
        ("duration", "period"), [(150.0, 1.0), (2.5, 0.5), (0.3, 0.1), (1.234, 0.002)]
    )
    def test_decision_period(self, duration: float, period: float) -> None:
        assert decision_period(duration) == period


def test_field_comparison_includes_the_field_agent(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "--env", "DrillStringField-v0", "--controllers", "soft_speed", "--depths", "1500",
        "--conditions", "nominal", "--noise", "0", "--duration-s", "2", "--observations",
        "surface", "--no-plots", "--no-progress", "--out", str(tmp_path),
    ]  # fmt: skip
    assert main(argv) == 0
    rows = json.loads((tmp_path / "compare.json").read_text())
    assert [(r["controller"], r["observation"]) for r in rows] == [
        ("soft_speed", "surface"),
        ("soft_speed", "surface"),
        ("field_agent", "surface"),
        ("field_agent", "surface"),
    ]
    assert "| field_agent (surface) | 2 |" in capsys.readouterr().out
