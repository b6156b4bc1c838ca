"""The coupled axial-torsional string with the regenerative bit (drill_env.coupled), checked
against references built here: the parameter table and closed forms of docs/coupled-model.md,
a tight scipy integration while the delayed surface is still the steady history, the growth
and decay of small disturbances against the roots of the characteristic equation, step
halving, the energy balance, and the stick and surface rules."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from drill_env.coupled import (
    RGD_PRESETS,
    STANDARD_POINTS,
    CoupledTrace,
    RgdParameters,
    critical_speed_rad_s,
    rightmost_roots,
    run_features,
    simulate,
    simulated_map,
    stability_map,
    standard_run,
    steady_state,
)

RGD_A = RGD_PRESETS["rgd_a"]


def test_rgd_a_matches_the_parameter_table() -> None:
    """The derived constants and steady states of the specification's tables."""
    p = RGD_A
    assert p.axial_mass_kg == pytest.approx(34_426, abs=1)
    assert p.inertia_kg_m2 == pytest.approx(115.54, abs=0.01)
    assert p.torsional_stiffness_nm_rad == pytest.approx(938.1, abs=0.05)
    assert p.k_a == pytest.approx(1.5552e7, rel=1e-12)
    assert p.k_t == pytest.approx(1.39968e6, rel=1e-12)
    assert p.contact_force_n == pytest.approx(31_104, rel=1e-12)
    assert p.contact_torque_nm == pytest.approx(1007.77, abs=0.01)
    assert math.sqrt(p.torsional_stiffness_nm_rad / p.inertia_kg_m2) == pytest.approx(
        2.849, abs=1e-3
    )
    table = {"P1": (1.858e-3, 23.66e-3), "P2": (1.858e-3, 11.83e-3), "P3": (1.858e-3, 4.73e-3)}
    table["P4"] = (3.787e-3, 9.64e-3)
    for point, (d0, v0) in table.items():
        force, speed = STANDARD_POINTS[point]
        steady = steady_state("rgd_a", speed, force)
        assert steady.depth_of_cut_m == pytest.approx(d0, abs=1e-6), point
        assert steady.rate_of_penetration_m_s == pytest.approx(v0, abs=1e-5), point


def test_steady_state_closed_form_with_damping() -> None:
    p = dataclasses.replace(RGD_A, axial_damping_ns_m=2e5, torsional_damping_nms_rad=30.0)
    omega0, w0 = 7.0, 75e3
    s = steady_state(p, omega0, w0)
    # balance: W0 - c_a V0 = k_a d0 + W_f; T0 = k_t d0 + T_f; C theta0 = T0 + c_t Omega0
    v0 = p.blades * omega0 * s.depth_of_cut_m / (2 * math.pi)
    assert s.rate_of_penetration_m_s == pytest.approx(v0, rel=1e-14)
    assert w0 - 2e5 * v0 == pytest.approx(p.k_a * s.depth_of_cut_m + 31_104, rel=1e-12)
    assert s.torque_on_bit_nm == pytest.approx(p.k_t * s.depth_of_cut_m + 1007.7696, rel=1e-9)
    assert p.torsional_stiffness_nm_rad * s.twist_rad == pytest.approx(
        s.torque_on_bit_nm + 30.0 * omega0, rel=1e-14
    )


def test_run_started_on_steady_drilling_stays_there() -> None:
    force, speed = STANDARD_POINTS["P1"]
    s = steady_state("rgd_a", speed, force)
    trace = simulate(
        "rgd_a",
        speed,
        force,
        2.0,
        initial_bit_speed_rad_s=speed,
        initial_axial_speed_m_s=s.rate_of_penetration_m_s,
    )
    assert np.max(np.abs(trace.bit_speed_rad_s - speed)) < 1e-9
    assert np.max(np.abs(trace.depth_m - s.rate_of_penetration_m_s * trace.time_s)) < 1e-12
    assert np.max(np.abs(trace.depth_of_cut_m - s.depth_of_cut_m)) < 1e-12
    assert np.max(np.abs(trace.weight_on_bit_n - force)) < 1e-5
    assert np.max(np.abs(trace.torque_on_bit_nm - s.torque_on_bit_nm)) < 1e-6
    assert not (trace.stuck.any() or trace.off_bottom.any() or trace.axial_hold.any())


