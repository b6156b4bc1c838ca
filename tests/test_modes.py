"""Tests of drill_env.modes against the continuous wave-equation string and other independent
references (finite differences of the compiled derivative, closed forms written here).

The continuous reference: each uniform section carries ``(theta, T)`` (angle amplitude, torque
``G J theta'``) by its transfer matrix ``[[cos kL, sin kL / (G J k)], [-G J k sin kL, cos kL]]``
with ``k = omega / c``; a free top drive of inertia ``J_td`` starts ``(1, -omega^2 J_td)``, a free
bit of inertia ``J_b`` ends with ``T = omega^2 J_b theta``; a clamped top starts ``(0, 1)``, a
stuck bit ends with ``theta = 0``. Roots by bracketing on a fine grid and ``scipy.optimize.brentq``.

Print the figures with ``.venv/bin/python -m pytest tests/test_modes.py -s -q``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pytest
from scipy.linalg import eigh
from scipy.optimize import brentq

from drill_env.chain import chain_derivative, chain_parameter_vector
from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    StringDamping,
    StringSection,
    discretize,
    with_measured_depth,
)
from drill_env.modes import (
    damped_modes,
    highest_frequency_rad_s,
    linearize,
    lumped_equivalent,
    natural_frequencies_hz,
    pipe_impedance,
    pipe_travel_time_s,
    stick_slip_frequency_rad_s,
)
from drill_env.parameters import PRESETS

FloatArray = npt.NDArray[np.float64]
FIELD = DISTRIBUTED_PRESETS["field_2500m"]


def _continuous_hz(
    p: DistributedStringParameters, count: int, top: str = "free", bit: str = "free"
) -> FloatArray:
    """Lowest non-zero natural frequencies of the piecewise-uniform continuous string, Hz."""
    sections: Sequence[tuple[float, float, float, float]] = [
        (s.length_m, math.pi * (s.outer_diameter_m**4 - s.inner_diameter_m**4) / 32,
         s.shear_modulus_pa, s.density_kg_m3)
        for s in p.sections
    ]  # fmt: skip

    def residual(w: float) -> float:
        theta, torque = (1.0, -w * w * p.top_drive_inertia_kg_m2) if top == "free" else (0.0, 1.0)
        for length, j, g, rho in sections:
            k = w / math.sqrt(g / rho)
            z = g * j * k
            cos, sin = math.cos(k * length), math.sin(k * length)
            theta, torque = theta * cos + torque * sin / z, -z * sin * theta + torque * cos
        return torque - w * w * p.bit_inertia_kg_m2 * theta if bit == "free" else theta

    grid = np.arange(1e-3, 40.0, 2e-3)  # rad/s; no root of the presets is closer than 0.5
    values = np.array([residual(w) for w in grid])
    roots: list[float] = []
    for i in np.flatnonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0):
        roots.append(brentq(residual, grid[i], grid[i + 1], xtol=1e-14, rtol=1e-15))
        if len(roots) == count:
            break
    assert len(roots) == count
    return np.array(roots) / (2 * math.pi)


# --------------------------------------------------------------- against the continuous string
@pytest.mark.parametrize(
    ("top", "bit"), [("free", "free"), ("clamped", "free"), ("clamped", "stuck")]
)
def test_first_three_modes_within_one_percent_of_the_continuous_string(top: str, bit: str) -> None:
    """field_2500m at the default 25 m elements: the first three frequencies within 1 %."""
    exact = _continuous_hz(FIELD, 3, top, bit)
    got = natural_frequencies_hz(FIELD, 3, top=top, bit=bit)  # type: ignore[arg-type]
    rel = np.abs(got - exact) / exact
    print(f"\n[modes] {top}/{bit}: continuous {np.array2string(exact, precision=5)} Hz, "
          f"relative error {np.array2string(rel, precision=2)}")  # fmt: skip
    assert np.all(rel < 0.01)


def test_frequency_error_falls_with_the_square_of_the_element_length() -> None:
    """Lumped masses: error ~ h^2. Fitted log-log slope over h = 50, 25, 12.5, 6.25 m is 2."""
    exact = _continuous_hz(FIELD, 3)
    lengths = np.array([50.0, 25.0, 12.5, 6.25])
    errors = np.array([
        np.abs(natural_frequencies_hz(dataclasses.replace(FIELD, element_length_m=h), 3) - exact)
        / exact
        for h in lengths
    ])  # fmt: skip
    slopes = [np.polyfit(np.log(lengths), np.log(errors[:, j]), 1)[0] for j in range(3)]
    print(f"\n[convergence] relative errors (rows h = {lengths.tolist()} m):\n"
          f"{np.array2string(errors, precision=2)}\n  slopes {np.round(slopes, 3)}")  # fmt: skip
    assert np.all(np.diff(errors, axis=0) < 0)
    for slope in slopes:
        assert 1.8 < slope < 2.2


def _uniform_pipe(length: float, element_length: float) -> DistributedStringParameters:
    pipe = StringSection(length, 0.127, 0.1086, 79.3e9, 7850.0)
    return DistributedStringParameters(
        sections=(pipe,), top_drive_inertia_kg_m2=1000.0, bit_inertia_kg_m2=0.0,
        bit_radius_m=0.108, element_length_m=element_length,
    )  # fmt: skip


def test_stick_slip_frequency_of_a_uniform_pipe_is_the_quarter_wave() -> None:
    """Top clamped, bit free, no bit inertia: omega -> c pi / (2 L), error shrinking ~ h^2."""
    length = 3000.0
    c = math.sqrt(79.3e9 / 7850.0)
    quarter = c * math.pi / (2 * length)
    errors = [
        abs(stick_slip_frequency_rad_s(_uniform_pipe(length, h)) - quarter) / quarter
        for h in (100.0, 50.0, 25.0)
    ]
    print(f"\n[quarter wave] c pi / 2L = {quarter:.5f} rad/s, relative errors {errors}")
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 1e-4
    # With the bit stuck both ends are fixed: the half-wave c pi / L.
    half = stick_slip_frequency_rad_s(_uniform_pipe(length, 25.0), bit="stuck")
    assert half == pytest.approx(2 * quarter, rel=1e-4)


def test_highest_frequency_is_twice_the_wave_speed_over_the_element_length() -> None:
    """A uniform lumped chain cuts off at 2 c / l; the field string at 1 ms is far inside the
    RK4 stability limit (h omega = 2.8)."""
    c = math.sqrt(79.3e9 / 7850.0)
    assert highest_frequency_rad_s(_uniform_pipe(3000.0, 25.0)) == pytest.approx(
        2 * c / 25.0, rel=1e-3
    )
    assert 1e-3 * highest_frequency_rad_s(FIELD) < 0.35


def test_stick_slip_frequency_of_the_field_string() -> None:
    """field_2500m: the clamped-top, free-bit mode equals the continuous string's lowest."""
    exact = 2 * math.pi * _continuous_hz(FIELD, 1, "clamped", "free")[0]
    assert stick_slip_frequency_rad_s(FIELD) == pytest.approx(exact, rel=1e-4)


