"""``drill-gym coupled-controllers``: a small grid's tables, files and figure, the rows as the
env gives them, the agent's evaluation, and the user errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from agents.inference import ObsNorm, PolicySpec
from agents.policy import ResidualPolicy
from drill_env.coupled_env import DrillStringCoupledEnv
from experiments.cli import main
from experiments.coupled_controllers import map_figure, run_point
from experiments.plots import text_problems


def test_small_grid_tables_files_and_figure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["coupled-controllers", "--torque-loops", "pi", "stiff_pi", "--forces", "60", "90"]
    argv += ["--speeds", "4", "--duration-s", "1", "--out", str(tmp_path), "--no-progress"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "| stiff_pi | autodriller |" in out and "points held" in out
    data = json.loads((tmp_path / "coupled_controllers.json").read_text())
    assert len(data["rows"]) == 2 * 2 * 2
    assert (tmp_path / "figures" / "coupled_controllers_map.png").stat().st_size > 10_000
    assert (tmp_path / "coupled_controllers.csv").read_text().count("\n") == 9
    fig = map_figure(data["rows"], ["pi", "stiff_pi"], [60.0, 90.0], [4.0])
    assert text_problems(fig) == []


def test_a_row_is_the_second_half_of_the_env_episode() -> None:
    row = run_point("pi", "fixed_force", 90e3, 12.0, 1.0)
    env = DrillStringCoupledEnv(episode_s=1.0, randomize=False, applied_force_n=90e3)
    env.reset(seed=0)
    depth, stuck = [], []
    for _ in range(20):
        _, _, _, _, info = env.step(np.zeros(2, dtype=np.float32))
        depth.append(info["depth_m"])
        stuck.append(info["stuck_fraction"])
    assert row["rop_mm_s"] == pytest.approx(1e3 * (depth[-1] - depth[9]) / 0.5, rel=1e-9)
    assert row["stuck_fraction"] == pytest.approx(np.mean(stuck[10:]), abs=1e-12)
    assert row["mse_mpa"] > 10


def test_agent_evaluation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    spec = PolicySpec(observation_size=8, hidden_sizes=(4,), action_size=2,
                      action_low=(-1.0, -1.0), action_high=(1.0, 1.0))  # fmt: skip
    weights = {k: np.zeros(shape) for k, shape in spec.weight_shapes().items()}
    kwargs = {"torque_loop": "pi", "control_dt_s": 0.1, "residual_torque_nm": 5e3,
              "max_torque_nm": 5e4}  # fmt: skip
    policy = ResidualPolicy(spec, weights, ObsNorm.identity(8), kwargs, "zero",
                            env_id="DrillStringCoupled-v0")  # fmt: skip
    policy.save(tmp_path / "model")
    argv = ["coupled-controllers", "--agent", str(tmp_path / "model"), "--agent-episodes", "1"]
    assert main([*argv, "--no-grid", "--out", str(tmp_path / "out")]) == 0
    rows = json.loads((tmp_path / "out" / "coupled_agent.json").read_text())["rows"]
    # A zero policy is its base loops: the same rewards, term by term.
    assert rows[0]["reward"] == pytest.approx(rows[1]["reward"], rel=1e-12)
    assert "| agent zero |" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (
            ["--torque-loops", "warp"],
            "argument --torque-loops: unknown loop 'warp': allowed pi, csmc",
        ),
        (["--forces", "20"], "argument --forces: 20 is out of range"),
        (["--agent", "nowhere"], "--agent: 'nowhere' does not exist"),
        (["--duration-s", "0"], "argument --duration-s: 0 is out of range: allowed [0.1, 1000] s"),
        (["--episode", "0"], "argument --episode: 0 is out of range: allowed [0.1, 1000] s"),
    ],
)
def test_user_errors_are_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code = main(["coupled-controllers", *argv, "--out", str(tmp_path / "new")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err
