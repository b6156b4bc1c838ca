"""Tests of the residual PPO agent (``agents``): the SB3 adapter of the vector env, a tiny
training run end to end, resume, export/load against SB3's own predictions, zero-residual
equivalence, the run-folder rules, the command line and the loading errors.

Tiny budgets only (a few hundred steps); the real training is timed in ``benchmarks/``.
Hostile model files are in ``tests/test_model_files.py``.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import safetensors.numpy

pytest.importorskip("stable_baselines3")
pytest.importorskip("torch")

import drill_env  # noqa: E402,F401
from agents import DEFAULT_MODEL_DIR, export_policy, load_default_policy, load_policy  # noqa: E402
from agents.checkpoints import load_checkpoint  # noqa: E402
from agents.config import TrainConfig, field_docs  # noqa: E402
from agents.policy import is_model_folder, policy_from_sb3  # noqa: E402
from agents.train import (  # noqa: E402
    find_last_checkpoint,
    make_model,
    make_training_env,
    planned_timesteps,
    train,
)
from agents.vec_env import GymnasiumVecEnv, LeanVecNormalize  # noqa: E402
from drill_env.evaluation import ZeroAction, episode_metrics, rollout  # noqa: E402
from experiments.cli import main as cli_main  # noqa: E402
from experiments.evaluate import main as evaluate_main  # noqa: E402
from experiments.train import OPTION_NAMES, parse_config  # noqa: E402

MODEL_FILES = ("config.json", "policy.safetensors", "obs_norm.safetensors")


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
    with pytest.raises(
        ValueError, match=r"--num-envs = 0 is out of range: allowed an integer >= 1"
    ):
        TrainConfig(num_envs=0)
    with pytest.raises(TypeError, match=r"unrecognized config key\(s\): nope"):
        TrainConfig.from_dict({"nope": 1})
    with pytest.raises(
        ValueError, match=r"^--total-timesteps = -5 is out of range: allowed an integer >= 1$"
    ):
        parse_config(["--total-timesteps", "-5"])
    with pytest.raises(ValueError, match=r"--gamma = 1.5 is out of range: allowed \(0, 1\]"):
        parse_config(["--gamma", "1.5"])
    with pytest.raises(ValueError, match=r"--resume and --overwrite exclude each other"):
        parse_config(["--resume", "--overwrite"])


def test_help_is_plain_text_and_shows_every_default(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        parse_config(["--help-all"])
    text = capsys.readouterr().out
    assert "``" not in text and ":class:" not in text and ":func:" not in text
    for f in dataclasses.fields(TrainConfig):
        flag = (
            OPTION_NAMES[f.name].flag if f.name in OPTION_NAMES else "--" + f.name.replace("_", "-")
        )
        assert flag in text, flag
    # one "(default: ...)" per option (argparse wraps lines, so join them first)
    flat = " ".join(text.split())
    assert flat.count("(default: ") == len(dataclasses.fields(TrainConfig))
    assert (
        "(default: 3000000; DrillStringField-v0: " in flat
        and "(default: false)" in flat
        and "(default: 64 64)" in flat
    )
    assert "--no-tensorboard turns it off" in flat


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


def test_lean_training_wrappers_give_sb3s_numbers_bit_for_bit() -> None:
    """The training env's own pieces (the adapter stepping without infos, LeanVecNormalize)
    against SB3's VecNormalize over an adapter that copies infos: the same observations,
    rewards, dones, terminal observations and running statistics, bit for bit, over episodes
    that end."""
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    kwargs = {"base_controller": "proposed", "episode_s": 0.5, "randomize": True}

    def adapter(info_keys: tuple[str, ...]) -> GymnasiumVecEnv:
        vector_env = gym.make_vec("DrillString-v0", num_envs=4, max_episode_steps=4, **kwargs)
        return GymnasiumVecEnv(vector_env, info_keys=info_keys)

    lean_adapter = adapter(())
    assert lean_adapter._step_without_info is not None
    lean = LeanVecNormalize(VecMonitor(lean_adapter), gamma=0.99, clip_obs=2.0, clip_reward=0.5)
    sb3 = VecNormalize(VecMonitor(adapter(("time_s",))), gamma=0.99, clip_obs=2.0, clip_reward=0.5)
    for venv in (lean, sb3):
        venv.seed(3)
    np.testing.assert_array_equal(lean.reset(), sb3.reset())
    rng = np.random.default_rng(2)
    for _ in range(13):
        actions = rng.uniform(-1, 1, (4, 1)).astype(np.float32)
        got, expected = lean.step(actions), sb3.step(actions)
        for a, b in zip(got[:3], expected[:3], strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
        for a, b in zip(got[3], expected[3], strict=True):
            assert ("terminal_observation" in a) == ("terminal_observation" in b)
            if "terminal_observation" in a:
                np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
                assert a["episode"]["r"] == b["episode"]["r"]
        np.testing.assert_array_equal(lean.get_original_obs(), sb3.get_original_obs())
        np.testing.assert_array_equal(lean.get_original_reward(), sb3.get_original_reward())
    for name in ("obs_rms", "ret_rms"):
        mine, theirs = getattr(lean, name), getattr(sb3, name)
        np.testing.assert_array_equal(mine.mean, theirs.mean)
        np.testing.assert_array_equal(mine.var, theirs.var)
        assert mine.count == theirs.count
    assert lean.ret_rms.count > 10  # rewards were normalised over ended episodes


def test_lean_running_statistics_are_np_mean_and_np_var() -> None:
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    from agents.vec_env import _update_statistics

    rng = np.random.default_rng(4)
    for batch in (
        rng.normal(3.0, 5.0, (16, 11)).astype(np.float32),
        rng.normal(0.0, 1e-3, (7, 3)),
        rng.normal(-2.0, 1e4, 16),
        rng.normal(0.0, 1.0, 1),
    ):
        mine, theirs = RunningMeanStd(shape=batch.shape[1:]), RunningMeanStd(shape=batch.shape[1:])
        for _ in range(3):
            _update_statistics(mine, batch)
            theirs.update(batch)
            batch = batch * 1.5 + 0.25
        assert np.asarray(mine.mean).tobytes() == np.asarray(theirs.mean).tobytes()
        assert np.asarray(mine.var).tobytes() == np.asarray(theirs.var).tobytes()
        assert mine.count == theirs.count


@pytest.mark.slow
def test_train_throughput_benchmark_compares_two_checkouts() -> None:
    """``benchmarks/train_throughput.py --against`` as a user runs it (this checkout against
    itself, a tiny budget): every rate, the ratio of the best rates and the rounds' median."""
    root = Path(__file__).resolve().parents[1]
    result = subprocess.run(
        [sys.executable, "benchmarks/train_throughput.py", "--against", str(root),
         "--decisions", "320", "--repeat", "1", "--rounds", "1"],
        cwd=root, capture_output=True, text=True, check=True, timeout=900,
    )  # fmt: skip
    rows = [line for line in result.stdout.splitlines() if line.startswith("(")]
    assert [row[:24] for row in rows] == [
        "(a) training env alone, ",
        "(a) training env alone, ",
        "(b) PPO collecting rollo",
        "(b) PPO end to end (roll",
        "(b) PPO updates alone   ",
    ]
    assert all(float(row.split()[-1]) > 0 for row in rows)
    assert all(float(row.split()[-3]) > 0 for row in rows)  # the ratio of the best rates


