"""Tests of the compiled chain (drill_env.chain) against independent references.

References: the absolute-angle scipy solver of ``tests/reference_chain.py`` (events located by
``solve_ivp``), the 4-DOF event-located integrator, closed forms written here (steady drilling),
the energy balance, and the step-halving order of RK4. Nothing is compared with a stored copy of
the package's own output.

Print the measured accuracy figures with::

    .venv/bin/python -m pytest tests/test_chain.py -k "accuracy or energy" -s -q
"""

from __future__ import annotations

import dataclasses
import math
from functools import cache

import numpy as np
import numpy.typing as npt
import pytest

from drill_env.chain import (
    CHAIN_WORK_ROWS,
    chain_integrate_constant_torque,
    chain_parameter_length,
    chain_parameter_vector,
    chain_state_derivative,
    chain_step,
    chain_work,
    stack_chain_parameters,
    steady_drilling_state,
    steady_drilling_torque_nm,
)
from drill_env.distributed import DISTRIBUTED_PRESETS, discretize
from drill_env.dynamics import state_derivative
from drill_env.friction import STUCK
from drill_env.integration import integrate_constant_torque, plant_step
from drill_env.parameters import PRESETS, plant_parameter_vector
from reference_chain import DEEP_5000M, FIELD_2500M, ReferenceString, reference_chain_trajectory

FloatArray = npt.NDArray[np.float64]
PLANT_DT = 1e-3
REQUIREMENT_RAD_S = 1e-2
GOAL_RAD_S = 1e-3

# The open-loop stick-slip case of field_2500m: constant 9,500 N m at 100 kN WOB, from rest.
# T_a = 0.8 * 100e3 * 0.108 = 8,640 N m; the bit sticks and slips with a period of about 5 s.
WOB_N = 100e3
TORQUE_NM = 9_500.0
T_END_S = 30.0

REFERENCES: dict[str, ReferenceString] = {"field_2500m": FIELD_2500M, "deep_5000m": DEEP_5000M}


@cache
def _errors(name: str, torque_nm: float, wob_n: float, t_end_s: float) -> tuple[
    FloatArray, npt.NDArray[np.int64], FloatArray, list[tuple[float, str]]
]:  # fmt: skip
    """(package states, package modes, reference states, reference segments) at every 1 ms."""
    states, modes = chain_integrate_constant_torque(name, torque_nm, wob_n, t_end_s)
    t = np.arange(states.shape[0]) * PLANT_DT
    ref, segments = reference_chain_trajectory(REFERENCES[name], torque_nm, wob_n, t_end_s, t)
    return states, modes, ref, segments


# ------------------------------------------------------------------------- parameter vector
def test_parameter_vector_layout_by_hand() -> None:
    """Header (n, mu_a, mu_0, R, xi, Dw), then 1/J, d, k, c, for the 4-DOF chain."""
    q = PRESETS["zribi2024"]
    p = chain_parameter_vector(q)
    expected = [4, q.mu_a, q.mu_0, q.R, q.xi, q.Dw,
                1 / q.J_dt, 1 / q.J_pi, 1 / q.J_co, 1 / q.J_bi,
                q.c_dt, 0.0, 0.0, q.c_bit,
                q.k_pi, q.k_co, q.k_bi,
                q.c_pi, q.c_co, q.c_bi]  # fmt: skip
    np.testing.assert_array_equal(p, expected)
    assert chain_parameter_length(4) == len(expected) == 4 * 4 + 4


def test_parameter_vectors_pad_and_stack() -> None:
    """Zero padding to a common width; each row keeps its own n in p[0]."""
    stacked = stack_chain_parameters(["field_2500m", "zribi2024", "deep_5000m"])
    n_field, n_deep = discretize("field_2500m").n_nodes, discretize("deep_5000m").n_nodes
    assert stacked.shape == (3, chain_parameter_length(n_deep))
    assert list(stacked[:, 0]) == [n_field, 4, n_deep]
    np.testing.assert_array_equal(stacked[1, :20], chain_parameter_vector("zribi2024"))
    assert np.all(stacked[1, 20:] == 0.0)
    padded = chain_parameter_vector("field_2500m", length=1000)
    assert padded.shape == (1000,)
    np.testing.assert_array_equal(padded[: chain_parameter_length(n_field)],
                                  chain_parameter_vector("field_2500m"))  # fmt: skip