def test_pipe_impedance_and_travel_time() -> None:
    """J sqrt(G rho) and L / c of the pipe by hand; sqrt(k_pi J_pi) for the 4-DOF plant."""
    j = math.pi * (0.146529**4 - 0.123024**4) / 32
    assert pipe_impedance(FIELD) == pytest.approx(j * math.sqrt(61e9 * 7850), rel=1e-13)
    length = 2500.0 - (48.70 + 114.80 + 56.70 + 38.88)
    assert pipe_travel_time_s(FIELD) == pytest.approx(length / math.sqrt(61e9 / 7850), rel=1e-13)
    q = PRESETS["zribi2024"]
    assert pipe_impedance(q) == pytest.approx(math.sqrt(q.k_pi * q.J_pi), rel=1e-14)
    assert pipe_travel_time_s(q) == pytest.approx(math.sqrt(q.J_pi / q.k_pi), rel=1e-14)


def test_four_dof_natural_frequencies_by_hand() -> None:
    """For the 4-DOF plant, the free-free eigenproblem written here with scipy.linalg.eigh."""
    q = PRESETS["zribi2024"]
    k1, k2, k3 = q.k_pi, q.k_co, q.k_bi
    stiffness = np.array([[k1, -k1, 0, 0], [-k1, k1 + k2, -k2, 0],
                          [0, -k2, k2 + k3, -k3], [0, 0, -k3, k3]])  # fmt: skip
    mass = np.diag([q.J_dt, q.J_pi, q.J_co, q.J_bi])
    w2 = eigh(stiffness, mass, eigvals_only=True)
    expected = np.sqrt(w2[1:]) / (2 * math.pi)
    np.testing.assert_allclose(natural_frequencies_hz(q, 3), expected, rtol=1e-10)


