"""Tests of drill_env.distributed: geometry, presets, depth changes and the discretisation.

The expected numbers are worked out here from the stated rules (J = pi (OD^4 - ID^4) / 32,
k = G J / l, half of each element's rho J l at each end node), never copied from the package.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    StringDamping,
    StringSection,
    chain_from_parameters,
    discretize,
    resolve_distributed_parameters,
    resolve_plant,
    section_element_counts,
    with_measured_depth,
)
from drill_env.parameters import PRESETS

# Well B of Aarsnes & Shor (2018), written out again: (length m, OD m, ID m, G Pa).
WELL_B_BHA = [
    (48.70, 0.150473, 0.096207, 67e9),
    (114.80, 0.187322, 0.098912, 67e9),
    (56.70, 0.209550, 0.071438, 67e9),
    (38.88, 0.247280, 0.123391, 67e9),
]
BHA_LENGTH = 48.70 + 114.80 + 56.70 + 38.88


def _polar(od: float, idia: float) -> float:
    return math.pi * (od**4 - idia**4) / 32.0


def test_field_preset_is_well_b_at_2500m() -> None:
    """``field_2500m``: 2,500 m, the Well B pipe and BHA, rho 7,850, top drive 2,900 kg m^2."""
    p = DISTRIBUTED_PRESETS["field_2500m"]
    assert p.measured_depth_m == pytest.approx(2500.0, abs=1e-9)
    pipe = p.sections[0]
    assert (pipe.outer_diameter_m, pipe.inner_diameter_m) == (0.146529, 0.123024)
    assert pipe.shear_modulus_pa == 61e9
    assert pipe.length_m == pytest.approx(2500.0 - BHA_LENGTH)
    got = [(s.length_m, s.outer_diameter_m, s.inner_diameter_m, s.shear_modulus_pa)
           for s in p.sections[1:]]  # fmt: skip
    assert got == WELL_B_BHA
    assert all(s.density_kg_m3 == 7850.0 for s in p.sections)
    assert p.top_drive_inertia_kg_m2 == 2900.0
    assert p.bit_radius_m == 0.108
    assert (p.mu_a, p.mu_0, p.xi, p.Dw) == (0.8, 0.5, 0.5, 1e-3)
    assert p.element_length_m == 25.0


def test_deep_preset_is_api_5in_19_5_pipe_over_the_same_bha() -> None:
    """``deep_5000m``: 5,000 m; API 5DP 5 in 19.5 lb/ft pipe (wall 0.362 in), same BHA."""
    p = DISTRIBUTED_PRESETS["deep_5000m"]
    assert p.measured_depth_m == pytest.approx(5000.0, abs=1e-9)
    pipe = p.sections[0]
    assert pipe.outer_diameter_m == pytest.approx(0.127)
    assert pipe.inner_diameter_m == pytest.approx((5.0 - 2 * 0.362) * 0.0254)
    assert p.sections[1:] == DISTRIBUTED_PRESETS["field_2500m"].sections[1:]


def test_section_properties_from_geometry() -> None:
    """Polar moment, rho J, G J, wave speed and impedance J sqrt(G rho) of a tube."""
    s = StringSection(100.0, 0.2, 0.1, 80e9, 8000.0)
    j = math.pi * (0.2**4 - 0.1**4) / 32
    assert s.polar_moment_m4 == pytest.approx(j, rel=1e-14)
    assert s.inertia_per_length_kg_m == pytest.approx(8000 * j)
    assert s.torsional_rigidity_nm2 == pytest.approx(80e9 * j)
    assert s.wave_speed_m_s == pytest.approx(math.sqrt(1e7))
    assert s.impedance_nm_s_rad == pytest.approx(j * math.sqrt(80e9 * 8000))
    assert s.stiffness_nm_rad == pytest.approx(80e9 * j / 100)
    assert s.inertia_kg_m2 == pytest.approx(8000 * j * 100)


def test_element_counts_are_whole_and_no_longer_than_asked() -> None:
    """Each section gets ceil(L / h) elements, at least one; none is longer than h."""
    p = DISTRIBUTED_PRESETS["field_2500m"]
    assert section_element_counts(p) == (
        math.ceil((2500.0 - BHA_LENGTH) / 25), 2, 5, 3, 2,
    )  # fmt: skip
    coarse = dataclasses.replace(p, element_length_m=1000.0)
    assert section_element_counts(coarse) == (3, 1, 1, 1, 1)
    exact = dataclasses.replace(
        p, sections=(StringSection(100.0, 0.2, 0.1, 80e9, 8000.0),), element_length_m=25.0
    )
    assert section_element_counts(exact) == (4,)


def test_discretisation_follows_the_lumping_rule() -> None:
    """Node inertias, springs, mud and Kelvin-Voigt dampers of a two-section string by hand."""
    upper = StringSection(60.0, 0.15, 0.12, 60e9, 7800.0)
    lower = StringSection(20.0, 0.2, 0.08, 70e9, 7900.0)
    damping = StringDamping(
        mud_rate_per_s=0.1, material_time_constant_s=2e-3, top_drive_nm_s_rad=400.0,
        bit_nm_s_rad=30.0,
    )  # fmt: skip
    p = DistributedStringParameters(
        sections=(upper, lower), top_drive_inertia_kg_m2=1000.0, bit_inertia_kg_m2=2.0,
        bit_radius_m=0.1, damping=damping, element_length_m=25.0,
    )  # fmt: skip
    chain = discretize(p)
    # 60 m -> 3 elements of 20 m; 20 m -> 1 element of 20 m.
    ju, jl = _polar(0.15, 0.12), _polar(0.2, 0.08)
    mu, ml = 7800 * ju * 20, 7900 * jl * 20  # inertia per element
    np.testing.assert_allclose(
        chain.element_stiffness_nm_rad, [60e9 * ju / 20] * 3 + [70e9 * jl / 20], rtol=1e-14
    )
    expected_j = [1000 + mu / 2, mu, mu, mu / 2 + ml / 2, ml / 2 + 2.0]
    np.testing.assert_allclose(chain.node_inertia_kg_m2, expected_j, rtol=1e-14)
    expected_d = [400 + 0.1 * mu / 2, 0.1 * mu, 0.1 * mu, 0.1 * (mu + ml) / 2, 0.1 * ml / 2 + 30]
    np.testing.assert_allclose(chain.node_damping_nm_s_rad, expected_d, rtol=1e-14)
    np.testing.assert_allclose(
        chain.element_damping_nm_s_rad, 2e-3 * chain.element_stiffness_nm_rad, rtol=1e-14
    )
    np.testing.assert_allclose(chain.node_depth_m, [0, 20, 40, 60, 80])
    # Totals: all of the string's inertia and mud damping is somewhere in the chain.
    total_j = 1000 + 2 + 7800 * ju * 60 + 7900 * jl * 20
    assert chain.node_inertia_kg_m2.sum() == pytest.approx(total_j, rel=1e-14)


def test_field_preset_has_about_a_hundred_elements() -> None:
    """The default element length gives ~100 elements for 2.5 km (the env's default)."""
    chain = discretize("field_2500m")
    assert chain.n_nodes - 1 == 102
    assert chain.state_size == 2 * chain.n_nodes - 1


def test_four_dof_plant_is_the_n4_chain() -> None:
    """The 4-DOF parameters map to inertias (J_dt..J_bi), c_dt and c_bit to ground, springs."""
    q = PRESETS["zribi2024"]
    chain = chain_from_parameters(q)
    np.testing.assert_array_equal(chain.node_inertia_kg_m2, [q.J_dt, q.J_pi, q.J_co, q.J_bi])
    np.testing.assert_array_equal(chain.node_damping_nm_s_rad, [q.c_dt, 0, 0, q.c_bit])
    np.testing.assert_array_equal(chain.element_stiffness_nm_rad, [q.k_pi, q.k_co, q.k_bi])
    np.testing.assert_array_equal(chain.element_damping_nm_s_rad, [q.c_pi, q.c_co, q.c_bi])
    assert chain_from_parameters("zribi2024").node_inertia_kg_m2[0] == q.J_dt


@pytest.mark.parametrize("depth", [1000.0, 3333.3, 5000.0, 6000.0])
def test_with_measured_depth_changes_only_the_pipe(depth: float) -> None:
    """A new depth lengthens or shortens the pipe; the BHA and everything else stay."""
    base = DISTRIBUTED_PRESETS["field_2500m"]
    p = with_measured_depth(base, depth)
    assert p.measured_depth_m == pytest.approx(depth, rel=1e-13)
    assert p.sections[1:] == base.sections[1:]
    assert dataclasses.replace(p.sections[0], length_m=1.0) == dataclasses.replace(
        base.sections[0], length_m=1.0
    )
    assert p.top_drive_inertia_kg_m2 == base.top_drive_inertia_kg_m2
    assert with_measured_depth("field_2500m", depth) == p


def test_with_measured_depth_rejects_a_depth_inside_the_bha() -> None:
    """The pipe must keep a positive length."""
    with pytest.raises(
        ValueError, match=r"measured_depth_m = 200.0 is out of range: allowed > BHA"
    ):
        with_measured_depth("field_2500m", 200.0)


def test_parameters_are_frozen() -> None:
    """Parameter sets cannot be changed in place."""
    with pytest.raises(dataclasses.FrozenInstanceError):
        DISTRIBUTED_PRESETS["field_2500m"].bit_radius_m = 1.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        DISTRIBUTED_PRESETS["field_2500m"].sections[0].length_m = 1.0  # type: ignore[misc]


def test_chain_arrays_are_read_only() -> None:
    """The discretised arrays cannot be edited behind the parameters' back."""
    chain = discretize("field_2500m")
    with pytest.raises(ValueError, match="read-only"):
        chain.node_inertia_kg_m2[0] = 1.0


def test_sections_list_is_stored_as_tuple() -> None:
    """A list of sections is accepted and stored as a tuple (so the set stays hashable)."""
    s = StringSection(100.0, 0.2, 0.1, 80e9, 8000.0)
    p = DistributedStringParameters([s], 1000.0, 1.0, 0.1)  # type: ignore[arg-type]
    assert p.sections == (s,)
    hash(p)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(length_m=-3.0), ValueError, r"length_m = -3.0 is out of range: allowed > 0"),
        (dict(outer_diameter_m=0.0), ValueError, r"outer_diameter_m = 0.0 is out of range"),
        (dict(inner_diameter_m=0.3), ValueError,
         r"inner_diameter_m = 0.3 is out of range: allowed 0 <= inner_diameter_m < outer"),
        (dict(inner_diameter_m=-0.1), ValueError, r"inner_diameter_m = -0.1 is out of range"),
        (dict(shear_modulus_pa=math.nan), ValueError, r"shear_modulus_pa = nan is out of range"),
        (dict(density_kg_m3="steel"), TypeError, r"density_kg_m3 must be a real number"),
        (dict(length_m=True), TypeError, r"length_m must be a real number"),
    ],
)  # fmt: skip
def test_bad_section_is_rejected(kwargs: dict[str, object], error: type, match: str) -> None:
    """Every bad section field raises an error naming the field, value and allowed range."""
    base = dict(length_m=10.0, outer_diameter_m=0.2, inner_diameter_m=0.1,
                shear_modulus_pa=80e9, density_kg_m3=7850.0)  # fmt: skip
    with pytest.raises(error, match=match):
        StringSection(**{**base, **kwargs})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        (dict(sections=()), ValueError, r"sections = \(\) is out of range"),
        (dict(sections="pipe"), TypeError, r"sections must be a sequence of StringSection"),
        (dict(sections=(1.0,)), TypeError, r"sections\[0\] must be a StringSection, got float"),
        (dict(top_drive_inertia_kg_m2=0.0), ValueError,
         r"top_drive_inertia_kg_m2 = 0.0 is out of range: allowed > 0"),
        (dict(bit_inertia_kg_m2=-1.0), ValueError, r"bit_inertia_kg_m2 = -1.0 is out of range"),
        (dict(bit_radius_m=0.0), ValueError, r"bit_radius_m = 0.0 is out of range"),
        (dict(mu_0=0.9), ValueError, r"mu_0 = 0.9 is out of range: allowed 0 < mu_0 <= mu_a"),
        (dict(element_length_m=-5.0), ValueError, r"element_length_m = -5.0 is out of range"),
        (dict(Dw=0.0), ValueError, r"Dw = 0.0 is out of range: allowed > 0"),
        (dict(damping=0.1), TypeError, r"damping must be a StringDamping, got float"),
    ],
)  # fmt: skip
def test_bad_string_is_rejected(kwargs: dict[str, object], error: type, match: str) -> None:
    """Bad string-level fields raise errors naming the field."""
    with pytest.raises(error, match=match):
        dataclasses.replace(DISTRIBUTED_PRESETS["field_2500m"], **kwargs)


@pytest.mark.parametrize(
    "name", ["mud_rate_per_s", "material_time_constant_s", "top_drive_nm_s_rad", "bit_nm_s_rad"]
)
def test_negative_damping_is_rejected(name: str) -> None:
    """Damping coefficients must be >= 0."""
    with pytest.raises(ValueError, match=rf"{name} = -1.0 is out of range: allowed >= 0"):
        StringDamping(**{name: -1.0})  # type: ignore[arg-type]


def test_unknown_preset_names_the_valid_ones() -> None:
    """A wrong name lists the presets."""
    with pytest.raises(ValueError, match=r"'well_x' is not a known distributed preset: allowed"):
        resolve_distributed_parameters("well_x")
    with pytest.raises(ValueError, match=r"deep_5000m.*field_2500m.*navarro_lopez2007"):
        resolve_plant("well_x")
    with pytest.raises(TypeError, match=r"parameters must be a preset name"):
        resolve_plant(3.0)  # type: ignore[arg-type]
