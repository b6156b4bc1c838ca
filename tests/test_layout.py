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
