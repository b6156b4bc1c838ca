"""Tests of the residual PPO agent (``agents``): the SB3 adapter of the vector env, a tiny
training run end to end, resume, save/load, zero-residual equivalence and the loading errors.

Tiny budgets only (a few hundred steps); the real training is timed in ``benchmarks/``.
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

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

import drill_env  # noqa: E402,F401
from agents import DEFAULT_MODEL_DIR, ResidualPolicy, load_default_policy, load_policy  # noqa: E402
from agents.config import TrainConfig, field_docs, parse_config  # noqa: E402
from agents.train import find_last_checkpoint, make_model, make_training_env, train  # noqa: E402
from agents.vec_env import GymnasiumVecEnv  # noqa: E402
from drill_env.evaluation import ZeroAction, episode_metrics, rollout  # noqa: E402
from experiments.evaluate import main as evaluate_main  # noqa: E402


def tiny_config(tmp_path: Path, **changes: Any) -> TrainConfig:
    """A run of a few hundred decisions on 10 s episodes."""
    values: dict[str, Any] = {
        "run_dir": str(tmp_path / "run"),
        "total_timesteps": 256,
        "num_envs": 2,
        "n_steps": 64,
        "batch_size": 64,
        "n_epochs": 2,
        "episode_s": 10.0,
        "checkpoint_every": 128,
        "validate_every": 128,
        "validation_episodes": 1,
        "progress_bar": False,
        "tensorboard": False,
    }
    values.update(changes)
    return TrainConfig(**values)


@pytest.fixture(scope="module")
def trained(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The final model folder of one tiny training run."""
    return train(tiny_config(tmp_path_factory.mktemp("tiny")))


# ----------------------------------------------------------------------------- import, config
def test_import_agents_does_not_import_torch() -> None:
    code = (
        "import sys, agents; agents.DEFAULT_MODEL_DIR; "
        "sys.exit(int('torch' in sys.modules or 'stable_baselines3' in sys.modules))"
    )
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_every_config_field_has_a_docstring() -> None:
    docs = field_docs()
    missing = [f.name for f in dataclasses.fields(TrainConfig) if not docs.get(f.name)]
    assert missing == []


def test_parse_config_flags() -> None:
    config = parse_config(
        ["--seed", "7", "--net-arch", "32", "32", "--no-norm-reward", "--resume", "--gamma", "0.99"]
    )
    assert (config.seed, config.net_arch, config.norm_reward, config.resume, config.gamma) == (
        7,
        [32, 32],
        False,
        True,
        0.99,
    )


def test_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError, match=r"num_envs = 0 is out of range"):
        TrainConfig(num_envs=0)
    with pytest.raises(TypeError, match=r"unrecognized config key\(s\): nope"):
        TrainConfig.from_dict({"nope": 1})


# ----------------------------------------------------------------------------------- adapter
def test_adapter_matches_single_envs_and_autoresets_in_the_same_step() -> None:
    kwargs = {"base_controller": "proposed", "control_dt_s": 0.1, "episode_s": 0.5}
    venv = GymnasiumVecEnv(
        gym.make_vec("DrillString-v0", num_envs=3, max_episode_steps=5, **kwargs)
    )
    venv.seed(11)
    obs = venv.reset()
    singles = [gym.make("DrillString-v0", max_episode_steps=5, **kwargs) for _ in range(3)]
    expected = np.array([env.reset(seed=11 + i)[0] for i, env in enumerate(singles)])
    np.testing.assert_array_equal(obs, expected)
    actions = np.array([[0.1], [-0.2], [0.3]], dtype=np.float32)
    for step in range(5):
        obs, rewards, dones, infos = venv.step(actions)
        results = [env.step(actions[i]) for i, env in enumerate(singles)]
        np.testing.assert_allclose(rewards, [r[1] for r in results], rtol=1e-6)
        if step < 4:
            np.testing.assert_array_equal(obs, [r[0] for r in results])
            assert not dones.any()
    assert dones.all()
    for i, info in enumerate(infos):
        np.testing.assert_array_equal(info["terminal_observation"], results[i][0])
        assert info["TimeLimit.truncated"] is True
    # The returned observation already belongs to the next episode: the string is at rest.
    assert np.all(obs[:, 8] == 0.0)  # last applied torque of a fresh episode
    venv.close()