# ------------------------------------------------------------------------ training, loading
def test_tiny_training_run_writes_a_loadable_model(trained: Path) -> None:
    for name in MODEL_FILES:
        assert (trained / name).is_file()
    assert not (trained / "model.zip").exists()
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
    policy = load_policy(trained)
    copy = policy.save(tmp_path / "copy")
    again = load_policy(copy)
    obs = np.random.default_rng(0).normal(size=(32, 11)).astype(np.float32)
    a1, _ = policy.predict(obs)
    a2, _ = again.predict(obs)
    np.testing.assert_array_equal(a1, a2)
    assert again.metadata["train_config"] == policy.metadata["train_config"]


def _sb3_reference(model: Any, policy: Any, obs: np.ndarray) -> np.ndarray:
    """SB3's own deterministic action for raw observations ``obs`` (normalised here, in the
    test, with VecNormalize's formula)."""
    z = np.clip(
        (obs.astype(np.float64) - policy.obs_norm.mean)
        / np.sqrt(policy.obs_norm.var + policy.obs_norm.epsilon),
        -policy.obs_norm.clip_obs,
        policy.obs_norm.clip_obs,
    ).astype(np.float32)
    action, _ = model.predict(z, deterministic=True)
    return np.asarray(action)


@pytest.mark.parametrize("variant", ["tanh", "relu-3-layers", "gsde"])
def test_exported_policy_matches_sb3_predictions(variant: str, tmp_path: Path) -> None:
    """A freshly built SB3 PPO (random weights), exported and loaded back without torch, acts
    as SB3 does on recorded observations, to float32 rounding."""
    import torch as th
    from stable_baselines3 import PPO

    kwargs = {"base_controller": "proposed", "control_dt_s": 0.1, "residual_scale_nm": 1e4}
    env = gym.make("DrillString-v0", max_episode_steps=-1, randomize=True, episode_s=20.0, **kwargs)
    recorded = np.asarray(rollout(env, ZeroAction(), seed=4).observations, dtype=np.float32)
    arch: dict[str, Any] = {"net_arch": [32, 32], "activation_fn": th.nn.Tanh}
    if variant == "relu-3-layers":
        arch = {"net_arch": [16, 24, 8], "activation_fn": th.nn.ReLU}
    model = PPO(
        "MlpPolicy", env, policy_kwargs=arch, use_sde=variant == "gsde", seed=3, device="cpu"
    )
    rng = np.random.default_rng(1)
    mean = recorded.mean(axis=0) + rng.normal(size=11) * 0.1
    var = rng.uniform(0.5, 2, 11) * recorded.var(axis=0) + 1e-4
    z = np.clip((recorded - mean) / np.sqrt(var + 1e-8), -10, 10).astype(np.float32)
    with th.no_grad():  # an action mean spread over [-1, 1] and beyond (clipped)
        latent = model.policy.mlp_extractor.forward_actor(th.as_tensor(z))
        weight = th.as_tensor(rng.normal(size=(1, latent.shape[1])), dtype=th.float32)
        projection = latent @ weight.T
        scale = 1.5 / float(projection.std())
        model.policy.action_net.weight.copy_(weight * scale)
        model.policy.action_net.bias.fill_(-float(projection.mean()) * scale)
    env_kwargs = {**kwargs, "min_torque_nm": 0.0, "max_torque_nm": 50_000.0}
    folder = export_policy(
        model, tmp_path / "m", name="fresh", env_kwargs=env_kwargs, obs_mean=mean, obs_var=var
    )
    policy = load_policy(folder)
    expected = _sb3_reference(model, policy, recorded)
    assert np.ptp(expected) > 1.0 and np.any(np.abs(expected) == 1.0)  # clipped ones too
    actions, _ = policy.predict(recorded)
    np.testing.assert_allclose(actions, expected, atol=1e-5)  # float32 rounding
    single = np.array([policy.predict(o)[0] for o in recorded[:20]])
    np.testing.assert_allclose(single, expected[:20], atol=1e-5)
    if variant == "gsde":
        # The stochastic spread: SB3's distribution for the same observations.
        z = th.as_tensor(policy.normalize(recorded[:50]))
        sb3_std = model.policy.get_distribution(z).distribution.stddev.detach().numpy()
        latent = policy.network.latent(policy.normalize(recorded[:50]).astype(np.float64))
        np.testing.assert_allclose(policy.network.action_std(latent), sb3_std, rtol=1e-3)


