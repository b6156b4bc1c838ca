"""Bad input to ``DrillString-v0`` and the baselines: every error is explicit and pinned."""

from __future__ import annotations

import math
import re
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from baselines import (
    ASMCGains,
    CSMCGains,
    MSMCGains,
    ProposedGains,
    SurfaceGains,
    controller_names,
    make_controller,
)
from drill_env.options import EnvConfig
from drill_env.scenarios import Randomization

ENV_ID = "DrillString-v0"


def _env(**kwargs: Any) -> gym.Env[Any, Any]:
    env = gym.make(ENV_ID, **kwargs)
    env.reset(seed=0)
    return env


# ----------------------------------------------------------------------------- actions
@pytest.mark.parametrize(
    ("action", "match"),
    [
        pytest.param(np.array([np.nan], np.float32), r"action must be finite", id="nan"),
        pytest.param(np.array([np.inf], np.float32), r"action must be finite", id="inf"),
        pytest.param(np.array([-np.inf]), r"action must be finite", id="-inf-float64"),
        pytest.param(np.zeros(2, np.float32), r"action must have shape \(1,\), got shape \(2,\)", id="shape-2"),
        pytest.param(np.zeros((1, 1), np.float32), r"action must have shape \(1,\), got shape \(1, 1\)", id="shape-1x1"),
        pytest.param(np.zeros(0, np.float32), r"action must have shape \(1,\), got shape \(0,\)", id="empty"),
        pytest.param("up", r"action must be numeric", id="string"),
        pytest.param([None], r"action must be", id="none-list"),
    ],
)  # fmt: skip
def test_bad_action_is_a_value_error(action: Any, match: str) -> None:
    """NaN, infinite, wrongly shaped or non-numeric actions raise ValueError naming ``action``."""
    env = _env()
    with pytest.raises(ValueError, match=match):
        env.unwrapped.step(action)


def test_bad_action_leaves_episode_usable() -> None:
    """A refused action does not advance or corrupt the episode."""
    env = _env(randomize=False, noise_std_rad_s=0.0)
    with pytest.raises(ValueError, match="action"):
        env.unwrapped.step(np.array([np.nan], np.float32))
    _, _, _, _, info = env.step(np.array([0.0], np.float32))
    assert info["time_s"] == pytest.approx(0.1)  # one default decision period
    assert info["top_drive_torque_nm"] == pytest.approx(25_000.0)


@pytest.mark.parametrize(
    ("value", "expected_nm"),
    [
        pytest.param(1.5, 50_000.0, id="above"),
        pytest.param(3.0, 50_000.0, id="far-above"),
        pytest.param(-2.0, 0.0, id="below"),
    ],
)
def test_out_of_range_action_is_clipped_and_counted(value: float, expected_nm: float) -> None:
    """An action outside [-1, 1] is clipped to the torque limit and counted in ``info``."""
    env = _env()
    _, _, _, _, info = env.step(np.array([value], np.float32))
    assert info["top_drive_torque_nm"] == pytest.approx(expected_nm, abs=1e-6)
    assert info["action_clipped"] is True
    assert info["actions_clipped_total"] == 1
    _, _, _, _, info = env.step(np.array([0.0], np.float32))
    assert info["action_clipped"] is False
    assert info["actions_clipped_total"] == 1
    _, _, _, _, info = env.step(np.array([value], np.float32))
    assert info["actions_clipped_total"] == 2
    _, info = env.reset(seed=1)
    assert info["actions_clipped_total"] == 0


def test_out_of_range_residual_is_clipped() -> None:
    """In residual mode an out-of-range action is clipped to +-residual_scale."""
    env = _env(base_controller="proposed", residual_scale_nm=1_000.0)
    _, _, _, _, info = env.step(np.array([4.0], np.float32))
    assert info["residual_torque_nm"] == pytest.approx(1_000.0)
    assert info["action_clipped"] is True


