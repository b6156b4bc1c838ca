"""The bit-side torsional model that ``drill-gym calibrate`` fits to a measured log
(docs/calibration.md section 2), as a pure compiled simulator.

The top drive's measured speed ``w_t(t)`` is a kinematic boundary. One spring-damper (stiffness
``k``, damping ``c``) joins it to the bit (inertia ``J``), on which the rock acts:

    twist'  = w_t - w_b
    J w_b'  = T_e - T_bit,      T_e = k twist + c (w_t - w_b)

The torque on bit ``T_bit`` follows one of three nested friction families:

* ``karnopp``: the project's law (docs/specification.md section 1) with a zero-width stick
  band: a stuck bit holds ``|T_e| <= T_a`` (``T_bit = T_e``); a slipping one feels
  ``sign(w_b) [T_0 + (T_a - T_0) exp(-xi |w_b|)]``.
* ``stribeck_viscous``: the same plus a viscous term ``c_v w_b``.
* ``memory``: the Stribeck term is a function of a lagged speed ``v`` with
  ``tau v' = |w_b| - v`` (frictional memory): the torque on bit is larger while the bit
  accelerates than while it decelerates at the same speed, so the torque-speed plot draws a
  loop, which no single-valued law can.

With a measured weight on bit the two friction torques scale with it: ``T_a = a_a WOB`` and
``T_0 = a_0 WOB`` (``a = mu R``, in m). The simulator steps every sample interval in
``substeps`` equal steps (semi-implicit Euler, the boundary speed interpolated linearly),
detects the stops of the bit inside a step, and returns the bit speed and torque on bit at
the log's sample times.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.validation import shown

__all__ = [
    "FAMILIES",
    "FAMILY_CODES",
    "MAX_SUBSTEPS",
    "N_MODEL_PARAMS",
    "P_A0",
    "P_AA",
    "P_C",
    "P_CV",
    "P_J",
    "P_K",
    "P_TAU",
    "P_XI",
    "STRING_KEYS",
    "TOP_DRIVE_KEYS",
    "simulate_bit",
    "simulate_free_running",
    "simulate_top_side",
    "substeps_for",
]

FAMILIES: Final = ("karnopp", "stribeck_viscous", "memory")
"""Friction families, simplest first; each contains the one before it."""
FAMILY_CODES: Final = {name: i for i, name in enumerate(FAMILIES)}
"""Family name -> integer code of the compiled simulator."""

P_J, P_K, P_C, P_AA, P_A0, P_XI, P_CV, P_TAU = range(8)
"""Indices of the model parameter vector: bit inertia (kg m^2), stiffness (N m/rad), damping
(N m s/rad), static and sliding friction (N m, or m per N of WOB), Stribeck decline rate
(s/rad), viscous bit friction (N m s/rad), friction memory time (s)."""
N_MODEL_PARAMS: Final = 8
"""Length of the model parameter vector."""
STEPS_PER_PERIOD: Final = 40_000
"""The simulator's step is at most this fraction of the string's natural period."""
MAX_SUBSTEPS: Final = 2000
"""Most steps per sample interval (a bound on the cost of a simulation)."""


def substeps_for(p: npt.NDArray[np.float64], sample_period_s: float) -> int:
    """Steps per sample interval: at least :data:`STEPS_PER_PERIOD` per natural period
    ``2 pi sqrt(J/k)``, and a step below ``J / (10 c)`` and ``tau / 4``; at most
    :data:`MAX_SUBSTEPS`."""
    period = 2.0 * math.pi * math.sqrt(p[P_J] / p[P_K])
    h = period / STEPS_PER_PERIOD
    if p[P_C] + p[P_CV] > 0:
        h = min(h, 0.1 * p[P_J] / (p[P_C] + p[P_CV]))
    if p[P_TAU] > 0:
        h = min(h, 0.25 * p[P_TAU])
    return max(1, min(MAX_SUBSTEPS, int(math.ceil(sample_period_s / h))))


@njit(cache=True)
def _bit_substep(j_bit, k, c, t_a, t_0, xi, c_v, tau, h, wt_a, wt_b, twist, w, v, direction):  # fmt: skip
    """One step ``h`` of the bit with the top-drive speed going from ``wt_a`` to ``wt_b``;
    returns ``(twist, w, v, direction, t_bit)`` (``direction`` 0 while stuck)."""
    t_e = k * twist + c * (wt_a - w)
    if direction == 0:
        if abs(t_e) <= t_a:
            twist += h * 0.5 * (wt_a + wt_b)
            if tau > 0:
                v += (0.0 - v) * (1.0 - math.exp(-h / tau))
            else:
                v = 0.0
            return twist, w, v, 0, t_e
        direction = 1 if t_e > 0 else -1
    slip = direction * (t_0 + (t_a - t_0) * math.exp(-xi * v))
    # Damping implicit for stability: J (w1 - w) = h (k twist + c (wt - w1) - slip - c_v w1).
    w1 = (j_bit * w + h * (k * twist + c * wt_b - slip)) / (j_bit + h * (c + c_v))
    if w1 * direction <= 0.0:
        # The bit stops inside the step: stick if the string cannot turn it.
        w1 = 0.0
        t_e1 = k * twist + c * wt_b
        if abs(t_e1) <= t_a:
            direction = 0
            t_bit = t_e1
        else:
            direction = 1 if t_e1 > 0 else -1
            t_bit = slip
    else:
        t_bit = slip + c_v * w1
    twist += h * (0.5 * (wt_a + wt_b) - w1)
    if tau > 0:
        v += (abs(w1) - v) * (1.0 - math.exp(-h / tau))
    else:
        v = abs(w1)
    return twist, w1, v, direction, t_bit


@njit(cache=True)
def _simulate(time_s, top_speed, wob, use_wob, family, p, twist0, speed0, substeps, out_speed, out_torque, out_stuck):  # fmt: skip
    n = time_s.shape[0]
    j_bit = p[0]
    k = p[1]
    c = p[2]
    a_a = p[3]
    a_0 = p[4]
    xi = p[5]
    c_v = p[6] if family >= 1 else 0.0
    tau = p[7] if family >= 2 else 0.0
    twist = twist0
    w = speed0
    v = abs(speed0)
    direction = 0
    # Stuck at the start when the bit is (nearly) at rest and the string cannot move it.
    t_e0 = k * twist + c * (top_speed[0] - w)
    scale0 = wob[0] if use_wob else 1.0
    if abs(w) < 1e-9 and abs(t_e0) <= a_a * scale0:
        direction = 0
        w = 0.0
    else:
        direction = 1 if (w > 0 or (w == 0 and t_e0 > 0)) else -1
    out_speed[0] = w
    out_stuck[0] = direction == 0
    if direction == 0:
        out_torque[0] = t_e0
    else:
        out_torque[0] = direction * (a_0 + (a_a - a_0) * math.exp(-xi * v)) * scale0 + c_v * w
    for i in range(n - 1):
        dt = time_s[i + 1] - time_s[i]
        h = dt / substeps
        wt0 = top_speed[i]
        dwt = (top_speed[i + 1] - wt0) / substeps
        s0 = wob[i] if use_wob else 1.0
        ds = ((wob[i + 1] - wob[i]) / substeps) if use_wob else 0.0
        t_bit = 0.0
        for s in range(substeps):
            wt_a = wt0 + dwt * s
            scale = s0 + ds * (s + 0.5)
            twist, w, v, direction, t_bit = _bit_substep(
                j_bit, k, c, a_a * scale, a_0 * scale, xi, c_v, tau, h, wt_a, wt_a + dwt,
                twist, w, v, direction,
            )  # fmt: skip
        if direction == 0:
            t_bit = k * twist + c * top_speed[i + 1]
            scale_end = wob[i + 1] if use_wob else 1.0
            if abs(t_bit) > a_a * scale_end:
                t_bit = a_a * scale_end if t_bit > 0 else -a_a * scale_end
        out_speed[i + 1] = w
        out_torque[i + 1] = t_bit
        out_stuck[i + 1] = direction == 0
        if not (abs(w) < 1e9 and abs(twist) < 1e9):
            for m in range(i + 2, n):
                out_speed[m] = np.nan
                out_torque[m] = np.nan
                out_stuck[m] = False
            return False
    return True


def simulate_bit(
    time_s: npt.NDArray[np.float64],
    top_speed_rad_s: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    family: str,
    twist0_rad: float,
    speed0_rad_s: float,
    wob_n: npt.NDArray[np.float64] | None = None,
    substeps: int | None = None,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Simulate the bit driven by a measured top-drive speed.

    Args:
        time_s: Sample times, s, shape ``(n,)``, strictly increasing.
        top_speed_rad_s: Top-drive speed at those times, rad/s, shape ``(n,)``.
        p: Model parameter vector, shape ``(N_MODEL_PARAMS,)`` (``P_*`` indices).
        family: One of :data:`FAMILIES`.
        twist0_rad: Twist of the string at ``time_s[0]``, rad.
        speed0_rad_s: Bit speed at ``time_s[0]``, rad/s (0: the bit may start stuck).
        wob_n: Weight on bit, N, shape ``(n,)``; with it the friction parameters are per
            newton of WOB (m), without it in N m.
        substeps: Steps per sample interval (default :func:`substeps_for`).

    Returns:
        ``(bit_speed_rad_s, bit_torque_nm, stuck)`` at the sample times, each shape ``(n,)``;
        NaN after a divergence (speed or twist beyond 1e9).
    """
    t = np.ascontiguousarray(time_s, dtype=np.float64)
    top = np.ascontiguousarray(top_speed_rad_s, dtype=np.float64)
    params = np.ascontiguousarray(p, dtype=np.float64)
    if family not in FAMILY_CODES:
        raise ValueError(f"family = {shown(family)} is not known: allowed {', '.join(FAMILIES)}")
    n_sub = substeps or substeps_for(params, float(np.median(np.diff(t))))
    use_wob = wob_n is not None
    wob = np.ascontiguousarray(wob_n if use_wob else np.zeros(1), dtype=np.float64)
    speed = np.empty_like(t)
    torque = np.empty_like(t)
    stuck = np.empty(t.shape, dtype=np.bool_)
    _simulate(
        t, top, wob, use_wob, FAMILY_CODES[family], params, float(twist0_rad),
        float(speed0_rad_s), int(n_sub), speed, torque, stuck,
    )  # fmt: skip
    return speed, torque, stuck


