"""The industry baselines (stiff_pi, soft_speed, z_torque): the string's modal quantities, the
tuning formulas, hand-computed law outputs, gains validation, env integration, and the physics
they must show on a small stick-slip map."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from baselines import (
    DriveLimits,
    SoftSpeed,
    SoftSpeedGains,
    StiffPI,
    StiffPIGains,
    ZTorque,
    ZTorqueGains,
    controller_names,
    make_controller,
)
from baselines.base import measurement_vector
from baselines.speed_loop import (
    N_PI_PARAMS,
    N_PI_STATE,
    PI_C_PI,
    PI_J_FF,
    PI_K_PI,
    PI_KI,
    PI_KP,
    PI_TAU,
    PI_U_MAX,
    PI_U_MIN,
    PI_Z,
    PS_ERROR,
    PS_INT,
    PS_T_MEAN,
    speed_loop_law,
    speed_loop_torque,
)
from baselines.string_modes import (
    reflection_coefficient,
    stick_slip_frequency,
    top_drive_impedance,
)
from drill_env.distributed import resolve_plant
from drill_env.evaluation import ZeroAction, rollout
from drill_env.parameters import PRESETS, scale_uncertain
from experiments.stick_slip_map import StickSlipMap, compute_map

INDUSTRY = ("stiff_pi", "soft_speed", "z_torque")
P = PRESETS["zribi2024"]
Z = math.sqrt(P.k_pi * P.J_pi)  # pipe impedance of the default plant, N m s/rad
DT = 1e-3


def quadratic_roots(a: float, b: float, c: float) -> tuple[float, float]:
    d = math.sqrt(b * b - 4 * a * c)
    return (-b - d) / (2 * a), (-b + d) / (2 * a)


# ----------------------------------------------------------------------------------- tuning
def test_stiff_pi_tuning_formulas() -> None:
    t = StiffPI().tuning()
    assert t.kp == pytest.approx(50 * Z)
    assert t.ki == pytest.approx(t.kp**2 / (4 * P.J_dt))
    assert t.z == 0 and t.j_ff == 0
    # The stiff drive reflects almost every wave at the stick-slip frequency.
    w_s = stick_slip_frequency(P)
    r = reflection_coefficient(top_drive_impedance(w_s, t.kp, t.ki, P.J_dt, P.c_dt), Z)
    assert abs(r) > 0.95


def test_soft_speed_tuning_matches_the_pipe_at_the_stick_slip_frequency() -> None:
    t = SoftSpeed().tuning()
    w_s = stick_slip_frequency(P)
    assert t.kp == pytest.approx(Z - P.c_dt)
    assert t.ki == pytest.approx(w_s**2 * P.J_dt)
    assert t.j_ff == P.J_dt
    z_td = top_drive_impedance(w_s, t.kp, t.ki, P.J_dt, P.c_dt)
    assert z_td == pytest.approx(complex(Z, 0.0), abs=1e-9)
    assert abs(reflection_coefficient(z_td, Z)) < 1e-12
    assert SoftSpeed(inertia_compensation=False).tuning().j_ff == 0.0


def test_z_torque_tuning_formulas() -> None:
    t = ZTorque().tuning()
    assert t.z == pytest.approx(Z)
    assert t.tau_mean_s == pytest.approx(2 * math.pi / stick_slip_frequency(P))
    assert (t.k_pi, t.c_pi) == (P.k_pi, P.c_pi)
    assert t.kp == pytest.approx(StiffPI().tuning().kp)


@pytest.mark.parametrize("name", INDUSTRY)
def test_compiled_law_is_derived_from_the_model_it_is_given(name: str) -> None:
    controller = make_controller(name)
    nominal = controller.compiled_law()  # type: ignore[attr-defined]
    uncertain = scale_uncertain(P, (0.0, 0.5, 0.0))  # k_pi x 1.5
    law = controller.compiled_law(uncertain)  # type: ignore[attr-defined]
    assert law.function is speed_loop_law
    assert law.params.shape == (N_PI_PARAMS,) and law.initial_state.shape == (N_PI_STATE,)
    assert not law.initial_state.any()
    z_new = math.sqrt(uncertain.k_pi * uncertain.J_pi)
    if name == "soft_speed":
        assert law.params[PI_KP] == pytest.approx(z_new - P.c_dt)
        assert law.params[PI_KI] == pytest.approx(stick_slip_frequency(uncertain) ** 2 * P.J_dt)
    else:
        assert law.params[PI_KP] == pytest.approx(nominal.params[PI_KP] * math.sqrt(1.5))
    if name == "z_torque":
        assert law.params[PI_Z] == pytest.approx(z_new)
        assert law.params[PI_K_PI] == pytest.approx(uncertain.k_pi)
    assert (law.params[PI_U_MIN], law.params[PI_U_MAX]) == (0.0, 50_000.0)


# ------------------------------------------------------------------ hand-computed law outputs
# A measured state: top drive 10 rad/s, twist 20 rad, pipes 9 rad/s; reference 12 rad/s.
M0 = (10.0, 20.0, 9.0, 5.0, 8.5, 3.0, 8.0)


def speed_law(
    kp: float,
    ki: float,
    j_ff: float = 0.0,
    z: float = 0.0,
    tau: float = 0.0,
    u_min: float = 0.0,
    u_max: float = 50_000.0,
) -> np.ndarray:
    lp = np.zeros(N_PI_PARAMS)
    lp[PI_KP], lp[PI_KI], lp[PI_J_FF], lp[PI_Z] = kp, ki, j_ff, z
    lp[PI_K_PI], lp[PI_C_PI], lp[PI_TAU] = 700.0, 200.0, tau
    lp[PI_U_MIN], lp[PI_U_MAX] = u_min, u_max
    return lp


def test_pi_law_proportional_then_forward_euler_integral() -> None:
    lp, ls = speed_law(kp=1000.0, ki=50.0, u_min=-1e6), np.zeros(N_PI_STATE)
    # First call: integral 0, so u = kp (ref - x1) = 1000 * 2.
    assert speed_loop_torque(lp, ls, measurement_vector(M0), 12.0, DT) == pytest.approx(2000.0)
    assert ls[PS_INT] == pytest.approx(2.0 * DT)  # I += (ref - x1) dt
    assert ls[PS_ERROR] == pytest.approx(-2.0)  # x1 - w_set
    # Second call, top drive now above the reference: u = kp (-1) + ki * 2 dt.
    m1 = (13.0, *M0[1:])
    u = speed_loop_torque(lp, ls, measurement_vector(m1), 12.0, DT)
    assert u == pytest.approx(-1000.0 + 50.0 * 2.0 * DT)
    assert ls[PS_INT] == pytest.approx(2.0 * DT - 1.0 * DT)


def test_pi_law_sign_follows_the_speed_error() -> None:
    lp = speed_law(kp=500.0, ki=0.0)
    slow: float = speed_loop_torque(lp, np.zeros(N_PI_STATE), measurement_vector(M0), 12.0, DT)
    fast: float = speed_loop_torque(lp, np.zeros(N_PI_STATE), measurement_vector(M0), 8.0, DT)
    assert slow > 0 > fast


def test_set_point_feed_forward_uses_the_reference_change() -> None:
    lp, ls = speed_law(kp=1000.0, ki=0.0, j_ff=930.0), np.zeros(N_PI_STATE)
    # No feed-forward at the first call (no previous set-point), whatever the reference.
    assert speed_loop_torque(lp, ls, measurement_vector(M0), 12.0, DT) == pytest.approx(2000.0)
    # The reference rises by 0.01 rad/s in one step: + J (0.01 / dt).
    u = speed_loop_torque(lp, ls, measurement_vector(M0), 12.01, DT)
    assert u == pytest.approx(1000.0 * 2.01 + 930.0 * 0.01 / DT)


def test_torque_feedback_lowers_the_set_point_when_the_string_torque_rises() -> None:
    lp, ls = speed_law(kp=1000.0, ki=0.0, z=1400.0, tau=10.0), np.zeros(N_PI_STATE)
    t0 = 700.0 * M0[1] + 200.0 * (M0[0] - M0[2])  # k_pi x2 + c_pi (x1 - x3)
    # First call: the mean starts at the torque itself, so w_set = ref.
    assert speed_loop_torque(lp, ls, measurement_vector(M0), 12.0, DT) == pytest.approx(2000.0)
    assert ls[PS_T_MEAN] == pytest.approx(t0)  # the mean stays put when the torque does
    # The twist grows by 1 rad: T rises by 700 N m above its mean, w_set falls by 700 / z.
    m1 = (M0[0], M0[1] + 1.0, *M0[2:])
    u = speed_loop_torque(lp, ls, measurement_vector(m1), 12.0, DT)
    w_set = 12.0 - 700.0 / 1400.0
    assert u == pytest.approx(1000.0 * (w_set - M0[0]))
    assert ls[PS_ERROR] == pytest.approx(M0[0] - w_set)
    assert ls[PS_T_MEAN] == pytest.approx(t0 + 700.0 * DT / 10.0)  # low-pass by forward Euler


def test_integral_stops_while_the_output_is_saturated() -> None:
    lp, ls = speed_law(kp=1e5, ki=10.0, u_max=50_000.0), np.zeros(N_PI_STATE)
    u = speed_loop_torque(lp, ls, measurement_vector(M0), 12.0, DT)
    assert u == pytest.approx(2e5)  # returned unclipped: the env clips
    assert ls[PS_INT] == 0.0
    # Back inside the limits the integral advances again.
    speed_loop_torque(lp, ls, measurement_vector((11.9, *M0[1:])), 12.0, DT)
    assert ls[PS_INT] == pytest.approx(0.1 * DT)
    # Below the lower limit with a negative error it holds too.
    lp[PI_KP] = 1e3
    before = ls[PS_INT]
    assert speed_loop_torque(lp, ls, measurement_vector((13.0, *M0[1:])), 12.0, DT) < 0.0
    assert ls[PS_INT] == before


@pytest.mark.parametrize("name", INDUSTRY)
def test_python_torque_matches_the_compiled_law(name: str) -> None:
    controller = make_controller(name)
    law = controller.compiled_law()  # type: ignore[attr-defined]
    ls = law.initial_state.copy()
    rng = np.random.default_rng(3)
    controller.reset()
    for _ in range(50):
        m = rng.normal(5.0, 3.0, 7)
        ref = float(rng.uniform(1.0, 15.0))
        compiled = law.torque(ls, measurement_vector(m), ref, DT)
        assert controller.torque(m, ref, DT) == compiled
    assert controller.speed_error == ls[PS_ERROR]  # type: ignore[attr-defined]
    controller.reset()
    assert controller.integral == 0.0  # type: ignore[attr-defined]


def test_torque_rejects_a_bad_measurement_shape() -> None:
    with pytest.raises(ValueError, match=r"measurement must have shape \(7,\)"):
        StiffPI().torque(np.zeros(6), 12.0, DT)


# ------------------------------------------------------------------------ gains validation
@pytest.mark.parametrize(
    ("gains_type", "field", "value", "allowed"),
    [
        (StiffPIGains, "bandwidth_factor", 0.0, r"\(0, 10000\]"),
        (StiffPIGains, "damping_ratio", -1.0, r"\(0, 100\]"),
        (SoftSpeedGains, "impedance_factor", 200.0, r"\(0, 100\]"),
        (SoftSpeedGains, "frequency_factor", 0.0, r"\(0, 100\]"),
        (ZTorqueGains, "impedance_factor", -0.5, r"\(0, 100\]"),
        (ZTorqueGains, "mean_periods", 0.0, r"\(0, 1000\]"),
        (ZTorqueGains, "bandwidth_factor", 2e4, r"\(0, 10000\]"),
    ],
)
def test_gains_out_of_range_name_the_field(
    gains_type: type, field: str, value: float, allowed: str
) -> None:
    with pytest.raises(ValueError, match=rf"{gains_type.__name__}\.{field} = .* allowed {allowed}"):
        gains_type(**{field: value})


@pytest.mark.parametrize("gains_type", [StiffPIGains, SoftSpeedGains, ZTorqueGains])
def test_gains_reject_non_numbers(gains_type: type) -> None:
    field = dataclasses.fields(gains_type)[0].name
    with pytest.raises(ValueError, match=rf"{field} must be finite"):
        gains_type(**{field: math.nan})
    with pytest.raises(TypeError, match="limits must be a DriveLimits"):
        gains_type(limits=(0.0, 1.0))


def test_drive_limits_must_not_be_inverted() -> None:
    with pytest.raises(ValueError, match=r"DriveLimits\.u_max_nm = 0.0 is out of range"):
        DriveLimits(u_min_nm=10.0, u_max_nm=0.0)


def test_soft_speed_on_a_pipe_softer_than_the_drive_damping_has_no_proportional_gain() -> None:
    """Where the drive's own damping exceeds the target resistance, kp = 0 is the closest
    match: the drive then presents exactly its damping at the tuning frequency."""
    from baselines.string_modes import string_view

    for model, factor in (("deep_5000m", 1.0), ("zribi2024", 0.2)):
        view = string_view(resolve_plant(model))
        assert factor * view.impedance < view.c_dt
        tuning = SoftSpeed(impedance_factor=factor).tuning(resolve_plant(model))
        assert tuning.kp == 0.0 and tuning.ki > 0.0
        z_td = top_drive_impedance(
            view.stick_slip_rad_s, tuning.kp, tuning.ki, view.J_dt, view.c_dt
        )
        assert z_td == pytest.approx(view.c_dt)
        r = reflection_coefficient(z_td, view.impedance)
        assert r == pytest.approx((view.impedance - view.c_dt) / (view.impedance + view.c_dt))


@pytest.mark.parametrize("name", INDUSTRY)
def test_unknown_gain_and_wrong_gains_type(name: str) -> None:
    with pytest.raises(TypeError, match=r"unrecognized gain\(s\) for .*: kq"):
        make_controller(name, kq=1.0)
    with pytest.raises(TypeError, match="needs"):
        cls: Any = type(make_controller(name))
        cls(gains=DriveLimits())


def test_overrides_are_applied_and_validated() -> None:
    c = make_controller("stiff_pi", bandwidth_factor=80.0)
    assert c.gains.bandwidth_factor == 80.0  # type: ignore[attr-defined]
    assert c.tuning().kp == pytest.approx(80 * Z)  # type: ignore[attr-defined]
    assert "StiffPIGains" in repr(c)


def test_registered_names() -> None:
    assert set(INDUSTRY) <= set(controller_names())
    assert isinstance(make_controller("z_torque"), ZTorque)


# --------------------------------------------------------------------------------- the env
@pytest.mark.parametrize("name", INDUSTRY)
def test_runs_as_the_base_controller_of_the_env(name: str) -> None:
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller=name,
        episode_s=20.0,
        control_dt_s=1.0,
        max_episode_steps=20,
        noise_std_rad_s=0.1,
    )
    trace = rollout(env, ZeroAction(), seed=0)
    assert trace.termination_reason is None
    assert np.all(np.isfinite(trace.torque_nm))
    assert np.all(trace.adaptive_gain == 0.0)
    # Residual mode: the applied torque is the base torque clipped to the limits.
    np.testing.assert_allclose(trace.torque_nm, np.clip(trace.base_torque_nm, 0.0, 50_000.0))
    # The reported "sliding variable" is the speed error x1 - w_set (0 at t = 0 is x1 - ref).
    assert trace.sliding_variable[1] == pytest.approx(-12.0, abs=0.5)


@pytest.mark.parametrize("name", ["soft_speed", "z_torque"])
def test_default_scenario_settles_at_the_reference(name: str) -> None:
    """At the paper's scenario (97 kN, 12 rad/s) both soft controllers reach steady rotation."""
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller=name,
        episode_s=80.0,
        control_dt_s=1.0,
        max_episode_steps=80,
        noise_std_rad_s=0.0,
    )
    trace = rollout(env, ZeroAction(), seed=0)
    tail = trace.bit_speed_rad_s[-20_000:]
    assert abs(tail.mean() - 12.0) < 0.3
    assert tail.max() - tail.min() < 1.0
    assert not trace.bit_stuck[-40_000:].any()


