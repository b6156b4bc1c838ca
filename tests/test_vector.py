"""The native vector env (:mod:`drill_env.vector`): spaces, actions, partial reset and the
plant-rate samples of every string."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import reset_each
from drill_env.vector import DrillStringVectorEnv

ENV_ID = "DrillString-v0"
MODES = {"direct": {}, "residual": {"base_controller": "proposed"}}
OBS_SIZE = {"direct": 9, "residual": 11}
REQUIRED_INFO_KEYS = (
    "time_s",
    "bit_speed_rad_s",
    "top_drive_speed_rad_s",
    "reference_speed_rad_s",
    "top_drive_torque_nm",
    "wob_n",
    "bit_stuck",
)


@pytest.mark.parametrize("mode", sorted(MODES))
def test_make_vec_gives_native_vector_env(mode: str) -> None:
    """``gym.make_vec`` builds the native vector env, which resets and steps."""
    venv = gym.make_vec(ENV_ID, num_envs=3, **MODES[mode])
    assert isinstance(venv, DrillStringVectorEnv)
    assert venv.num_envs == 3
    assert venv.single_observation_space == gym.spaces.Box(-50, 50, (OBS_SIZE[mode],), np.float32)
    assert venv.single_action_space == gym.spaces.Box(-1, 1, (1,), np.float32)
    obs, infos = venv.reset(seed=0)
    assert obs.shape == (3, OBS_SIZE[mode])
    assert obs.dtype == np.float32
    for _ in range(5):
        obs, rewards, terminated, truncated, infos = venv.step(np.zeros((3, 1), np.float32))
    assert obs.shape == (3, OBS_SIZE[mode])
    assert venv.observation_space.contains(obs)
    assert rewards.shape == terminated.shape == truncated.shape == (3,)
    assert np.all((rewards >= -2.0) & (rewards <= 0.0))  # the default weights' range
    assert not terminated.any() and not truncated.any()
    for key in REQUIRED_INFO_KEYS:
        assert infos[key].shape == (3,)
    np.testing.assert_allclose(infos["time_s"], 0.5)  # 5 decisions of the default 0.1 s
    venv.close()


# ---------------------------------------------------------------------- reset options
def test_vector_env_of_one_takes_its_batched_action_shape() -> None:
    """``make_vec(num_envs=1)`` steps with actions of its own space's shape (1, 1)."""
    venv = gym.make_vec("DrillString-v0", num_envs=1)
    venv.reset(seed=0)
    assert venv.action_space.shape == (1, 1)
    obs, *_ = venv.step(np.zeros((1, 1), dtype=np.float32))
    assert obs.shape == (1, 9)
    with pytest.raises(ValueError, match=r"action must have shape \(1, 1\)"):
        venv.step(np.zeros((2, 1), dtype=np.float32))


def test_vector_env_partial_reset_matches_a_single_env() -> None:
    """``reset(options={"reset_mask": m})`` starts new episodes only where ``m`` is True; a
    string so reset continues exactly like a single env reset without a seed."""
    venv = gym.make_vec("DrillString-v0", num_envs=2)
    single = gym.make("DrillString-v0")
    venv.reset(seed=10)
    single.reset(seed=11)
    action = np.full((2, 1), 0.1, dtype=np.float32)
    for _ in range(5):
        obs_before, *_ = venv.step(action)
        single.step(action[1])
    obs, info = venv.reset(options={"reset_mask": np.array([False, True])})
    single_obs, single_info = single.reset()
    np.testing.assert_array_equal(obs[0], obs_before[0])  # string 0 untouched
    np.testing.assert_array_equal(obs[1], single_obs)
    assert info["wob_n"][1] == single_info["wob_n"]
    for _ in range(5):
        obs, *_ = venv.step(action)
        single_obs, *_ = single.step(action[1])
    np.testing.assert_array_equal(obs[1], single_obs)
    with pytest.raises(ValueError, match="reset_mask must be a bool array of shape"):
        venv.reset(options={"reset_mask": np.array([1, 0])})


def test_plant_samples_of_every_string() -> None:
    venv = gym.make_vec("DrillString-v0", num_envs=3, control_dt_s=0.02)
    venv.reset(seed=0)
    venv.step(np.zeros((3, 1), dtype=np.float32))
    samples = venv.unwrapped.plant_samples()  # type: ignore[attr-defined]
    assert samples.states.shape == (3, 20, 7) and samples.bit_stuck.shape == (3, 20)
    assert samples.bit_speed_rad_s.shape == (3, 20)


def test_reset_each_gives_every_string_its_own_options() -> None:
    """``reset_each`` resets string ``i`` with seed ``i`` and options ``i``, exactly as a
    single env reset with them."""
    venv = gym.make_vec("DrillString-v0", num_envs=3, randomize=False)
    options = [{"wob_n": 70e3}, {}, {"reference_speed_rad_s": 5.0, "uncertainty": "condition3"}]
    obs = reset_each(venv, [10, 11, 12], options)
    _, info = venv.reset(options={"reset_mask": np.zeros(3, dtype=bool)})
    single = gym.make("DrillString-v0", randomize=False)
    for i, opts in enumerate(options):
        single_obs, single_info = single.reset(seed=10 + i, options=opts or None)
        np.testing.assert_array_equal(obs[i], single_obs)
        assert info["wob_n"][i] == single_info["wob_n"]
        assert info["reference_speed_rad_s"][i] == single_info["reference_speed_rad_s"]
    with pytest.raises(ValueError, match="reset_each needs 3 seeds and 3 option dicts"):
        reset_each(venv, [1, 2], options)


