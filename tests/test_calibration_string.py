"""The string above the bit side: the free-running plant with a pipe inertia, the top side
driven by a measured bit speed, and the evidence for a pipe (docs/calibration.md)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drill_env.bit_model import (
    P_A0,
    P_AA,
    P_C,
    P_J,
    P_K,
    P_XI,
    simulate_free_running,
    simulate_top_side,
)
from drill_env.measured_log import MeasuredLog
from experiments.calibration_fit import identify_string

scipy_integrate = pytest.importorskip("scipy.integrate")

# A laboratory-scale string: top drive, pipe, bit (kg m^2, N m/rad, N m s/rad).
J_TOP, D_TOP, J_PIPE, K_1, C_1 = 0.08, 0.002, 0.06, 8.0, 0.004
J_BIT, K, C = 0.02, 1.5, 0.01
KP, KI, REF = 0.6, 1.5, 3.0


def _bit_params(static: float, sliding: float, stribeck: float = 1.0) -> np.ndarray:
    p = np.zeros(8)
    p[P_J], p[P_K], p[P_C], p[P_AA], p[P_A0] = J_BIT, K, C, static, sliding
    p[P_XI] = stribeck
    return p


def test_free_running_with_a_pipe_matches_a_tight_scipy_integration() -> None:
    """A slipping bit under a constant friction torque makes the 3-inertia loop linear:
    the compiled kernel against scipy's tight integration of the same equations."""
    friction = 1.0
    p = _bit_params(friction, friction)
    t = np.linspace(0.0, 3.0, 301)
    twist0 = friction / K  # the bit-side spring at the friction torque
    integral0 = friction / KI

    def rhs(_: float, y: list[float]) -> list[float]:  # upper, lower twist, speeds, integral
        twist_1, twist, wt, wp, wb, integral = y
        u = KP * (REF - wt) + KI * integral
        t_1 = K_1 * twist_1 + C_1 * (wt - wp)
        t_e = K * twist + C * (wp - wb)
        return [
            wt - wp, wp - wb, (u - D_TOP * wt - t_1) / J_TOP, (t_1 - t_e) / J_PIPE,
            (t_e - friction) / J_BIT, REF - wt,
        ]  # fmt: skip

    # The kernel starts the pipe at the top speed with its spring at the lower one's torque.
    twist_1 = (K * twist0 + C * (3.3 - 3.0)) / K_1
    ref0 = scipy_integrate.solve_ivp(
        rhs, (0, 3), [twist_1, twist0, 3.3, 3.3, 3.0, integral0], t_eval=t, rtol=1e-10,
        atol=1e-12,
    )  # fmt: skip
    top, bit, torque, surface = simulate_free_running(
        t, p, "karnopp", np.array([J_TOP, KP, KI, REF]), twist0, 3.3, 3.0, integral0,
        substeps=400, string=np.array([D_TOP, J_PIPE, K_1, C_1]),
    )  # fmt: skip
    assert np.all(ref0.y[4] > 0.5)  # the bit slips throughout: the loop is linear
    assert np.max(np.abs(top - ref0.y[2])) < 2e-3
    assert np.max(np.abs(bit - ref0.y[4])) < 2e-3
    assert np.allclose(torque, friction)
    u = KP * (REF - ref0.y[2]) + KI * ref0.y[5]
    assert np.max(np.abs(surface - u)) < 2e-3


def test_a_stiff_light_pipe_is_the_one_inertia_plant() -> None:
    """A pipe of negligible inertia on a very stiff spring changes nothing."""
    p = _bit_params(1.3, 0.9)
    t = np.arange(0.0, 4.0, 1e-3)
    top_drive = np.array([J_TOP, KP, KI, REF])
    one = simulate_free_running(t, p, "karnopp", top_drive, 0.5, 3.0, 0.0, 0.5)
    piped = simulate_free_running(
        t, p, "karnopp", top_drive, 0.5, 3.0, 0.0, 0.5, string=np.array([0.0, 1e-6, 1e4, 0.0])
    )
    assert np.std(one[1]) > 0.5  # it stick-slips
    assert np.max(np.abs(piped[1][:1500] - one[1][:1500])) < 0.05 * np.ptp(one[1])


