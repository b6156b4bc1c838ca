"""Property tests of ``DrillString-v0`` with hypothesis: random actions and random options."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drill_env.options import PER_EPISODE_KEYWORDS, EnvConfig

ENV_ID = "DrillString-v0"
FUZZ = settings(
    deadline=None,
    max_examples=50,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    derandomize=True,  # the suite stays reproducible; the draws still cover the ranges
)

# One env per mode for the whole module: building an env is the slow part, and every example
# starts with its own seeded reset, so examples do not leak into each other.
_ENVS: dict[str, gym.Env[Any, Any]] = {}


def _env(mode: str) -> gym.Env[Any, Any]:
    if mode not in _ENVS:
        kwargs: dict[str, Any] = {"episode_s": 5.0}
        if mode == "residual":
            kwargs["base_controller"] = "proposed"
        _ENVS[mode] = gym.make(ENV_ID, **kwargs).unwrapped
    return _ENVS[mode]


finite_actions = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False, width=32)
modes = st.sampled_from(["direct", "residual"])


@FUZZ
@given(
    mode=modes,
    seed=st.integers(0, 2**32 - 1),
    actions=st.lists(finite_actions, min_size=1, max_size=12),
)
def test_random_actions_keep_observations_finite_and_rewards_bounded(
    mode: str, seed: int, actions: list[float]
) -> None:
    """Any finite action sequence in [-3, 3] gives finite observations in the box and rewards
    in [-1, 0]; clipping is counted."""
    env = _env(mode)
    obs, _ = env.reset(seed=seed)
    assert env.observation_space.contains(obs)
    clipped = 0
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
        assert np.all(np.isfinite(obs))
        assert env.observation_space.contains(obs)
        assert isinstance(reward, float)
        assert -2.0 <= reward <= 0.0  # the default weights' range
        clipped += abs(a) > 1.0
        assert info["actions_clipped_total"] == clipped
        assert math.isfinite(info["bit_speed_rad_s"])
        if terminated or truncated:
            break


valid_options = st.fixed_dictionaries(
    {},
    optional={
        "randomize": st.booleans(),
        "wob_n": st.floats(1e3, 1e6),
        "reference_speed_rad_s": st.floats(0.0, 100.0),
        "uncertainty": st.one_of(
            st.sampled_from(["nominal", "condition1", "condition2", "condition3"]),
            st.tuples(*[st.floats(-0.9, 10.0)] * 3),
        ),
        "uncertainty_reading": st.sampled_from(["plant", "controller"]),
        "noise_std_rad_s": st.floats(0.0, 1.0),
        "parameters": st.sampled_from(["zribi2024", "navarro_lopez2007"]),
        "episode_s": st.sampled_from([0.1, 1.0, 5.0]),
    },
)


@FUZZ
@given(
    mode=modes,
    seed=st.integers(0, 2**32 - 1),
    options=valid_options,
    actions=st.lists(st.floats(-1.0, 1.0, width=32), min_size=1, max_size=5),
)
def test_random_valid_options_reset_and_step(
    mode: str, seed: int, options: dict[str, Any], actions: list[float]
) -> None:
    """Any valid per-episode options reset and step without error, inside the box."""
    env = _env(mode)
    obs, info = env.reset(seed=seed, options=options)
    assert env.observation_space.contains(obs)
    if options.get("randomize") is False:
        assert info["wob_n"] == options.get("wob_n", 97_347.0)
    for a in actions:
        obs, reward, terminated, truncated, info = env.step(np.array([a], dtype=np.float32))
        assert env.observation_space.contains(obs)
        assert -2.0 <= reward <= 0.0  # the default weights' range
        assert math.isfinite(info["bit_speed_rad_s"])
        if terminated or truncated:
            break


_NOT_NUMBERS = st.one_of(
    st.text(max_size=5), st.none(), st.lists(st.integers(), max_size=2), st.booleans()
)
_BAD_NUMBERS = st.sampled_from([math.nan, math.inf, -math.inf])
_MAKE_ONLY = sorted(set(EnvConfig.keywords()) - set(PER_EPISODE_KEYWORDS))
_VALID_NAMES = set(EnvConfig.keywords())

invalid_option = st.one_of(
    st.tuples(
        st.just("wob_n"),
        st.one_of(
            st.floats(max_value=0.0), st.floats(min_value=1.0001e6), _BAD_NUMBERS, _NOT_NUMBERS
        ),
    ),
    st.tuples(
        st.just("reference_speed_rad_s"),
        st.one_of(
            st.floats(max_value=-1e-9), st.floats(min_value=100.0001), _BAD_NUMBERS, _NOT_NUMBERS
        ),
    ),
    st.tuples(
        st.just("noise_std_rad_s"),
        st.one_of(st.floats(max_value=-1e-9), st.floats(min_value=10.0001), _BAD_NUMBERS),
    ),
    st.tuples(
        st.just("uncertainty"),
        st.one_of(
            st.text(max_size=12).filter(
                lambda s: s not in ("nominal", "condition1", "condition2", "condition3")
            ),
            st.lists(st.floats(-0.5, 0.5), min_size=0, max_size=2),
            st.lists(st.floats(-0.5, 0.5), min_size=4, max_size=5),
            st.tuples(st.floats(min_value=10.001), st.just(0.0), st.just(0.0)),
            st.tuples(st.just(0.0), st.floats(max_value=-0.9001), st.just(0.0)),
            st.integers(),
            st.none(),
        ),
    ),
    st.tuples(
        st.just("uncertainty_reading"),
        st.one_of(
            st.text(max_size=12).filter(lambda s: s not in ("plant", "controller")), st.none()
        ),
    ),
    st.tuples(
        st.just("randomize"), st.one_of(st.integers(), st.text(max_size=3), st.none(), st.floats())
    ),
    st.tuples(
        st.just("parameters"),
        st.one_of(
            st.text(max_size=12).filter(lambda s: s not in ("zribi2024", "navarro_lopez2007")),
            st.integers(),
            st.none(),
        ),
    ),
    st.tuples(
        st.just("episode_s"),
        st.one_of(
            st.floats(max_value=0.0),
            st.floats(0.051, 20.0).filter(lambda x: abs(x / 0.05 - round(x / 0.05)) > 1e-3),
            _BAD_NUMBERS,
            _NOT_NUMBERS,
        ),
    ),
    st.tuples(st.sampled_from(_MAKE_ONLY), st.floats(0.0, 1.0)),
    st.tuples(
        st.text(min_size=1, max_size=20).filter(lambda s: s not in _VALID_NAMES), st.integers()
    ),
)


@FUZZ
@given(
    mode=modes,
    bad=invalid_option,
    valid=valid_options,
)
def test_random_invalid_options_raise_value_or_type_error(
    mode: str, bad: tuple[str, Any], valid: dict[str, Any]
) -> None:
    """Any invalid option, among valid ones, raises ValueError or TypeError and nothing else,
    and the env still works afterwards."""
    env = _env(mode)
    key, value = bad
    options = {**valid, key: value}
    try:
        env.reset(seed=0, options=options)
    except (ValueError, TypeError):
        pass
    else:  # pragma: no cover - the strategy only builds invalid options
        raise AssertionError(f"options {options!r} were accepted")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


@FUZZ
@given(
    action=st.one_of(
        st.sampled_from([math.nan, math.inf, -math.inf]).map(lambda v: np.array([v], np.float32)),
        st.lists(finite_actions, min_size=2, max_size=4).map(np.array),
        st.lists(finite_actions, min_size=1, max_size=1).map(lambda a: np.array([a])),
        st.text(max_size=3),
        st.none(),
    )
)
def test_random_invalid_actions_raise_value_error(action: Any) -> None:
    """A non-finite, wrongly shaped or non-numeric action raises ValueError naming it."""
    env = _env("direct")
    env.reset(seed=0)
    try:
        env.step(action)
    except ValueError as err:
        assert "action" in str(err)
    else:  # pragma: no cover
        raise AssertionError(f"action {action!r} was accepted")
