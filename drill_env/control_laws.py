"""Compiled control laws that run inside the plant loop, one call per plant step.

A law is a pure function of a float64 parameter vector ``lp`` (gains and the controller's own
model of the string), a float64 state vector ``ls`` that it updates in place (integrals,
adaptive gains, last sliding variable), the *measured* state tuple ``m`` (rad/s, rad) and the
reference bit speed (rad/s); it returns the top-drive torque in N m. The user-facing
controller classes in :mod:`baselines` pack ``lp`` and ``ls``; the kernel dispatches on an
integer law id so that every built-in controller runs at compiled speed without a Python call.

Sliding-mode family (SPEC section 3), parameter layout::

    lp = [J_dt, c_dt, c_pi, k_pi, lam, delta, g0, g1, g2, g3, g4]
    ls = [I1, I2, k_adaptive, s_last]
"""

from __future__ import annotations

import math
from typing import Final

from numba import njit

__all__ = [
    "LAW_ASMC",
    "LAW_CSMC",
    "LAW_MSMC",
    "LAW_NONE",
    "LAW_PROPOSED",
    "N_LAW_PARAMS",
    "N_LAW_STATE",
    "control_torque",
    "smc_torque",
]

LAW_NONE: Final = 0
LAW_CSMC: Final = 1
LAW_MSMC: Final = 2
LAW_ASMC: Final = 3
LAW_PROPOSED: Final = 4

N_LAW_PARAMS: Final = 16
"""Length of every law parameter vector (unused tail entries are ignored)."""
N_LAW_STATE: Final = 8
"""Length of every law state vector (unused tail entries are ignored)."""

# Indices into the SMC vectors.
SMC_J_DT, SMC_C_DT, SMC_C_PI, SMC_K_PI, SMC_LAM, SMC_DELTA, SMC_G0 = 0, 1, 2, 3, 4, 5, 6
S_I1, S_I2, S_GAIN, S_SLIDING = 0, 1, 2, 3


@njit(cache=True)
def _sign(v: float) -> float:
    if v > 0.0:
        return 1.0
    if v < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def smc_torque(law: int, lp, ls, m, ref: float, dt: float) -> float:
    """Sliding-mode torque ``u = u_eq + u_disc`` of SPEC section 3, N m.

    Computes ``s = (x1 - xd) + lam I1 + lam I2`` from the measured state and the current
    integrals, returns the torque, then advances ``I1``, ``I2`` and the adaptive gain by forward
    Euler over ``dt`` seconds. ``ls[3]`` keeps the last ``s`` (rad/s).
    """
    x1, x2, x3, x7 = m[0], m[1], m[2], m[6]
    j_dt, c_dt, c_pi, k_pi = lp[SMC_J_DT], lp[SMC_C_DT], lp[SMC_C_PI], lp[SMC_K_PI]
    lam, delta = lp[SMC_LAM], lp[SMC_DELTA]
    e1 = x1 - ref
    e17 = x1 - x7
    s = e1 + lam * ls[S_I1] + lam * ls[S_I2]
    u_eq = c_pi * (x1 - x3) + k_pi * x2 + c_dt * x1 - j_dt * lam * e1 - j_dt * lam * e17
    abs_s = abs(s)
    sgn_s = _sign(s)
    gain = ls[S_GAIN]
    if law == LAW_CSMC:
        u_disc = -lp[SMC_G0] * sgn_s
    elif law == LAW_MSMC:
        u_disc = -lp[SMC_G0] * math.sqrt(abs_s) * sgn_s - lp[SMC_G0 + 1] * s
    elif law == LAW_ASMC:
        u_disc = -gain * sgn_s
        mu11, mu22 = lp[SMC_G0], lp[SMC_G0 + 1]
        rate = mu11 * abs_s * _sign(abs_s - delta) if gain > mu22 else mu22
        ls[S_GAIN] = gain + rate * dt
    else:  # LAW_PROPOSED
        mu1, mu2, alpha, a, b = (
            lp[SMC_G0], lp[SMC_G0 + 1], lp[SMC_G0 + 2], lp[SMC_G0 + 3], lp[SMC_G0 + 4]
        )  # fmt: skip
        u_disc = -gain * math.sqrt(abs_s) * sgn_s - a * gain * s
        rate = mu1 * abs_s**b * _sign(abs_s - delta) if gain > alpha else mu2
        ls[S_GAIN] = gain + rate * dt
    ls[S_I1] += e1 * dt
    ls[S_I2] += e17 * dt
    ls[S_SLIDING] = s
    return u_eq + u_disc


@njit(cache=True)
def control_torque(law: int, lp, ls, m, ref: float, dt: float) -> float:
    """Dispatch to the compiled law ``law``; ``LAW_NONE`` gives 0 N m."""
    if law == LAW_NONE:
        return 0.0
    return smc_torque(law, lp, ls, m, ref, dt)