def test_parameter_vector_too_short_is_rejected() -> None:
    """A length below 4 n + 4 is an error naming ``length``."""
    with pytest.raises(ValueError, match=r"length = 10 is out of range: allowed >= 20 for n = 4"):
        chain_parameter_vector("zribi2024", length=10)


# ----------------------------------------------------------------- the 4-DOF case (n = 4)
def test_n4_chain_reproduces_the_four_dof_integrator() -> None:
    """The 4-DOF plant run as a chain matches drill_env.integration step for step (the open-loop
    case of docs/specification.md section 1, 10 kN m at 97,347 N, which sticks and slips)."""
    s4, m4 = integrate_constant_torque(PRESETS["zribi2024"], 10_000.0, 97_347.0, 30.0)
    sc, mc = chain_integrate_constant_torque("zribi2024", 10_000.0, 97_347.0, 30.0)
    assert np.count_nonzero(np.diff(m4)) >= 6
    np.testing.assert_array_equal(m4, mc)
    np.testing.assert_allclose(sc, s4, rtol=0, atol=1e-9)


def test_n4_derivative_matches_the_four_dof_derivative() -> None:
    """``chain_state_derivative`` of the n = 4 chain equals drill_env.dynamics'."""
    x = np.array([3.0, 1.2, 2.5, 0.4, 2.0, 0.7, 1.5])
    for stuck in (False, True):
        xs = x.copy()
        if stuck:
            xs[-1] = 0.0
        got = chain_state_derivative(xs, 12_000.0, PRESETS["zribi2024"], 97_347.0, stuck)
        want = state_derivative(xs, 12_000.0, PRESETS["zribi2024"], 97_347.0, stuck)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)


def test_chain_step_single_steps_match_plant_step() -> None:
    """One chain_step from stuck, slipping and stopping states equals one 4-DOF plant_step."""
    q = PRESETS["zribi2024"]
    p4, pc = plant_parameter_vector(q), chain_parameter_vector(q)
    t_a, t_0 = q.static_torque_nm(97_347.0), q.sliding_torque_nm(97_347.0)
    work = chain_work(4)
    for x0, mode in (
        ((1.0, 14.0, 1.0, 0.5, 1.0, 0.4, 0.0), STUCK),  # breaks away (T_e > T_a)
        ((5.0, 10.0, 4.0, 2.0, 3.0, 1.0, 0.002), 1),  # comes to rest inside the step
        ((5.0, 12.0, 5.0, 3.0, 5.0, 4.0, 5.0), 1),
    ):
        want, want_mode = plant_step(x0, mode, 11_000.0, p4, t_a, t_0, PLANT_DT)
        x = np.array(x0)
        got_mode = chain_step(x, mode, 11_000.0, pc, t_a, t_0, PLANT_DT, work)
        assert got_mode == want_mode
        np.testing.assert_allclose(x, want, rtol=0, atol=1e-12)


def test_padding_of_state_and_work_is_ignored() -> None:
    """A longer state array, a wider scratch array and a padded parameter row give the same
    step, and the entries beyond 2 n - 1 are not touched."""
    p = chain_parameter_vector("field_2500m")
    n = int(p[0])
    ch = discretize("field_2500m")
    t_a, t_0 = ch.static_torque_nm(WOB_N), ch.sliding_torque_nm(WOB_N)
    x0, _ = steady_drilling_state("field_2500m", WOB_N, 3.0)
    a = x0.copy()
    mode_a = chain_step(a, 1, TORQUE_NM, p, t_a, t_0, PLANT_DT, chain_work(n))
    b = np.full(2 * n + 50, -7.0)
    b[: 2 * n - 1] = x0
    big = stack_chain_parameters(["deep_5000m", "field_2500m"])
    mode_b = chain_step(b, 1, TORQUE_NM, big[1], t_a, t_0, PLANT_DT, chain_work(3 * n))
    assert mode_a == mode_b
    np.testing.assert_array_equal(a, b[: 2 * n - 1])
    assert np.all(b[2 * n - 1 :] == -7.0)
    assert chain_work(10).shape == (CHAIN_WORK_ROWS, 10)


