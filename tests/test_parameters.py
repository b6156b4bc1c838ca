"""Tests of drill_env.parameters: the docs/specification.md section 1 presets and their validation."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from drill_env.parameters import (
    PRESETS,
    DrillStringParameters,
    plant_parameter_vector,
    resolve_parameters,
    scale_uncertain,
)

# docs/specification.md section 1, "Parameter presets", written out again here (not read from the package).
SPECIFIED_TABLE = {
    "zribi2024": dict(
        J_dt=930.0, J_pi=2782.25, J_co=750.0, J_bi=471.96,
        c_dt=425.0, c_pi=193.61, c_co=190.0, c_bi=181.49, c_bit=50.0,
        k_pi=698.06, k_co=1080.0, k_bi=907.48,
        R=0.15, mu_a=0.8, mu_0=0.5, xi=0.5, Dw=1e-3,
    ),
    "navarro_lopez2007": dict(
        J_dt=930.0, J_pi=2782.25, J_co=750.0, J_bi=471.9698,
        c_dt=425.0, c_pi=139.6126, c_co=190.0, c_bi=181.49, c_bit=50.0,
        k_pi=698.063, k_co=1080.0, k_bi=907.48,
        R=0.155575, mu_a=0.8, mu_0=0.5, xi=0.9, Dw=1e-6,
    ),
}  # fmt: skip

WOB_N = 97_347.0  # docs/specification.md section 2
V_REF = 12.0  # rad/s, docs/specification.md section 2


@pytest.mark.parametrize("name", sorted(SPECIFIED_TABLE))
def test_preset_has_spec_table_values(name: str) -> None:
    """Every field of each preset equals the docs/specification.md section 1 table, and nothing else exists."""
    params = PRESETS[name]
    fields = {f.name: getattr(params, f.name) for f in dataclasses.fields(params)}
    assert fields == SPECIFIED_TABLE[name]


def test_presets_are_exactly_the_spec_ones() -> None:
    """The package offers the two specified presets, ``zribi2024`` being the dataclass default."""
    assert sorted(PRESETS) == sorted(SPECIFIED_TABLE)
    assert DrillStringParameters() == PRESETS["zribi2024"]


def test_parameters_are_frozen() -> None:
    """A parameter set cannot be changed in place."""
    with pytest.raises(dataclasses.FrozenInstanceError):
        PRESETS["zribi2024"].J_dt = 1.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        pytest.param(name, bad, rf"{name} = {bad!r} is out of range: allowed > 0", id=f"{name}={bad}")
        for name in ("J_dt", "J_pi", "J_co", "J_bi", "k_pi", "k_co", "k_bi", "R", "Dw")
        for bad in (0.0, -1.0)
    ]
    + [
        pytest.param(name, -1.0, rf"{name} = -1.0 is out of range: allowed >= 0", id=f"{name}<0")
        for name in ("c_dt", "c_pi", "c_co", "c_bi", "c_bit", "xi")
    ]
    + [
        pytest.param(
            "mu_0", 0.9, r"mu_0 = 0.9 is out of range: allowed 0 < mu_0 <= mu_a = 0.8",
            id="mu_0>mu_a",
        ),
        pytest.param(
            "mu_0", 0.0, r"mu_0 = 0.0 is out of range: allowed 0 < mu_0 <= mu_a = 0.8",
            id="mu_0=0",
        ),
        pytest.param("J_bi", math.nan, r"J_bi must be finite, got nan", id="J_bi=nan"),
        pytest.param("c_pi", math.inf, r"c_pi must be finite, got inf", id="c_pi=inf"),
        pytest.param("Dw", -math.inf, r"Dw must be finite, got -inf", id="Dw=-inf"),
    ],
)  # fmt: skip
def test_invalid_value_names_field_value_and_range(field: str, value: float, match: str) -> None:
    """An out-of-range value is a ValueError naming the field, the value and the range."""
    with pytest.raises(ValueError, match=match):
        DrillStringParameters(**{field: value})


def test_mu_a_below_mu_0_is_refused_too() -> None:
    """Lowering mu_a under mu_0 breaks the same ordering rule."""
    with pytest.raises(
        ValueError, match=r"mu_0 = 0.5 is out of range: allowed 0 < mu_0 <= mu_a = 0.4"
    ):
        DrillStringParameters(mu_a=0.4)


@pytest.mark.parametrize(
    ("value", "type_name"),
    [
        pytest.param(True, "bool", id="bool"),
        pytest.param("930", "str", id="str"),
        pytest.param(None, "NoneType", id="None"),
        pytest.param([930.0], "list", id="list"),
    ],
)
def test_non_number_is_a_type_error(value: object, type_name: str) -> None:
    """A bool, string or other non-number is a TypeError naming field, value and type."""
    message = f"J_dt must be a real number, got {value!r} ({type_name})"
    with pytest.raises(TypeError, match=re.escape(message)):
        DrillStringParameters(J_dt=value)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", [930, np.float64(930.0)], ids=["int", "np.float64"])
def test_plain_numbers_are_accepted(value: object) -> None:
    """Python ints and numpy float64 (a float subclass) are valid parameter values."""
    params = DrillStringParameters(J_dt=value)  # type: ignore[arg-type]
    assert params.J_dt == 930.0


@pytest.mark.parametrize(
    "value", [np.float32(930.0), np.int64(930)], ids=["np.float32", "np.int64"]
)
def test_numpy_scalars_are_accepted(value: object) -> None:
    """numpy real scalars are real numbers and should be accepted like in the env keywords."""
    params = DrillStringParameters(J_dt=value)  # type: ignore[arg-type]
    assert params.J_dt == 930.0


@pytest.mark.parametrize(
    ("changes", "error", "match"),
    [
        pytest.param({"J_co": -750.0}, ValueError, r"J_co = -750.0 is out of range: allowed > 0", id="J_co"),
        pytest.param({"c_bit": -50.0}, ValueError, r"c_bit = -50.0 is out of range: allowed >= 0", id="c_bit"),
        pytest.param({"mu_0": 1.0}, ValueError, r"mu_0 = 1.0 is out of range", id="mu_0"),
        pytest.param({"R": math.nan}, ValueError, r"R must be finite, got nan", id="R-nan"),
        pytest.param({"xi": "0.5"}, TypeError, r"xi must be a real number", id="xi-str"),
    ],
)  # fmt: skip
def test_replace_validates_again(changes: dict[str, object], error: type, match: str) -> None:
    """``dataclasses.replace`` runs the same validation as construction."""
    with pytest.raises(error, match=match):
        dataclasses.replace(PRESETS["zribi2024"], **changes)


def test_replace_keeps_other_fields() -> None:
    """A valid replace changes only the named field."""
    base = PRESETS["navarro_lopez2007"]
    new = dataclasses.replace(base, c_dt=0.0)
    assert new.c_dt == 0.0
    assert dataclasses.replace(new, c_dt=base.c_dt) == base


@pytest.mark.parametrize("name", sorted(SPECIFIED_TABLE))
def test_resolve_parameters_by_name_and_object(name: str) -> None:
    """A preset name resolves to its preset; a parameter object passes through unchanged."""
    assert resolve_parameters(name) is PRESETS[name]
    custom = dataclasses.replace(PRESETS[name], R=0.2)
    assert resolve_parameters(custom) is custom


def test_resolve_parameters_unknown_name_lists_presets() -> None:
    """An unknown preset name is a ValueError listing the valid presets."""
    with pytest.raises(
        ValueError,
        match=r"parameters = 'zribi' is not a known preset: allowed \['navarro_lopez2007', 'zribi2024'\]",
    ):
        resolve_parameters("zribi")


def test_resolve_parameters_wrong_type() -> None:
    """Anything but a name or a parameter set is a TypeError."""
    with pytest.raises(
        TypeError, match=r"parameters must be a preset name or a DrillStringParameters, got dict"
    ):
        resolve_parameters({"J_dt": 930.0})  # type: ignore[arg-type]


def test_steady_torque_matches_spec_check() -> None:
    """docs/specification.md section 2: holding the string at 12 rad/s under 97,347 N takes 13,011.9 N m."""
    params = PRESETS["zribi2024"]
    assert params.steady_torque_nm(V_REF, WOB_N) == pytest.approx(13_011.9, abs=0.1)


@pytest.mark.parametrize("name", sorted(SPECIFIED_TABLE))
def test_friction_levels(name: str) -> None:
    """``T_a = mu_a WOB R`` and ``T_0 = mu_0 WOB R`` (docs/specification.md section 1)."""
    p = SPECIFIED_TABLE[name]
    params = PRESETS[name]
    assert params.static_torque_nm(WOB_N) == pytest.approx(p["mu_a"] * WOB_N * p["R"], rel=1e-15)
    assert params.sliding_torque_nm(WOB_N) == pytest.approx(p["mu_0"] * WOB_N * p["R"], rel=1e-15)


def test_steady_torque_formula_at_other_speeds() -> None:
    """``u = (c_dt + c_bit) V + T_0 + (T_a - T_0) exp(-xi V)`` at any positive speed."""
    p = SPECIFIED_TABLE["navarro_lopez2007"]
    params = PRESETS["navarro_lopez2007"]
    t_a, t_0 = p["mu_a"] * 150e3 * p["R"], p["mu_0"] * 150e3 * p["R"]
    for v in (0.5, 4.0, 30.0):
        expected = (p["c_dt"] + p["c_bit"]) * v + t_0 + (t_a - t_0) * math.exp(-p["xi"] * v)
        assert params.steady_torque_nm(v, 150e3) == pytest.approx(expected, rel=1e-14)


def test_scale_uncertain_applies_table3_reading() -> None:
    """docs/specification.md section 2: ``c_pi (1 + D1)``, ``k_pi (1 + D2)``, ``c_dt (1 + D3)``, nothing else."""
    base = PRESETS["zribi2024"]
    scaled = scale_uncertain(base, (0.4, 0.3, 0.3))
    assert scaled.c_pi == pytest.approx(193.61 * 1.4, rel=1e-15)
    assert scaled.k_pi == pytest.approx(698.06 * 1.3, rel=1e-15)
    assert scaled.c_dt == pytest.approx(425.0 * 1.3, rel=1e-15)
    assert dataclasses.replace(scaled, c_pi=base.c_pi, k_pi=base.k_pi, c_dt=base.c_dt) == base


def test_scale_uncertain_validates() -> None:
    """A delta that would make a coefficient negative is refused by the dataclass."""
    with pytest.raises(ValueError, match=r"k_pi = .* is out of range: allowed > 0"):
        scale_uncertain(PRESETS["zribi2024"], (0.0, -1.5, 0.0))


@pytest.mark.parametrize("name", sorted(SPECIFIED_TABLE))
def test_parameter_vector_is_field_order(name: str) -> None:
    """The kernels' parameter vector starts with the 17 fields in declaration order."""
    vec = plant_parameter_vector(PRESETS[name])
    assert vec.dtype == np.float64
    assert vec[:17].tolist() == list(SPECIFIED_TABLE[name].values())