class _CountingVectorEnv(gym.vector.VectorEnv):
    """Two counters in next-step autoreset mode with partial reset; env 0 ends after 2 steps,
    env 1 after 3."""

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.NEXT_STEP}  # noqa: RUF012

    def __init__(self) -> None:
        self.num_envs = 2
        self.single_observation_space = gym.spaces.Box(-100, 100, (1,), np.float32)
        self.single_action_space = gym.spaces.Box(-1, 1, (1,), np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, 2)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, 2)
        self.lengths = np.array([2, 3])
        self.t = np.zeros(2)
        self.pending = np.zeros(2, dtype=bool)

    def reset(self, *, seed: Any = None, options: Any = None) -> tuple[Any, dict[str, Any]]:
        mask = (options or {}).get("reset_mask", np.ones(2, dtype=bool))
        self.t[mask] = 0
        self.pending[mask] = False
        return self.t[:, None].astype(np.float32), {}

    def step(self, actions: Any) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
        rewards = np.ones(2)
        self.t[self.pending] = 0
        rewards[self.pending] = 0.0
        self.t[~self.pending] += 1
        truncated = (self.t >= self.lengths) & ~self.pending
        self.pending = truncated.copy()
        return self.t[:, None].astype(np.float32), rewards, np.zeros(2, bool), truncated, {}


def test_adapter_resets_only_the_strings_that_ended() -> None:
    venv = GymnasiumVecEnv(_CountingVectorEnv())
    venv.reset()
    actions = np.zeros((2, 1), np.float32)
    venv.step(actions)
    obs, rewards, dones, infos = venv.step(actions)
    assert dones.tolist() == [True, False] and obs[:, 0].tolist() == [0.0, 2.0]
    assert infos[0]["terminal_observation"][0] == 2.0 and infos[0]["TimeLimit.truncated"]
    obs, rewards, dones, infos = venv.step(actions)  # env 0 runs on, env 1 ends
    assert obs[:, 0].tolist() == [1.0, 0.0] and rewards.tolist() == [1.0, 1.0]
    assert dones.tolist() == [False, True] and infos[1]["terminal_observation"][0] == 3.0


# ------------------------------------------------------------------------ training, loading
def test_tiny_training_run_writes_a_loadable_model(trained: Path) -> None:
    for name in ("model.zip", "obs_norm.npz", "config.json"):
        assert (trained / name).is_file()
    run_dir = trained.parent
    assert (run_dir / "config.json").is_file() and (run_dir / "validation.csv").is_file()
    record = json.loads((trained / "config.json").read_text())
    assert record["env_kwargs"]["base_controller"] == "proposed"
    assert record["train_config"]["total_timesteps"] == 256
    policy = load_policy(trained, base_controller="proposed")
    assert policy.name == "residual_ppo" and policy.observation_size == 11
    action, state = policy.predict(np.zeros(11, np.float32))
    assert action.shape == (1,) and state is None
    actions, _ = policy.predict(np.zeros((4, 11), np.float32))
    assert actions.shape == (4, 1)


def test_save_load_round_trip_predicts_the_same(trained: Path, tmp_path: Path) -> None:
    from agents.policy import save_policy

    policy = load_policy(trained)
    copy = save_policy(
        policy.model,
        tmp_path / "copy",
        name="copy",
        env_kwargs=policy.env_kwargs,
        obs_mean=policy.obs_mean,
        obs_var=policy.obs_std**2 - 1e-8,
        clip_obs=policy.clip_obs,
    )
    again = load_policy(copy)
    obs = np.random.default_rng(0).normal(size=(32, 11)).astype(np.float32)
    a1, _ = policy.predict(obs)
    a2, _ = again.predict(obs)
    np.testing.assert_allclose(a1, a2, atol=1e-6)
    # The NumPy forward pass matches SB3's own deterministic prediction.
    a3, _ = policy.model.predict(policy.normalize(obs), deterministic=True)
    np.testing.assert_allclose(a1, a3, atol=1e-5)


def test_resume_continues_from_the_last_checkpoint(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, total_timesteps=256, validate_every=0)
    train(config)
    last = find_last_checkpoint(config.resolved_run_dir())
    assert last is not None and last[2] == 256 and last[1] is not None
    out = train(dataclasses.replace(config, total_timesteps=512, resume=True))
    record = json.loads((out / "config.json").read_text())
    assert record["resumed_from"] == 256 and record["run_timesteps"] == 512
    assert (config.resolved_run_dir() / "progress-resumed-at-256.csv").is_file()


def test_training_twice_with_one_seed_gives_the_same_model(trained: Path, tmp_path: Path) -> None:
    again = train(tiny_config(tmp_path))
    a = load_policy(trained)
    b = load_policy(again)
    np.testing.assert_array_equal(a.obs_mean, b.obs_mean)
    for pa, pb in zip(a.model.policy.parameters(), b.model.policy.parameters(), strict=True):
        np.testing.assert_array_equal(pa.detach().numpy(), pb.detach().numpy())


def test_resume_without_checkpoint_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="--resume: no checkpoint in"):
        train(tiny_config(tmp_path, resume=True))


