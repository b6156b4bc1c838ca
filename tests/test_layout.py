"""The one home of every index (:mod:`drill_env.layout`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drill_env import layout
from drill_env.parameters import PRESETS, DrillStringParameters, plant_parameter_vector


def test_plant_vector_indices_follow_the_parameter_fields() -> None:
    """``P_<FIELD>`` is the position of each field; the reciprocal inertias follow."""
    params = PRESETS["navarro_lopez2007"]
    vector = plant_parameter_vector(params)
    assert vector.shape == (layout.N_PLANT_PARAMS,)
    for k, field in enumerate(dataclasses.fields(DrillStringParameters)):
        assert getattr(layout, f"P_{field.name.upper()}") == k
        assert vector[k] == getattr(params, field.name)
    for name in ("dt", "pi", "co", "bi"):
        index = getattr(layout, f"P_INV_J_{name.upper()}")
        assert vector[index] == 1.0 / getattr(params, f"J_{name}")


def test_state_names_and_speed_indices() -> None:
    assert len(layout.STATE_NAMES) == layout.N_STATE == 7
    assert [layout.STATE_NAMES[k] for k in layout.SPEED_INDICES] == [
        "top_drive_speed_rad_s",
        "pipe_speed_rad_s",
        "collar_speed_rad_s",
        "bit_speed_rad_s",
    ]
    assert layout.STATE_NAMES[layout.X_BIT_SPEED] == "bit_speed_rad_s"
    assert layout.STATE_NAMES[layout.X_TOP_DRIVE_SPEED] == "top_drive_speed_rad_s"


@pytest.mark.parametrize(
    ("prefix", "count"),
    [
        ("REC_", "N_RECORD"),
        ("REP_", "N_REPORT"),
        ("SRC_", "N_FIXED_SOURCES"),
        ("M_", "N_MEASUREMENT"),
    ],
    ids=["records", "report", "sources", "measurement"],
)
def test_columns_are_distinct_and_inside_their_vector(prefix: str, count: str) -> None:
    columns = {n: v for n, v in vars(layout).items() if n.startswith(prefix)}
    columns.pop("SRC_STATE", None)  # the state block follows the fixed sources
    size = getattr(layout, count)
    assert len(set(columns.values())) == len(columns)
    assert all(0 <= v < size for v in columns.values())
    # Multi-entry columns (the state) occupy 7 slots from their start.
    covered = set(columns.values())
    for name in ("REC_X0", "M_STATE"):
        if name in columns:
            covered |= set(range(columns[name], columns[name] + layout.N_STATE))
    assert covered == set(range(size))


@pytest.mark.parametrize("residual", [False, True], ids=["direct", "residual"])
def test_observation_fields(residual: bool) -> None:
    fields = layout.observation_fields(residual)
    assert len(fields) == layout.observation_size(residual) == (11 if residual else 9)
    assert [f.name for f in fields[:7]] == [
        "measured_top_drive_speed_rad_s",
        "top_drive_pipe_twist_rad",
        "measured_pipe_speed_rad_s",
        "pipe_collar_twist_rad",
        "measured_collar_speed_rad_s",
        "collar_bit_twist_rad",
        "measured_bit_speed_rad_s",
    ]
    scales = layout.observation_scales(fields, 50_000.0)
    assert scales[0] == 1 / layout.SPEED_SCALE_RAD_S and scales[1] == 1 / layout.TWIST_SCALE_RAD
    assert scales[8] == 1 / 50_000.0
    np.testing.assert_array_equal(layout.observation_sources(fields), [f.source for f in fields])


def test_unscale_measurement_inverts_the_observation_scales() -> None:
    fields = layout.observation_fields(True)
    physical = np.array([10.0, 3.0, 9.0, 1.0, 8.0, 0.5, 7.5, 12.0, 13e3, 12e3, -0.4])
    obs = physical * layout.observation_scales(fields, 50_000.0)
    state, reference = layout.unscale_measurement(obs)
    np.testing.assert_allclose(state, physical[:7])
    assert reference == pytest.approx(12.0)


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        ("DrillString-v0", {}),
        ("DrillString-v0", {"base_controller": "z_torque", "observation": "surface"}),
        ("DrillString-v0", {"telemetry_period_s": 1.0, "telemetry_delay_s": 0.5}),
        ("DrillStringField-v0", {"base_controller": "soft_speed"}),
        ("DrillStringField-v0", {"observation": "state", "randomize": False}),
    ],
)
def test_observation_names_describe_the_observation(env_id: str, kwargs: dict) -> None:
    """Each named entry of a running env holds the value its name says, scaled."""
    import gymnasium as gym

    import drill_env  # noqa: F401

    env = gym.make(env_id, **kwargs)
    names = env.unwrapped.observation_names
    assert len(names) == env.observation_space.shape[0] == len(set(names))
    env.reset(seed=3)
    for _ in range(40):
        obs, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    index = {name: i for i, name in enumerate(names)}
    scale = {"speed": layout.SPEED_SCALE_RAD_S, "time": layout.TIME_SCALE_S}
    expected = {
        "reference_speed_rad_s": (info["reference_speed_rad_s"], scale["speed"]),
        "last_torque_nm": (info["top_drive_torque_nm"], env.unwrapped.config.torque_scale_nm),
        "measured_surface_torque_nm": (
            info["surface_torque_nm"],
            env.unwrapped.config.torque_scale_nm,
        ),
        "telemetry_bit_speed_rad_s": (info.get("telemetry_bit_speed_rad_s"), scale["speed"]),
        "telemetry_age_s": (info.get("telemetry_age_s"), scale["time"]),
        "base_torque_nm": (info.get("base_torque_nm"), env.unwrapped.config.torque_scale_nm),
    }
    for name, (value, unit) in expected.items():
        if name in index:
            assert obs[index[name]] == pytest.approx(value / unit, rel=1e-6, abs=1e-6), name
    env.close()
