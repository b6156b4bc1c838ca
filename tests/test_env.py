"""Tests of the ``DrillString-v0`` Gymnasium contract (docs/specification.md section 5)."""

from __future__ import annotations

import dataclasses
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import drill_env
from baselines import make_controller
from drill_env.integration import plant_step
from drill_env.parameters import PRESETS, plant_parameter_vector
from drill_env.rewards import TERMS

ENV_ID = "DrillString-v0"
MODES = {
    "direct": {},
    "residual": {"base_controller": "proposed"},
}
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
RESIDUAL_INFO_KEYS = (
    "base_torque_nm",
    "residual_torque_nm",
    "sliding_variable_rad_s",
    "adaptive_gain",
)
UNIT_SUFFIXES = ("_s", "_rad_s", "_nm", "_n", "_rad")
UNITLESS_INFO_KEYS = {
    "bit_stuck",
    "reward_terms",
    "action_clipped",
    "actions_clipped_total",
    "termination_reason",
    "adaptive_gain",
}
WOB_N = 97_347.0
V_REF = 12.0


def make(mode: str = "direct", **kwargs: Any) -> gym.Env[Any, Any]:
    """``gym.make`` of the env in ``mode`` with extra keywords, at a 50 ms decision period
    unless ``control_dt_s`` is given (the step counts of these tests are written for it)."""
    return gym.make(ENV_ID, **MODES[mode], **{"control_dt_s": 0.05, **kwargs})


def act(value: float) -> np.ndarray:
    return np.array([value], dtype=np.float32)


# ------------------------------------------------------------------------ registration
def test_import_registers_env() -> None:
    """Importing ``drill_env`` registers ``DrillString-v0`` without a registered step limit
    (the env truncates itself); a made env's spec states its own: 1000 decisions by default
    (100 s at the default 0.1 s decision period)."""
    spec = gym.spec(ENV_ID)
    assert spec.entry_point == "drill_env.creators:make_drill_string_env"
    assert spec.max_episode_steps is None
    assert gym.make(ENV_ID).spec.max_episode_steps == 1000  # type: ignore[union-attr]
    made = gym.make(ENV_ID, episode_s=150.0, control_dt_s=0.1)
    assert made.spec.max_episode_steps == 1500  # type: ignore[union-attr]
    assert drill_env.ENV_ID == ENV_ID


# ---------------------------------------------------------------------------- checkers
@pytest.mark.parametrize("mode", sorted(MODES))
def test_gymnasium_env_checker_without_warnings(mode: str) -> None:
    """Gymnasium's ``check_env`` passes and warns about nothing."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = make(mode)
        check_env(env.unwrapped)
        env.close()


@pytest.mark.parametrize("mode", sorted(MODES))
def test_sb3_env_checker_without_warnings(mode: str) -> None:
    """Stable-Baselines3's ``check_env`` passes and warns about nothing."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = make(mode)
        sb3_check_env(env.unwrapped, warn=True)
        env.close()


@pytest.mark.parametrize("mode", sorted(MODES))
def test_step_returns_python_types(mode: str) -> None:
    """``step`` returns a float reward and Python bools, as the Gymnasium API asks."""
    env = make(mode)
    env.reset(seed=0)
    _, reward, terminated, truncated, _ = env.unwrapped.step(act(0.0))
    assert type(reward) is float
    assert type(terminated) is bool
    assert type(truncated) is bool


# ------------------------------------------------------------------------ spaces, obs
@pytest.mark.parametrize("mode", sorted(MODES))
def test_spaces(mode: str) -> None:
    """Action ``Box(-1, 1, (1,), float32)``; observation ``Box(-50, 50, (n,), float32)``."""
    env = make(mode)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    assert env.observation_space == gym.spaces.Box(-50.0, 50.0, (OBS_SIZE[mode],), np.float32)


