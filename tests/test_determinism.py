"""Seeding and reproducibility of ``DrillString-v0`` (single and vector)."""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from drill_env.parameters import PRESETS
from drill_env.scenarios import Randomization

ENV_ID = "DrillString-v0"
MODES = {
    "direct": {},
    "residual": {"base_controller": "proposed"},
}
SCALAR_INFO_KEYS = (
    "time_s",
    "bit_speed_rad_s",
    "top_drive_speed_rad_s",
    "reference_speed_rad_s",
    "top_drive_torque_nm",
    "wob_n",
    "bit_stuck",
    "actions_clipped_total",
)
RESIDUAL_INFO_KEYS = (
    "base_torque_nm",
    "residual_torque_nm",
    "sliding_variable_rad_s",
    "adaptive_gain",
)


def _actions(n_steps: int, seed: int = 123, shape: tuple[int, ...] = (1,)) -> np.ndarray:
    """Reproducible actions in [-1.2, 1.2] (some get clipped)."""
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.2, 1.2, (n_steps, *shape)).astype(np.float32)


def _run(
    mode: str, seed: int | None, n_steps: int = 200, **kwargs: Any
) -> tuple[list[np.ndarray], list[float], list[dict[str, Any]]]:
    """Observations, rewards and infos of ``n_steps`` from ``reset(seed)``, resetting (without
    a seed) whenever an episode ends."""
    env = gym.make(ENV_ID, **MODES[mode], **kwargs)
    obs, info = env.reset(seed=seed)
    observations, rewards, infos = [obs], [], [info]
    for a in _actions(n_steps):
        obs, reward, terminated, truncated, info = env.step(a)
        observations.append(obs)
        rewards.append(float(reward))
        infos.append(info)
        if terminated or truncated:
            obs, info = env.reset()
            observations.append(obs)
            infos.append(info)
    return observations, rewards, infos


def _assert_identical(a: Any, b: Any) -> None:
    """Bit-identical observations, rewards and infos (NaN-free by construction)."""
    obs_a, rew_a, info_a = a
    obs_b, rew_b, info_b = b
    assert len(obs_a) == len(obs_b)
    for x, y in zip(obs_a, obs_b, strict=True):
        np.testing.assert_array_equal(x, y)
    assert rew_a == rew_b
    assert info_a == info_b


# ----------------------------------------------------------------------------- seeds
@pytest.mark.parametrize("mode", sorted(MODES))
def test_same_seed_is_bit_identical(mode: str) -> None:
    """Two envs reset with one seed give identical observations, rewards and infos over 200
    steps (randomised scenario, measurement noise on, an episode boundary included)."""
    kwargs = {"randomize": True, "noise_std_rad_s": 0.1, "episode_s": 5.0}
    _assert_identical(_run(mode, 42, **kwargs), _run(mode, 42, **kwargs))


@pytest.mark.parametrize("mode", sorted(MODES))
def test_different_seeds_differ(mode: str) -> None:
    """Different seeds draw different scenarios and noise."""
    obs_a, _, info_a = _run(mode, 1, n_steps=20)
    obs_b, _, info_b = _run(mode, 2, n_steps=20)
    assert info_a[0]["wob_n"] != info_b[0]["wob_n"]
    assert info_a[0]["reference_speed_rad_s"] != info_b[0]["reference_speed_rad_s"]
    assert not np.array_equal(obs_a[-1], obs_b[-1])


def test_noise_differs_between_seeds_with_fixed_scenario() -> None:
    """With the scenario fixed, the seed still drives the measurement noise."""
    obs_a, _, _ = _run("direct", 1, n_steps=3, randomize=False)
    obs_b, _, _ = _run("direct", 2, n_steps=3, randomize=False)
    assert not np.array_equal(obs_a[0], obs_b[0])
    np.testing.assert_array_equal(obs_a[0][[1, 3, 5, 7, 8]], obs_b[0][[1, 3, 5, 7, 8]])


def test_no_noise_no_randomisation_ignores_seed() -> None:
    """Without noise and randomisation the seed changes nothing."""
    kwargs = {"randomize": False, "noise_std_rad_s": 0.0}
    _assert_identical(
        _run("direct", 1, n_steps=40, **kwargs), _run("direct", 2, n_steps=40, **kwargs)
    )


