"""Compiled dynamics and event-located integrator of a torsional chain (distributed string).

Chain. ``n`` nodes (node 0 the top drive, node ``n - 1`` the bit) with inertias ``J_i`` and
dampers ``d_i`` to ground, joined by ``n - 1`` elements, each a spring ``k_e`` in parallel with a
damper ``c_e`` (:class:`drill_env.distributed.Chain`). The 4-DOF plant is the ``n = 4`` chain.

State. One flat float64 array of length ``2 n - 1``, alternating node speeds and element twists
from the top::

    x = (w_0, phi_0 - phi_1, w_1, phi_1 - phi_2, ..., phi_{n-2} - phi_{n-1}, w_{n-1})

so ``x[2 i]`` is the speed of node ``i`` (rad/s) and ``x[2 e + 1]`` the twist of element ``e``
(rad). A longer array may be passed: only its first ``2 n - 1`` entries are read and written.

Dynamics. Element torque ``tau_e = k_e theta_e + c_e (w_e - w_{e+1})``;
``J_0 w_0' = u - tau_0 - d_0 w_0``; ``J_i w_i' = tau_{i-1} - tau_i - d_i w_i``;
``J_{n-1} w_{n-1}' = tau_{n-2} - d_{n-1} w_{n-1} - T_bit``; ``theta_e' = w_e - w_{e+1}``. The
torque the string applies to the bit is ``T_e = tau_{n-2} - d_{n-1} w_{n-1}`` (linear in the
state) and ``T_bit`` is Karnopp's law of :mod:`drill_env.friction`; a stuck bit has
``w_{n-1}' = 0`` and its speed is exactly 0.

Parameter vector. One flat float64 array per string (:func:`chain_parameter_vector`)::

    p[0]                       n, the number of nodes (a whole number stored as float)
    p[1], p[2]                 mu_a, mu_0 (friction coefficients)
    p[3]                       R, bit radius, m
    p[4]                       xi, Stribeck decline rate, s/rad
    p[5]                       Dw, stick band half-width, rad/s
    p[6       : 6 + n]         1 / J_i, reciprocal node inertias, 1/(kg m^2)
    p[6 + n   : 6 + 2n]        d_i, node damping to ground, N m s/rad
    p[6 + 2n  : 6 + 3n - 1]    k_e, element stiffness, N m/rad
    p[6 + 3n - 1 : 6 + 4n - 2] c_e, element damping, N m s/rad
    p[6 + 4n - 2 :]            zero padding (ignored)

``chain_parameter_length(n) = 4 n + 4`` entries are used; strings of different lengths share a
2-D array ``(n_strings, max_len)`` (:func:`stack_chain_parameters`), each row read through its
own ``p[0]``. The kernel computes ``T_a = p[1] WOB p[3]`` and ``T_0 = p[2] WOB p[3]``.

Integrator. :func:`chain_step` advances one step exactly as the 4-DOF integrator
(:mod:`drill_env.integration`) does: classical RK4 with the bit's slip mode frozen; break-away
located by linear interpolation of ``T_e``; a zero crossing of the bit speed located by three
regula-falsi steps; Karnopp capture inside the stick band. Internally the state is split into
contiguous speed and twist rows of the caller's scratch array ``work``
(``CHAIN_WORK_ROWS x n_max``, :func:`chain_work`) so that the loops vectorise; nothing is
allocated inside a step.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.distributed import (
    Chain,
    DistributedStringParameters,
    chain_from_parameters,
    resolve_plant,
)
from drill_env.friction import STUCK
from drill_env.parameters import PLANT_DT_S, DrillStringParameters
from drill_env.validation import check_int, check_real, shown

__all__ = [
    "CHAIN_HEADER",
    "CHAIN_SPEED_ROW",
    "CHAIN_TWIST_ROW",
    "CHAIN_WORK_ROWS",
    "CP_DW",
    "CP_MU_0",
    "CP_MU_A",
    "CP_N",
    "CP_R",
    "CP_XI",
    "PlantLike",
    "chain_derivative",
    "chain_probe_state",
    "chain_surface_torque",
    "chain_integrate_constant_torque",
    "chain_load_rows",
    "chain_probe_rows",
    "chain_parameter_length",
    "chain_parameter_vector",
    "chain_state_derivative",
    "chain_step",
    "chain_step_checked",
    "chain_step_rows",
    "chain_store_rows",
    "chain_surface_torque_rows",
    "chain_work",
    "stack_chain_parameters",
    "steady_drilling_state",
    "steady_drilling_torque_nm",
]

FloatArray = npt.NDArray[np.float64]
PlantLike = DrillStringParameters | DistributedStringParameters | Chain | str

CP_N: Final = 0
CP_MU_A: Final = 1
CP_MU_0: Final = 2
CP_R: Final = 3
CP_XI: Final = 4
CP_DW: Final = 5
CHAIN_HEADER: Final = 6
"""Entries of the parameter vector before the per-node and per-element arrays."""

# Rows of the scratch array: start state, crossing state, result, RK4 stage, element torques,
# and a copy of the start state that an event is about to overwrite. Every RK4 step runs from
# the START rows into the OUT rows; events copy rows around it.
_START_W, _START_T, _CROSS_W, _CROSS_T, _OUT_W, _OUT_T, _STAGE_W, _STAGE_T, _TAU = range(9)
_KEEP_W, _KEEP_T = 9, 10
CHAIN_WORK_ROWS: Final = 11
"""Rows of the scratch array :func:`chain_step` needs (columns: at least ``n``)."""

_FALSE_POSITION_ITERATIONS = 3


def chain_parameter_length(n_nodes: int) -> int:
    """Entries of the parameter vector used by a chain of ``n_nodes`` nodes: ``4 n + 4``."""
    return CHAIN_HEADER + 4 * n_nodes - 2


def chain_parameter_vector(parameters: PlantLike, length: int | None = None) -> FloatArray:
    """Pack a plant into the flat parameter vector the compiled code reads (layout above).

    Args:
        parameters: A distributed or 4-DOF parameter set, a :class:`Chain`, or a preset name.
        length: Total length, zero-padded; at least ``chain_parameter_length(n)``. Default: no
            padding.

    Raises:
        ValueError: naming ``length`` when it is too short.
    """
    chain = chain_from_parameters(parameters)
    n = chain.n_nodes
    used = chain_parameter_length(n)
    size = used if length is None else check_int("length", length, 0)
    if size < used:
        raise ValueError(f"length = {shown(length)} is out of range: allowed >= {used} for n = {n}")
    p = np.zeros(size)
    p[CP_N] = n
    p[CP_MU_A], p[CP_MU_0], p[CP_R] = chain.mu_a, chain.mu_0, chain.bit_radius_m
    p[CP_XI], p[CP_DW] = chain.xi, chain.Dw
    h = CHAIN_HEADER
    p[h : h + n] = 1.0 / chain.node_inertia_kg_m2
    p[h + n : h + 2 * n] = chain.node_damping_nm_s_rad
    p[h + 2 * n : h + 3 * n - 1] = chain.element_stiffness_nm_rad
    p[h + 3 * n - 1 : h + 4 * n - 2] = chain.element_damping_nm_s_rad
    return p


def stack_chain_parameters(strings: list[PlantLike] | tuple[PlantLike, ...]) -> FloatArray:
    """Parameter vectors of several strings as one zero-padded array ``(n_strings, max_len)``."""
    vectors = [chain_parameter_vector(s) for s in strings]
    if not vectors:
        raise ValueError("strings = [] is out of range: allowed at least one string")
    width = max(v.shape[0] for v in vectors)
    out = np.zeros((len(vectors), width))
    for i, v in enumerate(vectors):
        out[i, : v.shape[0]] = v
    return out


def chain_work(n_max: int) -> FloatArray:
    """Scratch array for :func:`chain_step` on chains of up to ``n_max`` nodes."""
    return np.zeros((CHAIN_WORK_ROWS, check_int("n_max", n_max, 2)))


# ------------------------------------------------------------------------------ compiled core
@njit(cache=True)
def chain_derivative(x, u: float, p, t_a: float, t_0: float, mode: int, dx) -> None:
    """Time derivative of the interleaved state ``x`` into ``dx`` (both length >= 2 n - 1).

    Args:
        x: State (rad/s, rad), layout in the module docstring.
        u: Top-drive torque, N m.
        p: Parameter vector (:func:`chain_parameter_vector`).
        t_a: Maximum static bit torque, N m.
        t_0: Sliding bit torque, N m.
        mode: Bit slip mode: 0 stuck (bit speed held), +1/-1 slipping.
        dx: Output, rad/s^2 and rad/s.
    """
    n = int(p[0])
    h = 6
    tau_prev = u
    for i in range(n - 1):
        w = x[2 * i]
        dw = w - x[2 * i + 2]
        tau = p[h + 2 * n + i] * x[2 * i + 1] + p[h + 3 * n - 1 + i] * dw
        dx[2 * i] = (tau_prev - tau - p[h + n + i] * w) * p[h + i]
        dx[2 * i + 1] = dw
        tau_prev = tau
    m = n - 1
    if mode == STUCK:
        dx[2 * m] = 0.0
    else:
        wb = x[2 * m]
        slip = mode * (t_0 + (t_a - t_0) * math.exp(-p[4] * abs(wb)))
        dx[2 * m] = (tau_prev - p[h + n + m] * wb - slip) * p[h + m]


@njit(cache=True, inline="always")
def _stage(
    n, in_w, in_t, out_w, out_t, w0, t0, acc_w, acc_t, tau, inv_j, d, k, c,
    u, mode, t_a, t_0, xi, a, b, first, last,
):  # fmt: skip
    """One RK4 stage: derivative at (in_w, in_t); acc += b k; out = start + a k.

    ``first``: acc is initialised to start + b k; ``last``: out is not written. in and out may
    be the same rows (each entry is read before it is overwritten).
    """
    m = n - 1
    if first:
        for i in range(m):
            dw = in_w[i] - in_w[i + 1]
            tau[i] = k[i] * in_t[i] + c[i] * dw
            acc_t[i] = t0[i] + b * dw
            out_t[i] = t0[i] + a * dw
    elif last:
        for i in range(m):
            dw = in_w[i] - in_w[i + 1]
            tau[i] = k[i] * in_t[i] + c[i] * dw
            acc_t[i] += b * dw
    else:
        for i in range(m):
            dw = in_w[i] - in_w[i + 1]
            tau[i] = k[i] * in_t[i] + c[i] * dw
            acc_t[i] += b * dw
            out_t[i] = t0[i] + a * dw
    if mode == STUCK:
        kb = 0.0
    else:
        wb = in_w[m]
        slip = mode * (t_0 + (t_a - t_0) * math.exp(-xi * abs(wb)))
        kb = (tau[m - 1] - d[m] * wb - slip) * inv_j[m]
    k0 = (u - tau[0] - d[0] * in_w[0]) * inv_j[0]
    if first:
        for i in range(1, m):
            kw = (tau[i - 1] - tau[i] - d[i] * in_w[i]) * inv_j[i]
            acc_w[i] = w0[i] + b * kw
            out_w[i] = w0[i] + a * kw
        acc_w[0] = w0[0] + b * k0
        out_w[0] = w0[0] + a * k0
        acc_w[m] = w0[m] + b * kb
        out_w[m] = w0[m] + a * kb
    elif last:
        for i in range(1, m):
            kw = (tau[i - 1] - tau[i] - d[i] * in_w[i]) * inv_j[i]
            acc_w[i] += b * kw
        acc_w[0] += b * k0
        acc_w[m] += b * kb
    else:
        for i in range(1, m):
            kw = (tau[i - 1] - tau[i] - d[i] * in_w[i]) * inv_j[i]
            acc_w[i] += b * kw
            out_w[i] = w0[i] + a * kw
        acc_w[0] += b * k0
        out_w[0] = w0[0] + a * k0
        acc_w[m] += b * kb
        out_w[m] = w0[m] + a * kb


@njit(cache=True)
def _rk4(p, n, work, u, t_a, t_0, mode, h) -> None:
    """One classical RK4 step of ``h`` s, slip mode frozen, from the START rows of ``work``
    into its OUT rows; the START rows are left unchanged. (Always the same rows, fixed here: the
    compiler then knows they do not overlap and vectorises the stages, and there is one
    compiled copy of the step.)"""
    o = 6
    inv_j = p[o : o + n]
    d = p[o + n : o + 2 * n]
    k = p[o + 2 * n : o + 3 * n - 1]
    c = p[o + 3 * n - 1 : o + 4 * n - 2]
    xi = p[4]
    w0 = work[_START_W]
    t0 = work[_START_T]
    acc_w = work[_OUT_W]
    acc_t = work[_OUT_T]
    sw = work[_STAGE_W]
    st = work[_STAGE_T]
    tau = work[_TAU]
    half = 0.5 * h
    _stage(n, w0, t0, sw, st, w0, t0, acc_w, acc_t, tau, inv_j, d, k, c,
           u, mode, t_a, t_0, xi, half, h / 6.0, True, False)  # fmt: skip
    _stage(n, sw, st, sw, st, w0, t0, acc_w, acc_t, tau, inv_j, d, k, c,
           u, mode, t_a, t_0, xi, half, h / 3.0, False, False)  # fmt: skip
    _stage(n, sw, st, sw, st, w0, t0, acc_w, acc_t, tau, inv_j, d, k, c,
           u, mode, t_a, t_0, xi, h, h / 3.0, False, False)  # fmt: skip
    _stage(n, sw, st, sw, st, w0, t0, acc_w, acc_t, tau, inv_j, d, k, c,
           u, mode, t_a, t_0, xi, 0.0, h / 6.0, False, True)  # fmt: skip


@njit(cache=True)
def _torque_on_bit(p, n, w, t) -> float:
    """``T_e = k theta + c (w_{n-2} - w_{n-1}) - d_{n-1} w_{n-1}`` at the rows ``w``, ``t``, N m."""
    m = n - 1
    o = 6
    wb = w[m]
    return (
        p[o + 2 * n + m - 1] * t[m - 1]
        + p[o + 3 * n - 1 + m - 1] * (w[m - 1] - wb)
        - p[o + n + m] * wb
    )


@njit(cache=True)
def _copy_rows(n, src_w, src_t, dst_w, dst_t) -> None:
    for i in range(n - 1):
        dst_w[i] = src_w[i]
        dst_t[i] = src_t[i]
    dst_w[n - 1] = src_w[n - 1]


@njit(cache=True)
def _mode_after_stop(p, n, w, t, t_a) -> int:
    """Slip mode of a bit that has just come to rest (bit speed 0 in ``w``)."""
    t_e = _torque_on_bit(p, n, w, t)
    if abs(t_e) <= t_a:
        return STUCK
    return 1 if t_e > 0.0 else -1


@njit(cache=True)
def _slip_step(p, n, work, mode, u, t_a, t_0, h, kept: bool):
    """Advance a slipping bit from the START rows by ``h`` into the OUT rows, stopping it where
    its speed crosses zero (the START rows may then be overwritten, after a copy into the KEEP
    rows unless ``kept``: one is there already). Returns ``(mode, kept)``."""
    m = n - 1
    start_w, start_t = work[_START_W], work[_START_T]
    cross_w, cross_t = work[_CROSS_W], work[_CROSS_T]
    out_w, out_t = work[_OUT_W], work[_OUT_T]
    _rk4(p, n, work, u, t_a, t_0, mode, h)
    wb = out_w[m]
    if mode * wb > 0.0:
        if abs(wb) < p[5] and abs(_torque_on_bit(p, n, out_w, out_t)) <= t_a:
            out_w[m] = 0.0  # Karnopp capture inside the stick band
            return STUCK, kept
        return mode, kept
    # The speed crossed zero inside the step: find the instant by regula falsi on theta.
    lo, hi = 0.0, 1.0
    f_lo, f_hi = start_w[m], wb
    theta = 1.0
    _copy_rows(n, out_w, out_t, cross_w, cross_t)
    for _ in range(_FALSE_POSITION_ITERATIONS):
        if mode * f_lo <= 0.0:  # already at or past zero at the start
            theta = lo
            _copy_rows(n, start_w, start_t, cross_w, cross_t)
            break
        theta = lo + (hi - lo) * f_lo / (f_lo - f_hi)
        _rk4(p, n, work, u, t_a, t_0, mode, theta * h)
        _copy_rows(n, out_w, out_t, cross_w, cross_t)
        f = cross_w[m]
        if mode * f > 0.0:
            lo, f_lo = theta, f
        else:
            hi, f_hi = theta, f
    cross_w[m] = 0.0
    new_mode = _mode_after_stop(p, n, cross_w, cross_t, t_a)
    rest = (1.0 - theta) * h
    if rest <= 0.0:
        _copy_rows(n, cross_w, cross_t, out_w, out_t)
        return new_mode, kept
    if not kept:
        _copy_rows(n, start_w, start_t, work[_KEEP_W], work[_KEEP_T])
    _copy_rows(n, cross_w, cross_t, start_w, start_t)
    _rk4(p, n, work, u, t_a, t_0, new_mode, rest)
    return new_mode, True


@njit(cache=True, inline="always")
def _advance_rows(mode: int, u: float, p, t_a: float, t_0: float, h: float, work):
    """One step from the START rows into the OUT rows; returns the new slip mode and whether
    an event overwrote the START rows (then a copy of them is in the KEEP rows)."""
    n = int(p[0])
    start_w, start_t = work[_START_W], work[_START_T]
    out_w, out_t = work[_OUT_W], work[_OUT_T]
    kept = False
    if mode != STUCK:
        # kept (False here) as a computed bool: the literal False would compile _slip_step twice
        new_mode, kept = _slip_step(p, n, work, mode, u, t_a, t_0, h, mode == STUCK)
    else:
        _rk4(p, n, work, u, t_a, t_0, mode, h)
        te_new = _torque_on_bit(p, n, out_w, out_t)
        if abs(te_new) <= t_a:
            new_mode = STUCK
        else:
            # Break-away inside the step: T_e is linear in the state, so interpolate it.
            te_old = _torque_on_bit(p, n, start_w, start_t)
            limit = t_a if te_new > 0.0 else -t_a
            theta = 0.0
            if te_new != te_old:
                theta = min(max((limit - te_old) / (te_new - te_old), 0.0), 1.0)
            direction = 1 if te_new > 0.0 else -1
            if theta > 0.0:
                _rk4(p, n, work, u, t_a, t_0, mode, theta * h)
                _copy_rows(n, start_w, start_t, work[_KEEP_W], work[_KEEP_T])
                kept = True
                _copy_rows(n, out_w, out_t, start_w, start_t)
            rest = (1.0 - theta) * h
            if rest <= 0.0:
                _copy_rows(n, start_w, start_t, out_w, out_t)
                new_mode = direction
            else:
                new_mode, kept = _slip_step(p, n, work, direction, u, t_a, t_0, rest, kept)
    return new_mode, kept


@njit(cache=True, inline="always")
def _advance_work(x, mode: int, u: float, p, t_a: float, t_0: float, h: float, work) -> int:
    """One step from ``x`` into the OUT rows of ``work``; returns the new slip mode."""
    chain_load_rows(x, p, work)
    new_mode, _ = _advance_rows(mode, u, p, t_a, t_0, h, work)
    return new_mode


@njit(cache=True)
def chain_step(x, mode: int, u: float, p, t_a: float, t_0: float, h: float, work) -> int:
    """Advance the chain by one step of ``h`` seconds under constant top-drive torque ``u``.

    Args:
        x: State (layout in the module docstring), updated IN PLACE; entries beyond
            ``2 n - 1`` are not touched.
        mode: Bit slip mode at the start of the step: 0 (``STUCK``) or +1/-1 (slipping).
        u: Top-drive torque held over the step, N m.
        p: Parameter vector (:func:`chain_parameter_vector`); ``n = int(p[0])``.
        t_a: Maximum static bit torque ``mu_a WOB R``, N m.
        t_0: Sliding bit torque ``mu_0 WOB R``, N m.
        h: Step, s.
        work: Scratch float64 array, shape ``(CHAIN_WORK_ROWS, >= n)`` (:func:`chain_work`).

    Returns:
        The slip mode at the end of the step. A stuck bit's speed is exactly 0.
    """
    new_mode = _advance_work(x, mode, u, p, t_a, t_0, h, work)
    m = int(p[0]) - 1
    for i in range(m):
        x[2 * i] = work[_OUT_W, i]
        x[2 * i + 1] = work[_OUT_T, i]
    x[2 * m] = work[_OUT_W, m]
    return new_mode


@njit(cache=True)
def chain_step_checked(
    x, mode: int, u: float, p, t_a: float, t_0: float, h: float, work, max_speed: float,
    max_twist: float,
):  # fmt: skip
    """:func:`chain_step` that keeps ``x`` unchanged when the new state is not finite or
    beyond the bounds (rad/s for speeds, rad for twists). Returns ``(mode, accepted)``."""
    n = int(p[0])
    m = n - 1
    new_mode = _advance_work(x, mode, u, p, t_a, t_0, h, work)
    for i in range(m):
        w = work[_OUT_W, i]
        t = work[_OUT_T, i]
        if not (abs(w) <= max_speed and abs(t) <= max_twist):  # also false for NaN
            return mode, False
    if not abs(work[_OUT_W, m]) <= max_speed:
        return mode, False
    for i in range(m):
        x[2 * i] = work[_OUT_W, i]
        x[2 * i + 1] = work[_OUT_T, i]
    x[2 * m] = work[_OUT_W, m]
    return new_mode, True


# The kernel keeps a string's state in the START rows of its scratch array for a whole call
# (speeds and twists each contiguous): a step then neither reads nor writes the interleaved
# state, and the probes read contiguous rows. The arithmetic is that of chain_step.
CHAIN_SPEED_ROW: Final = _START_W
"""Row of the scratch array that holds the node speeds between :func:`chain_step_rows`."""
CHAIN_TWIST_ROW: Final = _START_T
"""Row of the scratch array that holds the element twists between :func:`chain_step_rows`."""


@njit(cache=True)
def chain_load_rows(x, p, work) -> None:
    """Copy the interleaved state ``x`` into the speed and twist rows of ``work``."""
    m = int(p[0]) - 1
    start_w, start_t = work[_START_W], work[_START_T]
    for i in range(m):
        start_w[i] = x[2 * i]
        start_t[i] = x[2 * i + 1]
    start_w[m] = x[2 * m]


@njit(cache=True)
def chain_store_rows(work, p, x) -> None:
    """Copy the speed and twist rows of ``work`` into the interleaved state ``x``."""
    m = int(p[0]) - 1
    start_w, start_t = work[_START_W], work[_START_T]
    for i in range(m):
        x[2 * i] = start_w[i]
        x[2 * i + 1] = start_t[i]
    x[2 * m] = start_w[m]


@njit(cache=True)
def chain_step_rows(
    mode: int, u: float, p, t_a: float, t_0: float, h: float, work, max_speed: float,
    max_twist: float,
):  # fmt: skip
    """:func:`chain_step_checked` on the state in the speed and twist rows of ``work``
    (:func:`chain_load_rows`): the rows advance in place, or keep the old state when the new
    one is not finite or beyond the bounds. Returns ``(mode, accepted)``."""
    n = int(p[0])
    m = n - 1
    new_mode, kept = _advance_rows(mode, u, p, t_a, t_0, h, work)
    out_w, out_t = work[_OUT_W], work[_OUT_T]
    accepted = abs(out_w[m]) <= max_speed
    for i in range(m):
        accepted &= abs(out_w[i]) <= max_speed
        accepted &= abs(out_t[i]) <= max_twist  # both false for NaN
    if not accepted:
        if kept:  # an event overwrote the start rows
            _copy_rows(n, work[_KEEP_W], work[_KEEP_T], work[_START_W], work[_START_T])
        return mode, False
    _copy_rows(n, out_w, out_t, work[_START_W], work[_START_T])
    return new_mode, True


@njit(cache=True)
def chain_probe_rows(work, probes):
    """:func:`chain_probe_state` of the state in the rows of ``work``."""
    a, b, c, d = probes[0], probes[1], probes[2], probes[3]
    w, t = work[_START_W], work[_START_T]
    return (
        w[a], _row_sum(t, a, b), w[b], _row_sum(t, b, c), w[c], _row_sum(t, c, d), w[d],
    )  # fmt: skip


@njit(cache=True, inline="always")
def _row_sum(t, first: int, last: int) -> float:
    """:func:`_twist_sum` on the twist row (the same additions in the same order)."""
    s0 = s1 = s2 = s3 = 0.0
    e = first
    while e + 4 <= last:
        s0 += t[e]
        s1 += t[e + 1]
        s2 += t[e + 2]
        s3 += t[e + 3]
        e += 4
    while e < last:
        s0 += t[e]
        e += 1
    return (s0 + s1) + (s2 + s3)


@njit(cache=True)
def chain_surface_torque_rows(work, p) -> float:
    """:func:`chain_surface_torque` of the state in the rows of ``work``, N m."""
    n = int(p[CP_N])
    w, t = work[_START_W], work[_START_T]
    return p[CHAIN_HEADER + 2 * n] * t[0] + p[CHAIN_HEADER + 3 * n - 1] * (w[0] - w[1])


@njit(cache=True)
def chain_probe_state(x, probes):
    """The 4-DOF coordinates of the chain state ``x`` at the probe nodes ``probes`` (4 node
    indices, top to bottom: top drive, pipe, collars, bit; :func:`drill_env.modes.probe_nodes`):
    ``(w_a, phi_a - phi_b, w_b, phi_b - phi_c, w_c, phi_c - phi_d, w_d)``, rad/s and rad, each
    twist the sum of the element twists between two probes."""
    a, b, c, d = probes[0], probes[1], probes[2], probes[3]
    return (
        x[2 * a], _twist_sum(x, a, b), x[2 * b], _twist_sum(x, b, c), x[2 * c],
        _twist_sum(x, c, d), x[2 * d],
    )  # fmt: skip


@njit(cache=True, inline="always")
def _twist_sum(x, first: int, last: int) -> float:
    """Sum of the element twists ``first .. last - 1`` (four running sums: a long string's
    sum is then not one chain of dependent additions)."""
    s0 = s1 = s2 = s3 = 0.0
    e = first
    while e + 4 <= last:
        s0 += x[2 * e + 1]
        s1 += x[2 * e + 3]
        s2 += x[2 * e + 5]
        s3 += x[2 * e + 7]
        e += 4
    while e < last:
        s0 += x[2 * e + 1]
        e += 1
    return (s0 + s1) + (s2 + s3)


@njit(cache=True)
def chain_surface_torque(x, p) -> float:
    """Torque at the top of the string, N m: the top element's ``k theta + c (w_0 - w_1)``."""
    n = int(p[CP_N])
    return p[CHAIN_HEADER + 2 * n] * x[1] + p[CHAIN_HEADER + 3 * n - 1] * (x[0] - x[2])


