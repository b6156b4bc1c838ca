"""Independent event-located reference for the docs/specification.md section 1 plant (test helper).

This module re-implements the 4-DOF torsional drill string with ideal Karnopp friction from the
equations of ``docs/specification.md`` section 1 alone, with numpy and scipy only. It deliberately imports nothing from
``drill_env``, so the package's integrator can be checked against it.

The friction discontinuity is handled as a hybrid system rather than by smoothing it:

* STUCK: the bit speed ``x7`` is held at exactly 0 (``x7' = 0``, so ``x6' = x5``). The mode ends
  at the break-away event ``|T_e| = T_a``, after which the bit slips in the direction
  ``sign(T_e)``.
* SLIP with direction ``d`` (+1 or -1): ``T_bit = d [T_0 + (T_a - T_0) exp(-xi |x7|)]``. The mode
  ends when ``x7`` returns to 0; there ``x7`` is set to exactly 0 and the bit sticks if
  ``|T_e| <= T_a``, else it slips again in the direction ``sign(T_e)``.

Each mode is integrated by ``scipy.integrate.solve_ivp`` (DOP853, dense output) up to its
terminal event, segment by segment. The stick band ``Dw`` of the parameter sets is not used: the
reference is the limit ``Dw -> 0``.

State ``x = (x1..x7) = (w_dt, phi_dt - phi_pi, w_pi, phi_pi - phi_co, w_co, phi_co - phi_bi,
w_bi)``: speeds in rad/s, twists in rad.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.integrate import solve_ivp

__all__ = [
    "NAVARRO_LOPEZ2007",
    "PARAMETER_NAMES",
    "ZRIBI2024",
    "Segment",
    "reference_segments",
    "reference_trajectory",
    "string_torque",
]

FloatArray = npt.NDArray[np.float64]

PARAMETER_NAMES: tuple[str, ...] = (
    "J_dt",  # kg m^2, top drive
    "J_pi",  # kg m^2, drill pipes
    "J_co",  # kg m^2, drill collars
    "J_bi",  # kg m^2, bit
    "c_dt",  # N m s/rad, top drive to ground
    "c_pi",  # N m s/rad, top drive - pipes
    "c_co",  # N m s/rad, pipes - collars
    "c_bi",  # N m s/rad, collars - bit
    "c_bit",  # N m s/rad, bit to ground
    "k_pi",  # N m/rad, top drive - pipes
    "k_co",  # N m/rad, pipes - collars
    "k_bi",  # N m/rad, collars - bit
    "R",  # m, bit radius
    "mu_a",  # -, static (maximum) friction coefficient
    "mu_0",  # -, sliding friction coefficient
    "xi",  # s/rad, friction decline rate
    "Dw",  # rad/s, stick band (unused here: the reference is the limit Dw -> 0)
)

# docs/specification.md section 1, column `zribi2024` (paper Table 2 plus c_bi from Navarro-Lopez & Cortes 2007).
ZRIBI2024: dict[str, float] = {
    "J_dt": 930.0,
    "J_pi": 2782.25,
    "J_co": 750.0,
    "J_bi": 471.96,
    "c_dt": 425.0,
    "c_pi": 193.61,
    "c_co": 190.0,
    "c_bi": 181.49,
    "c_bit": 50.0,
    "k_pi": 698.06,
    "k_co": 1080.0,
    "k_bi": 907.48,
    "R": 0.15,
    "mu_a": 0.8,
    "mu_0": 0.5,
    "xi": 0.5,
    "Dw": 1e-3,
}

# docs/specification.md section 1, column `navarro_lopez2007`.
NAVARRO_LOPEZ2007: dict[str, float] = {
    "J_dt": 930.0,
    "J_pi": 2782.25,
    "J_co": 750.0,
    "J_bi": 471.9698,
    "c_dt": 425.0,
    "c_pi": 139.6126,
    "c_co": 190.0,
    "c_bi": 181.49,
    "c_bit": 50.0,
    "k_pi": 698.063,
    "k_co": 1080.0,
    "k_bi": 907.48,
    "R": 0.155575,
    "mu_a": 0.8,
    "mu_0": 0.5,
    "xi": 0.9,
    "Dw": 1e-6,
}

_STUCK = 0  # mode code; SLIP modes are +1 and -1 (the slip direction)
_MAX_ZERO_LENGTH_SEGMENTS = 100  # consecutive segments without progress before giving up

Rhs = Callable[[float, FloatArray], FloatArray]


def _check_parameters(p: dict[str, float]) -> None:
    missing = sorted(set(PARAMETER_NAMES) - set(p))
    unknown = sorted(set(p) - set(PARAMETER_NAMES))
    if missing or unknown:
        raise KeyError(
            f"parameter dict: missing {missing}, unknown {unknown}; "
            f"valid names are {list(PARAMETER_NAMES)}"
        )
    for name in PARAMETER_NAMES:
        value = p[name]
        if not np.isfinite(value) or value < 0.0:
            raise ValueError(f"parameter {name}={value!r} must be finite and >= 0")
    for name in ("J_dt", "J_pi", "J_co", "J_bi"):
        if p[name] <= 0.0:
            raise ValueError(f"parameter {name}={p[name]!r} must be > 0")


def string_torque(p: dict[str, float], x: FloatArray) -> FloatArray:
    """Torque T_e the string applies to the bit (docs/specification.md section 1), net of the bit's viscous term.

    Args:
        p: parameter dict with the docs/specification.md section 1 names.
        x: state(s), shape (..., 7).

    Returns:
        T_e = c_bi (x5 - x7) + k_bi x6 - c_bit x7 in N m, shape (...).
    """
    x = np.asarray(x, dtype=np.float64)
    return p["c_bi"] * (x[..., 4] - x[..., 6]) + p["k_bi"] * x[..., 5] - p["c_bit"] * x[..., 6]


def _make_rhs(p: dict[str, float], torque_nm: float, t_a: float, t_0: float, mode: int) -> Rhs:
    """Right-hand side of the plant in one hybrid mode (STUCK or SLIP with direction `mode`)."""
    j_dt, j_pi, j_co, j_bi = p["J_dt"], p["J_pi"], p["J_co"], p["J_bi"]
    c_dt, c_pi, c_co, c_bi, c_bit = p["c_dt"], p["c_pi"], p["c_co"], p["c_bi"], p["c_bit"]
    k_pi, k_co, k_bi = p["k_pi"], p["k_co"], p["k_bi"]
    xi = p["xi"]
    u = float(torque_nm)
    d = float(mode)

    def rhs(_t: float, y: FloatArray) -> FloatArray:
        x1, x2, x3, x4, x5, x6, x7 = (float(v) for v in y)
        dx1 = (-(c_dt + c_pi) * x1 - k_pi * x2 + c_pi * x3 + u) / j_dt
        dx2 = x1 - x3
        dx3 = (c_pi * x1 + k_pi * x2 - (c_pi + c_co) * x3 - k_co * x4 + c_co * x5) / j_pi
        dx4 = x3 - x5
        dx5 = (c_co * x3 + k_co * x4 - (c_co + c_bi) * x5 - k_bi * x6 + c_bi * x7) / j_co
        dx6 = x5 - x7
        if mode == _STUCK:
            dx7 = 0.0  # T_bit = T_e: the bit is held at rest
        else:
            t_bit = d * (t_0 + (t_a - t_0) * math.exp(-xi * abs(x7)))
            dx7 = (c_bi * x5 + k_bi * x6 - (c_bi + c_bit) * x7 - t_bit) / j_bi
        return np.array([dx1, dx2, dx3, dx4, dx5, dx6, dx7])

    return rhs


def _make_events(p: dict[str, float], t_a: float, mode: int) -> list[Callable[..., float]]:
    """Terminal events that end a segment in the given mode."""
    c_bi, k_bi, c_bit = p["c_bi"], p["k_bi"], p["c_bit"]

    def t_e(y: FloatArray) -> float:
        return float(c_bi * (y[4] - y[6]) + k_bi * y[5] - c_bit * y[6])

    events: list[Callable[..., float]] = []
    if mode == _STUCK:

        def break_away_forward(_t: float, y: FloatArray) -> float:
            return t_e(y) - t_a

        def break_away_backward(_t: float, y: FloatArray) -> float:
            return t_e(y) + t_a

        break_away_forward.terminal = True  # type: ignore[attr-defined]
        break_away_forward.direction = 1.0  # type: ignore[attr-defined]
        break_away_backward.terminal = True  # type: ignore[attr-defined]
        break_away_backward.direction = -1.0  # type: ignore[attr-defined]
        events += [break_away_forward, break_away_backward]
    else:

        def bit_at_rest(_t: float, y: FloatArray) -> float:
            return float(y[6])

        bit_at_rest.terminal = True  # type: ignore[attr-defined]
        bit_at_rest.direction = -float(mode)  # type: ignore[attr-defined]
        events.append(bit_at_rest)
    return events


@dataclass(frozen=True)
class Segment:
    """One stretch of the hybrid trajectory in a single mode.

    Attributes:
        t_start_s: start of the segment, s.
        t_stop_s: end of the segment, s: an event time, or t_end_s for the last segment.
        mode: "stuck", "slip+" or "slip-".
        solution: scipy dense output over [t_start_s, t_stop_s]; maps times (n,) to states
            (7, n).
    """

    t_start_s: float
    t_stop_s: float
    mode: str
    solution: Callable[[FloatArray], FloatArray]


_MODE_NAMES = {_STUCK: "stuck", 1: "slip+", -1: "slip-"}


def reference_segments(
    p: dict[str, float],
    torque_nm: float,
    wob_n: float,
    t_end_s: float,
    rtol: float = 1e-9,
    atol: float = 1e-11,
    *,
    max_events: int = 10_000,
    max_step_s: float = 0.05,
) -> list[Segment]:
    """Hybrid segments of the plant under a constant top-drive torque, from rest, bit stuck.

    Segment k ends where segment k + 1 starts, at a break-away (stuck -> slip) or at a return
    of the bit speed to 0 (slip -> stuck or slip in the other direction).

    Args:
        p: parameter dict with the docs/specification.md section 1 names (see `PARAMETER_NAMES`); ``Dw`` is
            required but unused.
        torque_nm: constant top-drive torque u, N m.
        wob_n: weight on bit, N (> 0).
        t_end_s: end of the integration, s (> 0).
        rtol: relative tolerance of the DOP853 integrator.
        atol: absolute tolerance of the DOP853 integrator.
        max_events: the most mode switches allowed before `RuntimeError` is raised.
        max_step_s: largest integrator step, s (keeps event detection from stepping over a
            double crossing).

    Returns:
        The segments in time order, covering [0, t_end_s].

    Raises:
        KeyError: `p` lacks a parameter or has an unknown one.
        ValueError: a parameter, `wob_n` or `t_end_s` is out of range.
        RuntimeError: the integrator failed, more than `max_events` events occurred or the mode
            kept switching without the time advancing.
    """
    _check_parameters(p)
    if not (np.isfinite(wob_n) and wob_n > 0.0):
        raise ValueError(f"wob_n={wob_n!r} must be finite and > 0")
    if not (np.isfinite(t_end_s) and t_end_s > 0.0):
        raise ValueError(f"t_end_s={t_end_s!r} must be finite and > 0")
    if not np.isfinite(torque_nm):
        raise ValueError(f"torque_nm={torque_nm!r} must be finite")

    t_a = p["mu_a"] * wob_n * p["R"]  # maximum static torque, N m
    t_0 = p["mu_0"] * wob_n * p["R"]  # sliding torque, N m

    segments: list[Segment] = []
    t = 0.0
    y = np.zeros(7)
    mode = _STUCK  # from rest, the bit is stuck
    n_zero_length = 0
    while True:
        sol = solve_ivp(
            _make_rhs(p, torque_nm, t_a, t_0, mode),
            (t, t_end_s),
            y,
            method="DOP853",
            rtol=rtol,
            atol=atol,
            dense_output=True,
            events=_make_events(p, t_a, mode),
            max_step=max_step_s,
        )
        if sol.status == -1:
            raise RuntimeError(f"solve_ivp failed at t={t} s in mode {mode}: {sol.message}")
        t_next = float(sol.t[-1])
        segments.append(Segment(t, t_next, _MODE_NAMES[mode], sol.sol))
        if sol.status == 0:  # reached t_end_s
            return segments

        if len(segments) > max_events:
            raise RuntimeError(f"more than max_events={max_events} events before t={t_next} s")
        n_zero_length = n_zero_length + 1 if t_next <= t else 0
        if n_zero_length > _MAX_ZERO_LENGTH_SEGMENTS:
            raise RuntimeError(f"the mode switches without progress at t={t_next} s")

        y = np.array(sol.y[:, -1], dtype=np.float64)  # state at the terminal event
        y[6] = 0.0  # both events leave the bit at rest (exactly so at a zero crossing)
        torque_e = float(string_torque(p, y))
        if mode == _STUCK:
            mode = 1 if torque_e > 0.0 else -1  # break-away: slip in the direction of T_e
        elif abs(torque_e) <= t_a:
            mode = _STUCK
        else:
            mode = 1 if torque_e > 0.0 else -1
        t = t_next


def reference_trajectory(
    p: dict[str, float],
    torque_nm: float,
    wob_n: float,
    t_end_s: float,
    t_eval_s: FloatArray,
    rtol: float = 1e-9,
    atol: float = 1e-11,
    *,
    max_events: int = 10_000,
    max_step_s: float = 0.05,
) -> FloatArray:
    """States of the plant under a constant top-drive torque, from rest with the bit stuck.

    Args:
        p: parameter dict with the docs/specification.md section 1 names (see `PARAMETER_NAMES`); ``Dw`` is
            required but unused.
        torque_nm: constant top-drive torque u, N m.
        wob_n: weight on bit, N (> 0).
        t_end_s: end of the integration, s (> 0).
        t_eval_s: times at which to report the state, s, shape (n,), non-decreasing, within
            [0, t_end_s]. A time that falls exactly on an event gets the post-event state.
        rtol: relative tolerance of the DOP853 integrator.
        atol: absolute tolerance of the DOP853 integrator.
        max_events: the most mode switches allowed before `RuntimeError` is raised.
        max_step_s: largest integrator step, s (keeps event detection from stepping over a
            double crossing).

    Returns:
        States, shape (n, 7): (w_dt, phi_dt - phi_pi, w_pi, phi_pi - phi_co, w_co,
        phi_co - phi_bi, w_bi) in rad/s and rad. While the bit is stuck, column 6 is exactly 0.

    Raises:
        KeyError: `p` lacks a parameter or has an unknown one.
        ValueError: a parameter, `wob_n`, `t_end_s` or `t_eval_s` is out of range.
        RuntimeError: the integrator failed or more than `max_events` events occurred.
    """
    t_eval = np.asarray(t_eval_s, dtype=np.float64)
    if t_eval.ndim != 1:
        raise ValueError(f"t_eval_s must be 1-D, got shape {t_eval.shape}")
    if t_eval.size and (t_eval[0] < 0.0 or t_eval[-1] > t_end_s or np.any(np.diff(t_eval) < 0)):
        raise ValueError(f"t_eval_s must be non-decreasing within [0, t_end_s={t_end_s}]")
    segments = reference_segments(
        p, torque_nm, wob_n, t_end_s, rtol, atol, max_events=max_events, max_step_s=max_step_s
    )

    out = np.empty((t_eval.size, 7))
    filled = 0  # t_eval[:filled] are done
    for k, seg in enumerate(segments):
        # A segment covers [t_start, t_stop); the last one also covers its end point, and a
        # time exactly at an event belongs to the segment that starts there.
        last = k == len(segments) - 1
        stop = int(np.searchsorted(t_eval, seg.t_stop_s, side="right" if last else "left"))
        if stop > filled:
            out[filled:stop] = seg.solution(t_eval[filled:stop]).T
            if seg.mode == "stuck":
                out[filled:stop, 6] = 0.0
            filled = stop
    assert filled == t_eval.size, (filled, t_eval.size)
    return out