def _old_sb3_model_folder(config: TrainConfig, folder: Path) -> tuple[Any, Any]:
    """A model folder as earlier versions wrote it: SB3's model.zip (a pickle, ours), the
    obs_norm.npz and a format-1 config.json."""
    import torch as th

    venv = make_training_env(config)
    model = make_model(dataclasses.replace(config, zero_init_action=False), venv)
    with th.no_grad():
        model.policy.action_net.weight.mul_(100.0)
    folder.mkdir()
    model.save(folder / "model.zip")
    rng = np.random.default_rng(2)
    mean, var = rng.normal(size=11), rng.uniform(0.5, 2.0, 11)
    np.savez(folder / "obs_norm.npz", mean=mean, var=var, clip_obs=10.0, epsilon=1e-8)
    record = {
        "format": 1,
        "name": "old",
        "env_kwargs": {
            "base_controller": "proposed",
            "control_dt_s": 0.1,
            "residual_scale_nm": 10000.0,
            "min_torque_nm": 0.0,
            "max_torque_nm": 50000.0,
        },
        "observation_size": 11,
        "train_config": json.loads(config.to_json()),
        "timesteps": 0,
    }
    (folder / "config.json").write_text(json.dumps(record))
    return model, venv


def test_old_sb3_model_loads_and_converts_with_the_opt_in(tmp_path: Path) -> None:
    from agents.convert import convert_model

    model, venv = _old_sb3_model_folder(tiny_config(tmp_path), tmp_path / "old")
    for trust in (False, True):  # a folder is never searched for a pickle to trust
        with pytest.raises(ValueError, match=r"model.zip' is a Stable-Baselines3 model \(a pickle"):
            load_policy(tmp_path / "old", trust_pickle=trust)
    obs = np.random.default_rng(5).normal(size=(64, 11)).astype(np.float32)
    policy = load_policy(tmp_path / "old" / "model.zip", trust_pickle=True)
    expected = _sb3_reference(model, policy, obs)
    assert np.ptp(expected) > 0.5
    np.testing.assert_allclose(policy.predict(obs)[0], expected, atol=1e-5)
    convert_model(tmp_path / "old" / "model.zip", tmp_path / "new", trust_pickle=True)
    assert {p.name for p in (tmp_path / "new").iterdir()} == set(MODEL_FILES)
    converted = load_policy(tmp_path / "new")
    np.testing.assert_array_equal(converted.predict(obs)[0], policy.predict(obs)[0])
    assert converted.metadata["source"].startswith("converted from a Stable-Baselines3")
    assert converted.metadata["train_config"]["n_steps"] == 64
    venv.close()


