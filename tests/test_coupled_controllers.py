"""``drill-gym coupled-controllers``: a small grid's tables, files and figure, the rows as the
env gives them, the agent's evaluation, and the user errors."""

from __future__ import annotations

import json
import sqlite3
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from agents.inference import ObsNorm, PolicySpec
from agents.policy import ResidualPolicy
from drill_env.coupled_env import DrillStringCoupledEnv
from experiments.cli import main
from experiments.coupled_controllers import CoupledStudy, map_figure, run_point
from experiments.plots import text_problems
from experiments.sweep import Backend, run_sweep, spec_hash


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


def _zero_policy(tmp_path: Path) -> ResidualPolicy:
    """A ``DrillStringCoupled-v0`` policy whose action is always zero, saved in
    ``tmp_path / "model"``."""
    spec = PolicySpec(observation_size=8, hidden_sizes=(4,), action_size=2,
                      action_low=(-1.0, -1.0), action_high=(1.0, 1.0))  # fmt: skip
    weights = {k: np.zeros(shape) for k, shape in spec.weight_shapes().items()}
    kwargs = {"torque_loop": "pi", "control_dt_s": 0.1, "residual_torque_nm": 5e3,
              "max_torque_nm": 5e4}  # fmt: skip
    policy = ResidualPolicy(spec, weights, ObsNorm.identity(8), kwargs, "zero",
                            env_id="DrillStringCoupled-v0")  # fmt: skip
    policy.save(tmp_path / "model")
    return policy


def replace_weights(policy: ResidualPolicy) -> ResidualPolicy:
    """``policy`` with its first weight array nudged."""
    weights = {k: np.array(v) for k, v in policy.weights.items()}
    first = sorted(weights)[0]
    weights[first].flat[0] += 1e-3
    return ResidualPolicy(policy.spec, weights, policy.obs_norm, policy.env_kwargs, policy.name,
                          env_id=policy.env_id)  # fmt: skip


def test_agent_evaluation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _zero_policy(tmp_path)
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


def _grid_argv(out: Path) -> list[str]:
    argv = ["coupled-controllers", "--torque-loops", "stiff_pi", "--forces", "60", "90"]
    return [*argv, "--speeds", "8", "--duration-s", "1", "--no-plots", "--no-progress",
            "--out", str(out)]  # fmt: skip


def _outputs(out: Path) -> dict[str, str]:
    return {p.name: p.read_text() for p in sorted(out.iterdir()) if p.suffix in (".json", ".csv")}


def test_a_results_database_and_a_resume_give_the_serial_files(tmp_path: Path) -> None:
    assert main(_grid_argv(tmp_path / "serial")) == 0
    database = tmp_path / "c.sqlite"
    assert main([*_grid_argv(tmp_path / "db"), "--results", str(database)]) == 0
    assert main([*_grid_argv(tmp_path / "again"), "--results", str(database), "--resume"]) == 0
    serial = _outputs(tmp_path / "serial")
    assert len(serial) == 2
    assert _outputs(tmp_path / "db") == serial == _outputs(tmp_path / "again")
    with sqlite3.connect(database) as db:
        assert db.execute("SELECT COUNT(*) FROM results").fetchone() == (4,)


def test_the_study_resumes_nothing_twice_and_its_settings_hash_follows_the_numbers(
    tmp_path: Path,
) -> None:
    study = CoupledStudy(("stiff_pi",), ("fixed_force",), (60.0,), (8.0, 12.0), duration_s=1.0)
    path = tmp_path / "c.sqlite"
    first = run_sweep(study, Backend(), path, progress=False)
    again = run_sweep(study, Backend(), path, resume=True, progress=False)
    assert again.ran == [] and again.loaded == 2 and again.records == first.records
    hashes = {spec_hash(study.name, study.spec())}
    for change in ({"duration_s": 2.0}, {"forces_kn": (90.0,)}, {"speeds_rad_s": (8.0,)},
                   {"torque_loops": ("csmc",)}, {"axial_loops": ("autodriller",)}):  # fmt: skip
        hashes.add(spec_hash(study.name, replace(study, **change).spec()))
    assert len(hashes) == 6
    same = replace(study, task_items=2)
    assert spec_hash(study.name, same.spec()) == spec_hash(study.name, study.spec())


def test_the_agent_evaluation_hash_follows_the_model_and_episodes(tmp_path: Path) -> None:
    policy = _zero_policy(tmp_path)
    study = CoupledStudy(grid=False, agent=policy, agent_episodes=1)
    other = replace(study, agent=replace_weights(policy))
    hashes = {
        spec_hash(study.name, s.spec()) for s in (study, other, replace(study, agent_episodes=2))
    }
    assert len(hashes) == 3
    records = run_sweep(study, Backend(), progress=False).records
    assert list(records) == ["base loops/episode=0", "agent/episode=0"]


def test_on_ray_the_files_are_the_serial_files(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    assert main(_grid_argv(tmp_path / "serial")) == 0
    argv = [*_grid_argv(tmp_path / "ray"), "--workers", "2", "--task-size", "1"]
    assert main(argv) == 0
    assert _outputs(tmp_path / "ray") == _outputs(tmp_path / "serial")
