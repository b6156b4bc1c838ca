"""Copies, pickling, reward bounds and keyword checks of the three envs."""

from __future__ import annotations

import copy
import math
import pickle
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from drill_env.coupled_env import DrillStringCoupledEnv
from drill_env.ids import COUPLED_ENV_ID, ENV_ID, FIELD_ENV_ID
from drill_env.kernel import PackedArrays
from drill_env.limits import HOOK_STIFFNESS_RANGE_N_M
from drill_env.options import FieldEnvConfig
from drill_env.rewards import DIVERGED_REWARD, TERMS, RewardWeights

SHORT = {"episode_s": 4.0}


def _actions(space: gym.spaces.Box, n: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.uniform(-1.0, 1.0, space.shape).astype(np.float32) for _ in range(n)]


def _run(env: gym.Env, actions: list[np.ndarray]) -> list[tuple[Any, ...]]:
    out = []
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(a)
        out.append((obs.copy(), float(reward), terminated, truncated, info["time_s"]))
    return out


def _same(a: list[tuple[Any, ...]], b: list[tuple[Any, ...]]) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x[0], y[0]) and x[1:] == y[1:] for x, y in zip(a, b, strict=True)
    )


def _arrays_of(env: Any) -> list[np.ndarray]:
    """Every array the engine of ``env`` runs on (the kernel's and the coupled loop's)."""
    batch = env.batch
    return [*batch.arrays, *(batch.coupled_arrays or ())]


def _held_arrays(env: Any) -> list[tuple[str, np.ndarray]]:
    """The arrays held as attributes by the env, its batch and its episodes."""
    batch = env.batch
    owners = [("env", env), ("batch", batch)]
    owners += [(f"episode {i}", e) for i, e in enumerate(batch.episodes) if e is not None]
    return [
        (f"{owner}.{key}", value)
        for owner, obj in owners
        for key, value in vars(obj).items()
        if isinstance(value, np.ndarray)
    ]


def _assert_independent(original: Any, twin: Any) -> None:
    """No array of ``twin`` shares memory with ``original``'s engine, every view ``original``
    holds into its engine's arrays is a view of ``twin``'s, and the packed addresses are
    those of ``twin``'s arrays."""
    engine = _arrays_of(original)
    twin_engine = _arrays_of(twin)
    held = dict(_held_arrays(original))
    for name, value in _held_arrays(twin):
        assert not any(np.may_share_memory(value, a) for a in engine), name
        if any(np.may_share_memory(held[name], a) for a in engine):
            assert any(np.may_share_memory(value, a) for a in twin_engine), name
    packed = twin.batch._packed
    if packed is not None:
        addresses = [a.__array_interface__["data"][0] for a in twin.batch.arrays]
        assert packed.meta[:, 0].tolist() == addresses
        assert twin.batch._kernel_input is packed.meta


@pytest.mark.parametrize(
    ("env_id", "keywords"),
    [
        (ENV_ID, {}),
        (ENV_ID, {"base_controller": "proposed"}),
        (ENV_ID, {"max_episode_steps": 200}),  # through Gymnasium's TimeLimit wrapper
        (FIELD_ENV_ID, {}),
        pytest.param(  # the coupled loop's closure holds its arrays (about 25 s to load)
            FIELD_ENV_ID, {"bit": "rgd", "episode_s": 20.0}, marks=pytest.mark.slow
        ),
    ],
)
def test_a_deep_copy_runs_on_its_own_memory(env_id: str, keywords: dict[str, Any]) -> None:
    """The copy continues bit for bit as the original does under the same actions, and
    stepping it leaves the original untouched (over more steps than a noise block holds)."""
    env = gym.make(env_id, **keywords)
    reference = gym.make(env_id, **keywords)
    warm = _actions(env.action_space, 3, seed=1)
    actions = _actions(env.action_space, 40, seed=2)
    for e in (env, reference):
        e.reset(seed=5)
        _run(e, warm)
    twin = copy.deepcopy(env)
    _assert_independent(env.unwrapped, twin.unwrapped)
    from_twin = _run(twin, actions)  # first, the copy alone
    from_env = _run(env, actions)
    assert _same(from_twin, from_env)
    assert _same(from_env, _run(reference, actions))