@njit(cache=True)
def _integrate(x0, mode0, p, t_a, t_0, u, h, n_steps, every, out_x, out_mode, work) -> None:
    size = out_x.shape[1]
    x = x0.copy()
    mode = mode0
    out_x[0, :] = x
    out_mode[0] = mode
    for i in range(n_steps):
        mode = chain_step(x, mode, u, p, t_a, t_0, h, work)
        if (i + 1) % every == 0:
            row = (i + 1) // every
            for j in range(size):
                out_x[row, j] = x[j]
            out_mode[row] = mode


# --------------------------------------------------------------------------- numpy helpers
def _wob(wob_n: float) -> float:
    return _positive("wob_n", wob_n)


def _positive(name: str, value: object) -> float:
    """``value`` as a float if it is a finite real number > 0; else the validation family's
    error naming ``name``, the value shown bounded and escaped."""
    v = check_real(name, value, "a finite number > 0")
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed > 0")
    return v


def _state(x: npt.ArrayLike | None, size: int, name: str) -> FloatArray:
    if x is None:
        return np.zeros(size)
    state = np.array(x, dtype=np.float64)
    if state.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {state.shape}")
    if not np.all(np.isfinite(state)):
        raise ValueError(f"{name} must be finite")
    return state


def chain_state_derivative(
    x: npt.ArrayLike, torque_nm: float, parameters: PlantLike, wob_n: float, bit_stuck: bool
) -> FloatArray:
    """``dx/dt`` of the chain at state ``x`` (shape ``(2 n - 1,)``) for numpy users.

    Args:
        x: State, rad/s and rad.
        torque_nm: Top-drive torque, N m.
        parameters: Plant (either kind, a :class:`Chain` or a preset name).
        wob_n: Weight on bit, N (> 0).
        bit_stuck: Whether the bit is held by static friction (its speed must then be 0).
    """
    chain = chain_from_parameters(resolve_plant(parameters))
    state = _state(x, chain.state_size, "x")
    wob = _wob(wob_n)
    mode = STUCK if bit_stuck else (1 if state[-1] >= 0 else -1)
    dx = np.empty_like(state)
    chain_derivative(
        state,
        float(torque_nm),
        chain_parameter_vector(chain),
        chain.static_torque_nm(wob),
        chain.sliding_torque_nm(wob),
        mode,
        dx,
    )
    return dx