@njit(cache=True)
def _simulate_free(time_s, wob, use_wob, family, p, top, string, twist0, top_speed0, speed0, integral0, substeps, out_top, out_speed, out_torque, out_surface):  # fmt: skip
    n = time_s.shape[0]
    j_bit = p[0]
    k = p[1]
    c = p[2]
    a_a = p[3]
    a_0 = p[4]
    xi = p[5]
    c_v = p[6] if family >= 1 else 0.0
    tau = p[7] if family >= 2 else 0.0
    j_top, kp, ki, reference = top[0], top[1], top[2], top[3]
    d_top, j_pipe, k_1, c_1 = string[0], string[1], string[2], string[3]
    twist = twist0
    wt = top_speed0
    # With a pipe (j_pipe > 0) the bit-side spring hangs from the pipe, joined to the top
    # drive by (k_1, c_1); it starts at the top speed with the static twist of its spring.
    wp = top_speed0
    twist_1 = (k * twist0 + c * (top_speed0 - speed0)) / k_1 if j_pipe > 0 else 0.0
    w = speed0
    v = abs(speed0)
    integral = integral0
    t_e0 = k * twist + c * (wt - w)
    scale0 = wob[0] if use_wob else 1.0
    direction = 0
    if abs(w) >= 1e-9 or abs(t_e0) > a_a * scale0:
        direction = 1 if (w > 0 or (w == 0 and t_e0 > 0)) else -1
    else:
        w = 0.0
    out_top[0] = wt
    out_speed[0] = w
    out_surface[0] = kp * (reference - wt) + ki * integral
    if direction == 0:
        out_torque[0] = t_e0
    else:
        out_torque[0] = direction * (a_0 + (a_a - a_0) * math.exp(-xi * v)) * scale0 + c_v * w
    for i in range(n - 1):
        h = (time_s[i + 1] - time_s[i]) / substeps
        s0 = wob[i] if use_wob else 1.0
        ds = ((wob[i + 1] - wob[i]) / substeps) if use_wob else 0.0
        t_bit = 0.0
        for s in range(substeps):
            scale = s0 + ds * (s + 0.5)
            error = reference - wt
            u = kp * error + ki * integral
            integral += h * error
            if j_pipe > 0:
                t_1 = k_1 * twist_1 + c_1 * (wt - wp)
                t_e = k * twist + c * (wp - w)
                wt_b = wt + h * (u - d_top * wt - t_1) / j_top
                wp_b = wp + h * (t_1 - t_e) / j_pipe
                twist_1 += h * 0.5 * (wt + wt_b - wp - wp_b)
                twist, w, v, direction, t_bit = _bit_substep(
                    j_bit, k, c, a_a * scale, a_0 * scale, xi, c_v, tau, h, wp, wp_b, twist, w,
                    v, direction,
                )  # fmt: skip
                wp = wp_b
            else:
                t_e = k * twist + c * (wt - w)
                wt_b = wt + h * (u - d_top * wt - t_e) / j_top
                twist, w, v, direction, t_bit = _bit_substep(
                    j_bit, k, c, a_a * scale, a_0 * scale, xi, c_v, tau, h, wt, wt_b, twist, w,
                    v, direction,
                )  # fmt: skip
            wt = wt_b
        if direction == 0:
            t_bit = k * twist + c * (wp if j_pipe > 0 else wt)
        out_top[i + 1] = wt
        out_speed[i + 1] = w
        out_torque[i + 1] = t_bit
        out_surface[i + 1] = kp * (reference - wt) + ki * integral
        if not (abs(w) < 1e9 and abs(twist) < 1e9 and abs(wt) < 1e9 and abs(wp) < 1e9):
            for m in range(i + 2, n):
                out_top[m] = np.nan
                out_speed[m] = np.nan
                out_torque[m] = np.nan
                out_surface[m] = np.nan
            return False
    return True