def test_top_side_matches_a_tight_scipy_integration() -> None:
    """The top drive under its PI loop with a pipe, driven by a sampled bit speed."""
    t = np.arange(0.0, 4.0, 1e-3)
    bit = 3.0 + 2.0 * np.sin(2 * math.pi * 1.2 * t)
    x = np.array([J_TOP, D_TOP, K, C, J_PIPE, K_1, C_1, KP, KI, REF])
    state0 = (0.6, 3.0, 0.3, 3.0, 0.4)

    def rhs(time: float, y: list[float]) -> list[float]:
        twist, wp, twist_1, wt, integral = y
        wb = float(np.interp(time, t, bit))
        u = KP * (REF - wt) + KI * integral
        t_1 = K_1 * twist_1 + C_1 * (wt - wp)
        t_e = K * twist + C * (wp - wb)
        return [wp - wb, (t_1 - t_e) / J_PIPE, wt - wp, (u - D_TOP * wt - t_1) / J_TOP, REF - wt]

    ref = scipy_integrate.solve_ivp(rhs, (0, 4), list(state0), t_eval=t, rtol=1e-10, atol=1e-12,
                                    max_step=5e-4)  # fmt: skip
    top, surface = simulate_top_side(t, bit, x, state0, 50)
    assert np.max(np.abs(top - ref.y[3])) < 5e-3 * np.ptp(ref.y[3])
    u = KP * (REF - ref.y[3]) + KI * ref.y[4]
    assert np.max(np.abs(surface - u)) < 5e-3 * np.ptp(u)


def _log(pipe: bool, seed: int) -> MeasuredLog:
    """A stick-slip log of the free-running plant, with or without the pipe, and noise."""
    p = _bit_params(1.3, 0.9)
    t = np.arange(0.0, 8.0, 1e-3)
    string = np.array([D_TOP, J_PIPE, K_1, C_1]) if pipe else np.array([D_TOP, 0, 0, 0])
    top, bit, torque, surface = simulate_free_running(
        t, p, "karnopp", np.array([J_TOP, KP, KI, REF]), 0.5, 3.0, 0.0, 0.5, string=string
    )
    rng = np.random.default_rng(seed)
    noisy = {
        "top_speed_rad_s": top + rng.normal(0, 0.01, t.size),
        "bit_speed_rad_s": bit + rng.normal(0, 0.02, t.size),
        "bit_torque_nm": torque + rng.normal(0, 0.01, t.size),
        "surface_torque_nm": surface + rng.normal(0, 0.01, t.size),
    }
    return MeasuredLog(t, noisy).window(4.0, 7.99)


@pytest.mark.parametrize("seed", [3, 11])
def test_the_pipe_is_found_where_it_is_and_not_where_it_is_not(seed: int) -> None:
    """On a log of the plant with a pipe the evidence picks the pipe and its inertia and
    stiffness come back within 10 %; on a log without one it keeps one inertia."""
    loop = (KP, KI, REF)
    with_pipe = identify_string(_log(True, seed), (K, C), loop, J_TOP + J_PIPE)
    assert with_pipe.chosen == "pipe", with_pipe.reason
    values = with_pipe.models["pipe"].values
    assert values["pipe_inertia_kg_m2"] == pytest.approx(J_PIPE, rel=0.1)
    assert values["pipe_stiffness_nm_rad"] == pytest.approx(K_1, rel=0.1)
    assert values["top_inertia_kg_m2"] == pytest.approx(J_TOP, rel=0.1)
    without = identify_string(_log(False, seed), (K, C), loop, J_TOP)
    assert without.chosen == "one_inertia"
    assert without.models["one_inertia"].values["top_inertia_kg_m2"] == pytest.approx(
        J_TOP, rel=0.05
    )
