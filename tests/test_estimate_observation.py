"""``observation="estimate"``: the surface observation plus the base controller's observer
estimate of the bit speed and the bit-rock torque (drill_env.layout.ESTIMATE_FIELDS), with a
speed loop running the observer beside it (baselines.speed_loop.speed_loop_observer_law)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from agents.config import TrainConfig
from baselines import make_controller
from baselines.speed_loop import SpeedLoopController
from drill_env.layout import ESTIMATE_FIELDS, OBS_BOUND, REC_X0, SPEED_SCALE_RAD_S, X_BIT_SPEED
from drill_env.options import FieldEnvConfig

FIELD = "DrillStringField-v0"
QUIET: dict[str, Any] = {
    "noise_std_rad_s": 0.0,
    "torque_noise_std_nm": 0.0,
    "telemetry_noise_std_rad_s": 0.0,
}
ZERO = np.zeros(1, dtype=np.float32)


def _run(observation: str, steps: int, **kwargs: Any) -> tuple[np.ndarray, list[dict[str, Any]]]:
    env = gym.make(
        FIELD, randomize=False, base_controller="z_torque_tuned", observation=observation, **kwargs
    )
    obs, info = env.reset(seed=3)
    rows, infos = [obs], [info]
    for _ in range(steps):
        obs, _, terminated, _, info = env.step(ZERO)
        assert not terminated
        rows.append(obs)
        infos.append(info)
    return np.array(rows), infos


def test_estimate_observation_is_the_surface_one_plus_the_estimates() -> None:
    """The first entries and the base torque are those of ``observation="surface"`` (the
    observer does not change the loop); the last two are the estimates ``info`` reports,
    scaled as a speed and as a torque."""
    surface, surface_infos = _run("surface", 60)
    estimate, infos = _run("estimate", 60)
    env = gym.make(FIELD, observation="estimate", base_controller="z_torque_tuned").unwrapped
    names = env.observation_names  # type: ignore[attr-defined]
    assert names[-2:] == tuple(name for name, _ in ESTIMATE_FIELDS)
    assert estimate.shape == (61, surface.shape[1] + 2)
    np.testing.assert_array_equal(estimate[:, :-2], surface)
    for a, b in zip(surface_infos[1:], infos[1:], strict=True):
        assert a["base_torque_nm"] == b["base_torque_nm"]
        assert a["top_drive_torque_nm"] == b["top_drive_torque_nm"]
    speed = np.array([i["estimated_bit_speed_rad_s"] for i in infos[1:]])
    torque = np.array([i["estimated_bit_torque_nm"] for i in infos[1:]])
    scale = FieldEnvConfig().torque_scale_nm
    np.testing.assert_allclose(estimate[1:, -2], speed / SPEED_SCALE_RAD_S, rtol=1e-6)
    np.testing.assert_allclose(estimate[1:, -1], torque / scale, rtol=1e-6, atol=1e-7)
    assert np.all(np.abs(estimate) <= OBS_BOUND)
    np.testing.assert_array_equal(estimate[0, -2:], 0.0)  # the observer starts at rest


def test_speed_loop_observer_tracks_the_bit_speed() -> None:
    """Noise-free field string under ``z_torque_tuned`` (its sensors at 100 Hz, telemetry 5 s
    late): after 20 s the estimate is within 0.25 rad/s of the true bit speed of the plant's
    records (0.10 measured), as the sliding-mode laws' observer is (tests/test_observer.py)."""
    env = gym.make(FIELD, randomize=False, base_controller="z_torque_tuned",
                   observation="estimate", **QUIET)  # fmt: skip
    records = env.unwrapped.batch.records  # type: ignore[attr-defined]
    env.reset(seed=0)
    errors = []
    for _ in range(300):
        _, _, _, _, info = env.step(ZERO)
        truth = records[0, -1, REC_X0 + X_BIT_SPEED]
        assert info["estimated_bit_speed_rad_s"] - truth == pytest.approx(
            info["estimate_error_bit_speed_rad_s"], abs=1e-9
        )
        if info["time_s"] > 20.0:
            errors.append(info["estimate_error_bit_speed_rad_s"])
    assert np.abs(errors).max() < 0.25


def test_vector_env_gives_each_string_the_single_env_observation() -> None:
    kwargs: dict[str, Any] = {
        "base_controller": "z_torque_tuned",
        "observation": "estimate",
        "episode_s": 5.0,
    }
    venv = gym.make_vec(FIELD, num_envs=2, **kwargs)
    obs, _ = venv.reset(seed=10)
    singles = [gym.make(FIELD, **kwargs) for _ in range(2)]
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(obs[i], env.reset(seed=10 + i)[0])
    for _ in range(12):
        obs, *_ = venv.step(np.zeros((2, 1), dtype=np.float32))
        for i, env in enumerate(singles):
            np.testing.assert_array_equal(obs[i], env.step(ZERO)[0])
    assert np.all(obs[:, -2] > 0.0)  # the estimates move with the string


def test_the_surface_law_is_unchanged_without_the_estimate() -> None:
    """A speed loop compiled for a surface channel runs its plain law (no observer state)."""
    controller = make_controller("z_torque_tuned")
    assert isinstance(controller, SpeedLoopController)
    law = controller.compiled_law()
    assert law.estimate_slots == () and law.info_slots == ()
    assert law.function.__name__ == "speed_loop_law"


class _Constant:
    """A Python base controller: a constant torque, no observer."""

    def reset(self) -> None:
        pass

    def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
        return 10_000.0


@pytest.mark.parametrize("base", [None, _Constant()], ids=["direct", "python"])
def test_estimate_needs_a_base_controller_with_an_observer(base: Any) -> None:
    with pytest.raises(ValueError, match=r"observation = 'estimate' needs a base controller"):
        gym.make(FIELD, observation="estimate", base_controller=base)


def test_train_config_takes_the_estimate_observation() -> None:
    assert TrainConfig(env_id=FIELD, observation="estimate").observation == "estimate"
    with pytest.raises(ValueError, match=r"allowed surface, estimate, state or empty"):
        TrainConfig(env_id=FIELD, observation="bit")


def test_a_model_trained_on_the_estimate_loads_and_runs_with_it(tmp_path: Path) -> None:
    """A tiny training with ``observation="estimate"`` writes a model whose ``env_kwargs``
    name the mode; loaded, it drives the env with the 10-entry observation."""
    pytest.importorskip("stable_baselines3")
    from agents.policy import load_policy
    from agents.train import train
    from drill_env.evaluation import rollout

    config = TrainConfig.for_env(
        FIELD, observation="estimate", run_dir=str(tmp_path / "run"), total_timesteps=60,
        num_envs=2, n_steps=30, batch_size=30, n_epochs=1, episode_s=3.0, control_dt_s=0.1,
        checkpoint_every=0, validate_every=0, tensorboard=False,
    )  # fmt: skip
    policy = load_policy(train(config, progress=False))
    assert policy.env_kwargs["observation"] == "estimate"
    assert policy.metadata["observation_size"] == 10
    env = gym.make(FIELD, randomize=False, episode_s=3.0, **policy.env_kwargs)
    trace = rollout(env, policy, seed=1)
    assert trace.observations.shape[1] == 10 and len(trace.actions) == 30