# -------------------------------------------------------------------------------- accuracy
def test_open_loop_case_sticks_and_slips() -> None:
    """The accuracy case is a real stick-slip run, and both solvers see the same events."""
    _, modes, _, segments = _errors("field_2500m", TORQUE_NM, WOB_N, T_END_S)
    names = [mode for _, mode in segments]
    assert names.count("stuck") >= 4
    assert names.count("slip+") >= 4
    assert int(np.count_nonzero(np.diff(modes))) == len(segments) - 1


def test_accuracy_bit_speed_against_scipy_reference() -> None:
    """Bit speed within 1e-3 rad/s (the goal; 1e-2 required) of the reference at every 1 ms."""
    states, _, ref, _ = _errors("field_2500m", TORQUE_NM, WOB_N, T_END_S)
    err = np.abs(states[:, -1] - ref[:, -1])
    worst = float(err.max())
    at = float(np.argmax(err) * PLANT_DT)
    print(f"\n[accuracy] field_2500m, {TORQUE_NM:.0f} N m, {WOB_N:.0f} N: "
          f"max |bit speed error| = {worst:.2e} rad/s at t = {at:.3f} s")  # fmt: skip
    assert worst <= REQUIREMENT_RAD_S
    assert worst <= GOAL_RAD_S


def test_accuracy_all_states_against_scipy_reference() -> None:
    """Every node speed and element twist follows the reference at every 1 ms."""
    states, _, ref, _ = _errors("field_2500m", TORQUE_NM, WOB_N, T_END_S)
    worst_speed = float(np.abs(states[:, 0::2] - ref[:, 0::2]).max())
    worst_twist = float(np.abs(states[:, 1::2] - ref[:, 1::2]).max())
    print(f"\n[accuracy] field_2500m: max |speed error| {worst_speed:.2e} rad/s, "
          f"max |twist error| {worst_twist:.2e} rad")  # fmt: skip
    assert worst_speed <= GOAL_RAD_S
    assert worst_twist <= 1e-4  # twists reach 0.1 rad per element


def test_stuck_intervals_are_exactly_at_rest() -> None:
    """Where the reference bit is stuck (interior of its stuck intervals), the package's bit
    speed is exactly 0.0 and its mode STUCK."""
    states, modes, ref, _ = _errors("field_2500m", TORQUE_NM, WOB_N, T_END_S)
    stuck = ref[:, -1] == 0.0
    interior = stuck.copy()
    interior[1:] &= stuck[:-1]
    interior[:-1] &= stuck[1:]
    assert interior.sum() > 5000
    assert np.all(states[interior, -1] == 0.0)
    assert np.all(modes[interior] == STUCK)


@pytest.mark.parametrize(
    ("name", "torque_nm", "wob_n", "bound"),
    [
        # The bit stops one step early inside the Karnopp band (|w| < Dw = 1e-3 rad/s): the
        # error is then below Dw by construction.
        pytest.param("field_2500m", 5_200.0, 60e3, GOAL_RAD_S, id="field-60kN"),
        pytest.param("field_2500m", 13_000.0, 150e3, GOAL_RAD_S, id="field-150kN"),
        pytest.param("field_2500m", 20_000.0, 100e3, GOAL_RAD_S, id="field-breaks-free"),
    ],
)
def test_accuracy_other_open_loop_cases(
    name: str, torque_nm: float, wob_n: float, bound: float
) -> None:
    """Other torques and WOBs meet the goal as well (not tuned to one case)."""
    states, _, ref, segments = _errors(name, torque_nm, wob_n, 20.0)
    assert len(segments) >= 2
    worst = float(np.abs(states[:, -1] - ref[:, -1]).max())
    print(f"\n[accuracy] {name}, {torque_nm:.0f} N m, {wob_n:.0f} N: {worst:.2e} rad/s")
    assert worst <= bound


