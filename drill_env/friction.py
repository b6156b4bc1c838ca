"""Karnopp bit-rock friction (docs/specification.md section 1), as pure compiled functions.

The slip mode of the bit is an integer: 0 when the bit is stuck (held at rest by static
friction), +1 or -1 when it slips forwards or backwards. Torques are in N m, speeds in rad/s.
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["STUCK", "karnopp_torque", "slip_torque", "string_torque_on_bit"]

STUCK = 0
"""Slip mode of a bit held at rest by static friction."""


@njit(cache=True)
def string_torque_on_bit(x5: float, x6: float, x7: float, c_bi: float, k_bi: float, c_bit: float):
    """Torque ``T_e = c_bi (x5 - x7) + k_bi x6 - c_bit x7`` the string applies to the bit, N m."""
    return c_bi * (x5 - x7) + k_bi * x6 - c_bit * x7


@njit(cache=True)
def slip_torque(x7: float, direction: int, t_a: float, t_0: float, xi: float):
    """Bit torque while slipping in ``direction`` (+1/-1): ``d [T_0 + (T_a - T_0) e^(-xi|x7|)]``."""
    return direction * (t_0 + (t_a - t_0) * math.exp(-xi * abs(x7)))


@njit(cache=True)
def karnopp_torque(x7: float, t_e: float, t_a: float, t_0: float, xi: float, dw: float):
    """The Karnopp bit torque ``T_bit`` of docs/specification.md section 1 as a function of the bit speed, N m.

    Args:
        x7: Bit speed, rad/s.
        t_e: Torque the string applies to the bit, N m.
        t_a: Maximum static torque ``mu_a WOB R``, N m.
        t_0: Sliding torque ``mu_0 WOB R``, N m.
        xi: Stribeck decline rate, s/rad.
        dw: Half-width of the stick band, rad/s.
    """
    if abs(x7) < dw:
        if abs(t_e) <= t_a:
            return t_e
        return t_a if t_e > 0 else -t_a
    return slip_torque(x7, 1 if x7 > 0 else -1, t_a, t_0, xi)