def test_vector_env_bad_actions() -> None:
    """The vector env refuses NaN and wrong shapes and counts clipping per string."""
    venv = gym.make_vec(ENV_ID, num_envs=2)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be finite"):
        venv.step(np.array([[0.0], [np.nan]], np.float32))
    with pytest.raises(ValueError, match=r"action must have shape \(2, 1\), got shape \(3, 1\)"):
        venv.step(np.zeros((3, 1), np.float32))
    _, _, _, _, infos = venv.step(np.array([[2.0], [0.0]], np.float32))
    assert infos["action_clipped"].tolist() == [True, False]
    assert infos["actions_clipped_total"].tolist() == [1, 0]
    assert infos["top_drive_torque_nm"][0] == pytest.approx(50_000.0)


def test_step_before_reset() -> None:
    """Stepping before the first reset is refused."""
    env = gym.make(ENV_ID).unwrapped
    with pytest.raises(RuntimeError, match=r"call reset\(\) before step\(\)"):
        env.step(np.zeros(1, np.float32))


# ------------------------------------------------------------------------ make keywords
BAD_KEYWORDS = [
    pytest.param({"wob_n": -5.0}, ValueError, r"wob_n = -5.0 is out of range: allowed \[1e-09, 1e\+06\]", id="wob_n<0"),
    pytest.param({"wob_n": 0.0}, ValueError, r"wob_n = 0.0 is out of range", id="wob_n=0"),
    pytest.param({"wob_n": 2e6}, ValueError, r"wob_n = 2000000.0 is out of range", id="wob_n-huge"),
    pytest.param({"wob_n": math.nan}, ValueError, r"wob_n = nan is out of range", id="wob_n-nan"),
    pytest.param({"wob_n": "heavy"}, TypeError, r"wob_n must be a real number, got 'heavy'", id="wob_n-str"),
    pytest.param({"wob_n": True}, TypeError, r"wob_n must be a real number, got True", id="wob_n-bool"),
    pytest.param({"reference_speed_rad_s": 150.0}, ValueError, r"reference_speed_rad_s = 150.0 is out of range: allowed \[0, 100\]", id="reference>100"),
    pytest.param({"reference_speed_rad_s": -1.0}, ValueError, r"reference_speed_rad_s = -1.0 is out of range: allowed \[0, 100\]", id="reference<0"),
    pytest.param({"control_dt_s": 0.0015}, ValueError, r"control_dt_s = 0.0015 is out of range: allowed a multiple of plant_dt = 0.001 s", id="control_dt-not-multiple"),
    pytest.param({"control_dt_s": 0.0005}, ValueError, r"control_dt_s = 0.0005 is out of range: allowed \[0.001, 10\]", id="control_dt-too-small"),
    pytest.param({"episode_s": 1.01}, ValueError, r"episode_s = 1.01 is out of range: allowed a multiple of control_dt_s = 0.1", id="episode-not-multiple"),
    pytest.param({"episode_s": 0.0}, ValueError, r"episode_s = 0.0 is out of range", id="episode-zero"),
    pytest.param({"min_torque_nm": 10_000.0, "max_torque_nm": 10_000.0}, ValueError, r"min_torque_nm = 10000.0 must be below max_torque_nm = 10000.0", id="min=max"),
    pytest.param({"min_torque_nm": 60_000.0}, ValueError, r"min_torque_nm = 60000.0 must be below max_torque_nm = 50000.0", id="min>max"),
    pytest.param({"max_torque_nm": 2e6}, ValueError, r"max_torque_nm = 2000000.0 is out of range", id="max-huge"),
    pytest.param({"uncertainty": "condition4"}, ValueError, r"uncertainty = 'condition4' is not a known condition: allowed \['condition1', 'condition2', 'condition3', 'nominal'\]", id="uncertainty-name"),
    pytest.param({"uncertainty": (0.1, 0.2)}, ValueError, r"uncertainty must have 3 entries \(Delta1..3\), got 2", id="uncertainty-length"),
    pytest.param({"uncertainty": (0.1, -0.95, 0.0)}, ValueError, r"uncertainty\[1\] = -0.95 is out of range: allowed \[-0.9, 10\]", id="uncertainty-delta"),
    pytest.param({"uncertainty": 3}, TypeError, r"uncertainty must be a condition name or 3 numbers, got 3", id="uncertainty-int"),
    pytest.param({"uncertainty_reading": "both"}, ValueError, r"uncertainty_reading = 'both' is not a known reading: allowed \['controller', 'plant'\]", id="reading"),
    pytest.param({"noise_std_rad_s": -0.1}, ValueError, r"noise_std_rad_s = -0.1 is out of range: allowed \[0, 10\]", id="noise<0"),
    pytest.param({"parameters": "zribi"}, ValueError, r"parameters = 'zribi' is not a known preset: allowed \['navarro_lopez2007', 'zribi2024'\]", id="preset"),
    pytest.param({"randomize": 1}, TypeError, r"randomize must be True or False, got 1", id="randomize-int"),
    pytest.param({"base_controller": "pid"}, ValueError, r"unknown controller 'pid': valid names are csmc, msmc, asmc, proposed", id="controller-name"),  # a prefix: more may follow
    pytest.param({"base_controller": 42}, TypeError, r"base_controller must be None, a controller name or an object with reset\(\)", id="controller-type"),
    pytest.param({"residual_scale_nm": -1.0}, ValueError, r"residual_scale_nm = -1.0 is out of range", id="residual-scale"),
    pytest.param({"wob_step_time_s": 10.0}, ValueError, r"wob_step_time_s and wob_final_n must be given together", id="wob-step-alone"),
    pytest.param({"randomization": {"wob_range": (1, 2)}}, TypeError, r"unrecognized field\(s\) for randomization: wob_range", id="randomization-dict"),
    pytest.param({"randomization": 3}, TypeError, r"randomization must be a Randomization", id="randomization-int"),
    pytest.param({"reward_weights": {"tracking": -1.0}}, ValueError, r"reward weight tracking = -1.0 is out of range", id="reward-dict"),
    pytest.param({"reward_weights": (1, 0, 0)}, TypeError, r"reward_weights must be a RewardWeights", id="reward-weights"),
]  # fmt: skip


