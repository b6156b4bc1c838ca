"""The field agent (``drill-gym train --env DrillStringField-v0``): the per-env training
defaults, frame stacking at inference against SB3's ``VecFrameStack``, a tiny field training
run end to end (its saved models reload and act as SB3's policy does), and the shipped field
model in ``drill-gym evaluate``.

Tiny budgets only; the real training is timed by ``benchmarks/field_agent.py``.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from agents.config import ENV_DEFAULTS, FIELD_ENV_ID, TrainConfig
from agents.inference import ObsNorm, PolicySpec, stack_frames
from agents.policy import DEFAULT_MODEL_DIR, ResidualPolicy, is_model_folder, load_policy
from drill_env.evaluation import rollout
from experiments.train import parse_config

FIELD = FIELD_ENV_ID
SHIPPED = DEFAULT_MODEL_DIR / "field_agent"
ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------- per-env defaults
def test_the_paper_env_keeps_the_shipped_agents_defaults() -> None:
    config = parse_config([])
    assert config == TrainConfig()
    assert (config.env_id, config.base_controller, config.frame_stack, config.observation) == (
        "DrillString-v0",
        "proposed",
        1,
        "",
    )
    # the settings of the shipped paper-string agent's training (its record)
    record = json.loads((DEFAULT_MODEL_DIR / "residual_ppo" / "config.json").read_text())
    for name in ("total_timesteps", "validation_episodes", "residual_scale_nm", "reward_torque"):
        assert getattr(config, name) == record["train_config"][name], name


def test_field_defaults_apply_to_the_fields_not_given() -> None:
    config = parse_config(["--env", FIELD])
    for name, value in ENV_DEFAULTS[FIELD].items():
        assert getattr(config, name) == value, name
    assert config.env_id == FIELD
    # the fields without a field default are the dataclass's
    paper = TrainConfig()
    for f in dataclasses.fields(TrainConfig):
        if f.name not in ENV_DEFAULTS[FIELD] and f.name != "env_id":
            assert getattr(config, f.name) == getattr(paper, f.name), f.name


def test_a_value_given_wins_over_the_field_default_even_the_paper_default() -> None:
    given = ["--env-id", FIELD, "--frame-stack", "1", "--base-controller", "proposed"]
    config = parse_config([*given, "--control-dt-s", "0.1", "--no-norm-reward"])
    assert (config.frame_stack, config.base_controller, config.control_dt_s) == (
        1,
        "proposed",
        0.1,
    )
    assert config.norm_reward is False
    assert config.residual_scale_nm == ENV_DEFAULTS[FIELD]["residual_scale_nm"]
    # the same rule in Python
    from_python = TrainConfig.for_env(FIELD, frame_stack=1, seed=5)
    assert (from_python.frame_stack, from_python.seed) == (1, 5)
    assert from_python.base_controller == ENV_DEFAULTS[FIELD]["base_controller"]
    # the flags of the paper env do not pick up the field defaults
    assert parse_config(["--frame-stack", "4"]).base_controller == "proposed"


def test_bad_env_settings_are_one_line_errors() -> None:
    with pytest.raises(SystemExit):
        parse_config(["--env", "Nope-v0"])
    with pytest.raises(ValueError, match=r"--env-id = 'Nope-v0' is not valid: allowed Drill"):
        TrainConfig.for_env("Nope-v0")
    with pytest.raises(ValueError, match=r"--env-id = 'Nope-v0' is not valid: allowed"):
        TrainConfig(env_id="Nope-v0")
    with pytest.raises(
        ValueError, match=r"--observation = 'surface' is not valid with --env/--env-id"
    ):
        parse_config(["--observation", "surface"])
    with pytest.raises(ValueError, match=r"--observation = 'all' is not valid: allowed surface"):
        parse_config(["--env", FIELD, "--observation", "all"])
    with pytest.raises(
        ValueError, match=r"--frame-stack = 0 is out of range: allowed an integer in \[1, 256\]"
    ):
        parse_config(["--frame-stack", "0"])


def _episodes(
    severity: list[float], iae: float = 10.0, rmsd: float = 1e4
) -> list[dict[str, float]]:
    return [{"iae": iae, "rmsd_nm": rmsd, "stick_slip_severity": s} for s in severity]


def test_the_severity_term_prices_a_ripple_the_mean_hides() -> None:
    """Four scenarios: the policy lowers the one that sticks (1.0 -> 0.4) and doubles the
    ripple on two that do not (0.1 -> 0.2). The mean severity falls (0.8 / 1.2), the
    interquartile mean (the middle two of four) doubles: only the severity term sees it."""
    from agents.train import RMSD_TARGET, validation_score

    base = _episodes([0.0, 0.1, 0.1, 1.0])
    policy = _episodes([0.0, 0.2, 0.2, 0.4], iae=9.0, rmsd=1.02e4)
    plain = validation_score(policy, base)
    assert plain.iae_ratio == pytest.approx(0.9) and plain.rmsd_ratio == pytest.approx(1.02)
    assert plain.severity_ratio == pytest.approx(0.8 / 1.2)
    assert plain.severity_iqm_ratio == pytest.approx(2.0)
    assert plain.score == pytest.approx(0.9 + 10 * (1.02 - RMSD_TARGET))
    weighted = validation_score(policy, base, severity_weight=1.5)
    assert weighted.score == pytest.approx(plain.score + 1.5 * (2.0 - 1.0))
    # a ripple below the base loop's costs nothing
    assert validation_score(base, policy, 1.5).score == validation_score(base, policy).score
    # an even base loop: an even policy ties, a rippling one is infinitely worse
    even = _episodes([0.0, 0.0, 0.0, 0.0])
    assert validation_score(even, even, 1.0).severity_iqm_ratio == 1.0
    assert validation_score(policy, even, 1.0).score == float("inf")
    assert validation_score(policy, even).score < float("inf")  # weight 0: not priced


def test_the_field_defaults_select_on_validation_with_the_severity_term() -> None:
    config = TrainConfig.for_env(FIELD)
    assert config.validation_severity_weight > 0 and config.validate_every > 0
    assert TrainConfig().validation_severity_weight == 0  # the paper string's rule unchanged
    with pytest.raises(ValueError, match=r"^--validation-severity-weight = -1 is out of range"):
        TrainConfig(validation_severity_weight=-1)


def test_a_resumed_run_keeps_the_validation_columns_it_started_with(tmp_path: Path) -> None:
    """A run of an earlier version (no ``severity_iqm_ratio`` column) goes on writing its own
    columns; the sweep runner reads both kinds of file by column."""
    pytest.importorskip("stable_baselines3")  # the validation's TensorBoard writer
    from types import SimpleNamespace

    from agents.train import VALIDATION_COLUMNS, _Validation
    from experiments.sweep_train import _validations

    old = "timesteps,iae_ratio,rmsd_ratio,severity_ratio,score"
    (tmp_path / "validation.csv").write_text(old + "\n100,0.90000,1.00000,0.80000,0.90000\n")
    config = TrainConfig(validation_episodes=1, episode_s=1.0)
    validation = _Validation(config, tmp_path, progress=False)
    quiet = SimpleNamespace(logger=SimpleNamespace(output_formats=[]))
    values = dict(zip(VALIDATION_COLUMNS[False][1:], (0.8, 0.99, 0.7, 1.2, 0.8), strict=True))
    validation._write(quiet, values, 200)
    lines = (tmp_path / "validation.csv").read_text().splitlines()
    assert lines == [
        old,
        "100,0.90000,1.00000,0.80000,0.90000",
        "200,0.80000,0.99000,0.70000,0.80000",
    ]
    rows = _validations(tmp_path / "validation.csv")
    assert rows[1] == {
        "timesteps": 200,
        "iae_ratio": 0.8,
        "rmsd_ratio": 0.99,
        "severity_ratio": 0.7,
        "score": 0.8,
    }
    fresh = tmp_path / "fresh"
    fresh.mkdir()
    validation = _Validation(config, fresh, progress=False)
    validation._write(quiet, values, 200)
    assert _validations(fresh / "validation.csv") == [{"timesteps": 200, **values}]


def test_wide_training_ranges_contain_the_envs_and_leave_validation_alone() -> None:
    from agents.train import TRAINING_RANGES, env_kwargs, validation_scenarios
    from drill_env.scenarios import FieldRandomization

    config = TrainConfig.for_env(FIELD, training_ranges="wide")
    wide = env_kwargs(config)["randomization"]
    assert wide is TRAINING_RANGES["wide"]
    env = FieldRandomization()
    for f in dataclasses.fields(FieldRandomization):
        low, high = getattr(env, f.name), getattr(wide, f.name)
        if isinstance(low, tuple):
            assert high[0] <= low[0] and low[1] <= high[1], f.name
        else:
            assert high == low, f.name
    # stickier than the env ever draws: heavier, slower, stickier, less mud damping
    assert wide.wob_range_n[1] > env.wob_range_n[1]
    assert wide.reference_range_rad_s[0] < env.reference_range_rad_s[0]
    assert wide.mu_a_range[1] > env.mu_a_range[1]
    assert wide.mud_damping_factor_range[0] < env.mud_damping_factor_range[0]
    # the env's own ranges: no randomization keyword; validation never takes the wide ranges
    assert "randomization" not in env_kwargs(TrainConfig.for_env(FIELD, training_ranges="env"))
    assert "randomization" not in validation_scenarios(config)[0]
    # the training envs draw from the wide ranges
    made = gym.make(FIELD, **{**env_kwargs(config), "episode_s": 1.0})
    try:
        assert made.unwrapped.config.randomization == wide
    finally:
        made.close()


def test_bad_training_ranges_are_one_line_errors() -> None:
    with pytest.raises(
        ValueError, match=r"--training-ranges = 'sticky' is not valid: allowed env, wide"
    ):
        parse_config(["--env", FIELD, "--training-ranges", "sticky"])
    with pytest.raises(
        ValueError, match=r"--training-ranges = 'wide' is not valid with --env/--env-id"
    ):
        parse_config(["--training-ranges", "wide"])


def test_help_shows_the_field_defaults(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        parse_config(["--help-all"])
    flat = " ".join(capsys.readouterr().out.split())
    assert f"(default: 1; {FIELD}: {ENV_DEFAULTS[FIELD]['frame_stack']})" in flat
    assert f"(default: proposed; {FIELD}: z_torque_tuned;" in flat
    assert f"(default: env; {FIELD}: wide)" in flat


# --------------------------------------------------------------------------- frame stacking
def test_stack_frames_by_hand() -> None:
    first = np.array([[1.0, 2.0]], np.float32)
    h = stack_frames(None, first, np.array([True]), 3)
    assert h.tolist() == [[0, 0, 0, 0, 1, 2]]
    h = stack_frames(h, first + 10, np.array([False]), 3)
    h = stack_frames(h, first + 20, None, 3)
    assert h.tolist() == [[1, 2, 11, 12, 21, 22]]
    h = stack_frames(h, first + 30, np.array([False]), 3)
    assert h.tolist() == [[11, 12, 21, 22, 31, 32]]
    again = stack_frames(h, first, np.array([True]), 3)  # a new episode clears the history
    assert again.tolist() == [[0, 0, 0, 0, 1, 2]]
    with pytest.raises(ValueError, match=r"state has shape \(1, 4\): expected \(1, 6\)"):
        stack_frames(np.zeros((1, 4)), first, None, 3)
    with pytest.raises(ValueError, match=r"episode_start has 2 entries: expected 1"):
        stack_frames(None, first, np.array([True, False]), 3)


def test_stack_frames_is_sb3_vec_frame_stack_across_episode_ends() -> None:
    """The stacked observations SB3's ``VecFrameStack`` gives in training over the native
    vector env, through two episode ends (with the terminal observations SB3 keeps), are
    those :func:`stack_frames` builds from the plain observations and the episode starts."""
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.vec_env import VecFrameStack

    from agents.vec_env import GymnasiumVecEnv

    k = 4
    kwargs = {"base_controller": "soft_speed", "control_dt_s": 0.5, "episode_s": 3.0}
    plain = GymnasiumVecEnv(gym.make_vec(FIELD, num_envs=3, **kwargs))
    plain.seed(3)
    stacked_env = VecFrameStack(GymnasiumVecEnv(gym.make_vec(FIELD, num_envs=3, **kwargs)), k)
    stacked_env.seed(3)
    obs = plain.reset()
    stacked = stacked_env.reset()
    history = stack_frames(None, obs, np.ones(3, bool), k)
    np.testing.assert_array_equal(stacked, history)
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(14):
        action = rng.uniform(-1, 1, (3, 1)).astype(np.float32)
        obs, _, dones, infos = plain.step(action)
        stacked, _, stacked_dones, stacked_infos = stacked_env.step(action)
        np.testing.assert_array_equal(dones, stacked_dones)
        for i in np.flatnonzero(dones):  # the last observation of an ended episode
            last = stack_frames(history[i : i + 1], infos[i]["terminal_observation"][None], None, k)
            np.testing.assert_array_equal(stacked_infos[i]["terminal_observation"], last[0])
        history = stack_frames(history, obs, dones, k)
        np.testing.assert_array_equal(stacked, history)
        ends += int(dones.sum())
    assert ends == 6  # every string ended twice (6 decisions per episode)
    plain.close()
    stacked_env.close()


def _stacked_policy(k: int, size: int = 8) -> ResidualPolicy:
    spec = PolicySpec(observation_size=size, hidden_sizes=(16,), frame_stack=k)
    rng = np.random.default_rng(1)
    weights = {n: 0.3 * rng.standard_normal(s) for n, s in spec.weight_shapes().items()}
    norm = ObsNorm(rng.standard_normal(size * k), rng.uniform(0.5, 2.0, size * k))
    kwargs = {
        "base_controller": "soft_speed",
        "control_dt_s": 0.5,
        "residual_scale_nm": 5_000.0,
        "min_torque_nm": 0.0,
        "max_torque_nm": 50_800.0,
        "observation": "surface",
    }
    return ResidualPolicy(spec, weights, norm, kwargs, "stacked", env_id=FIELD)


def test_predict_carries_the_history_in_its_state() -> None:
    policy = _stacked_policy(3)
    rng = np.random.default_rng(2)
    frames = rng.standard_normal((5, 8)).astype(np.float32)
    state = None
    for t, frame in enumerate(frames):
        action, state = policy.predict(frame, state, np.array([t == 0]))
        window = np.zeros((3, 8), np.float32)
        recent = frames[max(0, t - 2) : t + 1]
        window[3 - len(recent) :] = recent
        expected = policy.network.clip(
            policy.network.mean_action(
                policy.network.latent(policy.normalize(window.reshape(1, -1)).astype(np.float64))
            )
        )
        np.testing.assert_allclose(action, expected[0], rtol=1e-6)
        assert action.shape == (1,) and state.shape == (1, 24)
    # a batch: each row has its own history; a row that starts is cleared
    batch_state = np.repeat(state, 2, axis=0)
    actions, batch_state = policy.predict(
        np.stack([frames[0], frames[0]]), batch_state, np.array([True, False])
    )
    single, _ = policy.predict(frames[0], None, np.array([True]))
    np.testing.assert_allclose(actions[0], single, rtol=1e-6)
    assert actions.shape == (2, 1) and not np.allclose(batch_state[0], batch_state[1])


def test_rollout_resets_the_history_at_every_episode(tmp_path: Path) -> None:
    policy = _stacked_policy(4)
    folder = policy.save(tmp_path / "stacked")
    loaded = load_policy(folder)
    assert loaded.frame_stack == 4 and loaded.observation_size == 8
    env = gym.make(FIELD, randomize=False, episode_s=2.0, **loaded.env_kwargs)
    first = rollout(env, loaded, seed=4)
    second = rollout(env, loaded, seed=4)  # the same episode again: no history left over
    np.testing.assert_array_equal(first.actions, second.actions)
    # by hand, from the observations of the trace
    state = None
    for t, obs in enumerate(first.observations):
        action, state = loaded.predict(obs, state, np.array([t == 0]))
        np.testing.assert_array_equal(action, first.actions[t])


# ------------------------------------------------------------------- a tiny field training
def _tiny(tmp_path: Path, **changes: Any) -> TrainConfig:
    values: dict[str, Any] = {
        "run_dir": str(tmp_path / "run"),
        "total_timesteps": 120,
        "num_envs": 2,
        "n_steps": 30,
        "batch_size": 30,
        "n_epochs": 2,
        "episode_s": 3.0,
        "control_dt_s": 0.1,
        "frame_stack": 3,
        "checkpoint_every": 60,
        "validate_every": 60,
        "validation_episodes": 1,
        "tensorboard": False,
        "learning_rate": 3e-3,
    }
    values.update(changes)
    return TrainConfig.for_env(FIELD, **values)


@pytest.fixture(scope="module")
def field_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[TrainConfig, Path]:
    pytest.importorskip("stable_baselines3")
    from agents.train import train

    config = _tiny(tmp_path_factory.mktemp("field"))
    return config, train(config, progress=False)


def test_tiny_field_training_writes_a_field_model(field_run: tuple[TrainConfig, Path]) -> None:
    config, model = field_run
    run = config.resolved_run_dir()
    assert is_model_folder(model) and is_model_folder(run / "best")
    policy = load_policy(model)
    assert policy.env_id == FIELD and policy.frame_stack == 3
    assert policy.env_kwargs == {
        "base_controller": ENV_DEFAULTS[FIELD]["base_controller"],
        "control_dt_s": 0.1,
        "residual_scale_nm": ENV_DEFAULTS[FIELD]["residual_scale_nm"],
        "min_torque_nm": 0.0,
        "max_torque_nm": 50_800.0,
        "observation": "surface",
    }
    assert policy.metadata["train_config"]["env_id"] == FIELD
    lines = (run / "validation.csv").read_text().splitlines()
    # at 60 decisions and once at the end (120), after the last update
    assert lines[0].startswith("timesteps,iae_ratio") and len(lines) == 1 + 2
    assert [line.split(",")[0] for line in lines[1:]] == ["60", "120"]
    # the first validation (60 decisions in) is close to the base controller
    assert abs(float(lines[1].split(",")[1]) - 1.0) < 0.2


def test_saved_field_model_acts_as_sb3s_policy(field_run: tuple[TrainConfig, Path]) -> None:
    """The last checkpoint's SB3 policy (rebuilt from its training state) and the portable
    model saved beside it give the same actions over whole episodes of the training stack:
    SB3 through VecFrameStack and VecNormalize, the portable model from the plain
    observations with its own history."""
    from agents.checkpoints import load_checkpoint
    from agents.train import find_last_checkpoint, make_model, make_training_env

    config, _ = field_run
    last = find_last_checkpoint(config.resolved_run_dir())
    assert last is not None
    venv = make_training_env(config)
    model = make_model(config, venv)
    load_checkpoint(model, venv, last.path)
    venv.training = False
    venv.norm_reward = False
    portable = load_policy(last.path)
    assert portable.frame_stack == 3
    venv.seed(11)
    obs = venv.reset()
    start = np.ones(config.num_envs, bool)
    state = None
    moved = 0.0
    for _ in range(45):  # one and a half episodes
        expected, _ = model.predict(obs, deterministic=True)
        raw = venv.get_original_obs()[:, -portable.observation_size :]
        action, state = portable.predict(raw, state, start)
        np.testing.assert_allclose(action, expected, rtol=1e-5, atol=1e-6)
        moved = max(moved, float(np.abs(action).max()))
        obs, _, dones, _ = venv.step(action)
        start = dones
    assert moved > 1e-3  # the trained residual is not zero: the comparison can fail
    venv.close()


# --------------------------------------------------------------- the shipped field model
@pytest.mark.skipif(not is_model_folder(SHIPPED), reason="no shipped field model")
def test_shipped_field_model_names_its_env_and_how_to_retrain_it() -> None:
    policy = load_policy(SHIPPED)
    assert policy.env_id == FIELD and policy.env_kwargs["observation"] == "surface"
    assert policy.env_kwargs["base_controller"] == ENV_DEFAULTS[FIELD]["base_controller"]
    assert policy.frame_stack == ENV_DEFAULTS[FIELD]["frame_stack"]
    record = policy.metadata["train_config"]
    assert record["env_id"] == FIELD
    assert "drill-gym train --env DrillStringField-v0" in policy.metadata["source"]
    # trained with the field defaults: the default command retrains it
    for name, value in ENV_DEFAULTS[FIELD].items():
        assert record[name] == value, name
    assert record["seed"] == TrainConfig().seed
    assert record["run_dir"] == record["save_dir"] == ""  # no folder of the trainer's machine


_NUMPY_ONLY = """
import json, sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("torch", "stable_baselines3"):
            raise ImportError(f"{name} is blocked in this test")
        return None