# ------------------------------------------------------------------------------- damping
def test_mass_proportional_damping_gives_zeta_k_over_2_omega() -> None:
    """With mud damping only (k_t rho J per metre, nothing else), every mode of a string
    without end inertias has zeta = k_t / (2 omega) exactly (Rayleigh mass-proportional)."""
    damping = StringDamping(mud_rate_per_s=0.2, material_time_constant_s=0.0,
                            top_drive_nm_s_rad=0.0, bit_nm_s_rad=0.0)  # fmt: skip
    p = dataclasses.replace(
        _uniform_pipe(2000.0, 50.0), damping=damping, top_drive_inertia_kg_m2=1e-9
    )
    freq, zeta = damped_modes(p, 4)
    omega_n = 2 * math.pi * natural_frequencies_hz(p, 4)
    np.testing.assert_allclose(zeta, 0.2 / (2 * omega_n), rtol=1e-8)
    np.testing.assert_allclose(freq, omega_n / (2 * math.pi), rtol=1e-9)


def test_default_damping_of_the_field_string() -> None:
    """The lowest modes of field_2500m have damping ratios of a few percent (3-4 % for the
    first, about 1 % for the next), far below the 4-DOF paper plant's (> 15 %)."""
    _, zeta_free = damped_modes(FIELD, 3)
    _, zeta_clamped = damped_modes(FIELD, 3, top="clamped")
    print(f"\n[damping] field_2500m free/free zeta {np.round(zeta_free, 4)}, "
          f"clamped/free {np.round(zeta_clamped, 4)}")  # fmt: skip
    assert 0.03 < zeta_free[0] < 0.045
    assert 0.03 < zeta_clamped[0] < 0.045
    assert np.all((zeta_free[1:] > 0.005) & (zeta_free[1:] < 0.02))
    _, zeta_paper = damped_modes("zribi2024", 2)
    assert np.all(zeta_paper > 0.15)


# --------------------------------------------------------------------------- linearisation
def _fd_jacobian(name: str, x: FloatArray, u: float, wob: float) -> tuple[FloatArray, FloatArray]:
    """Central differences of the compiled derivative: (d f / d x, d f / d (u, WOB))."""
    chain = discretize(name) if name in DISTRIBUTED_PRESETS else None
    p = chain_parameter_vector(chain if chain is not None else PRESETS[name])
    mu_a, mu_0, radius = p[1], p[2], p[3]

    def f(state: FloatArray, torque: float, weight: float) -> FloatArray:
        out = np.empty_like(state)
        chain_derivative(state, torque, p, mu_a * weight * radius, mu_0 * weight * radius, 1, out)
        return out

    size = x.size
    jac = np.empty((size, size))
    for j in range(size):
        step = 1e-6 * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += step
        xm[j] -= step
        jac[:, j] = (f(xp, u, wob) - f(xm, u, wob)) / (2 * step)
    b = np.empty((size, 2))
    b[:, 0] = (f(x, u + 1.0, wob) - f(x, u - 1.0, wob)) / 2.0
    b[:, 1] = (f(x, u, wob + 10.0) - f(x, u, wob - 10.0)) / 20.0
    return jac, b