def test_first_blade_passage_matches_scipy() -> None:
    """While the delayed angle is still in the steady history (``Phi < 2 pi / n``), the
    surface is ``R(phi) = r phi`` and the model is an ODE: integrate it with scipy."""
    integrate = pytest.importorskip("scipy.integrate")
    p = RGD_A
    force, speed = 60e3, 10.0
    s = steady_state(p, speed, force)
    r, blade = s.surface_slope_m_rad, 2 * math.pi / p.blades

    def rhs(t: float, y: npt.NDArray[np.float64]) -> list[float]:
        u, v, phi, om = y
        dn = u - r * (phi - blade)
        ts = p.torsional_stiffness_nm_rad * (speed * t + s.twist_rad - phi)
        w = p.k_a * dn + p.contact_force_n
        tq = p.k_t * dn + p.contact_torque_nm
        dom = (ts - p.torsional_damping_nms_rad * om - tq) / p.inertia_kg_m2
        return [v, (force - w) / p.axial_mass_kg, om, dom]

    trace = simulate(p, speed, force, 0.15)
    assert (trace.regime == 0).all() and trace.bit_angle_rad[-1] < blade
    reference = integrate.solve_ivp(
        rhs,
        (0.0, 0.15),
        [0.0, s.rate_of_penetration_m_s, 0.0, 0.9 * speed],
        method="DOP853",
        rtol=1e-12,
        atol=1e-15,
        t_eval=trace.time_s[::100],
    )
    u, v, phi, om = reference.y
    assert np.max(np.abs(trace.bit_speed_rad_s[::100] - om)) < 1e-9
    assert np.max(np.abs(trace.axial_speed_m_s[::100] - v)) < 1e-11
    assert np.max(np.abs(trace.depth_m[::100] - u)) < 1e-12
    assert np.max(np.abs(trace.bit_angle_rad[::100] - phi)) < 1e-10


def _envelope_rate(
    time_s: npt.NDArray[np.float64], signal: npt.NDArray[np.float64]
) -> tuple[float, float]:
    """Growth rate (1/s) of the peaks of ``|signal|`` by a least-squares line through their
    logarithms, and the angular frequency (rad/s) from the spacing of the positive peaks."""
    inner = signal[1:-1]
    peak = (inner > signal[:-2]) & (inner >= signal[2:]) & (inner > 0)
    times, values = time_s[1:-1][peak], inner[peak]
    slope = np.polyfit(times, np.log(values), 1)[0]
    period = float(np.mean(np.diff(times)))
    return float(slope), 2 * math.pi / period


def test_torsional_decay_matches_the_rightmost_root() -> None:
    """P1 is stable: a small speed disturbance decays at the torsional root's rate. The state
    dependence of the delay shows: plain damping would decay at ``c_t / 2I``, 6 % faster."""
    force, speed = STANDARD_POINTS["P1"]
    roots = rightmost_roots("rgd_a", speed, force, count=2)
    torsional = roots[np.argmin(np.abs(roots.imag - 2.9))]
    trace = simulate("rgd_a", speed, force, 30.0, initial_bit_speed_rad_s=speed + 0.02)
    keep = trace.time_s >= 3.0
    rate, frequency = _envelope_rate(trace.time_s[keep], trace.bit_speed_rad_s[keep] - speed)
    assert rate == pytest.approx(torsional.real, rel=0.01)
    assert frequency == pytest.approx(torsional.imag, rel=2e-3)
    plain = -RGD_A.torsional_damping_nms_rad / (2 * RGD_A.inertia_kg_m2)
    assert abs(rate - plain) > 0.04 * abs(plain)