@pytest.mark.parametrize("mode", sorted(MODES))
def test_observations_are_float32_in_the_box(mode: str) -> None:
    """Every observation of a random episode has the declared dtype, shape and bounds."""
    env = make(mode, episode_s=2.0)
    obs, _ = env.reset(seed=3)
    env.action_space.seed(3)
    observations = [obs]
    for _ in range(40):
        obs, *_ = env.step(env.action_space.sample())
        observations.append(obs)
    for obs in observations:
        assert obs.dtype == np.float32
        assert obs.shape == (OBS_SIZE[mode],)
        assert env.observation_space.contains(obs)


def test_initial_observation_is_rest() -> None:
    """At reset the string is at rest: twists 0, noise-free speeds 0, reference scaled."""
    env = make(randomize=False, noise_std_rad_s=0.0)
    obs, info = env.reset(seed=0)
    expected = np.zeros(9, dtype=np.float32)
    expected[7] = V_REF / 20.0
    np.testing.assert_array_equal(obs, expected)
    assert info["bit_stuck"] is True
    assert info["time_s"] == 0.0


def test_observation_scales_physical_values() -> None:
    """Observation entries are the documented physical values over their scales."""
    env = make(randomize=False, noise_std_rad_s=0.0, episode_s=5.0)
    env.reset(seed=0)
    for _ in range(20):
        obs, _, _, _, info = env.step(act(-0.4))
    assert obs[0] == pytest.approx(info["top_drive_speed_rad_s"] / 20.0, rel=1e-6)
    assert obs[6] == pytest.approx(info["bit_speed_rad_s"] / 20.0, rel=1e-6, abs=1e-9)
    assert obs[7] == pytest.approx(info["reference_speed_rad_s"] / 20.0, rel=1e-6)
    assert obs[8] == pytest.approx(info["top_drive_torque_nm"] / 50_000.0, rel=1e-6)


# --------------------------------------------------------------------------------- info
@pytest.mark.parametrize("mode", sorted(MODES))
def test_info_keys_carry_units(mode: str) -> None:
    """``info`` has the docs/specification.md section 5 keys at reset and step, and numeric keys name a unit."""
    env = make(mode)
    _, reset_info = env.reset(seed=0)
    _, _, _, _, step_info = env.step(act(0.0))
    expected = REQUIRED_INFO_KEYS + (RESIDUAL_INFO_KEYS if mode == "residual" else ())
    for info in (reset_info, step_info):
        assert set(expected) <= set(info)
        for key, value in info.items():
            if key in UNITLESS_INFO_KEYS or isinstance(value, (bool, np.bool_)):
                continue
            if isinstance(value, (float, np.floating)):
                assert key.endswith(UNIT_SUFFIXES), f"info[{key!r}] has no unit in its name"
    assert type(step_info["bit_stuck"]) is bool
    assert set(step_info["reward_terms"]) == set(TERMS)


def test_info_values_follow_the_scenario() -> None:
    """Time, WOB and reference in ``info`` are those of the (fixed) scenario."""
    env = make(randomize=False, control_dt_s=0.02, episode_s=1.0, max_episode_steps=50)
    _, info = env.reset(seed=0)
    assert info["wob_n"] == WOB_N
    assert info["reference_speed_rad_s"] == V_REF
    for k in range(1, 6):
        _, _, _, _, info = env.step(act(0.0))
        assert info["time_s"] == pytest.approx(0.02 * k, abs=1e-12)
        assert info["wob_n"] == WOB_N
        assert info["reference_speed_rad_s"] == V_REF


# --------------------------------------------------------------------------- episode end
@pytest.mark.parametrize(
    "max_episode_steps", [None, 20, 2000], ids=["registered", "matching", "longer"]
)
def test_truncation_after_episode_s(max_episode_steps: int | None) -> None:
    """An episode of ``episode_s = 1 s`` at 50 ms is truncated at exactly step 20."""
    kwargs: dict[str, Any] = {"episode_s": 1.0}
    if max_episode_steps is not None:
        kwargs["max_episode_steps"] = max_episode_steps
    env = make(**kwargs)
    env.reset(seed=0)
    for k in range(1, 21):
        _, _, terminated, truncated, info = env.step(act(0.0))
        assert not terminated
        assert truncated == (k == 20)
    assert info["time_s"] == pytest.approx(1.0)