def test_zero_residual_reproduces_the_base_controller(tmp_path: Path) -> None:
    config = tiny_config(tmp_path)
    venv = make_training_env(config)
    model = make_model(config, venv)
    rng = np.random.default_rng(1)
    untrained = ResidualPolicy(
        model,
        rng.normal(size=11),
        rng.uniform(0.5, 2.0, 11),
        {"base_controller": "proposed"},
        "untrained",
    )
    kwargs = {
        "base_controller": "proposed",
        "randomize": False,
        "episode_s": 30.0,
        "control_dt_s": config.control_dt_s,
        "residual_scale_nm": config.residual_scale_nm,
    }
    env = gym.make("DrillString-v0", max_episode_steps=300, **kwargs)
    base = episode_metrics(rollout(env, ZeroAction(), seed=3))
    agent = episode_metrics(rollout(env, untrained, seed=3))
    for key in ("iae", "ise", "rmsd_nm", "overshoot_pct", "stick_slip_severity"):
        assert agent[key] == pytest.approx(base[key], rel=0.01), key
    venv.close()


# -------------------------------------------------------------------------- loading errors
def test_load_missing_path(tmp_path: Path) -> None:
    with pytest.raises(
        FileNotFoundError, match=r"no model at .*nowhere.*: expected a model folder"
    ):
        load_policy(tmp_path / "nowhere")


def test_load_incomplete_folder(trained: Path, tmp_path: Path) -> None:
    folder = tmp_path / "m"
    folder.mkdir()
    (folder / "model.zip").write_bytes((trained / "model.zip").read_bytes())
    with pytest.raises(FileNotFoundError, match=r"missing obs_norm.npz, config.json"):
        load_policy(folder)


def _copy_model(trained: Path, folder: Path) -> Path:
    folder.mkdir()
    for name in ("model.zip", "obs_norm.npz", "config.json"):
        (folder / name).write_bytes((trained / name).read_bytes())
    return folder


def test_load_corrupt_zip(trained: Path, tmp_path: Path) -> None:
    folder = _copy_model(trained, tmp_path / "m")
    (folder / "model.zip").write_bytes(b"not a zip at all")
    with pytest.raises(ValueError, match=r"not a valid Stable-Baselines3 model: expected a zip"):
        load_policy(folder)


def test_load_wrong_observation_size(trained: Path, tmp_path: Path) -> None:
    folder = _copy_model(trained, tmp_path / "m")
    record = json.loads((folder / "config.json").read_text())
    record["env_kwargs"]["base_controller"] = None  # direct mode: 9 observations
    (folder / "config.json").write_text(json.dumps(record))
    with pytest.raises(
        ValueError, match=r"wrong observation size: expected 9 .*found statistics of shape \(11,\)"
    ):
        load_policy(folder)
    np.savez(folder / "obs_norm.npz", mean=np.zeros(9), var=np.ones(9), clip_obs=10.0, epsilon=1e-8)
    with pytest.raises(
        ValueError, match=r"wrong observation size: expected 9 .*found a model taking \(11,\)"
    ):
        load_policy(folder)


def test_load_wrong_base_controller(trained: Path, tmp_path: Path) -> None:
    with pytest.raises(
        ValueError,
        match=r"wrong base controller: expected a model trained on 'csmc', found one trained on 'proposed'",
    ):
        load_policy(trained, base_controller="csmc")
    folder = _copy_model(trained, tmp_path / "m")
    record = json.loads((folder / "config.json").read_text())
    record["env_kwargs"]["base_controller"] = "pid9000"
    (folder / "config.json").write_text(json.dumps(record))
    with pytest.raises(
        ValueError, match=r"trained on base controller 'pid9000', which is not registered"
    ):
        load_policy(folder)


def test_load_bad_config_json(trained: Path, tmp_path: Path) -> None:
    folder = _copy_model(trained, tmp_path / "m")
    (folder / "config.json").write_text("{not json")
    with pytest.raises(ValueError, match=r"config.json' is not valid JSON"):
        load_policy(folder)


# ------------------------------------------------------------------ shipped model, evaluation
def test_default_policy_is_the_shipped_residual_agent() -> None:
    policy = load_default_policy()
    if not (DEFAULT_MODEL_DIR / "residual_ppo" / "model.zip").is_file():
        assert policy is None
        return
    assert policy is not None and policy.name == "residual_ppo"
    assert policy.env_kwargs["base_controller"] == "proposed"
    env = gym.make("DrillString-v0", randomize=False, episode_s=5.0, **policy.env_kwargs)
    obs, _ = env.reset(seed=0)
    action, _ = policy.predict(obs)
    assert env.action_space.contains(action)


def test_evaluate_cli_writes_table_and_files(trained: Path, tmp_path: Path) -> None:
    out = tmp_path / "eval"
    code = evaluate_main(
        [
            str(trained),
            "--out",
            str(out),
            "--controllers",
            "proposed",
            "--scenarios",
            "h14",
            "--no-figures",
        ]
    )
    assert code == 0
    rows = json.loads((out / "heldout.json").read_text())
    assert [r["controller"] for r in rows] == ["proposed", "residual_ppo"]
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["goal"]) == {"proposed", "residual_ppo"}