def test_axial_growth_matches_the_rightmost_root() -> None:
    """Below the critical speed the axial (regenerative) mode grows at the root's rate."""
    force, speed = 60e3, 14.0
    root = rightmost_roots("rgd_a", speed, force, count=1)[0]
    assert root.real > 0 and root.imag == pytest.approx(29, abs=1)
    v0 = steady_state("rgd_a", speed, force).rate_of_penetration_m_s
    trace = simulate(
        "rgd_a",
        speed,
        force,
        8.0,
        initial_bit_speed_rad_s=speed,
        initial_axial_speed_m_s=v0 + 1e-7,
    )
    keep = trace.time_s >= 1.0
    rate, frequency = _envelope_rate(trace.time_s[keep], trace.axial_speed_m_s[keep] - v0)
    assert rate == pytest.approx(root.real, rel=0.01)
    assert frequency == pytest.approx(root.imag, rel=2e-3)


def test_closed_forms_of_the_modes() -> None:
    """The axial Hopf speed ``2 sqrt(2 k_a / M) / n`` (small depth of cut) and the torsional
    frequency ``sqrt(C / (I - (a / 2 zeta) M r))``."""
    p = RGD_A
    hopf = 2 * math.sqrt(2 * p.k_a / p.axial_mass_kg) / p.blades
    assert hopf == pytest.approx(15.03, abs=5e-3)
    barely = p.contact_force_n + 20.0
    critical = critical_speed_rad_s(p, barely, speed_range_rad_s=(12.0, 18.0), grid=5)
    assert critical == pytest.approx(hopf, rel=1e-3)
    force, speed = STANDARD_POINTS["P1"]
    r = steady_state(p, speed, force).surface_slope_m_rad
    reduced = p.inertia_kg_m2 - p.bit_radius_m / (2 * p.force_ratio) * p.axial_mass_kg * r
    omega_t = math.sqrt(p.torsional_stiffness_nm_rad / reduced)
    roots = rightmost_roots(p, speed, force, count=3)
    torsional = roots[np.argmin(np.abs(roots.imag - omega_t))]
    assert torsional.imag == pytest.approx(omega_t, rel=1e-3)


def test_pure_rgd_has_no_stable_steady_state() -> None:
    pure = dataclasses.replace(RGD_A, torsional_damping_nms_rad=0.0)
    for speed in (4.0, 10.0, 20.0, 40.0):
        roots = rightmost_roots(pure, speed, 60e3, count=3)
        torsional = roots[np.argmin(np.abs(roots.imag - 2.9))]
        assert 0 < torsional.real < 0.1, speed
    with pytest.raises(ValueError, match="unstable at every top-drive speed"):
        critical_speed_rad_s(pure, 60e3, speed_range_rad_s=(10.0, 30.0), grid=4)


def test_rgd_a_critical_speed_separates_growth_from_decay() -> None:
    critical = critical_speed_rad_s("rgd_a", 60e3, speed_range_rad_s=(10.0, 20.0), grid=6)
    assert 14.0 < critical < 15.03
    below = rightmost_roots("rgd_a", critical - 0.05, 60e3, count=1)[0]
    above = rightmost_roots("rgd_a", critical + 0.05, 60e3, count=1)[0]
    assert below.real > 0 > above.real
    grid = stability_map("rgd_a", [60e3], [critical - 0.05, critical + 0.05])
    assert grid.shape == (1, 2) and grid[0, 0] > 0 > grid[0, 1]


def test_step_halving_converges() -> None:
    """Stick-slip (P3) over 20 s at h, h/2, h/4: the differences shrink at second order
    (the surface is interpolated linearly between samples one step apart)."""
    ends = []
    for step in (1e-4, 5e-5, 2.5e-5):
        trace = simulate("rgd_a", 4.0, 60e3, 20.0, step_s=step)
        assert trace.stuck.any()
        ends.append(
            np.array([trace.bit_speed_rad_s[-1], trace.depth_m[-1], trace.bit_angle_rad[-1]])
        )
    coarse, fine = np.abs(ends[0] - ends[2]), np.abs(ends[1] - ends[2])
    assert np.all(coarse / fine > 3.5)
    assert np.all(fine / np.array([4.0, 0.1, 80.0]) < 1e-5)