def test_time_limit_wrapper_truncates_earlier() -> None:
    """A ``max_episode_steps`` shorter than ``episode_s`` truncates through the wrapper."""
    env = make(episode_s=1.0, max_episode_steps=5)
    env.reset(seed=0)
    truncations = [env.step(act(0.0))[3] for _ in range(5)]
    assert truncations == [False] * 4 + [True]


def _diverging_env(mode: str = "direct") -> gym.Env[Any, Any]:
    """Undamped top drive, 1e6 N m at action +1: the top drive passes 1000 rad/s in ~1.3 s."""
    undamped = dataclasses.replace(PRESETS["zribi2024"], c_dt=0.0, c_bit=0.0)
    return make(
        mode,
        parameters=undamped,
        randomize=False,
        max_torque_nm=1e6,
        residual_scale_nm=1e6,
        episode_s=20.0,
        max_episode_steps=400,
    )


@pytest.mark.parametrize("mode", sorted(MODES))
def test_divergence_terminates_cleanly(mode: str) -> None:
    """A state leaving the physical bounds ends the episode: terminated, reason, reward -1,
    finite observation inside the box."""
    env = _diverging_env(mode)
    env.reset(seed=0)
    for _ in range(400):
        obs, reward, terminated, truncated, info = env.step(act(1.0))
        assert np.all(np.isfinite(obs))
        if terminated or truncated:
            break
    assert terminated is True
    assert truncated is False
    assert info["termination_reason"] == "diverged"
    assert reward == -1.0
    assert env.observation_space.contains(obs)
    for key in ("bit_speed_rad_s", "top_drive_speed_rad_s", "top_drive_torque_nm"):
        assert np.isfinite(info[key])
    # The episode is over; a new one starts cleanly.
    with pytest.raises(RuntimeError, match=r"call reset\(\)"):
        env.unwrapped.step(act(0.0))
    obs, info = env.reset(seed=0)
    assert info["time_s"] == 0.0
    assert "termination_reason" not in info
    _, reward, terminated, _, _ = env.step(act(-1.0))
    assert not terminated
    assert -1.0 <= reward <= 0.0


# ------------------------------------------------------------------------ torque mapping
@pytest.mark.parametrize(
    ("action", "expected_nm"),
    [
        pytest.param(-1.0, 1_000.0, id="min"),
        pytest.param(1.0, 30_000.0, id="max"),
        pytest.param(0.0, 15_500.0, id="middle"),
        pytest.param(0.5, 22_750.0, id="three-quarters"),
    ],
)
def test_direct_torque_mapping(action: float, expected_nm: float) -> None:
    """Direct mode: ``u = min + (a + 1) / 2 (max - min)`` (docs/specification.md section 5)."""
    env = make(min_torque_nm=1_000.0, max_torque_nm=30_000.0)
    env.reset(seed=0)
    _, _, _, _, info = env.step(act(action))
    assert info["top_drive_torque_nm"] == pytest.approx(expected_nm, rel=1e-12)
    assert info["action_clipped"] is False


def test_direct_torque_mapping_defaults() -> None:
    """With the default limits, -1 is 0 N m and +1 is 50,000 N m."""
    env = make()
    env.reset(seed=0)
    assert env.step(act(-1.0))[4]["top_drive_torque_nm"] == 0.0
    assert env.step(act(1.0))[4]["top_drive_torque_nm"] == pytest.approx(50_000.0, rel=1e-12)