TOP_DRIVE_KEYS: Final = (
    "inertia_kg_m2",
    "speed_gain_nm_s_rad",
    "integral_gain_nm_rad",
    "reference_speed_rad_s",
)
"""The identified top drive of the free-running mode, in this order: its inertia, the
proportional and integral gains of its PI speed loop, and the loop's speed reference."""
STRING_KEYS: Final = (
    "damping_nm_s_rad",
    "pipe_inertia_kg_m2",
    "pipe_stiffness_nm_rad",
    "pipe_damping_nm_s_rad",
)
"""The optional upper string of the free-running mode, in this order (each 0 when absent):
the top drive's viscous damping to ground, and the pipe inertia between the top drive and
the bit-side spring with the spring and damper that join it to the top drive."""


@njit(cache=True)
def _simulate_top_side(time_s, bit, x, twist0, pipe_speed0, twist_1_0, top_speed0, integral0, substeps, out_top, out_surface):  # fmt: skip
    j_top, d_top, k, c, j_pipe, k_1, c_1 = x[0], x[1], x[2], x[3], x[4], x[5], x[6]
    kp, ki, reference = x[7], x[8], x[9]
    wt = top_speed0
    wp = pipe_speed0
    twist = twist0
    twist_1 = twist_1_0
    integral = integral0
    out_top[0] = wt
    out_surface[0] = kp * (reference - wt) + ki * integral
    for i in range(time_s.shape[0] - 1):
        h = (time_s[i + 1] - time_s[i]) / substeps
        for s in range(substeps):
            f = (s + 0.5) / substeps
            u = kp * (reference - wt) + ki * integral
            integral += h * (reference - wt)
            wb = bit[i] + f * (bit[i + 1] - bit[i])
            if j_pipe > 0:
                t_1 = k_1 * twist_1 + c_1 * (wt - wp)
                t_e = k * twist + c * (wp - wb)
                # Symplectic Euler (speeds first); the caller's step resolves the modes.
                wt += h * (u - d_top * wt - t_1) / j_top
                wp += h * (t_1 - t_e) / j_pipe
                twist_1 += h * (wt - wp)
                twist += h * (wp - wb)
            else:
                wt += h * (u - d_top * wt - k * twist - c * (wt - wb)) / j_top
                twist += h * (wt - wb)
        out_top[i + 1] = wt
        out_surface[i + 1] = kp * (reference - wt) + ki * integral
        if not abs(wt) < 1e9:
            for m in range(i + 2, time_s.shape[0]):
                out_top[m] = np.nan
                out_surface[m] = np.nan
            return False
    return True