def _energy_residual(trace: CoupledTrace, start_s: float) -> tuple[float, float]:
    """Work in (top drive and applied force) minus the change of kinetic and spring energy,
    of the dissipation (bit forces, damping) and of the energy removed at the velocity
    resets, over ``[start_s, end]``; and the work in, J."""
    p = trace.parameters
    t, om, v = trace.time_s, trace.bit_speed_rad_s, trace.axial_speed_m_s
    twist = trace.string_torque_nm
    energy = (
        0.5 * p.axial_mass_kg * v**2
        + 0.5 * p.inertia_kg_m2 * om**2
        + 0.5 * twist**2 / p.torsional_stiffness_nm_rad
    )
    work_in = twist * trace.top_drive_speed_rad_s + trace.applied_force_n * v
    dissipated = (
        trace.weight_on_bit_n * v
        + trace.torque_on_bit_nm * om
        + p.torsional_damping_nms_rad * om**2
        + p.axial_damping_ns_m * v**2
    )
    i = int(np.searchsorted(t, start_s))
    w_in = float(np.trapezoid(work_in[i:], t[i:]))
    lost = float(np.trapezoid(dissipated[i:], t[i:]))
    resets = float(trace.switch_loss_j[-1] - trace.switch_loss_j[i])
    return w_in - lost - resets - float(energy[-1] - energy[i]), w_in


@pytest.mark.parametrize("point", ["P3", "P4"], ids=["stick_slip", "bounce"])
def test_energy_balance_over_cycles(point: str) -> None:
    force, speed = STANDARD_POINTS[point]
    trace = simulate("rgd_a", speed, force, 60.0)
    window = trace.time_s >= 10.0
    assert trace.stuck[window].any()
    if point == "P4":
        assert trace.off_bottom[window].any() and trace.switch_loss_j[-1] > 0
    residual, work = _energy_residual(trace, 10.0)
    assert abs(residual) < 1e-5 * work


def test_surface_rules_agree_until_the_bit_lifts_off() -> None:
    force, speed = STANDARD_POINTS["P3"]
    kept = simulate("rgd_a", speed, force, 40.0, surface="max")
    delayed = simulate("rgd_a", speed, force, 40.0, surface="delay")
    assert not kept.off_bottom.any() and kept.stuck.any()
    for name in ("bit_speed_rad_s", "axial_speed_m_s", "depth_m", "weight_on_bit_n"):
        assert np.array_equal(getattr(kept, name), getattr(delayed, name)), name

    force, speed = STANDARD_POINTS["P4"]
    kept = simulate("rgd_a", speed, force, 40.0, surface="max")
    delayed = simulate("rgd_a", speed, force, 40.0, surface="delay")
    lift = int(np.argmax(kept.off_bottom))
    assert lift > 0
    assert np.array_equal(kept.depth_m[:lift], delayed.depth_m[:lift])
    assert not np.allclose(kept.depth_m[lift:], delayed.depth_m[lift:], atol=1e-4)


def test_stuck_bit_is_exactly_at_rest() -> None:
    force, speed = STANDARD_POINTS["P4"]
    trace = simulate("rgd_a", speed, force, 40.0)
    assert (trace.bit_speed_rad_s >= 0).all()
    on_rock = trace.stuck & ~trace.off_bottom
    assert on_rock.sum() > 1000
    assert (trace.bit_speed_rad_s[on_rock] == 0).all()
    assert (trace.axial_speed_m_s[on_rock] == 0).all()
    both = on_rock[1:] & on_rock[:-1]
    assert (np.diff(trace.depth_m)[both] == 0).all()
    assert (np.diff(trace.bit_angle_rad)[both] == 0).all()
    assert np.allclose(trace.weight_on_bit_n[on_rock], force, rtol=0, atol=1e-9)
    assert np.allclose(trace.torque_on_bit_nm[on_rock], trace.string_torque_nm[on_rock])
    capacity = RGD_A.k_t * trace.depth_of_cut_m[on_rock] + RGD_A.contact_torque_nm
    assert (trace.string_torque_nm[on_rock] <= capacity + 1e-6).all()
    assert (trace.torque_on_bit_nm[on_rock] < 0).any()  # the rock holds back rotation
    air = trace.off_bottom
    assert (trace.weight_on_bit_n[air] == 0).all() and (trace.torque_on_bit_nm[air] == 0).all()
    assert (trace.depth_of_cut_m[air] < 0).all()
    held = trace.axial_hold
    assert held.any() and (trace.axial_speed_m_s[held] == 0).all()
    free = force - RGD_A.k_a * trace.depth_of_cut_m[held]
    assert (free >= -1e-6).all() and (free <= RGD_A.contact_force_n + 1e-6).all()