def chain_integrate_constant_torque(
    parameters: PlantLike,
    torque_nm: float,
    wob_n: float,
    duration_s: float,
    step_s: float = PLANT_DT_S,
    initial_state: npt.ArrayLike | None = None,
    record_every: int = 1,
) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """Open-loop run of the chain under a constant top-drive torque, from rest by default.

    Args:
        parameters: Plant (either kind, a :class:`Chain` or a preset name).
        torque_nm: Top-drive torque, N m.
        wob_n: Weight on bit, N (> 0).
        duration_s: Length of the run, s (> 0).
        step_s: Integration step, s (> 0).
        initial_state: State at t = 0, shape ``(2 n - 1,)``; rest (bit stuck) by default. The bit
            starts stuck when its speed is exactly 0, else slipping in the direction of its speed.
        record_every: Keep every ``record_every``-th step (long runs of long strings).

    Returns:
        ``(states, modes)``: states at ``t = k record_every step_s`` for ``k = 0..N /
        record_every``, shape ``(N / record_every + 1, 2 n - 1)``, and the slip mode at each of
        those instants, where ``N = round(duration_s / step_s)``.
    """
    chain = chain_from_parameters(resolve_plant(parameters))
    wob = _wob(wob_n)
    step_s = _positive("step_s", step_s)
    duration_s = _positive("duration_s", duration_s)
    torque_nm = check_real("torque_nm", torque_nm)
    if not math.isfinite(torque_nm):
        raise ValueError(f"torque_nm = {shown(torque_nm)} is out of range: allowed a finite number")
    x0 = _state(initial_state, chain.state_size, "initial_state")
    mode0 = STUCK if x0[-1] == 0.0 else (1 if x0[-1] > 0 else -1)
    if isinstance(record_every, bool) or not isinstance(record_every, (int, np.integer)):
        raise TypeError(f"record_every must be an integer, got {shown(record_every)}")
    if record_every < 1:
        raise ValueError(f"record_every = {shown(record_every)} is out of range: allowed >= 1")
    record_every = check_int("record_every", record_every, 1, np.iinfo(np.int64).max)
    n_steps = round(duration_s / step_s)
    rows = n_steps // int(record_every) + 1
    out_x = np.empty((rows, chain.state_size))
    out_mode = np.empty(rows, dtype=np.int64)
    _integrate(
        x0,
        mode0,
        chain_parameter_vector(chain),
        chain.static_torque_nm(wob),
        chain.sliding_torque_nm(wob),
        float(torque_nm),
        float(step_s),
        n_steps,
        int(record_every),
        out_x,
        out_mode,
        chain_work(chain.n_nodes),
    )
    return out_x, out_mode


