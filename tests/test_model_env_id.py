"""A model file names the env it is for (``env_kwargs.env_id``): absent in every older file
(``DrillString-v0``), ``DrillStringField-v0`` for a model of the field string; the loader checks
the observation size against that env, and the studies run a model only on its own env."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from agents import DEFAULT_MODEL_DIR, load_policy
from agents.inference import ObsNorm, PolicySpec
from agents.policy import ResidualPolicy
from experiments import compare

FIELD = "DrillStringField-v0"
KWARGS = {
    "base_controller": "soft_speed",
    "control_dt_s": 0.1,
    "residual_scale_nm": 5_000.0,
    "min_torque_nm": 0.0,
    "max_torque_nm": 50_800.0,
}


def _field_policy(size: int, observation: str = "surface") -> ResidualPolicy:
    spec = PolicySpec(observation_size=size, hidden_sizes=(8,))
    rng = np.random.default_rng(0)
    weights = {k: 0.1 * rng.standard_normal(shape) for k, shape in spec.weight_shapes().items()}
    return ResidualPolicy(
        spec,
        weights,
        ObsNorm.identity(size),
        {**KWARGS, "observation": observation},
        "field_agent",
        env_id=FIELD,
    )


def _size(**kwargs: Any) -> int:
    env = gym.make(FIELD, **kwargs)
    try:
        return int(env.observation_space.shape[0])  # type: ignore[index]
    finally:
        env.close()


def test_a_model_without_env_id_is_for_the_paper_env(tmp_path: Path) -> None:
    policy = load_policy(DEFAULT_MODEL_DIR / "residual_ppo")
    assert policy.env_id == "DrillString-v0" and "env_id" not in policy.env_kwargs
    policy.save(tmp_path / "copy")
    saved = json.loads((tmp_path / "copy" / "config.json").read_text())
    assert "env_id" not in saved["env_kwargs"]  # written as before


def test_a_field_model_round_trips(tmp_path: Path) -> None:
    size = _size(**{k: v for k, v in KWARGS.items()}, observation="surface")
    folder = _field_policy(size).save(tmp_path / "field")
    saved = json.loads((folder / "config.json").read_text())
    assert saved["env_kwargs"]["env_id"] == FIELD
    loaded = load_policy(folder)
    assert loaded.env_id == FIELD
    assert loaded.env_kwargs == {**KWARGS, "observation": "surface"}
    assert "field_agent" in repr(loaded) and FIELD in repr(loaded)
    # it runs in its env as the studies make it
    env = gym.make(loaded.env_id, randomize=False, **loaded.env_kwargs)
    obs, _ = env.reset(seed=0)
    action, _ = loaded.predict(obs)
    env.step(action)


def test_a_field_model_of_the_wrong_size(tmp_path: Path) -> None:
    size = _size(**KWARGS, observation="surface")
    folder = _field_policy(size + 1).save(tmp_path / "field")
    with pytest.raises(
        ValueError,
        match=r"field observation_size: wrong observation size: expected \d+ "
        r"\(DrillStringField-v0 with base_controller='soft_speed'",
    ):
        load_policy(folder)


def _edited(tmp_path: Path, **env_kwargs: Any) -> Path:
    folder = tmp_path / "model"
    shutil.copytree(DEFAULT_MODEL_DIR / "residual_ppo", folder)
    record = json.loads((folder / "config.json").read_text())
    record["env_kwargs"].update(env_kwargs)
    (folder / "config.json").write_text(json.dumps(record))
    return folder


def test_env_id_and_observation_are_checked(tmp_path: Path) -> None:
    with pytest.raises(
        ValueError, match=r"env_kwargs\.env_id = 'Nope-v0': allowed 'DrillString-v0' or"
    ):
        load_policy(_edited(tmp_path / "a", env_id="Nope-v0"))
    with pytest.raises(ValueError, match=r"env_kwargs\.observation is a keyword of Drill"):
        load_policy(_edited(tmp_path / "b", observation="state"))
    with pytest.raises(
        ValueError,
        match=r"env_kwargs\.observation = 'all': allowed 'state', 'surface' or 'estimate'",
    ):
        load_policy(_edited(tmp_path / "c", env_id=FIELD, observation="all"))


def test_the_comparison_runs_an_agent_only_on_its_env() -> None:
    size = _size(**KWARGS, observation="surface")
    agent = _field_policy(size)
    cases = compare.comparison_cases(FIELD, ["nominal"], depths_m=[1500.0])[:1]
    common = dict(duration_s=1.0, keep_traces=False, progress=False)
    rows, _ = compare.run_comparison(
        [], [], [0.0], agent=agent, env_id=FIELD, cases=cases, **common
    )  # type: ignore[arg-type]
    assert [(r["controller"], r["observation"], r["gains"]) for r in rows] == [
        ("field_agent", "surface", "agent")
    ]
    rows, _ = compare.run_comparison([], ["nominal"], [0.0], agent=agent, **common)  # type: ignore[arg-type]
    assert rows == []