def test_resume_from_an_old_pickled_checkpoint_with_the_opt_in(tmp_path: Path) -> None:
    from agents.checkpoints import load_checkpoint as fill

    config = tiny_config(tmp_path, total_timesteps=128, validate_every=0)
    train(config)
    run_dir = config.resolved_run_dir()
    folder = run_dir / "checkpoints"
    venv = make_training_env(config)
    model = make_model(config, venv)
    fill(model, venv, folder / "steps_128")
    model.save(folder / "rl_model_128_steps.zip")  # what earlier versions wrote
    venv.save(str(folder / "rl_model_vecnormalize_128_steps.pkl"))
    venv.close()
    shutil.rmtree(folder / "steps_128")
    resumed = dataclasses.replace(config, total_timesteps=256, resume=True)
    with pytest.raises(ValueError, match=r"pickled Stable-Baselines3 checkpoint .*--trust-pickle"):
        train(resumed)
    files = (
        str(folder / "rl_model_128_steps.zip"),
        str(folder / "rl_model_vecnormalize_128_steps.pkl"),
    )
    with pytest.raises(ValueError, match=r"naming its files: --trust-pickle .*rl_model_128"):
        train(dataclasses.replace(resumed, trust_pickle=files[:1]))  # both pickles are read
    out = train(dataclasses.replace(resumed, trust_pickle=files))
    assert json.loads((out / "config.json").read_text())["resumed_from"] == 128
    last = find_last_checkpoint(run_dir)
    assert last is not None and last.steps == 256 and not last.legacy


def test_stochastic_actions_are_seeded_gaussian_samples(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, log_std_init=-2.0, zero_init_action=False)
    venv = make_training_env(config)
    model = make_model(config, venv)
    policy = policy_from_sb3(model, name="s", env_kwargs={"base_controller": "proposed"})
    obs = np.zeros((4000, 11), np.float32)
    policy.seed(7)
    a, _ = policy.predict(obs, deterministic=False)
    policy.seed(7)
    b, _ = policy.predict(obs, deterministic=False)
    np.testing.assert_array_equal(a, b)
    mean, _ = policy.predict(obs[0])
    assert abs(float(mean[0])) < 0.5  # far from the clipping bounds
    assert np.mean(a) == pytest.approx(float(mean[0]), abs=0.01)
    assert np.std(a) == pytest.approx(np.exp(-2.0), rel=0.05)
    venv.close()