def test_accuracy_deep_string() -> None:
    """deep_5000m (203 elements) against the reference, 1.1 T_a at 120 kN."""
    t_a = 0.8 * 120e3 * 0.108
    states, _, ref, segments = _errors("deep_5000m", 1.1 * t_a, 120e3, 30.0)
    assert len(segments) >= 3
    worst = float(np.abs(states[:, -1] - ref[:, -1]).max())
    print(f"\n[accuracy] deep_5000m: {worst:.2e} rad/s")
    assert worst <= GOAL_RAD_S


# --------------------------------------------------------------------------------- sticking
def test_stuck_bit_below_break_away_stays_exactly_at_rest() -> None:
    """Under 0.4 T_a (below half of T_a, so even the undamped overshoot of a step stays below
    T_a) the bit speed is exactly 0.0 and the mode STUCK at every step, while the rest of the
    string turns and winds up."""
    ch = discretize("field_2500m")
    states, modes = chain_integrate_constant_torque(
        "field_2500m", 0.4 * ch.static_torque_nm(WOB_N), WOB_N, 20.0
    )
    assert np.all(states[:, -1] == 0.0)
    assert np.all(modes == STUCK)
    assert states[:, 0].max() > 0.1
    assert states[-1, 1::2].sum() > 1.0  # rad of twist stored in the string


# --------------------------------------------------------------------------- steady drilling
@pytest.mark.parametrize("name", ["field_2500m", "deep_5000m", "zribi2024"])
def test_steady_drilling_torque_closed_form(name: str) -> None:
    """``u = (sum of damping to ground) V + T_0 + (T_a - T_0) exp(-xi V)``, written here."""
    ch = discretize(name) if name in DISTRIBUTED_PRESETS else None
    if ch is None:
        q = PRESETS[name]
        ground = q.c_dt + q.c_bit
        t_a, t_0, xi = q.static_torque_nm(WOB_N), q.sliding_torque_nm(WOB_N), q.xi
    else:
        ground = ch.ground_damping_nm_s_rad
        t_a, t_0, xi = ch.static_torque_nm(WOB_N), ch.sliding_torque_nm(WOB_N), ch.xi
    v = 12.0
    expected = ground * v + t_0 + (t_a - t_0) * math.exp(-xi * v)
    assert steady_drilling_torque_nm(name, WOB_N, v) == pytest.approx(expected, rel=1e-13)
    if name == "zribi2024":  # docs/specification.md section 2: 13,011.9 N m at 97,347 N
        assert steady_drilling_torque_nm(name, 97_347.0, v) == pytest.approx(13_011.9, abs=0.05)


def test_steady_drilling_is_reached_in_a_long_run() -> None:
    """Starting from steady drilling at 12 rad/s, the closed-form torque for 10 rad/s brings
    every node to 10 rad/s and every twist to its closed-form value (200 s run)."""
    x12, _ = steady_drilling_state("field_2500m", WOB_N, 12.0)
    x10, u10 = steady_drilling_state("field_2500m", WOB_N, 10.0)
    states, modes = chain_integrate_constant_torque(
        "field_2500m", u10, WOB_N, 200.0, initial_state=x12, record_every=1000
    )
    assert np.all(modes == 1)
    final = states[-1]
    speed_err = float(np.abs(final[0::2] - 10.0).max())
    twist_err = float(np.abs(final[1::2] - x10[1::2]).max())
    print(f"\n[steady] after 200 s: max |speed - 10| = {speed_err:.1e} rad/s, "
          f"max |twist error| = {twist_err:.1e} rad")  # fmt: skip
    assert speed_err < 1e-3
    assert twist_err < 1e-4
    # The equilibrium itself is a fixed point of the integrator.
    held, _ = chain_integrate_constant_torque(
        "field_2500m", u10, WOB_N, 5.0, initial_state=x10, record_every=5000
    )
    np.testing.assert_allclose(held[-1], x10, rtol=1e-10, atol=1e-12)


