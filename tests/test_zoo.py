"""Tests of the RL Zoo setup of the residual agent (``agents/zoo``)."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3", reason="agents.zoo needs the [rl] extra")

import drill_env  # noqa: E402, F401  (registers DrillString-v0)
from agents.config import TrainConfig  # noqa: E402
from agents.train import env_kwargs  # noqa: E402
from agents.zoo import HYPERPARAMS_FILE, ZeroInitAction  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
HAVE_ZOO = importlib.util.find_spec("rl_zoo3") is not None
ENV_KWARGS = {
    "base_controller": "proposed",
    "control_dt_s": 0.1,
    "residual_scale_nm": 20_000.0,
    "randomize": True,
    "episode_s": 100.0,
}


def test_the_yaml_reward_weights_make_the_training_reward() -> None:
    """The env kwargs of the file, reward weights as a mapping, give the env the reward of
    ``drill-gym train``: the same ``RewardWeights`` as ``agents.train.env_kwargs``."""
    yaml = pytest.importorskip("yaml", reason="reading the file needs pyyaml (the [dev] extra)")
    kwargs = yaml.safe_load(HYPERPARAMS_FILE.read_text())["DrillString-v0"]["env_kwargs"]
    env = gym.make("DrillString-v0", **kwargs)
    expected = env_kwargs(TrainConfig())["reward_weights"]
    assert env.unwrapped.config.reward_weights == expected  # type: ignore[attr-defined]


def test_zero_init_action_zeroes_only_an_untrained_model() -> None:
    """At the start of training the action mean is exactly 0; a model that was already
    updated keeps its weights."""
    import torch as th
    from stable_baselines3 import PPO

    env = gym.make("DrillString-v0", **ENV_KWARGS)
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, device="cpu", seed=0)
    callback = ZeroInitAction()
    callback.init_callback(model)
    callback.on_training_start({}, {})
    weights = [p.detach().clone() for p in model.policy.action_net.parameters()]
    assert all(bool(th.all(w == 0)) for w in weights)
    obs, _ = env.reset(seed=0)
    action, _ = model.predict(obs, deterministic=True)
    assert float(np.abs(action).max()) == 0.0
    with th.no_grad():
        for p in model.policy.action_net.parameters():
            p.fill_(0.5)
    model._n_updates = 3
    callback.on_training_start({}, {})
    assert all(bool(th.all(p == 0.5)) for p in model.policy.action_net.parameters())


def test_hyperparameters_are_the_train_config_defaults() -> None:
    """The YAML file carries TrainConfig's defaults (read with the zoo's own YAML loader)."""
    yaml = pytest.importorskip("yaml", reason="reading the file needs pyyaml (the [dev] extra)")
    params = yaml.safe_load(HYPERPARAMS_FILE.read_text())["DrillString-v0"]
    c = TrainConfig()
    assert params["n_envs"] == c.num_envs
    assert params["n_timesteps"] == c.total_timesteps
    assert params["n_steps"] == c.n_steps and params["batch_size"] == c.batch_size
    assert params["n_epochs"] == c.n_epochs
    assert params["learning_rate"].startswith("lin_") and c.anneal_lr
    assert float(params["learning_rate"][4:]) == c.learning_rate
    for key in ("gamma", "gae_lambda", "clip_range", "ent_coef", "vf_coef", "max_grad_norm"):
        assert params[key] == getattr(c, key), key
    assert params["normalize"]["norm_obs"] == c.norm_obs
    assert params["normalize"]["norm_reward"] == c.norm_reward
    assert "pi=[64, 64], vf=[64, 64]" in params["policy_kwargs"] and c.net_arch == [64, 64]
    assert f"log_std_init={c.log_std_init}" in params["policy_kwargs"]
    kwargs = params["env_kwargs"]
    assert kwargs["base_controller"] == c.base_controller
    assert kwargs["control_dt_s"] == c.control_dt_s
    assert kwargs["residual_scale_nm"] == c.residual_scale_nm
    assert kwargs["episode_s"] == c.episode_s and kwargs["noise_std_rad_s"] == c.noise_std_rad_s
    weights = kwargs["reward_weights"]
    for name in ("tracking", "chattering", "chattering_scale_nm", "stuck", "torque", "residual"):
        assert weights[name] == getattr(c, f"reward_{name}"), name
    assert params["callback"] == ["agents.zoo.ZeroInitAction"] and c.zero_init_action


@pytest.mark.skipif(not HAVE_ZOO, reason="rl_zoo3 is not installed: pip install -e '.[zoo]'")
def test_zoo_trains_and_saves_a_model(tmp_path: Path) -> None:
    """``python -m rl_zoo3.train`` with the shipped file trains 2000 decisions on 2 envs (one
    rollout, one update) and saves the model and its normalisation statistics."""
    cmd = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", "DrillString-v0",
        "--gym-packages", "drill_env", "--conf-file", str(HYPERPARAMS_FILE),
        "-n", "2000", "-params", "n_envs:2", "--eval-freq", "-1", "--seed", "1",
        "--num-threads", "1", "--device", "cpu", "--verbose", "0", "-f", str(tmp_path),
    ]  # fmt: skip
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env, timeout=600)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    run = tmp_path / "ppo" / "DrillString-v0_1"
    assert (run / "DrillString-v0.zip").stat().st_size > 10_000
    assert (run / "DrillString-v0" / "vecnormalize.pkl").is_file()
    from stable_baselines3 import PPO

    model = PPO.load(run / "DrillString-v0.zip", device="cpu")
    assert model.num_timesteps == 2000
    assert model.n_steps == 1000 and model.gamma == 0.995
    assert model.observation_space.shape == (11,)