@pytest.mark.parametrize("mode", sorted(MODES))
def test_unseeded_resets_after_a_seed_are_reproducible(mode: str) -> None:
    """``reset(seed)`` then ``reset()`` repeatedly gives the same sequence of episodes."""

    def episodes() -> list[tuple[float, float, list[np.ndarray]]]:
        """WOB, reference and observations of the episodes after the seeded one."""
        env = gym.make(ENV_ID, **MODES[mode], episode_s=1.0)
        out = []
        env.reset(seed=9)
        for k in range(4):
            observations = []
            if k > 0:
                obs, info = env.reset()
                observations.append(obs)
            for a in _actions(10, seed=k):
                obs, *_ = env.step(a)
                observations.append(obs)
            if k > 0:
                out.append((info["wob_n"], info["reference_speed_rad_s"], observations))
        return out

    first = episodes()
    second = episodes()
    for (w1, r1, o1), (w2, r2, o2) in zip(first, second, strict=True):
        assert (w1, r1) == (w2, r2)
        np.testing.assert_array_equal(np.array(o1), np.array(o2))
    # Later episodes differ from each other.
    assert len({w for w, _, _ in first}) == len(first)


def test_episode_draws_do_not_depend_on_earlier_episode_length() -> None:
    """The scenario of the second episode after ``reset(seed)`` does not depend on how many
    steps (noise draws) the first episode took."""

    def second_episode(first_steps: int) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
        env = gym.make(ENV_ID, episode_s=2.0)
        env.reset(seed=77)
        for a in _actions(first_steps):
            env.step(a)
        obs, info = env.reset()
        observations, infos = [obs], [info]
        for a in _actions(30, seed=5):
            obs, _, _, _, info = env.step(a)
            observations.append(obs)
            infos.append(info)
        return observations, infos

    obs_short, info_short = second_episode(2)
    obs_long, info_long = second_episode(35)
    for x, y in zip(obs_short, obs_long, strict=True):
        np.testing.assert_array_equal(x, y)
    assert info_short == info_long


def test_noise_level_does_not_change_scenario_draws() -> None:
    """The WOB profile and reference drawn for a seed are the same whatever the noise level
    or the reference range (one generator per random component)."""

    def wob_and_reference(**kwargs: Any) -> tuple[list[float], list[float]]:
        env = gym.make(ENV_ID, episode_s=2.0, **kwargs)
        env.reset(seed=2024)
        wobs, refs = [], []
        for a in _actions(40):
            _, _, _, _, info = env.step(a)
            wobs.append(info["wob_n"])
            refs.append(info["reference_speed_rad_s"])
        return wobs, refs

    wob_a, ref_a = wob_and_reference(noise_std_rad_s=0.1)
    wob_b, ref_b = wob_and_reference(noise_std_rad_s=0.7)
    wob_c, ref_c = wob_and_reference(noise_std_rad_s=0.0)
    assert wob_a == wob_b == wob_c
    assert ref_a == ref_b == ref_c
    # A different reference range changes the reference but not the WOB draw.
    wob_d, ref_d = wob_and_reference(
        randomization=Randomization(reference_range_rad_s=(20.0, 30.0))
    )
    assert wob_d == wob_a
    assert ref_d != ref_a
    assert 20.0 <= ref_d[0] <= 30.0
    # A different WOB range leaves the reference draw alone.
    wob_e, ref_e = wob_and_reference(randomization=Randomization(wob_range_n=(10e3, 20e3)))
    assert ref_e == ref_a
    assert all(10e3 <= w <= 20e3 for w in wob_e)


def test_randomised_draws_stay_in_their_ranges() -> None:
    """Drawn WOB and reference lie in the randomisation ranges, for many seeds."""
    env = gym.make(ENV_ID)
    r = Randomization()
    for seed in range(30):
        _, info = env.reset(seed=seed)
        assert r.wob_range_n[0] <= info["wob_n"] <= r.wob_range_n[1]
        assert (
            r.reference_range_rad_s[0]
            <= info["reference_speed_rad_s"]
            <= r.reference_range_rad_s[1]
        )