# ----------------------------------------------------------------------------- energy balance
def _energy_residual(step_s: float) -> tuple[float, float]:
    """(max |W_in - W_dissipated - dE| over the run, W_in at the end), J, by trapezoids."""
    ch = discretize("field_2500m")
    j, d = ch.node_inertia_kg_m2, ch.node_damping_nm_s_rad
    k, c = ch.element_stiffness_nm_rad, ch.element_damping_nm_s_rad
    t_a, t_0 = ch.static_torque_nm(WOB_N), ch.sliding_torque_nm(WOB_N)
    states, modes = chain_integrate_constant_torque(
        "field_2500m", TORQUE_NM, WOB_N, 20.0, step_s=step_s
    )
    w, twist = states[:, 0::2], states[:, 1::2]
    w_bit = w[:, -1]
    t_bit = np.where(
        modes == STUCK, 0.0, modes * (t_0 + (t_a - t_0) * np.exp(-ch.xi * np.abs(w_bit)))
    )
    power_in = TORQUE_NM * w[:, 0]
    power_lost = (d * w**2).sum(1) + (c * (w[:, :-1] - w[:, 1:]) ** 2).sum(1) + t_bit * w_bit
    energy = 0.5 * (j * w**2).sum(1) + 0.5 * (k * twist**2).sum(1)

    def integral(f: FloatArray) -> FloatArray:
        return np.concatenate(([0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * step_s)))

    w_in = integral(power_in)
    residual = w_in - integral(power_lost) - (energy - energy[0])
    assert int(np.count_nonzero(np.diff(modes))) >= 6  # the run sticks and slips
    return float(np.abs(residual).max()), float(w_in[-1])


def test_energy_balance_over_a_stick_slip_run() -> None:
    """Work in by the top drive = dissipated (mud, top drive, Kelvin-Voigt, bit) + change of
    kinetic + potential energy, to 1e-6 of the work in, over 20 s of stick-slip."""
    residual, work_in = _energy_residual(PLANT_DT)
    print(f"\n[energy] work in {work_in:.4e} J, max residual {residual:.2e} J "
          f"({residual / work_in:.1e} of the work in)")  # fmt: skip
    assert residual <= 1e-6 * work_in


# ------------------------------------------------------------------------------- time order
def _final_state(torque_nm: float, step_s: float) -> FloatArray:
    x0, _ = steady_drilling_state("field_2500m", WOB_N, 10.0)
    states, modes = chain_integrate_constant_torque(
        "field_2500m", torque_nm, WOB_N, 2.0, step_s=step_s, initial_state=x0,
        record_every=round(2.0 / step_s),
    )  # fmt: skip
    assert np.all(modes == 1), "the order test needs a window without events"
    return states[-1]


@pytest.mark.parametrize("torque_nm", [20_000.0, 7_000.0], ids=["accelerate", "decelerate"])
def test_fourth_order_in_smooth_slip(torque_nm: float) -> None:
    """Without events the step error falls about 16-fold per halving (classical RK4)."""
    finals = [_final_state(torque_nm, h) for h in (4e-3, 2e-3, 1e-3)]
    ratio = np.abs(finals[0] - finals[1]).max() / np.abs(finals[1] - finals[2]).max()
    assert 12.0 < ratio < 20.0, ratio