def test_resume_continues_from_the_last_checkpoint(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, total_timesteps=256, validate_every=0)
    out = train(config)
    last = find_last_checkpoint(config.resolved_run_dir())
    assert last is not None and last.steps == 256 and not last.legacy
    assert {p.name for p in last.path.iterdir()} == {
        *MODEL_FILES,
        "training.json",
        "training_state.safetensors",
        "vecnormalize.safetensors",
    }
    # The checkpoint loads into a fresh model: the weights are the saved ones.
    venv = make_training_env(config)
    model = make_model(config, venv)
    assert load_checkpoint(model, venv, last.path) == 256 and model.num_timesteps == 256
    saved = safetensors.numpy.load_file(last.path / "training_state.safetensors")
    for name, tensor in model.policy.state_dict().items():
        np.testing.assert_array_equal(tensor.numpy(), saved[f"policy/{name}"])
    final = load_policy(out)  # the last model, exported separately at the end of the run
    np.testing.assert_array_equal(
        model.policy.action_net.weight.detach().numpy(), final.weights["action.weight"]
    )
    np.testing.assert_array_equal(venv.obs_rms.mean, final.obs_norm.mean)
    # Adam continues: 2 updates x 2 epochs x 2 minibatches of 64 from rollouts of 128.
    steps = {float(s["step"]) for s in model.policy.optimizer.state_dict()["state"].values()}
    assert steps == {8.0}
    venv.close()
    # Resume: timesteps continue from 256 to 512, a new checkpoint at the end.
    out = train(dataclasses.replace(config, total_timesteps=512, resume=True))
    record = json.loads((out / "config.json").read_text())
    assert record["resumed_from"] == 256 and record["run_timesteps"] == 512
    assert (config.resolved_run_dir() / "progress-resumed-at-256.csv").is_file()
    last = find_last_checkpoint(config.resolved_run_dir())
    assert last is not None and last.steps == 512


def test_training_twice_with_one_seed_gives_the_same_model(trained: Path, tmp_path: Path) -> None:
    again = train(tiny_config(tmp_path))
    a = load_policy(trained)
    b = load_policy(again)
    np.testing.assert_array_equal(a.obs_mean, b.obs_mean)
    assert a.weights.keys() == b.weights.keys()
    for name in a.weights:
        np.testing.assert_array_equal(a.weights[name], b.weights[name])


def test_resume_without_checkpoint_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="--resume: no checkpoint in"):
        train(tiny_config(tmp_path, resume=True))


def test_budget_is_rounded_up_to_whole_rollouts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert planned_timesteps(TrainConfig(total_timesteps=20_000)) == 32_000
    assert planned_timesteps(TrainConfig()) == 3_008_000  # 188 rollouts of 16,000
    config = tiny_config(tmp_path, total_timesteps=200, validate_every=0, checkpoint_every=0)
    out = train(config)
    text = capsys.readouterr().out
    assert (
        "training 256 decisions: --total-timesteps 200 rounded up to whole rollouts of 128" in text
    )
    assert "residual_ppo: 128/256 decisions" in text and "residual_ppo: 256/256 decisions" in text
    assert json.loads((out / "config.json").read_text())["run_timesteps"] == 256
    # A short run without periodic checkpoints still ends with one, so it can be resumed.
    last = find_last_checkpoint(config.resolved_run_dir())
    assert last is not None and last.steps == 256