# --------------------------------------------------------------------------- vector env
def _vector_matches_single_envs(
    mode: str, kwargs: dict[str, Any], actions: np.ndarray, skip_keys: tuple[str, ...] = ()
) -> np.ndarray:
    """Step ``make_vec(num_envs=3)`` reset with seed s and single envs reset with s + i
    through the same actions, and compare bit for bit, autoresets included (next-step mode:
    the step after an episode ends returns the new episode's first observation).

    Returns:
        The vector env's ``terminated`` flags, (steps, num_envs).
    """
    seed, n = 11, actions.shape[1]
    venv = gym.make_vec(ENV_ID, num_envs=n, **MODES[mode], **kwargs)
    v_obs, v_info = venv.reset(seed=seed)
    vector = [(v_obs, None, None, None, v_info)]
    for a in actions:
        vector.append(venv.step(a))
    venv.close()
    keys = SCALAR_INFO_KEYS + (RESIDUAL_INFO_KEYS if mode == "residual" else ())
    keys = tuple(k for k in keys if k not in skip_keys)
    ended_episodes = 0
    for i in range(n):
        env = gym.make(ENV_ID, **MODES[mode], **kwargs)
        obs, info = env.reset(seed=seed + i)
        np.testing.assert_array_equal(obs, vector[0][0][i])
        done = False
        for t, a in enumerate(actions[:, i]):
            v_obs, v_rew, v_term, v_trunc, v_info = vector[t + 1]
            where = f"string {i}, step {t}"
            if done:
                obs, info = env.reset()
                reward, terminated, truncated = 0.0, False, False
            else:
                obs, reward, terminated, truncated, info = env.step(a)
            np.testing.assert_array_equal(obs, v_obs[i], err_msg=where)
            assert reward == v_rew[i], where
            assert (terminated, truncated) == (v_term[i], v_trunc[i]), where
            for key in keys:
                assert info[key] == v_info[key][i], f"{where}: info[{key!r}]"
            done = terminated or truncated
            ended_episodes += done
    assert ended_episodes >= 2 * n
    return np.array([step[2] for step in vector[1:]])


def _synchronous_run(mode: str, skip_keys: tuple[str, ...] = ()) -> None:
    """All strings end their episodes together (randomised scenarios, noise on)."""
    kwargs = {"episode_s": 2.0, "noise_std_rad_s": 0.1}
    _vector_matches_single_envs(mode, kwargs, _actions(300, shape=(3, 1)), skip_keys)


@pytest.mark.parametrize("mode", ["direct", "residual"])
def test_vector_env_reproduces_single_envs_with_autoreset(mode: str) -> None:
    """``make_vec`` seeded s equals single envs seeded s, s+1, s+2 over 300 steps, through
    several synchronous autoresets."""
    _synchronous_run(mode)


def _staggered_run(mode: str, skip_keys: tuple[str, ...] = ()) -> None:
    """String 0 diverges and restarts while the others keep going, so that one string
    autoresets while the others step."""
    undamped = dataclasses.replace(PRESETS["zribi2024"], c_dt=0.0, c_bit=0.0)
    kwargs = {
        "parameters": undamped,
        "randomize": False,
        "max_torque_nm": 1e6,
        "residual_scale_nm": 1e6,
        "episode_s": 5.0 if mode == "residual" else 2.0,
    }
    actions = _actions(260, shape=(3, 1))
    actions[:, 0] = 1.0  # string 0 diverges (about 1.3 s direct, 3 s residual)
    rng = np.random.default_rng(0)
    if mode == "residual":
        actions[:, 1:] = rng.uniform(-0.01, 0.01, (260, 2, 1))
    else:
        actions[:, 1:] = rng.uniform(-1.0, -0.97, (260, 2, 1))  # at most 15 kN m
    terminated = _vector_matches_single_envs(mode, kwargs, actions, skip_keys)
    assert terminated[:, 0].sum() >= 2  # string 0 diverged and restarted at least twice
    assert not terminated[:, 1:].any()


@pytest.mark.parametrize("mode", ["direct", "residual"])
def test_vector_env_reproduces_single_envs_with_staggered_autoreset(mode: str) -> None:
    """Vector and single envs match bit for bit when one string autoresets alone."""
    _staggered_run(mode)


def test_vector_env_seed_list() -> None:
    """A list of seeds seeds each string with its entry."""
    venv = gym.make_vec(ENV_ID, num_envs=2)
    obs, info = venv.reset(seed=[5, 3])
    for i, s in enumerate((5, 3)):
        single_obs, single_info = gym.make(ENV_ID).reset(seed=s)
        np.testing.assert_array_equal(obs[i], single_obs)
        assert info["wob_n"][i] == single_info["wob_n"]


def test_reset_info_has_no_residual_from_previous_episode() -> None:
    """At reset no residual has been applied yet: ``info["residual_torque_nm"]`` is 0."""
    env = gym.make(ENV_ID, **MODES["residual"])
    env.reset(seed=0)
    env.step(np.array([0.7], dtype=np.float32))
    _, info = env.reset(seed=0)
    assert info["residual_torque_nm"] == 0.0
