"""The keywords and the per-episode rule (:mod:`drill_env.options`)."""

from __future__ import annotations

import pytest

from drill_env.limits import DEFAULT_TORQUE_LIMITS
from drill_env.options import PER_EPISODE_KEYWORDS, EnvConfig, episode_config
from drill_env.parameters import PRESETS
from drill_env.scenarios import Scenario, SpeedProfile, WobProfile, spawn_generators


def test_defaults() -> None:
    config = EnvConfig()
    assert config.substeps == 100 and config.max_steps == 1000 and config.duration_s == 100.0
    assert config.torque_limits == DEFAULT_TORQUE_LIMITS and config.torque_scale_nm == 50_000.0
    assert not config.residual and config.randomize


def test_fixed_scenario_is_the_keywords() -> None:
    config = EnvConfig(
        randomize=False, wob_n=120e3, wob_step_time_s=30.0, wob_final_n=80e3,
        reference_speed_rad_s=7.0, uncertainty="condition2", uncertainty_reading="controller",
        noise_std_rad_s=0.0, parameters="navarro_lopez2007",
    )  # fmt: skip
    scenario = config.fixed_scenario()
    assert scenario == Scenario(
        wob=WobProfile(120e3, 30.0, 80e3),
        reference=SpeedProfile.constant(7.0),
        uncertainty=(0.6, 0.5, 0.4),
        reading="controller",
        noise_std_rad_s=0.0,
        parameters=PRESETS["navarro_lopez2007"],
    )
    assert scenario.plant == PRESETS["navarro_lopez2007"]  # the controller reading
    assert scenario.controller_model.k_pi == pytest.approx(1.5 * scenario.plant.k_pi)
    assert config.scenario(spawn_generators(__import__("numpy").random.SeedSequence(0))) == (
        scenario
    )


def test_a_scenario_gives_back_its_keywords() -> None:
    scenario = EnvConfig(randomize=False, wob_n=150e3, uncertainty="condition1").fixed_scenario()
    again = EnvConfig(**scenario.keywords()).fixed_scenario()
    assert again == scenario


def test_per_episode_options() -> None:
    base = EnvConfig()
    assert episode_config(base, None) is base
    changed = episode_config(base, {"wob_n": 1e5, "randomize": False})
    assert changed.wob_n == 1e5 and changed.control_dt_s == base.control_dt_s
    for fixed in set(EnvConfig.keywords()) - set(PER_EPISODE_KEYWORDS):
        with pytest.raises(ValueError, match=f"option\\(s\\) {fixed} cannot change per episode"):
            episode_config(base, {fixed: getattr(base, fixed)})
    with pytest.raises(ValueError, match=r"unknown option\(s\): wob"):
        episode_config(base, {"wob": 1.0})
    with pytest.raises(TypeError, match="options must be a dict"):
        episode_config(base, [("wob_n", 1.0)])  # type: ignore[arg-type]


def test_unknown_keywords_list_the_valid_ones() -> None:
    with pytest.raises(TypeError, match=r"unrecognized keyword\(s\): dt; valid keywords: "):
        EnvConfig.from_kwargs({"dt": 0.1})


def test_realism_levels_are_the_defaults_of_the_two_envs() -> None:
    from drill_env.options import (
        REALISM_KEYWORDS,
        REALISM_LEVELS,
        EnvConfig,
        FieldEnvConfig,
        realism_keywords,
    )

    ideal, field_level = realism_keywords("ideal"), realism_keywords("field")
    assert list(ideal) == list(REALISM_KEYWORDS) == list(field_level)
    assert all(ideal[k] == getattr(EnvConfig(), k) for k in REALISM_KEYWORDS)
    assert all(field_level[k] == getattr(FieldEnvConfig(), k) for k in REALISM_KEYWORDS)
    assert realism_keywords("surface_only")["telemetry_period_s"] is None
    wired = realism_keywords("wired_pipe")
    assert wired["telemetry_period_s"] < 0.1 and wired["observation"] == "surface"
    for level in REALISM_LEVELS:  # every level makes a valid env of either kind
        EnvConfig(**realism_keywords(level))
        FieldEnvConfig(**realism_keywords(level))
    with pytest.raises(ValueError, match=r"realism = 'lab' is not a known level: allowed"):
        realism_keywords("lab")


@pytest.mark.parametrize(
    ("config_type", "model"),
    [("EnvConfig", "residual_ppo"), ("FieldEnvConfig", "field_agent")],
)
def test_the_defaults_are_the_shipped_agents_recipe(config_type: str, model: str) -> None:
    """Plain ``gym.make`` with a base controller trains as the shipped agent did: its decision
    period, residual scale and reward weights (read from its config.json)."""
    import json
    from pathlib import Path

    from drill_env import options

    recorded = json.loads(
        (
            Path(__file__).resolve().parents[1] / "agents" / "models" / model / "config.json"
        ).read_text()
    )
    config = getattr(options, config_type)()
    for key in ("control_dt_s", "residual_scale_nm", "min_torque_nm", "max_torque_nm"):
        assert getattr(config, key) == recorded["env_kwargs"][key], key
    train = recorded["train_config"]
    weights = config.reward_weights
    for field in ("tracking", "chattering", "chattering_scale_nm", "stuck", "torque", "residual"):
        assert getattr(weights, field) == train[f"reward_{field}"], field
    assert config.noise_std_rad_s == train["noise_std_rad_s"]