@pytest.mark.parametrize("action", [-0.8, 0.0, 0.3, 1.0], ids=lambda a: f"a={a}")
def test_residual_torque_mapping(action: float) -> None:
    """Residual mode: ``u = clip(u_base + residual_scale a, min, max)``, both parts in info."""
    env = make("residual", randomize=False, residual_scale_nm=2_000.0)
    env.reset(seed=1)
    for _ in range(10):
        _, _, _, _, info = env.step(act(action))
        assert info["residual_torque_nm"] == pytest.approx(2_000.0 * action, rel=1e-6)
        expected = np.clip(info["base_torque_nm"] + info["residual_torque_nm"], 0.0, 50_000.0)
        assert info["top_drive_torque_nm"] == pytest.approx(expected, rel=1e-12, abs=1e-9)


def test_residual_zero_action_is_the_base_controller_alone() -> None:
    """With action 0 the residual env is the base controller closing the loop at every plant
    step, reproduced here by a plain loop of ``controller.torque`` and ``plant_step``."""
    env = make("residual", randomize=False, noise_std_rad_s=0.0)
    env.reset(seed=0)
    params = PRESETS["zribi2024"]
    p = plant_parameter_vector(params)
    t_a, t_0 = params.static_torque_nm(WOB_N), params.sliding_torque_nm(WOB_N)
    ctrl = make_controller("proposed")
    ctrl.reset()
    x: tuple[float, ...] = (0.0,) * 7
    mode = 0
    for _ in range(30):  # 1.5 s = 1500 plant steps
        _, _, _, _, info = env.step(act(0.0))
        for _ in range(50):
            u_base = ctrl.torque(np.array(x), V_REF, 1e-3)
            u = min(max(u_base, 0.0), 50_000.0)
            x, mode = plant_step(x, mode, u, p, t_a, t_0, 1e-3)
        assert info["residual_torque_nm"] == 0.0
        assert info["base_torque_nm"] == pytest.approx(u_base, rel=1e-9, abs=1e-9)
        assert info["top_drive_torque_nm"] == pytest.approx(u, rel=1e-9, abs=1e-9)
        assert info["bit_speed_rad_s"] == pytest.approx(x[6], rel=1e-9, abs=1e-9)
        assert info["top_drive_speed_rad_s"] == pytest.approx(x[0], rel=1e-9, abs=1e-9)
        assert info["bit_stuck"] == (mode == 0)
        assert info["sliding_variable_rad_s"] == pytest.approx(ctrl.sliding_variable, rel=1e-9)
        assert info["adaptive_gain"] == pytest.approx(ctrl.adaptive_gain, rel=1e-9)


def test_residual_observation_carries_base_controller() -> None:
    """Residual observations 9 and 10 are the base torque and the sliding variable."""
    env = make("residual", randomize=False, noise_std_rad_s=0.0)
    env.reset(seed=0)
    for _ in range(5):
        obs, _, _, _, info = env.step(act(0.2))
    assert obs[9] == pytest.approx(info["base_torque_nm"] / 50_000.0, rel=1e-6)
    assert obs[10] == pytest.approx(info["sliding_variable_rad_s"] / 20.0, rel=1e-6)


# --------------------------------------------------------------------------- vector env
def test_reset_options_override_one_episode() -> None:
    """``reset(options=...)`` changes the scenario for that episode only."""
    env = make(randomize=False, noise_std_rad_s=0.0, episode_s=1.0)
    options = {"wob_n": 150e3, "reference_speed_rad_s": 5.0, "episode_s": 0.5}
    obs, info = env.reset(seed=0, options=options)
    assert info["wob_n"] == 150e3
    assert info["reference_speed_rad_s"] == 5.0
    assert obs[7] == pytest.approx(5.0 / 20.0)
    truncations = []
    for _ in range(10):
        _, _, _, truncated, info = env.step(act(0.0))
        truncations.append(truncated)
        assert info["wob_n"] == 150e3
    assert truncations == [False] * 9 + [True]
    # The next episode is back to the make keywords.
    obs, info = env.reset(seed=0)
    assert info["wob_n"] == WOB_N
    assert info["reference_speed_rad_s"] == V_REF
    truncations = [env.step(act(0.0))[3] for _ in range(20)]
    assert truncations == [False] * 19 + [True]


