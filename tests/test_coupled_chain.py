"""Tests of drill_env.coupled_chain (the field string with axial elements and the RGD bit)
against independent references built here.

* Axial waves: the continuous piecewise-uniform bar, each section carrying ``(u, N)``
  (displacement amplitude, axial force ``E A u'``) by its transfer matrix
  ``[[cos kL, sin kL / (E A k)], [-E A k sin kL, cos kL]]`` with ``k = omega / c``,
  ``c = sqrt(E / rho)``; roots by bracketing on a fine grid and ``scipy.optimize.brentq``.
* The lumped RGD model (:func:`drill_env.coupled.simulate`) as the one-element limit.
* Energy balance from the integrals the kernel carries; step halving.

Print the figures with ``.venv/bin/python -m pytest tests/test_coupled_chain.py -s -q``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import numpy.typing as npt
import pytest
from scipy.linalg import eigh
from scipy.optimize import brentq

from drill_env import coupled
from drill_env.coupled_chain import (
    AxialChain,
    AxialProperties,
    CoupledChain,
    axial_wave_speed_m_s,
    coupled_chain,
    discretize_axial,
    simulate_field,
)
from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    Chain,
    DistributedStringParameters,
    StringSection,
    section_element_counts,
    with_measured_depth,
)

FloatArray = npt.NDArray[np.float64]
FIELD = DISTRIBUTED_PRESETS["field_2500m"]
RGD_A = coupled.RGD_PRESETS["rgd_a"]


def _chain_hz(chain: AxialChain, count: int, top: str) -> FloatArray:
    """Lowest non-zero undamped natural frequencies of the axial chain, Hz: ``top="free"``
    (force boundary) or ``"fixed"`` (the top node moving with a rigid hook); the bit free."""
    n = chain.n_nodes
    stiffness = np.zeros((n, n))
    for e, k in enumerate(chain.element_stiffness_n_m):
        stiffness[e : e + 2, e : e + 2] += k * np.array([[1.0, -1.0], [-1.0, 1.0]])
    mass = np.diag(chain.node_mass_kg)
    if top == "fixed":
        stiffness, mass = stiffness[1:, 1:], mass[1:, 1:]
    w2 = eigh(stiffness, mass, eigvals_only=True)
    w = np.sqrt(np.clip(w2, 0.0, None))
    return w[w > 1e-3][:count] / (2 * math.pi)  # without the rigid-body mode of a free bar


def _continuous_hz(
    p: DistributedStringParameters, moduli: tuple[float, ...], count: int, top: str
) -> FloatArray:
    """Lowest non-zero natural frequencies of the continuous piecewise-uniform bar, Hz."""
    sections = [
        (s.length_m, math.pi * (s.outer_diameter_m**2 - s.inner_diameter_m**2) / 4, e,
         s.density_kg_m3)
        for s, e in zip(p.sections, moduli, strict=True)
    ]  # fmt: skip

    def residual(w: float) -> float:
        state = np.array([1.0, 0.0]) if top == "free" else np.array([0.0, 1.0])
        for length, area, modulus, rho in sections:
            k = w / math.sqrt(modulus / rho)
            ea = modulus * area
            c, s = math.cos(k * length), math.sin(k * length)
            state = np.array([[c, s / (ea * k)], [-ea * k * s, c]]) @ state
        return float(state[1])  # free bit: no force at the bottom

    grid = np.linspace(1e-3, 2 * math.pi * 20.0, 40_000)
    values = [residual(w) for w in grid]
    roots = [
        brentq(residual, grid[i], grid[i + 1], xtol=1e-14, rtol=1e-15)
        for i in range(len(grid) - 1)
        if values[i] * values[i + 1] < 0
    ]
    return np.array(roots[:count]) / (2 * math.pi)


def test_axial_elements_carry_the_bar_wave_speed() -> None:
    p = with_measured_depth(FIELD, 1500.0)
    chain = discretize_axial(p)
    counts = section_element_counts(p)
    e = 0
    for section, count in zip(p.sections, counts, strict=True):
        length = section.length_m / count
        area = math.pi * (section.outer_diameter_m**2 - section.inner_diameter_m**2) / 4
        modulus = 2 * section.shear_modulus_pa * 1.3
        # an element's spring and mass: sqrt(k l^2 / (rho A l)) = sqrt(E / rho)
        speed = length * math.sqrt(
            chain.element_stiffness_n_m[e] / (section.density_kg_m3 * area * length)
        )
        assert speed == pytest.approx(axial_wave_speed_m_s(modulus, section.density_kg_m3))
        e += count
    assert chain.node_mass_kg.sum() == pytest.approx(
        sum(
            s.density_kg_m3 * math.pi * (s.outer_diameter_m**2 - s.inner_diameter_m**2) / 4
            * s.length_m
            for s in p.sections
        )
    )  # fmt: skip


def test_uniform_bar_quarter_wave() -> None:
    """A uniform steel bar hung from a rigid hook, free at the bit: ``f_k = (2k - 1) c / 4L``
    with ``c = sqrt(200e9 / 8000) = 5000 m/s``."""
    bar = DistributedStringParameters(
        sections=(StringSection(2000.0, 0.127, 0.108, 200e9 / 2.6, 8000.0),),
        top_drive_inertia_kg_m2=1.0, bit_inertia_kg_m2=0.0, bit_radius_m=0.108,
        element_length_m=10.0,
    )  # fmt: skip
    chain = discretize_axial(bar)
    speed = axial_wave_speed_m_s(200e9, 8000.0)
    assert speed == pytest.approx(5000.0)
    exact = np.array([(2 * k - 1) * speed / (4 * 2000.0) for k in (1, 2, 3)])
    got = _chain_hz(chain, 3, "fixed")
    print("\nuniform bar, Hz:", got, "exact:", exact)
    np.testing.assert_allclose(got, exact, rtol=2e-3)


@pytest.mark.parametrize("top", ["free", "fixed"])
@pytest.mark.parametrize("depth", [2500.0, 5000.0])
def test_lowest_axial_modes_within_one_percent_of_the_continuous_bar(
    top: str, depth: float
) -> None:
    p = with_measured_depth(FIELD, depth)
    axial = AxialProperties()
    got = _chain_hz(discretize_axial(p, axial), 4, top)
    exact = _continuous_hz(p, axial.moduli(p), 4, top)
    print(f"\n{depth:.0f} m, top {top}: chain {np.round(got, 4)} Hz, bar {np.round(exact, 4)} Hz")
    np.testing.assert_allclose(got, exact, rtol=1e-2)


def _one_element(p: coupled.RgdParameters) -> CoupledChain:
    """Two nodes: a top drive held at its speed and the bit with the lumped ``I``, ``M``;
    one element of the lumped stiffnesses ``C`` and ``K`` (undamped)."""
    torsion = Chain(
        node_inertia_kg_m2=np.array([1.0, p.inertia_kg_m2]),
        node_damping_nm_s_rad=np.array([0.0, p.torsional_damping_nms_rad]),
        element_stiffness_nm_rad=np.array([p.torsional_stiffness_nm_rad]),
        element_damping_nm_s_rad=np.array([0.0]),
        node_depth_m=np.array([0.0, 1.0]),
        bit_radius_m=p.bit_radius_m, mu_a=0.8, mu_0=0.5, xi=0.5, Dw=1e-3,
    )  # fmt: skip
    axial = AxialChain(
        node_mass_kg=np.array([1.0, p.axial_mass_kg]),
        node_damping_ns_m=np.array([0.0, p.axial_damping_ns_m]),
        element_stiffness_n_m=np.array([p.axial_stiffness_n_m]),
        element_damping_ns_m=np.array([0.0]),
    )
    return CoupledChain(torsion, axial)


@pytest.mark.parametrize(
    ("force", "speed", "stiffness"),
    [(60e3, 20.0, 7e5), (60e3, 4.0, 7e5), (90e3, 4.0, 7e5), (60e3, 10.0, 5e6)],
    ids=["P1", "P3", "P4", "P2-stiff"],
)
def test_one_element_string_is_the_lumped_model(
    force: float, speed: float, stiffness: float
) -> None:
    """A one-element string whose top moves with a rigid hook at ``V_0`` is the lumped model with
    the hook spring ``K`` (and ``c_a``): the same trajectory to round-off."""
    steady = coupled.steady_state(RGD_A, speed, force)
    p = dataclasses.replace(
        RGD_A, axial_stiffness_n_m=stiffness, axial_damping_ns_m=200.0,
        hook_speed_m_s=steady.rate_of_penetration_m_s,
    )  # fmt: skip
    duration = 8.0
    lumped = coupled.simulate(p, speed, force, duration)
    field = simulate_field(
        _one_element(p), speed, force, duration, axial_top="hook",
        hook_speed_m_s=steady.rate_of_penetration_m_s,
    )  # fmt: skip
    assert not field.diverged
    print(f"\n{force / 1e3:.0f} kN {speed} rad/s: stuck {lumped.stuck.mean():.3f}, off "
          f"{lumped.off_bottom.mean():.3f}, max |dOmega| "
          f"{np.abs(lumped.bit_speed_rad_s - field.bit_speed_rad_s).max():.2e}")  # fmt: skip
    np.testing.assert_allclose(field.bit_speed_rad_s, lumped.bit_speed_rad_s, rtol=0, atol=1e-8)
    np.testing.assert_allclose(field.axial_speed_m_s, lumped.axial_speed_m_s, rtol=0, atol=1e-10)
    np.testing.assert_allclose(field.depth_m, lumped.depth_m, rtol=0, atol=1e-10)
    np.testing.assert_allclose(field.bit_angle_rad, lumped.bit_angle_rad, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(field.regime, lumped.regime)
    np.testing.assert_allclose(field.weight_on_bit_n, lumped.weight_on_bit_n, rtol=1e-8, atol=1e-3)


def _short_field() -> DistributedStringParameters:
    return dataclasses.replace(with_measured_depth(FIELD, 1000.0), element_length_m=100.0)


@pytest.mark.parametrize("axial_top", ["force", "hook"])
def test_energy_balance(axial_top: str) -> None:
    """Stored energy now minus at the start = work in at the top - damping - bit work - the
    kinetic energy removed at switches."""
    hook = None if axial_top == "force" else 0.003
    trace = simulate_field(
        _short_field(), 3.0, 120e3, 8.0, axial_top=axial_top, hook_speed_m_s=hook,
        hook_stiffness_n_m=2e6, initial_bit_speed_rad_s=0.0,
    )  # fmt: skip
    balance = (
        trace.stored_energy_j - trace.stored_energy_j[0]
        - (trace.work_in_j - trace.dissipated_j - trace.bit_work_j - trace.switch_loss_j)
    )  # fmt: skip
    scale = float(np.abs(trace.work_in_j).max())
    print(f"\n{axial_top}: regimes {sorted(set(trace.regime.tolist()))}, stuck {trace.stuck.mean():.3f}, work in {scale:.4g} J, residual "
          f"{np.abs(balance).max():.2e} J")  # fmt: skip
    assert len(set(trace.regime.tolist())) >= 2  # the balance spans regime switches
    assert np.abs(balance).max() <= 1e-7 * scale


def test_step_halving() -> None:
    """The bit's trajectory converges at second order as the step halves (as the lumped
    model's: the rock surface is interpolated linearly between samples one step apart)."""
    runs = [simulate_field(_short_field(), 10.0, 80e3, 1.0, step_s=h) for h in (1e-4, 5e-5, 2.5e-5)]
    ends = [
        np.array([r.bit_speed_rad_s[-1], r.depth_m[-1] * 1e3, r.bit_angle_rad[-1]]) for r in runs
    ]
    first = np.abs(ends[0] - ends[1]).max()
    second = np.abs(ends[1] - ends[2]).max()
    print(f"\nstep halving: {first:.2e} then {second:.2e}")
    assert second <= first / 3
    assert second < 1e-7


