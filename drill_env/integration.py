"""Event-aware fixed-step integration of the drill string (docs/specification.md section 1, accuracy).

Each plant step of ``h`` seconds (1 ms in the environment) is one classical Runge-Kutta step
with the bit's slip mode frozen, followed by event handling:

* a stuck bit whose string torque ``|T_e|`` passes the static limit ``T_a`` breaks away at the
  crossing instant, located by linear interpolation of ``T_e`` (exact for the linear stuck
  dynamics to O(h^2));
* a slipping bit whose speed crosses zero is stopped at the crossing instant, located by three
  regula-falsi steps on the Runge-Kutta solution; there it sticks if ``|T_e| <= T_a`` and
  otherwise slips on in the direction of ``T_e``;
* a slipping bit that ends a step inside the stick band ``|x7| < Dw`` with ``|T_e| <= T_a`` is
  captured (Karnopp's rule), its speed set to exactly 0.

The rest of each step is integrated in the new mode, so the error does not stall at the size
of the step as it does with a plain fixed-step method. A stuck bit's speed is exactly 0.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.dynamics import derivative
from drill_env.friction import STUCK, string_torque_on_bit
from drill_env.layout import P_C_BI, P_C_BIT, P_DW, P_K_BI
from drill_env.parameters import PLANT_DT_S, DrillStringParameters, plant_parameter_vector
from drill_env.validation import shown

__all__ = ["integrate_constant_torque", "plant_step", "rk4"]

_FALSE_POSITION_ITERATIONS = 3


@njit(cache=True)
def rk4(x, u: float, p, t_a: float, t_0: float, mode: int, h: float):
    """One classical Runge-Kutta step of ``h`` seconds with the slip mode frozen."""
    k1 = derivative(x, u, p, t_a, t_0, mode)
    x2 = (
        x[0] + 0.5 * h * k1[0], x[1] + 0.5 * h * k1[1], x[2] + 0.5 * h * k1[2],
        x[3] + 0.5 * h * k1[3], x[4] + 0.5 * h * k1[4], x[5] + 0.5 * h * k1[5],
        x[6] + 0.5 * h * k1[6],
    )  # fmt: skip
    k2 = derivative(x2, u, p, t_a, t_0, mode)
    x3 = (
        x[0] + 0.5 * h * k2[0], x[1] + 0.5 * h * k2[1], x[2] + 0.5 * h * k2[2],
        x[3] + 0.5 * h * k2[3], x[4] + 0.5 * h * k2[4], x[5] + 0.5 * h * k2[5],
        x[6] + 0.5 * h * k2[6],
    )  # fmt: skip
    k3 = derivative(x3, u, p, t_a, t_0, mode)
    x4 = (
        x[0] + h * k3[0], x[1] + h * k3[1], x[2] + h * k3[2], x[3] + h * k3[3],
        x[4] + h * k3[4], x[5] + h * k3[5], x[6] + h * k3[6],
    )  # fmt: skip
    k4 = derivative(x4, u, p, t_a, t_0, mode)
    w = h / 6.0
    return (
        x[0] + w * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
        x[1] + w * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
        x[2] + w * (k1[2] + 2.0 * k2[2] + 2.0 * k3[2] + k4[2]),
        x[3] + w * (k1[3] + 2.0 * k2[3] + 2.0 * k3[3] + k4[3]),
        x[4] + w * (k1[4] + 2.0 * k2[4] + 2.0 * k3[4] + k4[4]),
        x[5] + w * (k1[5] + 2.0 * k2[5] + 2.0 * k3[5] + k4[5]),
        x[6] + w * (k1[6] + 2.0 * k2[6] + 2.0 * k3[6] + k4[6]),
    )


@njit(cache=True)
def _torque_on_bit(x, p):
    return string_torque_on_bit(x[4], x[5], x[6], p[P_C_BI], p[P_K_BI], p[P_C_BIT])


@njit(cache=True)
def _with_bit_at_rest(x):
    return (x[0], x[1], x[2], x[3], x[4], x[5], 0.0)


@njit(cache=True)
def _mode_after_stop(x, p, t_a: float):
    """Slip mode of a bit that has just come to rest at state ``x`` (bit speed 0)."""
    t_e = _torque_on_bit(x, p)
    if abs(t_e) <= t_a:
        return STUCK
    return 1 if t_e > 0 else -1


@njit(cache=True)
def _slip_step(x, mode: int, u: float, p, t_a: float, t_0: float, h: float):
    """Advance a slipping bit by ``h``, stopping it where its speed crosses zero."""
    xn = rk4(x, u, p, t_a, t_0, mode, h)
    if mode * xn[6] > 0.0:
        if abs(xn[6]) < p[P_DW] and abs(_torque_on_bit(xn, p)) <= t_a:
            return _with_bit_at_rest(xn), STUCK  # Karnopp capture inside the stick band
        return xn, mode
    # The speed crossed zero inside the step: find the instant by regula falsi on theta.
    lo, hi = 0.0, 1.0
    f_lo, f_hi = x[6], xn[6]
    x_cross = xn
    theta = 1.0
    for _ in range(_FALSE_POSITION_ITERATIONS):
        if mode * f_lo <= 0.0:  # already at or past zero at the start
            theta = lo
            x_cross = x
            break
        theta = lo + (hi - lo) * f_lo / (f_lo - f_hi)
        x_cross = rk4(x, u, p, t_a, t_0, mode, theta * h)
        f = x_cross[6]
        if mode * f > 0.0:
            lo, f_lo = theta, f
        else:
            hi, f_hi = theta, f
    x_cross = _with_bit_at_rest(x_cross)
    new_mode = _mode_after_stop(x_cross, p, t_a)
    rest = (1.0 - theta) * h
    if rest <= 0.0:
        return x_cross, new_mode
    return rk4(x_cross, u, p, t_a, t_0, new_mode, rest), new_mode


@njit(cache=True)
def plant_step(x, mode: int, u: float, p, t_a: float, t_0: float, h: float):
    """Advance the string by one step of ``h`` seconds under constant torque ``u``.

    Args:
        x: State 7-tuple (rad/s, rad).
        mode: Slip mode at the start of the step (0 stuck, +1/-1 slipping).
        u: Top-drive torque held over the step, N m.
        p: Plant parameter vector (:func:`drill_env.parameters.plant_parameter_vector`).
        t_a: Maximum static bit torque, N m.
        t_0: Sliding bit torque, N m.
        h: Step, s.

    Returns:
        ``(x_next, mode_next)``.
    """
    if mode != STUCK:
        return _slip_step(x, mode, u, p, t_a, t_0, h)
    # mode (STUCK here), not the constant: a literal argument would compile rk4 a second time
    xn = rk4(x, u, p, t_a, t_0, mode, h)
    te_new = _torque_on_bit(xn, p)
    if abs(te_new) <= t_a:
        return xn, STUCK
    # Break-away inside the step: T_e is linear in the state, so interpolate it.
    te_old = _torque_on_bit(x, p)
    limit = t_a if te_new > 0.0 else -t_a
    theta = 0.0
    if te_new != te_old:
        theta = min(max((limit - te_old) / (te_new - te_old), 0.0), 1.0)
    direction = 1 if te_new > 0.0 else -1
    x_break = rk4(x, u, p, t_a, t_0, mode, theta * h) if theta > 0.0 else x
    rest = (1.0 - theta) * h
    if rest <= 0.0:
        return x_break, direction
    return _slip_step(x_break, direction, u, p, t_a, t_0, rest)


@njit(cache=True)
def _integrate_constant_torque(x0, mode0, p, t_a, t_0, u, h, n_steps, out_x, out_mode):
    x = (x0[0], x0[1], x0[2], x0[3], x0[4], x0[5], x0[6])
    mode = mode0
    for k in range(7):
        out_x[0, k] = x[k]
    out_mode[0] = mode
    for i in range(n_steps):
        x, mode = plant_step(x, mode, u, p, t_a, t_0, h)
        for k in range(7):
            out_x[i + 1, k] = x[k]
        out_mode[i + 1] = mode


def integrate_constant_torque(
    params: DrillStringParameters,
    torque_nm: float,
    wob_n: float,
    duration_s: float,
    step_s: float = PLANT_DT_S,
    initial_state: npt.ArrayLike | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    """Open-loop run under a constant top-drive torque, from rest unless told otherwise.

    Args:
        params: Plant parameters.
        torque_nm: Top-drive torque, N m.
        wob_n: Weight on bit, N (> 0).
        duration_s: Length of the run, s.
        step_s: Integration step, s.
        initial_state: State at t = 0, shape (7,); rest (bit stuck) by default.

    Returns:
        ``(states, modes)``: states at ``t = k * step_s`` for ``k = 0..n``, shape (n + 1, 7),
        and the slip mode at each of those instants, shape (n + 1,).
    """
    if not wob_n > 0:
        raise ValueError(f"wob_n = {shown(wob_n)} is out of range: allowed > 0")
    n_steps = round(duration_s / step_s)
    x0 = np.zeros(7) if initial_state is None else np.asarray(initial_state, dtype=np.float64)
    mode0 = STUCK if x0[6] == 0.0 else (1 if x0[6] > 0 else -1)
    out_x = np.empty((n_steps + 1, 7))
    out_mode = np.empty(n_steps + 1, dtype=np.int64)
    _integrate_constant_torque(
        x0,
        mode0,
        plant_parameter_vector(params),
        params.static_torque_nm(wob_n),
        params.sliding_torque_nm(wob_n),
        float(torque_nm),
        float(step_s),
        n_steps,
        out_x,
        out_mode,
    )
    return out_x, out_mode
