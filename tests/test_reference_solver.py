"""Checks of the scipy reference itself (tests/reference_solver.py) against closed forms.

Nothing here touches drill_env: these tests make sure the reference that drill_env is later
compared with is right, from the docs/specification.md section 1 equations, closed-form equilibria, a matrix
exponential and an energy balance.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.integrate import trapezoid
from scipy.linalg import expm

from reference_solver import (
    NAVARRO_LOPEZ2007,
    PARAMETER_NAMES,
    ZRIBI2024,
    reference_segments,
    reference_trajectory,
    string_torque,
)

WOB_N = 97_347.0  # docs/specification.md section 2
V_REF = 12.0  # rad/s, docs/specification.md section 2
U_OPEN_LOOP = 10_000.0  # N m, docs/specification.md section 1 open-loop stick-slip case


def friction_levels(p: dict[str, float], wob_n: float) -> tuple[float, float]:
    """(T_a, T_0) in N m."""
    return p["mu_a"] * wob_n * p["R"], p["mu_0"] * wob_n * p["R"]


def grid(t_end_s: float, dt_s: float) -> np.ndarray:
    n = round(t_end_s / dt_s)
    return np.linspace(0.0, t_end_s, n + 1)


@pytest.mark.parametrize(
    ("p", "expected"),
    [
        pytest.param(
            ZRIBI2024,
            dict(J_dt=930, J_pi=2782.25, J_co=750, J_bi=471.96, c_dt=425, c_pi=193.61,
                 c_co=190, c_bi=181.49, c_bit=50, k_pi=698.06, k_co=1080, k_bi=907.48,
                 R=0.15, mu_a=0.8, mu_0=0.5, xi=0.5, Dw=1e-3),
            id="zribi2024",
        ),
        pytest.param(
            NAVARRO_LOPEZ2007,
            dict(J_dt=930, J_pi=2782.25, J_co=750, J_bi=471.9698, c_dt=425, c_pi=139.6126,
                 c_co=190, c_bi=181.49, c_bit=50, k_pi=698.063, k_co=1080, k_bi=907.48,
                 R=0.155575, mu_a=0.8, mu_0=0.5, xi=0.9, Dw=1e-6),
            id="navarro_lopez2007",
        ),
    ],
)  # fmt: skip
def test_presets_match_spec_table(p: dict[str, float], expected: dict[str, float]) -> None:
    assert tuple(p) == PARAMETER_NAMES
    assert p == pytest.approx(expected, rel=0, abs=0)


def test_torque_below_break_away_stays_stuck_and_reaches_static_equilibrium() -> None:
    p = ZRIBI2024
    t_a, _ = friction_levels(p, WOB_N)
    u = 0.5 * t_a
    t = np.concatenate([grid(20.0, 1e-3), [100.0, 200.0, 300.0]])
    x = reference_trajectory(p, u, WOB_N, 300.0, t)

    assert np.all(np.isfinite(x))
    assert np.all(x[:, 6] == 0.0)  # exactly at rest the whole time
    # The step response overshoots, but the string torque never reaches break-away.
    t_e = string_torque(p, x)
    assert t_e.max() > 1.2 * u
    assert np.abs(t_e).max() < t_a
    # With the bit stuck the string is a damped linear spring: every speed dies out and each
    # section carries the applied torque, x2 = u / k_pi, x4 = u / k_co, x6 = u / k_bi.
    expected = np.array([0.0, u / p["k_pi"], 0.0, u / p["k_co"], 0.0, u / p["k_bi"], 0.0])
    np.testing.assert_allclose(x[-1], expected, rtol=1e-6, atol=1e-6)


def test_stuck_phase_matches_matrix_exponential_until_break_away() -> None:
    """Before the first break-away the plant is linear (x7 = 0): x(t) = expm(A t) x(0) + ...."""
    p = ZRIBI2024
    t_a, _ = friction_levels(p, WOB_N)
    j_dt, j_pi, j_co = p["J_dt"], p["J_pi"], p["J_co"]
    c_dt, c_pi, c_co, c_bi = p["c_dt"], p["c_pi"], p["c_co"], p["c_bi"]
    k_pi, k_co, k_bi = p["k_pi"], p["k_co"], p["k_bi"]
    # Reduced state (x1..x6) with x7 = 0, affine in the constant input u.
    a = np.array(
        [
            [-(c_dt + c_pi) / j_dt, -k_pi / j_dt, c_pi / j_dt, 0, 0, 0],
            [1, 0, -1, 0, 0, 0],
            [c_pi / j_pi, k_pi / j_pi, -(c_pi + c_co) / j_pi, -k_co / j_pi, c_co / j_pi, 0],
            [0, 0, 1, 0, -1, 0],
            [0, 0, c_co / j_co, k_co / j_co, -(c_co + c_bi) / j_co, -k_bi / j_co],
            [0, 0, 0, 0, 1, 0],
        ],
        dtype=float,
    )
    b = np.array([1 / j_dt, 0, 0, 0, 0, 0])
    # Augment with the input so that expm gives the forced response exactly.
    m = np.zeros((7, 7))
    m[:6, :6] = a
    m[:6, 6] = b * U_OPEN_LOOP
    z0 = np.zeros(7)
    z0[6] = 1.0

    t = grid(5.7, 1e-2)  # break-away of the open-loop case is at about 5.78 s
    x = reference_trajectory(p, U_OPEN_LOOP, WOB_N, 5.7, t)
    closed = np.array([(expm(m * ti) @ z0)[:6] for ti in t])

    assert np.all(x[:, 6] == 0.0)
    np.testing.assert_allclose(x[:, :6], closed, rtol=0, atol=1e-7)

    # The first break-away happens where the closed-form string torque first reaches T_a.
    fine = np.linspace(5.0, 7.0, 20_001)
    t_e = np.array([c_bi * z[4] + k_bi * z[5] for z in (expm(m * ti) @ z0 for ti in fine)])
    t_break = fine[np.argmax(t_e >= t_a)]
    x_break = reference_trajectory(p, U_OPEN_LOOP, WOB_N, 7.0, fine)
    first_slip = fine[np.argmax(x_break[:, 6] != 0.0)]
    assert abs(first_slip - t_break) <= 2e-4


def test_steady_rotation_matches_closed_form_torque() -> None:
    """docs/specification.md section 2: u = (c_dt + c_bit) V + T_0 + (T_a - T_0) exp(-xi V) holds V = 12 rad/s."""
    p = ZRIBI2024
    t_a, t_0 = friction_levels(p, WOB_N)
    u_closed = (p["c_dt"] + p["c_bit"]) * V_REF + t_0 + (t_a - t_0) * np.exp(-p["xi"] * V_REF)
    assert u_closed == pytest.approx(13_011.9, abs=0.1)

    u = 13_011.9
    x = reference_trajectory(p, u, WOB_N, 300.0, np.array([250.0, 300.0]))
    assert abs(x[-1, 6] - V_REF) < 0.05
    # Steady rotation: every inertia turns at the bit speed, every section carries u - c_dt V.
    v = x[-1, 6]
    np.testing.assert_allclose(x[-1, [0, 2, 4]], v, atol=1e-6)
    carried = u - p["c_dt"] * v
    twists = np.array([carried / p["k_pi"], carried / p["k_co"], carried / p["k_bi"]])
    np.testing.assert_allclose(x[-1, [1, 3, 5]], twists, rtol=1e-6)
    np.testing.assert_allclose(x[-2], x[-1], atol=1e-6)  # settled, not passing through


def stick_onsets(t: np.ndarray, x7: np.ndarray) -> np.ndarray:
    """Times at which the bit speed becomes exactly 0 after having been nonzero."""
    onset = (x7[1:] == 0.0) & (x7[:-1] != 0.0)
    return t[1:][onset]


def test_open_loop_case_sticks_and_slips_with_period_of_about_7_s() -> None:
    """docs/specification.md section 1: u = 10,000 N m, WOB = 97,347 N, from rest, 30 s."""
    p = ZRIBI2024
    t = grid(30.0, 1e-3)
    x = reference_trajectory(p, U_OPEN_LOOP, WOB_N, 30.0, t)
    x7 = x[:, 6]

    assert np.all(np.isfinite(x))
    assert x7.max() > 1.0
    assert x7.min() >= 0.0  # no backward spinning in this case
    onsets = stick_onsets(t, x7)
    assert onsets.size >= 2, onsets
    periods = np.diff(onsets)
    assert np.all((periods > 5.0) & (periods < 9.0)), periods
    # While stuck the bit is held exactly and the string torque stays within the static limit.
    t_a, _ = friction_levels(p, WOB_N)
    stuck = x7 == 0.0
    assert np.all(np.abs(string_torque(p, x[stuck])) <= t_a * (1 + 1e-9))


def test_open_loop_energy_balance() -> None:
    """Work of u = change of kinetic + elastic energy + viscous and friction losses."""
    p = ZRIBI2024
    t_a, t_0 = friction_levels(p, WOB_N)
    t = grid(30.0, 1e-4)
    x = reference_trajectory(p, U_OPEN_LOOP, WOB_N, 30.0, t)
    x1, x2, x3, x4, x5, x6, x7 = x.T
    assert np.any(x7 == 0.0) and x7.max() > 1.0  # the run contains both stick and slip

    kinetic = 0.5 * (p["J_dt"] * x1**2 + p["J_pi"] * x3**2 + p["J_co"] * x5**2 + p["J_bi"] * x7**2)
    elastic = 0.5 * (p["k_pi"] * x2**2 + p["k_co"] * x4**2 + p["k_bi"] * x6**2)
    energy = kinetic + elastic
    viscous = (
        p["c_dt"] * x1**2
        + p["c_pi"] * (x1 - x3) ** 2
        + p["c_co"] * (x3 - x5) ** 2
        + p["c_bi"] * (x5 - x7) ** 2
        + p["c_bit"] * x7**2
    )
    # Slip friction T_bit x7 = |x7| [T_0 + (T_a - T_0) exp(-xi |x7|)]; zero while stuck.
    friction = np.abs(x7) * (t_0 + (t_a - t_0) * np.exp(-p["xi"] * np.abs(x7)))

    work_in = trapezoid(U_OPEN_LOOP * x1, t)
    dissipated = trapezoid(viscous + friction, t)
    stored = energy[-1] - energy[0]
    assert work_in > 1e5  # J, a substantial run
    assert trapezoid(friction, t) > 0.1 * work_in  # friction matters in this balance
    # The reference closes the balance to about 1e-11; 1e-6 leaves room for the quadrature.
    assert abs(work_in - (stored + dissipated)) <= 1e-6 * work_in


def test_negative_torque_mirrors_the_trajectory() -> None:
    """The plant is odd in (x, u): a negative torque gives the mirrored run (backward slip)."""
    t = grid(30.0, 1e-2)
    forward = reference_trajectory(ZRIBI2024, U_OPEN_LOOP, WOB_N, 30.0, t)
    backward = reference_trajectory(ZRIBI2024, -U_OPEN_LOOP, WOB_N, 30.0, t)
    np.testing.assert_allclose(backward, -forward, rtol=0, atol=1e-9)
    modes = [s.mode for s in reference_segments(ZRIBI2024, -U_OPEN_LOOP, WOB_N, 30.0)]
    assert modes == ["stuck", "slip-"] * 4


def test_tighter_tolerances_agree() -> None:
    """The reference has converged: tightening rtol/atol by 100 changes the bit speed little."""
    t = grid(30.0, 1e-2)
    loose = reference_trajectory(ZRIBI2024, U_OPEN_LOOP, WOB_N, 30.0, t)
    tight = reference_trajectory(ZRIBI2024, U_OPEN_LOOP, WOB_N, 30.0, t, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(loose, tight, rtol=0, atol=1e-6)


def test_navarro_lopez_preset_runs() -> None:
    p = NAVARRO_LOPEZ2007
    t = grid(30.0, 1e-2)
    x = reference_trajectory(p, U_OPEN_LOOP, WOB_N, 30.0, t)
    assert np.all(np.isfinite(x))
    assert x[:, 6].max() > 1.0


def test_segments_alternate_and_t_eval_at_an_event_gets_the_post_event_state() -> None:
    p = ZRIBI2024
    t_a, _ = friction_levels(p, WOB_N)
    segments = reference_segments(p, U_OPEN_LOOP, WOB_N, 30.0)
    assert [s.mode for s in segments] == ["stuck", "slip+"] * 4
    assert segments[0].t_start_s == 0.0 and segments[-1].t_stop_s == 30.0
    for before, after in itertools.pairwise(segments):
        assert before.t_stop_s == after.t_start_s
        assert after.t_start_s - before.t_start_s > 1.0

    # At a break-away the string torque has reached T_a; at a stick the bit speed is back to 0.
    for seg in segments[:-1]:
        x_end = seg.solution(np.array([seg.t_stop_s]))[:, 0]
        if seg.mode == "stuck":
            assert string_torque(p, x_end) == pytest.approx(t_a, rel=1e-9)
        else:
            assert abs(x_end[6]) < 1e-9

    # Sample exactly at the event times: the bit speed there is exactly 0 (post-event state),
    # and the state is continuous across the event.
    t_events = np.array([s.t_stop_s for s in segments[:-1]])
    t = np.sort(np.concatenate([[0.0, 0.0, 30.0], t_events, t_events - 1e-6, t_events + 1e-6]))
    x = reference_trajectory(p, U_OPEN_LOOP, WOB_N, 30.0, t)
    np.testing.assert_array_equal(x[:2], np.zeros((2, 7)))
    at_event = np.isin(t, t_events)
    assert np.all(x[at_event, 6] == 0.0)
    i = np.flatnonzero(at_event)
    np.testing.assert_allclose(x[i - 1], x[i], atol=1e-4)
    np.testing.assert_allclose(x[i + 1], x[i], atol=1e-4)
    assert reference_trajectory(p, U_OPEN_LOOP, WOB_N, 1.0, np.array([])).shape == (0, 7)


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        pytest.param({"wob_n": 0.0}, ValueError, "wob_n=0.0", id="wob"),
        pytest.param({"t_end_s": -1.0}, ValueError, "t_end_s=-1.0", id="t_end"),
        pytest.param({"t_eval_s": np.array([2.0, 1.0])}, ValueError, "non-decreasing", id="order"),
        pytest.param({"t_eval_s": np.array([0.0, 11.0])}, ValueError, "within", id="range"),
        pytest.param({"p": {**ZRIBI2024, "k_xx": 1.0}}, KeyError, "unknown", id="unknown-key"),
        pytest.param({"p": {**ZRIBI2024, "J_bi": 0.0}}, ValueError, "J_bi=0.0", id="zero-inertia"),
    ],
)
def test_bad_input_is_rejected(kwargs: dict, error: type[Exception], match: str) -> None:
    args = {
        "p": ZRIBI2024,
        "torque_nm": U_OPEN_LOOP,
        "wob_n": WOB_N,
        "t_end_s": 10.0,
        "t_eval_s": np.array([0.0, 1.0]),
        **kwargs,
    }
    with pytest.raises(error, match=match):
        reference_trajectory(**args)