def test_existing_run_folder_is_refused_unless_resume_or_overwrite(tmp_path: Path) -> None:
    config = tiny_config(tmp_path, total_timesteps=128, validate_every=0)
    run_dir = config.resolved_run_dir()
    run_dir.mkdir(parents=True)
    (run_dir / "leftover.txt").write_text("half-written")
    with pytest.raises(ValueError, match=r"already holds files .*--resume .*--overwrite"):
        train(config)
    with pytest.raises(ValueError, match=r"--overwrite: .* does not look like a run folder"):
        train(dataclasses.replace(config, overwrite=True))
    assert (run_dir / "leftover.txt").is_file()  # not deleted
    (run_dir / "leftover.txt").unlink()
    train(config)  # an empty folder is fine
    train(dataclasses.replace(config, overwrite=True))  # a run folder: cleared and rerun
    assert not (run_dir / "progress-resumed-at-128.csv").exists()


def test_progress_bar_without_rich_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "rich" else real(name, *a)
    )
    with pytest.raises(ValueError, match=r"--progress-bar needs the package\(s\) rich"):
        train(tiny_config(tmp_path, progress_bar=True))
    assert not (tmp_path / "run").exists()


def test_command_line_prints_user_errors_on_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cases = [
        (["train", "--total-timesteps", "-5"], "--total-timesteps = -5 is out of range"),
        (["train", "--run-dir", str(tmp_path / "r"), "--resume"], "--resume: no checkpoint in"),
        (
            ["train", "--base-controller", "pid9000"],
            "--base-controller = 'pid9000' is not registered",
        ),
        (["evaluate", str(tmp_path / "nowhere")], "no model at"),
    ]
    for argv, message in cases:
        assert cli_main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"drill-gym {argv[0]}: error: ") and message in err
        assert err.count("\n") == 1 and "Traceback" not in err


def test_zero_residual_reproduces_the_base_controller(tmp_path: Path) -> None:
    config = tiny_config(tmp_path)
    venv = make_training_env(config)
    model = make_model(config, venv)
    rng = np.random.default_rng(1)
    untrained = policy_from_sb3(
        model,
        name="untrained",
        env_kwargs={"base_controller": "proposed"},
        obs_mean=rng.normal(size=11),
        obs_var=rng.uniform(0.5, 2.0, 11),
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
    (folder / "policy.safetensors").write_bytes((trained / "policy.safetensors").read_bytes())
    with pytest.raises(FileNotFoundError, match=r"missing config.json, obs_norm.safetensors"):
        load_policy(folder)


def _copy_model(trained: Path, folder: Path) -> Path:
    folder.mkdir()
    for name in MODEL_FILES:
        (folder / name).write_bytes((trained / name).read_bytes())
    return folder


def test_load_wrong_observation_size(trained: Path, tmp_path: Path) -> None:
    folder = _copy_model(trained, tmp_path / "m")
    record = json.loads((folder / "config.json").read_text())
    record["env_kwargs"]["base_controller"] = None  # direct mode: 9 observations
    (folder / "config.json").write_text(json.dumps(record))
    with pytest.raises(
        ValueError, match=r"field observation_size: wrong observation size: expected 9 .*found 11"
    ):
        load_policy(folder)
    record["observation_size"] = 9
    (folder / "config.json").write_text(json.dumps(record))
    with pytest.raises(
        ValueError, match=r"obs_norm.safetensors': array mean has shape \(11,\): expected \(9,\)"
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
    assert is_model_folder(DEFAULT_MODEL_DIR / "residual_ppo")
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


def test_the_default_command_trains_the_shipped_agent() -> None:
    """``drill-gym train`` with its defaults is the recipe of the shipped agent: every setting
    that shapes the training (not where it writes or how often it checkpoints) is the default."""
    shipped = json.loads((DEFAULT_MODEL_DIR / "residual_ppo" / "config.json").read_text())
    output_only = {"run_dir", "save_dir", "checkpoint_every", "tensorboard", "progress_bar"}
    output_only.add("trust_pickle")  # the files a resume may unpickle (recorded as false then)
    # settings added after the shipped run, with the value that run had (one env, no stacking)
    later = {
        "env_id": "DrillString-v0",
        "observation": "",
        "frame_stack": 1,
        "training_ranges": "env",
        "validation_severity_weight": 0.0,
    }
    record = {**later, **shipped["train_config"]}
    defaults = dataclasses.asdict(TrainConfig())
    differ = {
        key: (record.get(key), value)
        for key, value in defaults.items()
        if key not in output_only and record.get(key) != value
    }
    assert not differ