def test_bad_vector_arguments() -> None:
    with pytest.raises(ValueError, match=r"num_envs = 0 is out of range"):
        DrillStringVectorEnv(num_envs=0)
    with pytest.raises(ValueError, match=r"max_episode_steps = 0 is out of range"):
        DrillStringVectorEnv(num_envs=1, max_episode_steps=0)
    venv = DrillStringVectorEnv(num_envs=2)
    with pytest.raises(ValueError, match="the first reset must reset every string"):
        venv.reset(options={"reset_mask": np.array([True, False])})
    with pytest.raises(ValueError, match="seed list must have 2 entries"):
        venv.reset(seed=[1])


def test_step_without_info_is_step_bit_for_bit() -> None:
    """Two vector envs seeded alike, one stepped with ``step`` and one with
    ``step_without_info``, over episodes that end (truncation and next-step autoreset), with
    actions in range, at the bounds and beyond them (clipped)."""
    kwargs = {"base_controller": "proposed", "episode_s": 0.5, "randomize": True}
    full = gym.make_vec(ENV_ID, num_envs=4, max_episode_steps=3, **kwargs)
    lean = gym.make_vec(ENV_ID, num_envs=4, max_episode_steps=3, **kwargs)
    assert isinstance(lean, DrillStringVectorEnv)
    np.testing.assert_array_equal(full.reset(seed=5)[0], lean.reset(seed=5)[0])
    rng = np.random.default_rng(1)
    ended = 0
    for step in range(12):
        actions = rng.uniform(-1.2, 1.2, (4, 1)).astype(np.float32)
        if step == 2:
            actions[:] = [[1.0], [-1.0], [-0.0], [0.0]]
        *expected, infos = full.step(actions)
        got = lean.step_without_info(actions)
        for a, b in zip(got, expected, strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)
        ended += int(expected[3].sum())
    assert ended >= 8  # every string ended at least twice
    # The clipped actions are counted per episode alike: the next full step reports them.
    lean_infos = lean.step(np.zeros((4, 1), np.float32))[-1]
    full_infos = full.step(np.zeros((4, 1), np.float32))[-1]
    np.testing.assert_array_equal(
        lean_infos["actions_clipped_total"], full_infos["actions_clipped_total"]
    )


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.float16])
@pytest.mark.parametrize("shape", [(3, 1), (3,)])
def test_batched_actions_in_range_pass_unchanged(dtype: type, shape: tuple[int, ...]) -> None:
    """The batched fast path of validate_actions returns what the general path does."""
    from drill_env.env import validate_actions

    values = np.array([-1.0, -0.0, 1.0], dtype=dtype).reshape(shape)
    a, clipped = validate_actions(values, 3, batched=True)
    assert a.dtype == np.float64 and a.shape == (3,) and not clipped.any()
    assert a.tolist() == [-1.0, -0.0, 1.0] and np.signbit(a[1])
    assert not np.shares_memory(a, values)
    beyond = np.array([0.5, 1.5, -2.0], dtype=dtype).reshape(shape)
    a, clipped = validate_actions(beyond, 3, batched=True)
    assert a.tolist() == [0.5, 1.0, -1.0] and clipped.tolist() == [False, True, True]
    for bad in (np.nan, np.inf):
        with pytest.raises(ValueError, match="action must be finite"):
            validate_actions(np.array([0.0, bad, 0.0], dtype=dtype).reshape(shape), 3, True)
    with pytest.raises(ValueError, match=r"action must have shape \(3, 1\)"):
        validate_actions(np.zeros((3, 2), dtype=dtype), 3, batched=True)


@pytest.mark.parametrize(
    ("weights", "residual_scale_nm"),
    [
        ({}, 20_000.0),
        ({}, None),
        ({"stuck": 0.5, "torque": 2.0, "residual": 0.5}, 0.5),
        ({"chattering": 0.0, "torque": 0.0}, 3e4),
    ],
)
def test_batch_rewards_are_reward_terms_and_total_reward_bit_for_bit(
    weights: dict[str, float], residual_scale_nm: float | None
) -> None:
    """The vector env's compiled rewards against the reference functions, on random report
    rows with edge cases: no steps, a capped chattering term, NaN."""
    from drill_env.layout import N_REPORT, REP_STEPS, REP_VARIATION
    from drill_env.rewards import TERMS, RewardWeights, report_rewards, reward_terms, total_reward

    rng = np.random.default_rng(6)
    report = rng.uniform(0.0, 1.0, (64, N_REPORT)) * rng.choice([1e-3, 1.0, 1e5, 1e9], (64, 1))
    report[:, REP_STEPS] = rng.integers(0, 101, 64)
    report[:4, REP_STEPS] = [0.0, -0.0, 1.0, np.nan]
    report[4:8, REP_VARIATION] = [5e4, 5e4 + 1e-9, np.inf, np.nan]
    reward_weights = RewardWeights(**weights)
    terms, rewards = report_rewards(reward_weights, 50_000.0, residual_scale_nm)(report)
    expected_terms = reward_terms(report, reward_weights, 50_000.0, residual_scale_nm)
    expected = total_reward(expected_terms, reward_weights)
    for row, name in zip(terms, TERMS, strict=True):
        assert row.tobytes() == np.asarray(expected_terms[name], np.float64).tobytes(), name
    assert rewards.tobytes() == expected.tobytes()
