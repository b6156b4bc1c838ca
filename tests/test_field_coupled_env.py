"""``DrillStringField-v0`` with ``bit="rgd"``: the field string with axial elements and the
regenerative bit inside the env's contract (checkers, observation and info, determinism single
vs vector, bad input); the default Karnopp bit is unchanged."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import drill_env
from drill_env.coupled import RGD_PRESETS
from drill_env.evaluation import ZeroAction, rollout
from drill_env.layout import FORCE_SCALE_N, ROP_SCALE_M_S

FIELD = drill_env.FIELD_ENV_ID
RGD: dict[str, Any] = {"bit": "rgd", "episode_s": 2.0, "control_dt_s": 0.1}
INFO_KEYS = (
    "weight_on_bit_n",
    "torque_on_bit_nm",
    "mean_weight_on_bit_n",
    "rate_of_penetration_m_s",
    "bit_depth_m",
    "bit_off_bottom",
)


@pytest.mark.parametrize(
    "extra",
    [{"base_controller": "soft_speed"}, {"observation": "state"}],
    ids=["surface-residual", "state"],
)
def test_checker(extra: dict[str, Any]) -> None:
    env = gym.make(FIELD, **RGD, **extra)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped, skip_render_check=True)


def test_observation_and_info_carry_weight_on_bit_and_rate_of_penetration() -> None:
    """At rest the string carries the applied force to the rock (the bit stuck, no
    penetration); the last two observation entries are the weight on bit and the rate of
    penetration over their scales; once drilling, the depth is the sum of the rates times the
    decision period."""
    env = gym.make(FIELD, randomize=False, base_controller="soft_speed", wob_n=80e3, **RGD)
    names = env.unwrapped.observation_names  # type: ignore[attr-defined]
    assert names[-2:] == ("weight_on_bit_n", "rate_of_penetration_m_s")
    plain = gym.make(FIELD, randomize=False, base_controller="soft_speed")
    assert env.observation_space.shape[0] == plain.observation_space.shape[0] + 2  # type: ignore[index]
    obs, info = env.reset(seed=0)
    assert set(INFO_KEYS) <= set(info)
    assert info["weight_on_bit_n"] == pytest.approx(80e3, rel=1e-12)
    assert info["rate_of_penetration_m_s"] == 0.0 and info["bit_stuck"]
    assert obs[-2] == pytest.approx(80e3 / FORCE_SCALE_N, rel=1e-6)
    depth = 0.0
    for _ in range(20):
        obs, _, terminated, truncated, info = env.step(np.zeros(1, np.float32))
        depth += info["rate_of_penetration_m_s"] * 0.1
        assert obs[-1] == pytest.approx(info["rate_of_penetration_m_s"] / ROP_SCALE_M_S, rel=1e-5)
        assert np.isfinite(obs).all() and not terminated
    assert truncated
    assert info["bit_depth_m"] == pytest.approx(depth, rel=1e-9, abs=1e-12)
    assert depth > 0.0  # the string drilled


def test_vector_env_reproduces_single_envs() -> None:
    """String i of the native vector env is the single env reset with seed s + i, bit for bit
    (randomised depths, autoreset included)."""
    kwargs = {**RGD, "episode_s": 1.0, "base_controller": "soft_speed"}
    venv = gym.make_vec(FIELD, num_envs=2, **kwargs)
    obs_v, info_v = venv.reset(seed=7)
    singles = [gym.make(FIELD, **kwargs) for _ in range(2)]
    obs_s = [env.reset(seed=7 + i)[0] for i, env in enumerate(singles)]
    for i in range(2):
        np.testing.assert_array_equal(obs_v[i], obs_s[i])
    rng = np.random.default_rng(1)
    for _ in range(13):  # past the 10-decision episode: autoreset
        actions = rng.uniform(-1, 1, (2, 1)).astype(np.float32)
        obs_v, rew_v, term_v, trunc_v, info_v = venv.step(actions)
        for i, env in enumerate(singles):
            if obs_s[i] is None:
                obs_s[i], _ = env.reset()
                np.testing.assert_array_equal(obs_v[i], obs_s[i])
                continue
            o, r, te, tr, info = env.step(actions[i])
            np.testing.assert_array_equal(obs_v[i], o)
            assert rew_v[i] == r and trunc_v[i] == tr and term_v[i] == te
            for key in INFO_KEYS:
                assert info_v[key][i] == info[key]
            obs_s[i] = None if (te or tr) else o


def test_same_seed_same_trajectory() -> None:
    env = gym.make(FIELD, **RGD)
    traces = [rollout(env, ZeroAction(), seed=3) for _ in range(2)]
    np.testing.assert_array_equal(traces[0].states, traces[1].states)
    np.testing.assert_array_equal(traces[0].observations, traces[1].observations)


def test_hook_boundary() -> None:
    """A hook lowered through a spring: once the axial wave has reached the bit (2,500 m at
    about 5 km/s), the weight on bit builds up while the bit is stuck."""
    env = gym.make(
        FIELD, randomize=False, axial_top="hook", hook_speed_m_s=0.01, hook_stiffness_n_m=1e6,
        torque_rate_limit_nm_per_s=None, **RGD,
    )  # fmt: skip
    _, info = env.reset(seed=0)
    start = info["weight_on_bit_n"]
    for _ in range(10):  # 1 s without torque: stuck
        _, _, terminated, _, info = env.step(np.full(1, -1.0, np.float32))
        assert info["bit_stuck"] and not terminated
    assert info["weight_on_bit_n"] > start + 1e3


def test_karnopp_default_is_unchanged() -> None:
    """``bit="karnopp"`` is the default: the same spaces and trajectory, no bit entries."""
    default = gym.make(FIELD, episode_s=1.0)
    explicit = gym.make(FIELD, episode_s=1.0, bit="karnopp")
    assert default.observation_space == explicit.observation_space
    a, b = rollout(default, ZeroAction(), seed=2), rollout(explicit, ZeroAction(), seed=2)
    np.testing.assert_array_equal(a.observations, b.observations)
    _, info = default.reset(seed=0)
    assert not set(INFO_KEYS) & set(info)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"bit": "pdc"}, "bit = 'pdc'"),
        ({"hook_speed_m_s": 0.01}, "hook_speed_m_s .* only with bit='rgd'"),
        ({"axial_top": "hook"}, "axial_top .* only with bit='rgd'"),
        ({"bit": "rgd", "axial_top": "hook"}, "hook_speed_m_s"),
        ({"bit": "rgd", "axial_top": "crane"}, "axial_top"),
        ({"bit": "rgd", "hook_speed_m_s": 0.01}, "hook_speed_m_s"),
        ({"bit": "rgd", "rgd_parameters": "rgd_z"}, "rgd_z"),
        (
            {"bit": "rgd", "axial_top": "hook", "hook_speed_m_s": 0.01, "hook_stiffness_n_m": 0.0},
            "hook_stiffness_n_m",
        ),  # fmt: skip
    ],
)
def test_bad_input(kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        gym.make(FIELD, **kwargs)


def test_rgd_parameters_object_and_fixed_at_make() -> None:
    env = gym.make(FIELD, bit="rgd", rgd_parameters=RGD_PRESETS["rgd_a"], episode_s=1.0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="cannot change per episode"):
        env.reset(options={"bit": "karnopp"})


class _ConstantTorque:
    """A plain Python controller (no ``compiled_law``) holding one torque: the env calls it at
    every plant step from Python (the slow path)."""

    def __init__(self, torque_nm: float) -> None:
        self.torque_nm = torque_nm

    def reset(self) -> None:
        pass

    def torque(self, measurement: np.ndarray, reference_speed_rad_s: float, dt_s: float) -> float:
        return self.torque_nm


def test_python_controller_path_reports_the_whole_decision() -> None:
    """On the slow path the weight on bit and rate of penetration still cover the whole
    decision: a Python controller holding a torque drives the coupled string exactly as the
    same torque commanded by the action on the compiled path."""
    kwargs = {**RGD, "randomize": False, "episode_s": 3.0}
    low, high = 0.0, 50_800.0
    torque = 20_000.0
    action = np.full(1, 2 * (torque - low) / (high - low) - 1, np.float32)
    compiled = gym.make(FIELD, **kwargs)
    python = gym.make(
        FIELD, base_controller=_ConstantTorque(float(action[0] + 1) / 2 * high), **kwargs
    )
    obs_c, _ = compiled.reset(seed=4)
    obs_p, _ = python.reset(seed=4)
    np.testing.assert_array_equal(obs_c[-2:], obs_p[-2:])
    for _ in range(30):
        obs_c, _, _, _, info_c = compiled.step(action)
        obs_p, _, _, _, info_p = python.step(np.zeros(1, np.float32))
        assert info_p["top_drive_torque_nm"] == pytest.approx(info_c["top_drive_torque_nm"])
        np.testing.assert_allclose(obs_p[-2:], obs_c[-2:], rtol=1e-6, atol=1e-9)
        for key in ("rate_of_penetration_m_s", "mean_weight_on_bit_n", "bit_depth_m"):
            assert info_p[key] == pytest.approx(info_c[key], rel=1e-6, abs=1e-12)
    assert info_c["bit_depth_m"] > 0.0  # the bit drilled


def test_diverging_string_ends_the_episode_with_a_reason() -> None:
    """A rock so hard that the cutting stiffness is beyond the RK4 step makes the state blow
    up: the episode ends, ``termination_reason`` says so, the observation stays finite."""
    hard = dataclasses.replace(RGD_PRESETS["rgd_a"], intrinsic_energy_pa=1e14)
    env = gym.make(
        FIELD, bit="rgd", rgd_parameters=hard, randomize=False, episode_s=5.0,
        control_dt_s=0.1, torque_rate_limit_nm_per_s=None,
    )  # fmt: skip
    env.reset(seed=0)
    for _ in range(50):
        obs, reward, terminated, truncated, info = env.step(np.ones(1, np.float32))
        assert np.isfinite(obs).all()
        if terminated or truncated:
            break
    assert terminated and info["termination_reason"] == "diverged" and reward == -1.0