@pytest.mark.parametrize(("kwargs", "error", "match"), BAD_KEYWORDS)
def test_invalid_make_keyword(kwargs: dict[str, Any], error: type, match: str) -> None:
    """Every invalid keyword value at ``make`` is refused with a message naming it."""
    with pytest.raises(error, match=match):
        gym.make(ENV_ID, **kwargs)


@pytest.mark.parametrize(("kwargs", "error", "match"), BAD_KEYWORDS[:12])
def test_invalid_make_keyword_vector(kwargs: dict[str, Any], error: type, match: str) -> None:
    """``make_vec`` validates the keywords the same way."""
    with pytest.raises(error, match=match):
        gym.make_vec(ENV_ID, num_envs=2, **kwargs)


def test_unknown_make_keyword_lists_valid_ones() -> None:
    """A misspelt keyword is a TypeError listing every valid keyword."""
    with pytest.raises(
        TypeError, match=r"unrecognized keyword\(s\): wob, ww; valid keywords: "
    ) as err:
        gym.make(ENV_ID, wob=1e5, ww=1)
    for name in EnvConfig.keywords():
        assert name in str(err.value)


def test_unknown_make_keyword_vector() -> None:
    """``make_vec`` refuses unknown keywords too."""
    with pytest.raises(TypeError, match=r"unrecognized keyword\(s\): noise"):
        gym.make_vec(ENV_ID, num_envs=2, noise=0.1)