def test_reset_option_switches_randomisation_off() -> None:
    """``randomize=False`` as an option gives the keyword scenario in a randomised env."""
    env = make(episode_s=1.0)
    _, info = env.reset(seed=5)
    assert info["wob_n"] != WOB_N
    _, info = env.reset(seed=5, options={"randomize": False})
    assert info["wob_n"] == WOB_N
    assert info["reference_speed_rad_s"] == V_REF


def test_reset_option_uncertainty_changes_plant() -> None:
    """A per-episode uncertainty condition changes the plant (and so the trajectory)."""
    env = make(randomize=False, noise_std_rad_s=0.0)
    runs = []
    for options in (None, {"uncertainty": "condition3"}, None):
        env.reset(seed=0, options=options)
        for _ in range(60):
            _, _, _, _, info = env.step(act(-0.4))
        runs.append(info["top_drive_speed_rad_s"])
    assert runs[0] == runs[2]
    assert runs[1] != runs[0]


def test_wob_step_change_shows_in_info() -> None:
    """A WOB step change (new rock layer) appears in ``info["wob_n"]`` at its time."""
    env = make(randomize=False, wob_step_time_s=0.5, wob_final_n=150e3, episode_s=1.0)
    _, info = env.reset(seed=0)
    assert info["wob_n"] == WOB_N
    wobs = [env.step(act(0.0))[4]["wob_n"] for _ in range(20)]
    assert wobs == [WOB_N] * 10 + [150e3] * 10


class _PythonController:
    """The proposed controller behind a plain Python object (no ``compiled_law``), so the env
    calls it at every plant step from Python."""

    def __init__(self) -> None:
        self.inner = make_controller("proposed")

    def reset(self) -> None:
        self.inner.reset()

    def torque(self, measurement: np.ndarray, reference_speed_rad_s: float, dt_s: float) -> float:
        return self.inner.torque(measurement, reference_speed_rad_s, dt_s)


def test_python_controller_matches_compiled_controller() -> None:
    """A controller object without ``compiled_law`` drives the env exactly like the compiled
    built-in (noise and randomised scenario on). Observation 10 (the sliding variable) is
    left out: the env cannot know it for a generic Python controller."""
    kwargs = {"episode_s": 2.0, "control_dt_s": 0.01}
    compiled = gym.make(ENV_ID, base_controller="proposed", **kwargs)
    python = gym.make(ENV_ID, base_controller=_PythonController(), **kwargs)
    obs_c, _ = compiled.reset(seed=4)
    obs_p, _ = python.reset(seed=4)
    np.testing.assert_array_equal(obs_c, obs_p)
    for a in np.linspace(-1.0, 1.0, 40):
        obs_c, rew_c, _, _, info_c = compiled.step(act(a))
        obs_p, rew_p, _, _, info_p = python.step(act(a))
        np.testing.assert_allclose(obs_p[:10], obs_c[:10], rtol=1e-6, atol=1e-7)
        assert rew_p == pytest.approx(rew_c, rel=1e-9, abs=1e-12)
        for key in ("bit_speed_rad_s", "top_drive_torque_nm", "base_torque_nm"):
            assert info_p[key] == pytest.approx(info_c[key], rel=1e-9, abs=1e-9)


def test_make_sets_the_time_limit_from_the_keywords() -> None:
    """``drill_env.make`` truncates at ``episode_s``, not at the registered 2000 decisions."""
    env = gym.make("DrillString-v0", randomize=False, episode_s=3.0, control_dt_s=0.001)
    env.reset(seed=0)
    steps = 0
    truncated = False
    while not truncated:
        _, _, terminated, truncated, info = env.step(np.zeros(1, dtype=np.float32))
        assert not terminated
        steps += 1
    assert steps == 3000
    assert info["time_s"] == pytest.approx(3.0)