@pytest.mark.parametrize(
    ("name", "wob", "speed"),
    [("field_2500m", 100e3, 10.0), ("field_2500m", 150e3, 1.0), ("zribi2024", 97_347.0, 12.0)],
)
def test_linearisation_matches_finite_differences(name: str, wob: float, speed: float) -> None:
    """A and B equal central differences of the compiled derivative at steady drilling, and so
    do the eigenvalues; the operating point is an equilibrium."""
    lin = linearize(name, wob, speed)
    jac, b = _fd_jacobian(name, np.array(lin.x_eq), float(lin.u_eq[0]), wob)
    scale = np.abs(lin.A).max()
    np.testing.assert_allclose(lin.A, jac, rtol=0, atol=1e-6 * scale)
    np.testing.assert_allclose(lin.B, b, rtol=1e-6, atol=1e-12)
    ev_a = np.sort_complex(np.linalg.eigvals(lin.A))
    ev_fd = np.sort_complex(np.linalg.eigvals(jac))
    np.testing.assert_allclose(ev_a, ev_fd, rtol=0, atol=1e-5 * np.abs(ev_a).max())
    p = chain_parameter_vector(discretize(name) if name in DISTRIBUTED_PRESETS else PRESETS[name])
    rate = np.empty(lin.x_eq.size)
    chain_derivative(np.array(lin.x_eq), float(lin.u_eq[0]), p, p[1] * wob * p[3],
                     p[2] * wob * p[3], 1, rate)  # fmt: skip
    assert np.abs(rate).max() < 1e-8


def test_linearisation_names_and_outputs() -> None:
    """Names match the shapes; C reads top speed, bit speed and the top element's torque."""
    lin = linearize(FIELD, 100e3, 10.0)
    n = discretize(FIELD).n_nodes
    assert lin.A.shape == (2 * n - 1, 2 * n - 1)
    assert lin.B.shape == (2 * n - 1, 2) and lin.C.shape == (3, 2 * n - 1)
    assert lin.D.shape == (3, 2) and not lin.D.any()
    assert len(lin.state_names) == 2 * n - 1
    assert lin.state_names[:3] == ("w0_rad_s", "twist0_rad", "w1_rad_s")
    assert lin.state_names[-1] == f"w{n - 1}_rad_s"
    assert lin.input_names == ("top_drive_torque_nm", "wob_n")
    assert lin.output_names == ("top_drive_speed_rad_s", "bit_speed_rad_s", "top_torque_nm")
    y = lin.C @ lin.x_eq
    top_damping = discretize(FIELD).node_damping_nm_s_rad[0]
    assert y[0] == pytest.approx(10.0) and y[1] == pytest.approx(10.0)
    assert y[2] == pytest.approx(lin.u_eq[0] - top_damping * 10.0, rel=1e-12)
    with pytest.raises(ValueError, match="read-only"):
        lin.A[0, 0] = 1.0


def test_velocity_weakening_makes_a_mode_unstable() -> None:
    """Steep Stribeck slope (150 kN, 1 rad/s): an eigenvalue with positive real part; at
    15 rad/s the slope is small and every mode decays."""
    steep = linearize(FIELD, 150e3, 1.0)
    flat = linearize(FIELD, 150e3, 15.0)
    print(f"\n[linearize] slope {steep.friction_slope_nm_s_rad:.0f} N m s/rad: max Re "
          f"{steep.eigenvalues.real.max():.3f} 1/s; slope {flat.friction_slope_nm_s_rad:.2f}: "
          f"max Re {flat.eigenvalues.real.max():.4f} 1/s")  # fmt: skip
    assert steep.friction_slope_nm_s_rad < 0
    assert steep.eigenvalues.real.max() > 0.1
    assert flat.eigenvalues.real.max() < 0.0
    # The real part grows with the steepness of the slope (xi scales it at fixed speed).
    growth = [
        linearize(dataclasses.replace(FIELD, xi=xi), 150e3, 1.0).eigenvalues.real.max()
        for xi in (0.0, 0.1, 0.5)
    ]
    assert growth[0] < 0.0 < growth[2]
    assert growth[0] < growth[1] < growth[2]