@pytest.mark.parametrize("num_envs", [0, -1, 2.5, True], ids=["zero", "negative", "float", "bool"])
def test_vector_env_bad_num_envs(num_envs: Any) -> None:
    """``num_envs`` must be a positive integer."""
    with pytest.raises(ValueError, match=r"num_envs = .* is out of range: allowed an integer >= 1"):
        gym.make_vec(ENV_ID, num_envs=num_envs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"wob_range_n": (2e5, 1e5)}, r"wob_range_n = \(200000.0, 100000.0\) is inverted", id="inverted"),
        pytest.param({"wob_range_n": (1e5,)}, r"wob_range_n must be a \(low, high\) pair", id="not-a-pair"),
        pytest.param({"wob_step_probability": 1.5}, r"wob_step_probability = 1.5 is out of range: allowed \[0, 1\]", id="probability"),
        pytest.param({"reference_range_rad_s": (0.0, 200.0)}, r"reference_range_rad_s\[1\] = 200.0 is out of range", id="reference-range"),
        pytest.param({"delta_range": (-1.0, 0.5)}, r"delta_range\[0\] = -1.0 is out of range: allowed \[-0.9, 10\]", id="delta-range"),
    ],
)  # fmt: skip
def test_invalid_randomization(kwargs: dict[str, Any], match: str) -> None:
    """Randomisation ranges are validated when built."""
    with pytest.raises(ValueError, match=match):
        Randomization(**kwargs)


# ------------------------------------------------------------------------ reset options
def test_unknown_reset_option_lists_valid_ones() -> None:
    """An unknown option is a ValueError listing the per-episode options."""
    env = _env()
    with pytest.raises(
        ValueError, match=r"unknown option\(s\): speed; valid options: parameters, randomize, wob_n"
    ):
        env.reset(options={"speed": 3.0})


@pytest.mark.parametrize(
    "key",
    ["control_dt_s", "base_controller", "min_torque_nm", "max_torque_nm", "residual_scale_nm"],
)
def test_make_only_option_is_refused(key: str) -> None:
    """Keywords that shape the spaces or the compiled loop cannot change per episode."""
    env = _env()
    value = {"control_dt_s": 0.01, "base_controller": "csmc"}.get(key, 1_000.0)
    with pytest.raises(
        ValueError, match=rf"option\(s\) {key} cannot change per episode: set them at make"
    ):
        env.reset(options={key: value})


@pytest.mark.parametrize(
    ("options", "error", "match"),
    [
        pytest.param({"wob_n": -5.0}, ValueError, r"wob_n = -5.0 is out of range", id="wob_n"),
        pytest.param({"reference_speed_rad_s": 101.0}, ValueError, r"reference_speed_rad_s = 101.0 is out of range", id="reference"),
        pytest.param({"noise_std_rad_s": math.inf}, ValueError, r"noise_std_rad_s = inf is out of range", id="noise"),
        pytest.param({"uncertainty": "worst"}, ValueError, r"uncertainty = 'worst' is not a known condition", id="uncertainty"),
        pytest.param({"uncertainty_reading": "model"}, ValueError, r"uncertainty_reading = 'model' is not a known reading", id="reading"),
        pytest.param({"episode_s": 0.17}, ValueError, r"episode_s = 0.17 is out of range: allowed a multiple of control_dt_s", id="episode"),
        pytest.param({"randomize": "no"}, TypeError, r"randomize must be True or False, got 'no'", id="randomize"),
        pytest.param({"parameters": 7}, TypeError, r"parameters must be a preset name or a DrillStringParameters, got int", id="parameters"),
    ],
)  # fmt: skip
def test_invalid_reset_option_value(options: dict[str, Any], error: type, match: str) -> None:
    """A bad per-episode value is refused with the same message as at make."""
    env = _env()
    with pytest.raises(error, match=match):
        env.reset(seed=0, options=options)


def test_reset_options_must_be_a_dict() -> None:
    """Options that are not a mapping are a TypeError."""
    env = _env()
    with pytest.raises(TypeError, match=r"options must be a dict, got list"):
        env.reset(options=[("wob_n", 1e5)])  # type: ignore[arg-type]