# ---------------------------------------------------------------------------------- physics
WOBS = (60e3, 100e3, 150e3, 200e3)
SPEEDS = (3.0, 5.0, 7.0, 9.0, 12.0, 15.0)


@pytest.fixture(scope="module")
def small_maps() -> dict[str, StickSlipMap]:
    return {
        name: compute_map(name, WOBS, SPEEDS, duration_s=80.0, window_s=40.0, progress=False)
        for name in INDUSTRY
    }


def test_stiff_loop_stick_slips_at_low_speed_and_high_wob(
    small_maps: dict[str, StickSlipMap],
) -> None:
    m = small_maps["stiff_pi"]
    i, j = WOBS.index(150e3), SPEEDS.index(3.0)
    assert m.severity[i, j] > 0.8
    assert m.stuck_fraction[i, j] > 0.1
    # docs/specification.md section 6: up to about 6 rad/s at 120-150 kN and about 8 rad/s at 200 kN.
    assert m.stuck_fraction[WOBS.index(200e3), SPEEDS.index(7.0)] > 0


def test_stiff_loop_rotates_steadily_at_high_speed_and_low_wob(
    small_maps: dict[str, StickSlipMap],
) -> None:
    m = small_maps["stiff_pi"]
    for wob in (60e3, 100e3):
        for speed in (12.0, 15.0):
            i, j = WOBS.index(wob), SPEEDS.index(speed)
            assert m.stuck_fraction[i, j] == 0.0
            assert m.severity[i, j] < 0.5


@pytest.mark.parametrize("name", ["soft_speed", "z_torque"])
def test_soft_controllers_shrink_the_stick_slip_region(
    small_maps: dict[str, StickSlipMap], name: str
) -> None:
    stiff = small_maps["stiff_pi"].unstable()
    soft = small_maps[name].unstable()
    assert soft.sum() < stiff.sum()
    assert soft.sum() <= stiff.sum() - 3
    # Every cell that is free of stick-slip under the stiff loop stays free.
    assert not (soft & ~stiff).any()
    assert not small_maps[name].diverged.any()