# ------------------------------------------------------------------------ 4-DOF equivalent
def test_lumped_equivalent_keeps_its_stated_rule() -> None:
    """Stick-slip frequency equal; total inertia, static compliance, ground damping (hence the
    steady torque) equal; the lowest free-free mode within 3 %."""
    q = lumped_equivalent(FIELD)
    chain = discretize(FIELD)
    assert stick_slip_frequency_rad_s(q) == pytest.approx(stick_slip_frequency_rad_s(FIELD),
                                                          rel=1e-9)  # fmt: skip
    total_j = (
        FIELD.top_drive_inertia_kg_m2
        + FIELD.bit_inertia_kg_m2
        + sum(s.inertia_kg_m2 for s in FIELD.sections)
    )
    assert q.J_dt + q.J_pi + q.J_co + q.J_bi == pytest.approx(total_j, rel=1e-12)
    compliance = sum(s.length_m / s.torsional_rigidity_nm2 for s in FIELD.sections)
    assert 1 / q.k_pi + 1 / q.k_co + 1 / q.k_bi == pytest.approx(compliance, rel=1e-12)
    assert q.k_pi == pytest.approx(FIELD.pipe.stiffness_nm_rad, rel=1e-14)
    assert q.c_dt + q.c_bit == pytest.approx(chain.ground_damping_nm_s_rad, rel=1e-12)
    lowest_4dof = natural_frequencies_hz(q, 1)[0]
    lowest = natural_frequencies_hz(FIELD, 1)[0]
    print(
        f"\n[lumped] lowest free-free mode: 4-DOF {lowest_4dof:.4f} Hz, distributed "
        f"{lowest:.4f} Hz ({(lowest_4dof / lowest - 1) * 100:+.1f} %); second: "
        f"{natural_frequencies_hz(q, 2)[1]:.3f} vs {natural_frequencies_hz(FIELD, 2)[1]:.3f} Hz"
    )
    assert abs(lowest_4dof / lowest - 1) < 0.03
    assert (q.R, q.mu_a, q.mu_0, q.xi, q.Dw) == (0.108, 0.8, 0.5, 0.5, 1e-3)


@pytest.mark.parametrize("depth", [1000.0, 5000.0])
def test_lumped_equivalent_at_other_depths(depth: float) -> None:
    """Over the env's depth range the stick-slip frequency is matched and the lowest free-free
    mode stays within 5 % (the single pipe inertia fits a long, heavy pipe less well)."""
    p = with_measured_depth(FIELD, depth)
    q = lumped_equivalent(p)
    assert stick_slip_frequency_rad_s(q) == pytest.approx(stick_slip_frequency_rad_s(p), rel=1e-9)
    mismatch = natural_frequencies_hz(q, 1)[0] / natural_frequencies_hz(p, 1)[0] - 1
    print(f"\n[lumped] {depth:.0f} m: lowest free-free mode {mismatch * 100:+.1f} %")
    assert abs(mismatch) < 0.05


# ---------------------------------------------------------------------------------- errors
def test_bad_arguments() -> None:
    """Unknown end conditions, counts out of range, a string without BHA."""
    with pytest.raises(
        ValueError, match=r"top = 'fixed' is not valid: allowed \['free', 'clamped'\]"
    ):
        natural_frequencies_hz(FIELD, 1, top="fixed")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"bit = 'on' is not valid: allowed \['free', 'stuck'\]"):
        damped_modes(FIELD, 1, bit="on")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"count = 0 is out of range: allowed 1\.\."):
        natural_frequencies_hz(FIELD, 0)
    with pytest.raises(ValueError, match=r"count = 4 is out of range: allowed 1\.\.3"):
        natural_frequencies_hz("zribi2024", 4)
    with pytest.raises(ValueError, match=r"sections has 1 section: allowed at least 2"):
        lumped_equivalent(_uniform_pipe(1000.0, 25.0))
    with pytest.raises(ValueError, match=r"bit_speed_rad_s = 0.0 is out of range: allowed > 0"):
        linearize(FIELD, 1e5, 0.0)