def test_features_of_a_known_signal() -> None:
    trace = simulate("rgd_a", 20.0, 60e3, 2.0)
    t = trace.time_s
    period, amplitude = 0.37, 1.5
    wave = 20.0 + amplitude * np.sin(2 * math.pi * t / period)
    stuck = np.zeros(t.size, dtype=bool)
    stuck[(t > 1.0) & (t <= 1.25)] = True
    synthetic = dataclasses.replace(trace, bit_speed_rad_s=wave, stuck=stuck)
    features = run_features(synthetic, (0.5, 2.0))
    assert features.om_amp_rel == pytest.approx(amplitude / 20.0, rel=1e-6)
    assert features.period_s == pytest.approx(period, rel=1e-4)
    assert features.frac_stick == pytest.approx(0.25 / 1.5, rel=1e-9)
    s = trace.steady
    rop = (trace.depth_m[20000] - trace.depth_m[5000]) / 1.5
    assert features.rop_m_s == pytest.approx(rop, rel=1e-12)
    assert features.rop_rel == pytest.approx(rop / s.rate_of_penetration_m_s, rel=1e-12)
    omega = run_features(trace, (0.5, 2.0)).om_mean_rad_s
    angle = (trace.bit_angle_rad[20000] - trace.bit_angle_rad[5000]) / 1.5
    assert omega == pytest.approx(angle, rel=1e-12)


def test_simulated_map_on_a_small_grid() -> None:
    result = simulated_map("rgd_a", [60e3], [4.0, 20.0], duration_s=20.0, window_s=(10.0, 20.0))
    assert result["frac_stick"].shape == (1, 2)
    assert result["frac_stick"][0, 0] > 0.1 and result["frac_stick"][0, 1] == 0
    assert (result["frac_bounce"] == 0).all()


@pytest.mark.parametrize(
    ("change", "error", "match"),
    [
        ({"blades": 0}, ValueError, "blades = 0 is out of range"),
        ({"bit_radius_m": -0.1}, ValueError, r"bit_radius_m = -0.1 is out of range: allowed > 0"),
        ({"force_ratio": math.nan}, ValueError, "force_ratio must be finite"),
        ({"inertia_kg_m2": "big"}, TypeError, "inertia_kg_m2 must be a real number"),
        ({"torsional_damping_nms_rad": -1.0}, ValueError, "torsional_damping_nms_rad = -1.0"),
    ],
)
def test_bad_parameters(change: dict[str, object], error: type[Exception], match: str) -> None:
    with pytest.raises(error, match=match):
        RgdParameters(**change)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("arguments", "keywords", "error", "match"),
    [
        (("rgd_b", 4.0, 60e3, 1.0), {}, ValueError, "parameters = 'rgd_b' is not a known"),
        (("rgd_a", 4.0, 20e3, 1.0), {}, ValueError, "applied_force_n = 20000.0 is out of range"),
        (("rgd_a", 0.0, 60e3, 1.0), {}, ValueError, "top_drive_speed_rad_s = 0.0"),
        (("rgd_a", 4.0, 60e3, -1.0), {}, ValueError, "duration_s = -1.0"),
        (("rgd_a", 4.0, 60e3, 1.0), {"step_s": 1e-3}, ValueError, "step_s = 0.001"),
        (("rgd_a", 4.0, 60e3, 1.0), {"surface": "min"}, ValueError, "surface = 'min'"),
        (("rgd_a", 4.0, 60e3, 1e5), {}, ValueError, "duration_s = 100000.0 .* at most"),
        (
            ("rgd_a", 4.0, 60e3, 1.0),
            {"initial_bit_speed_rad_s": -1.0},
            ValueError,
            "initial_bit_speed_rad_s = -1.0",
        ),
    ],
)
def test_bad_simulation_inputs(
    arguments: tuple[object, ...], keywords: dict[str, object], error: type[Exception], match: str
) -> None:
    with pytest.raises(error, match=match):
        simulate(*arguments, **keywords)  # type: ignore[arg-type]