sys.meta_path.insert(0, _Block())
sys.modules["torch"] = None
sys.modules["stable_baselines3"] = None
import gymnasium as gym, numpy as np
import drill_env
from agents.policy import load_policy
policy = load_policy(sys.argv[1])
env = gym.make(policy.env_id, randomize=False, episode_s=4.0, **policy.env_kwargs)
obs, _ = env.reset(seed=7)
state, start, actions, torques = None, np.array([True]), [], []
for _ in range(10):
    action, state = policy.predict(obs, state, start)
    obs, _, terminated, truncated, info = env.step(action)
    start = np.array([terminated or truncated])
    actions.append(float(action[0]))
loaded = [m for m in sys.modules if sys.modules[m] is not None]
assert not any(m.split(".")[0] in ("torch", "stable_baselines3") for m in loaded)
print(json.dumps(actions))
"""


@pytest.mark.skipif(not is_model_folder(SHIPPED), reason="no shipped field model")
def test_shipped_field_model_runs_the_field_env_with_numpy_only() -> None:
    """The shipped field agent loads and drives ``DrillStringField-v0`` for a few decisions in
    a process where torch and Stable-Baselines3 cannot be imported, and acts as the same model
    does in this process (with its own frame history)."""
    result = subprocess.run(
        [sys.executable, "-c", _NUMPY_ONLY, str(SHIPPED)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    actions = np.array(json.loads(result.stdout.strip().splitlines()[-1]))
    policy = load_policy(SHIPPED)
    env = gym.make(FIELD, randomize=False, episode_s=4.0, **policy.env_kwargs)
    trace = rollout(env, policy, seed=7)
    np.testing.assert_allclose(actions, trace.actions[:10].ravel(), rtol=1e-6, atol=1e-7)
    assert np.abs(actions).max() > 1e-3  # a trained residual, not the zero-initialised one


@pytest.mark.skipif(not is_model_folder(SHIPPED), reason="no shipped field model")
def test_evaluate_picks_the_field_model_only_on_its_env(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from experiments.evaluate import main as evaluate_main
    from experiments.evaluate import shipped_models

    assert SHIPPED in shipped_models()
    argv = ["--scenarios", "f03", "--controllers", "soft_speed", "--observations", "surface"]
    out = tmp_path / "field"
    assert (
        evaluate_main(["--env", FIELD, *argv, "--no-plots", "--no-progress", "--out", str(out)])
        == 0
    )
    captured = capsys.readouterr()
    assert "residual_ppo is for DrillString-v0, left out" in captured.err
    assert "| field_agent (surface) |" in captured.out
    paper = ["--scenarios", "h01", "--controllers", "proposed", "--no-plots", "--no-progress"]
    assert evaluate_main([*paper, "--out", str(tmp_path / "paper")]) == 0
    captured = capsys.readouterr()
    assert "field_agent is for DrillStringField-v0, left out" in captured.err
    assert "field_agent" not in captured.out


# --------------------------------------------------------------- the group table of the doc
def _benchmark() -> Any:
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "field_agent_bench", ROOT / "benchmarks" / "field_agent.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_group_means_by_hand(tmp_path: Path) -> None:
    def row(k: int, controller: str, iae: str, sev: float, prone: bool) -> dict[str, str]:
        deep = k in (9, 10)
        return {
            "scenario": f"f{k:02d}",
            "controller": controller,
            "observation": "surface",
            "parameters": "deep_5000m" if deep else "field_2500m",
            "in_range": str(k < 9),
            "prone": str(prone),
            "iae": iae,
            "rmsd_nm": "12000" if k % 2 else "14000",
            "stick_slip_severity": str(sev),
        }

    rows = [
        row(1, "a", "100", 0.5, True),
        row(2, "a", "300", 0.1, False),
        row(9, "a", "500", 1.0, True),
        row(10, "a", "700", 2.0, True),
        row(13, "a", "50", 0.2, False),
        row(13, "b", "", 0.0, False),  # b could not run there: left out
    ]
    means = {(m["group"].split()[0], m["controller"]): m for m in _benchmark().group_means(rows)}
    assert set(means) == {("in", "a (surface)"), ("deep", "a (surface)"),
                          ("outside", "a (surface)"), ("all", "a (surface)")}  # fmt: skip
    inside = means[("in", "a (surface)")]
    assert (inside["n"], inside["iae"], inside["rmsd_knm"]) == (2, 200.0, 13.0)
    assert (inside["severity_prone"], inside["n_prone"]) == (0.5, 1)
    assert means[("deep", "a (surface)")]["severity_prone"] == pytest.approx(1.5)
    assert means[("outside", "a (surface)")]["severity_prone"] is None
    everything = means[("all", "a (surface)")]
    assert (everything["n"], everything["iae"]) == (5, 330.0)
    assert everything["severity_prone"] == pytest.approx(3.5 / 3)