def simulate_top_side(
    time_s: npt.NDArray[np.float64],
    bit_speed_rad_s: npt.NDArray[np.float64],
    x: npt.NDArray[np.float64],
    state0: tuple[float, float, float, float, float],
    substeps: int,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """The top drive under its PI speed loop with the string hanging from it down to a
    measured bit speed (a kinematic boundary at the bottom): ``J_t w_t' = u - d_t w_t - T_1``
    with ``u = k_p (r - w_t) + k_i int(r - w_t)``; with a pipe (``J_p > 0``) ``T_1 = k_1
    (th_t - th_p) + c_1 (w_t - w_p)`` and ``J_p w_p' = T_1 - k (th_p - th_b) - c (w_p -
    w_b)``, without one ``T_1 = k (th_t - th_b) + c (w_t - w_b)``. Linear and held by its
    speed loop, so its errors decay; the phase of the measured bit speed drives it.

    Args:
        time_s: Sample times, s, shape ``(n,)``.
        bit_speed_rad_s: Measured bit speed, rad/s, shape ``(n,)`` (linear in between).
        x: ``(J_t, d_t, k, c, J_p, k_1, c_1, k_p, k_i, r)`` in kg m^2, N m s/rad, N m/rad,
            N m s/rad, kg m^2, N m/rad, N m s/rad, N m s/rad, N m/rad, rad/s (``J_p = 0``:
            no pipe).
        state0: ``(twist, pipe speed, upper twist, top speed, integral)`` at ``time_s[0]``
            (rad, rad/s, rad, rad/s, rad; twist is that of the lower spring ``k``, or of the
            only one; ``integral`` the loop's ``int(r - w_t)``).
        substeps: Steps per sample interval (symplectic Euler: they must resolve the modes).

    Returns:
        ``(top_speed_rad_s, surface_torque_nm)``, each shape ``(n,)`` (NaN after a divergence).
    """
    top = np.empty(time_s.shape[0])
    surface = np.empty(time_s.shape[0])
    _simulate_top_side(
        np.ascontiguousarray(time_s, dtype=np.float64),
        np.ascontiguousarray(bit_speed_rad_s, dtype=np.float64),
        np.ascontiguousarray(x, dtype=np.float64), float(state0[0]), float(state0[1]),
        float(state0[2]), float(state0[3]), float(state0[4]), int(substeps), top, surface,
    )  # fmt: skip
    return top, surface


def simulate_free_running(
    time_s: npt.NDArray[np.float64],
    p: npt.NDArray[np.float64],
    family: str,
    top_drive: npt.NDArray[np.float64],
    twist0_rad: float,
    top_speed0_rad_s: float,
    speed0_rad_s: float,
    integral0_rad: float,
    wob_n: npt.NDArray[np.float64] | None = None,
    substeps: int | None = None,
    string: npt.NDArray[np.float64] | None = None,
) -> tuple[
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
    npt.NDArray[np.float64],
]:
    """Simulate the bit and a modelled top drive, so that the plant self-excites.

    The top drive (inertia ``J_t``) follows its PI speed loop: ``J_t w_t' = u - d_t w_t -
    T_e`` with ``u = k_p (r - w_t) + k_i int(r - w_t)``; the bit side is that of
    :func:`simulate_bit`. With a pipe (``string``, :data:`STRING_KEYS`, ``J_p > 0``) the
    bit-side spring hangs from the pipe, which the spring ``k_1`` and damper ``c_1`` join
    to the top drive (it starts at the top speed, its spring at the lower one's torque).

    Args:
        time_s: Output times, s, shape ``(n,)``, strictly increasing.
        p: Model parameter vector, shape ``(N_MODEL_PARAMS,)``.
        family: One of :data:`FAMILIES`.
        top_drive: ``(J_t, k_p, k_i, r)`` in the units of :data:`TOP_DRIVE_KEYS`.
        twist0_rad: Initial twist, rad.
        top_speed0_rad_s: Initial top-drive speed, rad/s.
        speed0_rad_s: Initial bit speed, rad/s.
        integral0_rad: Initial state of the loop's integrator ``int(r - w_t)``, rad.
        wob_n: Weight on bit, N, shape ``(n,)`` (friction per newton of WOB), or None.
        substeps: Steps per output interval (default :func:`substeps_for`, and at least 20
            steps per time constant ``J_t / k_p`` of the speed loop).
        string: ``(d_t, J_p, k_1, c_1)`` (:data:`STRING_KEYS`), or None: all 0 (no pipe,
            no damping to ground).

    Returns:
        ``(top_speed_rad_s, bit_speed_rad_s, bit_torque_nm, surface_torque_nm)``, each shape
        ``(n,)``; NaN after a divergence.
    """
    t = np.ascontiguousarray(time_s, dtype=np.float64)
    params = np.ascontiguousarray(p, dtype=np.float64)
    top = np.ascontiguousarray(top_drive, dtype=np.float64)
    if family not in FAMILY_CODES:
        raise ValueError(f"family = {shown(family)} is not known: allowed {', '.join(FAMILIES)}")
    if top.shape != (4,) or not np.all(np.isfinite(top)) or top[0] <= 0:
        raise ValueError(f"top_drive = {shown(top)}: allowed 4 finite numbers, inertia > 0")
    dt = float(np.median(np.diff(t)))
    n_sub = substeps or substeps_for(params, dt)
    if top[1] > 0:
        n_sub = max(n_sub, int(math.ceil(20 * dt * top[1] / top[0])))
    upper = np.zeros(4) if string is None else np.ascontiguousarray(string, dtype=np.float64)
    if upper.shape != (4,) or not np.all(np.isfinite(upper)) or np.any(upper < 0):
        raise ValueError(f"string = {shown(upper)}: allowed 4 finite numbers >= 0")
    if upper[1] > 0:
        if upper[2] <= 0:
            raise ValueError(f"string = {shown(upper)}: a pipe needs a stiffness > 0")
        fastest = math.sqrt(upper[2] * (1 / top[0] + 1 / upper[1]) + params[P_K] / upper[1])
        n_sub = max(n_sub, int(math.ceil(dt * fastest * 200 / (2 * math.pi))))
        n_sub = max(n_sub, int(math.ceil(10 * dt * upper[3] / min(top[0], upper[1]))))
    if upper[0] > 0:
        n_sub = max(n_sub, int(math.ceil(10 * dt * upper[0] / top[0])))
    use_wob = wob_n is not None
    wob = np.ascontiguousarray(wob_n if use_wob else np.zeros(1), dtype=np.float64)
    outs = [np.empty_like(t) for _ in range(4)]
    _simulate_free(
        t, wob, use_wob, FAMILY_CODES[family], params, top, upper, float(twist0_rad),
        float(top_speed0_rad_s), float(speed0_rad_s), float(integral0_rad), int(n_sub), *outs,
    )  # fmt: skip
    return outs[0], outs[1], outs[2], outs[3]