def test_bad_windows_and_points() -> None:
    trace = simulate("rgd_a", 20.0, 60e3, 1.0)
    with pytest.raises(ValueError, match=r"window_s\[1\] = 5.0 is out of range"):
        run_features(trace, (0.5, 5.0))
    with pytest.raises(ValueError, match="point = 'P9' is not a known operating point"):
        standard_run("rgd_a", "P9")


@pytest.mark.slow
def test_standard_run_regimes() -> None:
    """The standard run (400 s, features over [100, 400] s) shows the regime the
    specification gives at each point."""
    features = {point: standard_run("rgd_a", point)[1] for point in STANDARD_POINTS}
    for point, f in features.items():
        assert f.om_mean_rad_s == pytest.approx(STANDARD_POINTS[point][1], rel=2e-3), point
    p1, p2, p3, p4 = (features[point] for point in ("P1", "P2", "P3", "P4"))
    assert p1.om_amp_rel < 0.01 and p1.frac_stick == 0 and p1.rop_rel == pytest.approx(1, 1e-3)
    assert p2.frac_stick == 0 and 0.9 < p2.om_amp_rel < 1.0 and p2.frac_bounce == 0
    assert p3.frac_stick > 0.2 and p3.frac_bounce == 0
    assert p4.frac_bounce > 0 and p4.frac_stick_backtorque == pytest.approx(0.16, abs=0.02)


@pytest.mark.parametrize(
    "change",
    [{"axial_damping_ns_m": 3e5}, {"axial_stiffness_n_m": 1e6}],
    ids=["axial_damping", "hook_spring"],
)
def test_steady_drilling_with_axial_damping_or_a_hook_spring(change: dict[str, Any]) -> None:
    """With ``c_a > 0`` the closed form includes ``c_a V0``; with a hook spring moving at
    ``V0`` the applied force stays ``W0``: both runs stay on steady drilling."""
    p = dataclasses.replace(RGD_A, **change)
    v0 = steady_state(p, 20.0, 60e3).rate_of_penetration_m_s
    if "axial_stiffness_n_m" in change:
        p = dataclasses.replace(p, hook_speed_m_s=v0)
    s = steady_state(p, 20.0, 60e3)
    trace = simulate(p, 20.0, 60e3, 1.0, initial_bit_speed_rad_s=20.0)
    assert np.max(np.abs(trace.bit_speed_rad_s - 20.0)) < 1e-9
    assert np.max(np.abs(trace.depth_m - s.rate_of_penetration_m_s * trace.time_s)) < 1e-12
    assert np.max(np.abs(trace.weight_on_bit_n - s.weight_on_bit_n)) < 1e-5


def test_a_bit_started_at_rest_is_released_by_the_steady_twist() -> None:
    """``Omega(0) = 0`` with the string twisted for steady drilling: the twist carries
    ``T0 + c_t Omega0``, above what the rock holds (``T0``), so the bit is released at once
    (S2, S3) into HOLD, since ``F_free = W0 - k_a d0 = W_f_bar``."""
    trace = simulate("rgd_a", 4.0, 60e3, 0.5, initial_bit_speed_rad_s=0.0)
    assert trace.regime[0] == 2 and trace.bit_speed_rad_s[1] > 0
