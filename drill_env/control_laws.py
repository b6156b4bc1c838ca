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

Top-drive speed-loop family (the industry baselines ``stiff_pi``, ``soft_speed`` and
``z_torque`` of :mod:`baselines`), parameter layout::

    lp = [kp, ki, j_ff, z, k_pi, c_pi, tau_mean, u_min, u_max]
    ls = [I, w_set_prev, 0, x1 - w_set, T_mean, started]

See :func:`speed_loop_torque`.
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
    "LAW_SOFT_SPEED",
    "LAW_STIFF_PI",
    "LAW_Z_TORQUE",
    "N_LAW_PARAMS",
    "N_LAW_STATE",
    "control_torque",
    "smc_torque",
    "speed_loop_torque",
]

LAW_NONE: Final = 0
LAW_CSMC: Final = 1
LAW_MSMC: Final = 2
LAW_ASMC: Final = 3
LAW_PROPOSED: Final = 4
LAW_STIFF_PI: Final = 5
LAW_SOFT_SPEED: Final = 6
LAW_Z_TORQUE: Final = 7

N_LAW_PARAMS: Final = 16
"""Length of every law parameter vector (unused tail entries are ignored)."""
N_LAW_STATE: Final = 8
"""Length of every law state vector (unused tail entries are ignored)."""

# Indices into the SMC vectors.
SMC_J_DT, SMC_C_DT, SMC_C_PI, SMC_K_PI, SMC_LAM, SMC_DELTA, SMC_G0 = 0, 1, 2, 3, 4, 5, 6
S_I1, S_I2, S_GAIN, S_SLIDING = 0, 1, 2, 3

# Indices into the speed-loop vectors.
PI_KP, PI_KI, PI_J_FF, PI_Z, PI_K_PI, PI_C_PI, PI_TAU, PI_U_MIN, PI_U_MAX = range(9)
N_PI_PARAMS: Final = 9
PS_INT, PS_SET_PREV, PS_GAIN, PS_ERROR, PS_T_MEAN, PS_STARTED = range(6)
N_PI_STATE: Final = 6


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
def speed_loop_torque(lp, ls, m, ref: float, dt: float) -> float:
    """Top-drive speed PI loop with optional set-point feed-forward and torque feedback, N m.

    With the measured string torque at the top drive ``T = k_pi x2 + c_pi (x1 - x3)`` and its
    running mean ``T_mean`` (first-order low-pass, time constant ``tau_mean``)::

        w_set = ref - (T - T_mean) / z              (z = 0: no torque feedback, w_set = ref)
        e     = w_set - x1
        u     = kp e + ki I + j_ff d(w_set)/dt       I = integral of e (forward Euler)

    ``stiff_pi`` and ``soft_speed`` use ``z = 0``; ``z_torque`` feeds the torque back through
    the pipe impedance ``z``. ``d(w_set)/dt`` is the backward difference of the set-point over
    ``dt`` (0 at the first call). The integral is clamped (conditional integration) while the
    unclipped output is beyond ``[u_min, u_max]`` and the error would push it further out. The
    torque is returned unclipped (the env clips it); then ``I``, ``T_mean`` and the previous
    set-point advance by ``dt``. ``ls[3]`` keeps the speed error ``x1 - w_set`` (rad/s) and
    ``ls[2]`` (the adaptive-gain slot of the SMCs) stays 0.
    """
    x1, x2, x3 = m[0], m[1], m[2]
    kp, ki, j_ff, z = lp[PI_KP], lp[PI_KI], lp[PI_J_FF], lp[PI_Z]
    w_set = ref
    t_string = lp[PI_K_PI] * x2 + lp[PI_C_PI] * (x1 - x3)
    first = ls[PS_STARTED] == 0.0
    if first:
        ls[PS_T_MEAN] = t_string
    if z > 0.0:
        w_set = ref - (t_string - ls[PS_T_MEAN]) / z
    feed = 0.0 if first else j_ff * (w_set - ls[PS_SET_PREV]) / dt
    e = w_set - x1
    u = kp * e + ki * ls[PS_INT] + feed
    saturated = (u > lp[PI_U_MAX] and e > 0.0) or (u < lp[PI_U_MIN] and e < 0.0)
    if not saturated:
        ls[PS_INT] += e * dt
    tau = lp[PI_TAU]
    if tau > 0.0:
        ls[PS_T_MEAN] += (t_string - ls[PS_T_MEAN]) * min(dt / tau, 1.0)
    ls[PS_SET_PREV] = w_set
    ls[PS_ERROR] = -e
    ls[PS_STARTED] = 1.0
    return u


@njit(cache=True)
def control_torque(law: int, lp, ls, m, ref: float, dt: float) -> float:
    """Dispatch to the compiled law ``law``; ``LAW_NONE`` gives 0 N m."""
    if law == LAW_NONE:
        return 0.0
    if LAW_STIFF_PI <= law <= LAW_Z_TORQUE:
        return speed_loop_torque(lp, ls, m, ref, dt)
    return smc_torque(law, lp, ls, m, ref, dt)