def test_env_usable_after_refused_options() -> None:
    """A refused reset leaves the env able to reset and step normally."""
    env = _env(randomize=False)
    with pytest.raises(ValueError, match="wob_n"):
        env.reset(options={"wob_n": -1.0})
    _, info = env.reset(seed=0)
    assert info["wob_n"] == 97_347.0
    _, reward, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
    assert -2.0 <= reward <= 0.0  # the default weights' range
    assert not terminated and not truncated


def test_vector_reset_options_validated() -> None:
    """The vector env validates reset options like the single env."""
    venv = gym.make_vec(ENV_ID, num_envs=2)
    with pytest.raises(ValueError, match=r"unknown option\(s\): wobble"):
        venv.reset(seed=0, options={"wobble": 1})
    with pytest.raises(ValueError, match=r"seed list must have 2 entries, got 3"):
        venv.reset(seed=[1, 2, 3])


# ---------------------------------------------------------------------------- baselines
def test_make_controller_unknown_name_lists_valid_ones() -> None:
    """An unknown controller name is a ValueError listing every registered name."""
    names = controller_names()
    assert names[:4] == ["csmc", "msmc", "asmc", "proposed"]
    message = f"unknown controller 'nope': valid names are {', '.join(names)}"
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        make_controller("nope")


def test_make_controller_unknown_gain() -> None:
    """A gain the controller does not have is a TypeError listing the valid gains."""
    with pytest.raises(
        TypeError, match=r"unrecognized gain\(s\) for csmc: k9; valid gains: lam, delta, k1"
    ):
        make_controller("csmc", k9=1.0)


@pytest.mark.parametrize(
    ("factory", "kwargs", "match"),
    [
        pytest.param(ProposedGains, {"k0": 0.05}, r"ProposedGains.k0 = 0.05 is out of range: allowed > alpha = 0.1", id="proposed-k0<alpha"),
        pytest.param(ProposedGains, {"b": 1.5}, r"ProposedGains.b = 1.5 is out of range: allowed \(0, 1\]", id="proposed-b"),
        pytest.param(ProposedGains, {"mu1": 0.0}, r"ProposedGains.mu1 = 0.0 is out of range: allowed > 0", id="proposed-mu1"),
        pytest.param(ProposedGains, {"a": -0.01}, r"ProposedGains.a = -0.01 is out of range: allowed >= 0", id="proposed-a"),
        pytest.param(CSMCGains, {"k1": -3.0}, r"CSMCGains.k1 = -3.0 is out of range: allowed > 0", id="csmc-k1"),
        pytest.param(MSMCGains, {"k3": -1.0}, r"MSMCGains.k3 = -1.0 is out of range: allowed >= 0", id="msmc-k3"),
        pytest.param(ASMCGains, {"mu22": 0.0}, r"ASMCGains.mu22 = 0.0 is out of range: allowed > 0", id="asmc-mu22"),
        pytest.param(SurfaceGains, {"lam": 0.0}, r"SurfaceGains.lam = 0.0 is out of range: allowed > 0", id="surface-lam"),
        pytest.param(SurfaceGains, {"delta": math.nan}, r"SurfaceGains.delta must be finite, got nan", id="surface-delta-nan"),
    ],
)  # fmt: skip
def test_controller_gain_validation(factory: type, kwargs: dict[str, Any], match: str) -> None:
    """Gains are validated on construction, naming class, gain, value and allowed range."""
    with pytest.raises(ValueError, match=match):
        factory(**kwargs)


def test_controller_gain_override_validated() -> None:
    """Gains passed through ``make_controller`` are validated too."""
    with pytest.raises(ValueError, match=r"ProposedGains.k0 = 0.05 is out of range"):
        make_controller("proposed", k0=0.05)


def test_controller_measurement_shape() -> None:
    """A controller refuses a measurement that is not 7 numbers."""
    ctrl = make_controller("csmc")
    with pytest.raises(
        ValueError,
        match=r"measurement must have shape \(7,\) \(the measured state\) or \(12,\) .*got \(4,\)",
    ):
        ctrl.torque(np.zeros(4), 12.0, 1e-3)