def test_steady_drilling_is_kept_when_stable() -> None:
    """At P1 started on steady drilling (``Omega(0) = Omega_0``), a field string drills on at
    the closed-form ``V_0`` and ``T_0``."""
    trace = simulate_field(_short_field(), 20.0, 60e3, 1.0, initial_bit_speed_rad_s=20.0)
    steady = trace.steady
    np.testing.assert_allclose(trace.axial_speed_m_s, steady.rate_of_penetration_m_s, rtol=1e-9)
    np.testing.assert_allclose(trace.torque_on_bit_nm, steady.torque_on_bit_nm, rtol=1e-9)
    np.testing.assert_allclose(trace.bit_speed_rad_s, 20.0, rtol=1e-9)


def test_bad_input() -> None:
    string = _short_field()
    with pytest.raises(ValueError, match="axial_top"):
        simulate_field(string, 10.0, 60e3, 0.01, axial_top="spring")
    with pytest.raises(ValueError, match="hook_speed_m_s"):
        simulate_field(string, 10.0, 60e3, 0.01, hook_speed_m_s=0.01)
    with pytest.raises(ValueError, match="hook_speed_m_s"):
        simulate_field(string, 10.0, 60e3, 0.01, axial_top="hook")
    with pytest.raises(ValueError, match="hook_stiffness_n_m"):
        simulate_field(string, 10.0, 60e3, 0.01, axial_top="hook", hook_speed_m_s=0.0,
                       hook_stiffness_n_m=-1.0)  # fmt: skip
    with pytest.raises(ValueError, match="applied_force_n"):
        simulate_field(string, 10.0, 1e3, 0.01)
    with pytest.raises(ValueError, match="step_s"):
        simulate_field(string, 10.0, 60e3, 0.01, step_s=1e-3)
    with pytest.raises(ValueError, match="poisson_ratio"):
        AxialProperties(poisson_ratio=0.7)
    with pytest.raises(ValueError, match="youngs_moduli_pa"):
        coupled_chain(string, AxialProperties(youngs_moduli_pa=(200e9,)))
    with pytest.raises(ValueError, match="surface"):
        simulate_field(string, 10.0, 60e3, 0.01, surface="min")