def test_a_deep_copy_of_a_vector_env_runs_on_its_own_memory() -> None:
    env = gym.make_vec(ENV_ID, num_envs=3, **SHORT)
    env.reset(seed=2)
    env.step(np.zeros((3, 1), np.float32))
    twin = copy.deepcopy(env)
    _assert_independent(env, twin)
    actions = [a.reshape(3, 1) for a in _actions(gym.spaces.Box(-1, 1, (3,)), 50, seed=3)]
    out_twin = [(o.copy(), r.copy()) for o, r, *_ in (twin.step(a) for a in actions)]
    out_env = [(o.copy(), r.copy()) for o, r, *_ in (env.step(a) for a in actions)]
    for (o1, r1), (o2, r2) in zip(out_twin, out_env, strict=True):
        assert np.array_equal(o1, o2) and np.array_equal(r1, r2)


def test_a_deep_copy_of_the_coupled_env_is_independent() -> None:
    env = gym.make(COUPLED_ENV_ID, episode_s=1.0)
    env.reset(seed=4)
    twin = copy.deepcopy(env)
    actions = _actions(env.action_space, 10, seed=4)
    assert _same(_run(twin, actions), _run(env, actions))


@pytest.mark.parametrize("env_id", [ENV_ID, FIELD_ENV_ID, COUPLED_ENV_ID])
def test_pickling_or_a_shallow_copy_is_refused_clearly(env_id: str) -> None:
    env = gym.make(env_id).unwrapped
    for attempt in (pickle.dumps, copy.copy):
        with pytest.raises(TypeError, match=r"cannot be pickled .*copy\.deepcopy"):
            attempt(env)


def test_packed_arrays_pickle_and_copy_with_their_own_addresses() -> None:
    env = gym.make(ENV_ID).unwrapped
    packed = env.batch._packed
    for twin in (pickle.loads(pickle.dumps(packed)), copy.deepcopy(packed)):
        assert isinstance(twin, PackedArrays)
        addresses = [a.__array_interface__["data"][0] for a in twin.arrays]
        assert twin.meta[:, 0].tolist() == addresses
        assert not any(
            np.may_share_memory(a, b) for a, b in zip(twin.arrays, packed.arrays, strict=True)
        )


# ------------------------------------------------------------------------------ rewards
class _Hostile:
    """A base controller that asks for an absurd torque."""

    def reset(self) -> None:
        pass

    def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
        return 1e200


def _terms_in_unit_interval(info: dict[str, Any]) -> None:
    for name in TERMS:
        value = info["reward_terms"][name]
        assert 0.0 <= value <= 1.0, (name, value)


def test_a_hostile_base_torque_keeps_the_reward_finite() -> None:
    """The residual term compares the applied torque with the base torque clipped to the
    torque range: 1e200 N m costs at most the range, not -inf."""
    weights = RewardWeights(residual=1.0)
    env = gym.make(ENV_ID, base_controller=_Hostile(), reward_weights=weights, **SHORT)
    env.reset(seed=0)
    for a in _actions(env.action_space, 5, seed=0):
        _, reward, terminated, _, info = env.step(a)
        assert math.isfinite(float(reward)) and float(reward) >= -3.0
        _terms_in_unit_interval(info)
        assert not terminated


@pytest.mark.parametrize(
    "keywords",
    [
        {},
        {"base_controller": "proposed", "reward_weights": {"residual": 1.0}},
    ],
)
def test_every_term_is_in_the_unit_interval_with_asymmetric_limits(
    keywords: dict[str, Any],
) -> None:
    """|min_torque_nm| > max_torque_nm: the torque term is scaled by the larger magnitude."""
    limits = {"min_torque_nm": -60_000.0, "max_torque_nm": 10_000.0}
    env = gym.make(ENV_ID, **limits, **keywords, **SHORT)
    env.reset(seed=1)
    extremes = [np.array([-1.0], np.float32)] * 5
    for a in extremes + _actions(env.action_space, 30, seed=1):
        _, _, terminated, truncated, info = env.step(a)
        _terms_in_unit_interval(info)
        if terminated or truncated:
            break
    vector = gym.make_vec(ENV_ID, num_envs=2, **limits, **keywords, **SHORT)
    vector.reset(seed=1)
    for _ in range(5):
        infos = vector.step(-np.ones((2, 1), np.float32))[4]
        for name in TERMS:
            assert np.all((infos["reward_terms"][name] >= 0) & (infos["reward_terms"][name] <= 1))