def steady_drilling_torque_nm(parameters: PlantLike, wob_n: float, bit_speed_rad_s: float) -> float:
    """Top-drive torque holding every node at one speed ``V > 0``, N m.

    With all speeds equal the element dampers carry nothing, so
    ``u = (sum of damping to ground) V + T_0 + (T_a - T_0) exp(-xi V)``.
    """
    chain = chain_from_parameters(resolve_plant(parameters))
    return float(steady_drilling_state(chain, wob_n, bit_speed_rad_s)[1])


def steady_drilling_state(
    parameters: PlantLike, wob_n: float, bit_speed_rad_s: float
) -> tuple[FloatArray, float]:
    """State and torque of steady drilling at bit speed ``V > 0`` (all nodes at speed ``V``).

    Element ``e`` carries the torque needed below it, ``tau_e = V sum_{i > e} d_i + T_bit(V)``,
    so its twist is ``tau_e / k_e``; the top drive supplies ``u = tau_0 + d_0 V``.

    Returns:
        ``(x, u)``: the state, shape ``(2 n - 1,)``, and the top-drive torque in N m.
    """
    chain = chain_from_parameters(resolve_plant(parameters))
    wob = _wob(wob_n)
    v = _positive("bit_speed_rad_s", bit_speed_rad_s)
    t_a, t_0 = chain.static_torque_nm(wob), chain.sliding_torque_nm(wob)
    t_bit = t_0 + (t_a - t_0) * math.exp(-chain.xi * v)
    d = chain.node_damping_nm_s_rad
    below = np.cumsum(d[::-1])[::-1]  # below[i] = sum_{j >= i} d_j
    tau = v * below[1:] + t_bit
    x = np.empty(chain.state_size)
    x[0::2] = v
    x[1::2] = tau / chain.element_stiffness_nm_rad
    return x, float(tau[0] + d[0] * v)