# -------------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(wob_n=0.0), r"wob_n = 0.0 is out of range: allowed > 0"),
        (dict(wob_n=math.nan), r"wob_n = nan is out of range"),
        (dict(duration_s=-1.0), r"duration_s = -1.0 is out of range: allowed > 0"),
        (dict(step_s=0.0), r"step_s = 0.0 is out of range: allowed > 0"),
        (dict(torque_nm=math.inf), r"torque_nm = inf is out of range"),
        (dict(initial_state=np.zeros(3)), r"initial_state must have shape \(205,\), got \(3,\)"),
        (dict(record_every=0), r"record_every = 0 is out of range: allowed >= 1"),
    ],
)
def test_bad_input_to_the_open_loop_helper(kwargs: dict[str, object], match: str) -> None:
    """Bad arguments raise ValueError naming the argument."""
    args: dict[str, object] = dict(torque_nm=1e4, wob_n=1e5, duration_s=1.0)
    with pytest.raises(ValueError, match=match):
        chain_integrate_constant_torque("field_2500m", **{**args, **kwargs})  # type: ignore[arg-type]


def test_record_every_keeps_every_kth_state() -> None:
    """Decimated output equals every k-th row of the full output."""
    full, modes = chain_integrate_constant_torque("field_2500m", 9_500.0, WOB_N, 6.0)
    every, modes_every = chain_integrate_constant_torque(
        "field_2500m", 9_500.0, WOB_N, 6.0, record_every=7
    )
    np.testing.assert_array_equal(every, full[::7])
    np.testing.assert_array_equal(modes_every, modes[::7])


def test_elements_change_the_string_not_the_statics() -> None:
    """Coarser elements: a different chain but the same closed-form steady torque."""
    coarse = dataclasses.replace(DISTRIBUTED_PRESETS["field_2500m"], element_length_m=100.0)
    assert discretize(coarse).n_nodes < discretize("field_2500m").n_nodes
    assert steady_drilling_torque_nm(coarse, WOB_N, 8.0) == pytest.approx(
        steady_drilling_torque_nm("field_2500m", WOB_N, 8.0), rel=1e-12
    )


def test_steps_on_the_rows_are_those_of_chain_step_and_refuse_like_it() -> None:
    """``chain_step_rows`` (the kernel's: the state kept in the scratch rows) gives the states
    and modes of ``chain_step`` bit for bit through stick, break-away and stop events, and a
    step beyond the bounds keeps the old state (also when an event moved the start rows)."""
    from drill_env.chain import (
        CHAIN_SPEED_ROW,
        CHAIN_TWIST_ROW,
        chain_load_rows,
        chain_step_rows,
        chain_store_rows,
    )

    chain = discretize(DISTRIBUTED_PRESETS["field_2500m"])
    p = chain_parameter_vector(chain)
    n = int(p[0])
    work = chain_work(n)
    x = np.zeros(2 * n - 1)
    chain_load_rows(x, p, work)
    mode_x = mode_rows = STUCK
    wob = 100_000.0
    t_a, t_0 = chain.static_torque_nm(wob), chain.sliding_torque_nm(wob)
    switches = 0
    state_rows = [CHAIN_SPEED_ROW, CHAIN_TWIST_ROW]
    for k in range(16_000):
        u = 0.0 if 8_000 <= k < 12_000 else 15_000.0  # break away, stop and stick, again
        # Refused (bounds 0: any motion is beyond them): the rows keep the state.
        trial = work.copy()
        mode, accepted = chain_step_rows(mode_rows, u, p, t_a, t_0, PLANT_DT, trial, 0.0, 0.0)
        assert not accepted and mode == mode_rows
        np.testing.assert_array_equal(trial[state_rows], work[state_rows])
        new_x = chain_step(x, mode_x, u, p, t_a, t_0, PLANT_DT, chain_work(n))
        switches += new_x != mode_x
        mode_x = new_x
        mode_rows, accepted = chain_step_rows(mode_rows, u, p, t_a, t_0, PLANT_DT, work, 1e3, 1e3)
        assert accepted and mode_rows == mode_x
    rows = np.zeros_like(x)
    chain_store_rows(work, p, rows)
    np.testing.assert_array_equal(rows, x)
    assert switches >= 3  # break-away, stop and stick happened