def test_a_reward_weight_names_the_finite_range() -> None:
    with pytest.raises(ValueError, match=r"allowed \[0, inf\)") as raised:
        RewardWeights(tracking=math.inf)
    assert "inf]" not in str(raised.value)


# -------------------------------------------------------------------------- keywords
def test_the_field_hook_stiffness_is_bounded_like_the_coupled_envs() -> None:
    low, high = HOOK_STIFFNESS_RANGE_N_M
    hook = {"bit": "rgd", "axial_top": "hook", "hook_speed_m_s": 0.01}
    for value in (high * 100, low / 2):
        with pytest.raises(ValueError, match=r"hook_stiffness_n_m = .* allowed \[1000, 1e\+10\]"):
            FieldEnvConfig(**hook, hook_stiffness_n_m=value)
        with pytest.raises(ValueError, match=r"hook_stiffness_n_m = .* allowed \[1000, 1e\+10\]"):
            DrillStringCoupledEnv(axial_input="hook_speed", hook_stiffness_n_m=value)
    for value in (low, high, math.inf):
        FieldEnvConfig(**hook, hook_stiffness_n_m=value)


def test_rgd_parameters_errors_name_the_keyword() -> None:
    with pytest.raises(ValueError, match=r"^rgd_parameters = 'x' is not a known preset"):
        FieldEnvConfig(bit="rgd", rgd_parameters="x")
    with pytest.raises(TypeError, match=r"^rgd_parameters must be"):
        FieldEnvConfig(bit="rgd", rgd_parameters=3)


def test_the_coupled_episode_must_be_whole_decisions() -> None:
    with pytest.raises(ValueError, match=r"episode_s = 1.02 .* multiple of control_dt_s = 0.05"):
        DrillStringCoupledEnv(episode_s=1.02, control_dt_s=0.05)
    assert gym.make(COUPLED_ENV_ID).spec.max_episode_steps == 600  # 30 s at 0.05 s
    assert gym.make(COUPLED_ENV_ID, episode_s=2.0).spec.max_episode_steps == 40


def _diverge(env: Any) -> None:
    """Put the plant beyond the physical speed bound, so that the next step diverges."""
    if isinstance(env, DrillStringCoupledEnv):
        env._y[:] = 5_000.0
    else:
        env.batch.x[0, 0] = 5_000.0


@pytest.mark.parametrize("env_id", [ENV_ID, COUPLED_ENV_ID])
def test_divergence_ends_the_episode_alike(env_id: str) -> None:
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    _diverge(env)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample() * 0)
    assert terminated and not truncated
    assert reward == DIVERGED_REWARD
    assert info["termination_reason"] == "diverged"
    assert np.all(np.isfinite(obs))
    with pytest.raises(RuntimeError, match=r"the episode has ended \(diverged\): call reset\(\)"):
        env.step(env.action_space.sample() * 0)
    env.reset(seed=0)
    env.step(env.action_space.sample() * 0)


@pytest.mark.parametrize("env_id", [ENV_ID, FIELD_ENV_ID, COUPLED_ENV_ID])
def test_a_numpy_integer_seed_is_a_seed(env_id: str) -> None:
    runs = []
    for seed in (7, np.int64(7), np.uint32(7)):
        env = gym.make(env_id, episode_s=1.0)
        obs, _ = env.reset(seed=seed)
        runs.append(
            [obs, *(o for o, *_ in (env.step(a) for a in _actions(env.action_space, 3, 0)))]
        )
    for run in runs[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(run, runs[0], strict=True))
