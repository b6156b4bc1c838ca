"""The commands as a user types them: each test starts ``drill-gym`` in a fresh process, in an
empty working directory, with the default options except for a tiny budget, and checks the
exit code, the files written and a line of the output.

The command is the installed ``drill-gym`` console script when it runs this checkout's code
(an editable install of it); otherwise (the script belongs to another checkout, or is not
installed) ``python -m experiments.cli`` with this checkout first on ``PYTHONPATH``.
``test_console_script_entry_point`` checks the script's entry point itself.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import experiments

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sys.executable).parent / "drill-gym"
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _environment() -> dict[str, str]:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env.pop("DRILL_GYM_DEBUG", None)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _script_runs_this_checkout(cwd: Path) -> bool:
    """Whether the installed console script imports this checkout's ``experiments``."""
    if not SCRIPT.is_file():
        return False
    first = SCRIPT.read_text(errors="replace").splitlines()[:1]
    python = first[0][2:].strip() if first and first[0].startswith("#!") else sys.executable
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    found = subprocess.run(
        [python, "-c", "import experiments; print(experiments.__file__)"],
        cwd=cwd, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    mine = Path(experiments.__file__).resolve()
    return found.returncode == 0 and Path(found.stdout.strip()).resolve() == mine


@pytest.fixture(scope="module")
def command(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    """How to start ``drill-gym`` so that it runs the code under test."""
    if _script_runs_this_checkout(tmp_path_factory.mktemp("probe")):
        return [str(SCRIPT)]
    return [sys.executable, "-m", "experiments.cli"]


def drill_gym(
    command: list[str], cwd: Path, *args: str, timeout: float = 120.0
) -> subprocess.CompletedProcess[str]:
    result = subprocess.run(
        [*command, *args], cwd=cwd, env=_environment(), capture_output=True, text=True,
        timeout=timeout, check=False,
    )  # fmt: skip
    assert result.returncode == 0, f"exit code {result.returncode}\n{result.stderr[-3000:]}"
    assert "Traceback" not in result.stderr
    return result


def test_console_script_entry_point() -> None:
    """pyproject's ``drill-gym = "experiments.cli:main"`` resolves to the dispatcher, and the
    installed script (if any) starts it."""
    import tomllib

    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"drill-gym": "experiments.cli:main"}
    module, _, name = scripts["drill-gym"].partition(":")
    entry = getattr(importlib.import_module(module), name)
    from experiments.cli import main

    assert entry is main and callable(entry)
    if not SCRIPT.is_file():
        pytest.skip(f"no drill-gym console script next to {sys.executable}: not installed")
    result = subprocess.run(
        [str(SCRIPT), "--help"], capture_output=True, text=True, check=False, timeout=60
    )
    assert result.returncode == 0 and "compare" in result.stdout, result.stderr


def test_train_with_its_defaults(command: list[str], tmp_path: Path) -> None:
    """The default settings but a budget of 2 rollouts of 500 decisions x 2 strings, without
    the validation runs (16 episodes of 100 s each): every default that shapes the run stays
    (100 s episodes, the proposed SMC under the residual, TensorBoard logs, the progress
    lines, no progress bar, n_epochs 10, a final checkpoint)."""
    result = drill_gym(
        command, tmp_path, "train", "--total-timesteps", "2000", "--num-envs", "2",
        "--n-steps", "500", "--batch-size", "500", "--validate-every", "0",
    )  # fmt: skip
    run = tmp_path / "runs" / "residual_ppo__1"
    assert "training 2,000 decisions: 2 rollouts of 1,000 (500 steps x 2 envs)" in result.stdout
    assert "residual_ppo: 1,000/2,000 decisions" in result.stdout
    assert f"model saved to {Path('runs/residual_ppo__1/model')}: last" in result.stdout
    for name in ("config.json", "policy.safetensors", "obs_norm.safetensors"):
        assert (run / "model" / name).is_file(), name
    assert (run / "checkpoints" / "steps_2000" / "training_state.safetensors").is_file()
    assert (run / "progress.csv").is_file() and any((run / "tb").rglob("events.out.tfevents*"))
    assert json.loads((run / "config.json").read_text())["n_epochs"] == 10


def test_train_without_progress_into_out(command: list[str], tmp_path: Path) -> None:
    result = drill_gym(
        command, tmp_path, "train", "--total-timesteps", "200", "--num-envs", "2",
        "--n-steps", "100", "--batch-size", "100", "--validate-every", "0", "--duration-s", "10",
        "--no-progress", "--out", "mine",
    )  # fmt: skip
    lines = result.stdout.splitlines()
    assert lines[0].startswith("training 200 decisions") and lines[-1].startswith("model saved")
    assert len(lines) == 2 and result.stderr == ""
    assert (tmp_path / "mine" / "model" / "policy.safetensors").is_file()


def test_evaluate_the_shipped_models(command: list[str], tmp_path: Path) -> None:
    result = drill_gym(
        command, tmp_path, "evaluate", "--scenarios", "h14", "--controllers", "proposed"
    )
    out = tmp_path / "results" / "evaluate"
    rows = json.loads((out / "heldout.json").read_text())
    assert {r["controller"] for r in rows} == {"proposed", "residual_ppo", "direct_ppo"}
    assert (out / "heldout.csv").is_file() and (out / "summary.json").is_file()
    for name in ("speed_torque_h14", "heldout_bit_speed", "heldout_torque", "heldout_iae_severity"):
        assert (out / "figures" / f"{name}.png").read_bytes()[:8] == PNG_MAGIC, name
    assert "| residual_ppo |" in result.stdout
    assert "residual_ppo, residual torque on proposed: " in result.stdout
    assert "direct_ppo, direct torque, no base controller: " in result.stdout
    assert "of the best engineered controller (proposed)" in result.stdout


def test_compare_one_controller(command: list[str], tmp_path: Path) -> None:
    result = drill_gym(
        command, tmp_path, "compare", "--controllers", "csmc", "--conditions", "nominal",
        "--noise", "0", "--duration-s", "2",
    )  # fmt: skip
    out = tmp_path / "results"
    rows = json.loads((out / "compare.json").read_text())
    assert [r["controller"] for r in rows] == ["csmc", "residual_ppo"]  # the shipped agent row
    assert "| residual_ppo | 1 |" in result.stdout and "| csmc | 1 |" in result.stdout
    assert len(result.stdout.splitlines()) <= 60
    assert "| csmc | nominal | 0 |" in (out / "compare.md").read_text()
    assert "2 runs simulated in" in result.stdout
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert "speed_torque_csmc.png" in figures and "adaptive_gains.png" in figures
    assert len(figures) == 9  # 2 runs, 1 noise level: 2 speed_torque, 2 noise, 4 bars, gains


def test_map_a_tiny_grid(command: list[str], tmp_path: Path) -> None:
    result = drill_gym(
        command, tmp_path, "map", "--wob-n", "2", "--speed-n", "2", "--duration-s", "2",
        "--window-s", "1",
    )  # fmt: skip
    out = tmp_path / "results"
    assert (out / "stick_slip_map_stiff_pi.csv").read_text().count("\n") == 5
    assert (out / "stick_slip_map_stiff_pi.png").read_bytes()[:8] == PNG_MAGIC
    assert "stiff_pi: 4 cells x 2 s in" in result.stdout


def test_a_user_error_in_a_fresh_process(command: list[str], tmp_path: Path) -> None:
    result = subprocess.run(
        [*command, "map", "--wob-min", "-3"], cwd=tmp_path, env=_environment(),
        capture_output=True, text=True, check=False, timeout=60,
    )  # fmt: skip
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr == (
        "drill-gym map: error: argument --wob-min: -3 is out of range: allowed (0, 1e+06] N "
        "(see drill-gym map --help)\n"
    )
    assert not any(tmp_path.iterdir())


# ---------------------------------------------------------- the environment as a user makes it
@pytest.mark.parametrize(
    ("kwargs", "decisions", "end_s"),
    [({}, 1000, 100.0), ({"episode_s": 150}, 1500, 150.0), ({"control_dt_s": 0.05}, 2000, 100.0)],
)
def test_gym_make_runs_to_its_own_end(
    kwargs: dict[str, float], decisions: int, end_s: float
) -> None:
    """Plain ``gym.make`` with one keyword: the episode ends by truncation exactly at
    ``episode_s`` (100 s by default), after ``env.spec.max_episode_steps`` decisions."""
    import gymnasium as gym
    import numpy as np

    import drill_env  # noqa: F401  (registers DrillString-v0)

    env = gym.make("DrillString-v0", **kwargs)
    assert env.spec is not None and env.spec.max_episode_steps == decisions
    env.reset(seed=0)
    action = np.zeros(1, dtype=np.float32)
    steps, terminated, truncated, info = 0, False, False, {}
    while not (terminated or truncated):
        _, _, terminated, truncated, info = env.step(action)
        steps += 1
        assert steps <= decisions
    assert (steps, terminated, truncated) == (decisions, False, True)
    assert info["time_s"] == pytest.approx(end_s)


def test_gym_make_by_module_path_without_importing_drill_env(tmp_path: Path) -> None:
    """``gym.make("drill_env:DrillString-v0")`` imports the package itself (Gymnasium's
    ``module:id`` form), in a process that never imported drill_env."""
    code = (
        "import sys, gymnasium as gym\n"
        "assert 'drill_env' not in sys.modules\n"
        "env = gym.make('drill_env:DrillString-v0', episode_s=1.0)\n"
        "obs, info = env.reset(seed=0)\n"
        "assert env.observation_space.contains(obs)\n"
        "print(env.spec.id, env.spec.max_episode_steps)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=_environment(), capture_output=True,
        text=True, check=False, timeout=120,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["DrillString-v0", "10"]  # 1 s of 0.1 s decisions
