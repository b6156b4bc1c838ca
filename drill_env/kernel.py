"""The compiled closed-loop engine: a batch of strings, their exogenous signals, measurement
noise and an in-loop controller, advanced by many plant steps in one call.

Per plant step ``j`` of string ``i`` (time ``t_j = step_index * dt``):

1. WOB and reference speed are read from piecewise-linear knot tables (a repeated knot time
   makes a step change);
2. the measurement vector (``drill_env.layout.M_*``) is the true state plus
   ``noise_std * noise[i, j]`` on the four speeds;
3. the base torque ``u_base`` comes from the compiled law at ``law_address``
   (:mod:`drill_env.control`), or from ``base_torque[i]`` when there is none (0 N m without a
   base controller; a Python controller's torque on the slow path);
4. the applied torque is ``clip(u_base + command[i], u_min, u_max)`` held over the step;
5. the pre-step state, torques, reference, WOB, stuck flag and the law's error signal and
   adaptive gain are written to ``records``, the reward sums and end state to ``report``;
6. :func:`drill_env.integration.plant_step` advances the state.

A state that is not finite or leaves the physical bounds (``drill_env.limits``) is not
accepted: the string keeps its last good state, its status becomes ``STATUS_DIVERGED`` and it
is not advanced again. At the end of the call the observation of every string is written from
its source vector (``drill_env.layout.SRC_*``) through the observation's source indices and
scales.

The kernel's inputs travel as two named tuples, :class:`BatchArrays` (the per-string arrays,
updated in place) and :class:`LoopSettings` (what the batch shares).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numba
import numpy as np
import numpy.typing as npt
from numba import njit, prange

from drill_env.control import call_law
from drill_env.friction import STUCK
from drill_env.integration import plant_step
from drill_env.layout import (
    M_STATE,
    N_RECORD,
    N_STATE,
    OBS_BOUND,
    P_MU_0,
    P_MU_A,
    P_R,
    REC_BASE_TORQUE,
    REC_LAW_ERROR,
    REC_LAW_GAIN,
    REC_REFERENCE,
    REC_STUCK,
    REC_TORQUE,
    REC_WOB,
    REC_X0,
    REP_BASE_TORQUE,
    REP_BIT_SPEED,
    REP_BIT_STUCK,
    REP_LAW_ERROR,
    REP_LAW_GAIN,
    REP_REFERENCE,
    REP_RESIDUAL_SQUARED,
    REP_STATUS,
    REP_STEPS,
    REP_STUCK_STEPS,
    REP_TIME,
    REP_TOP_DRIVE_SPEED,
    REP_TORQUE,
    REP_TORQUE_SQUARED,
    REP_TRACKING_SUM,
    REP_VARIATION,
    REP_WOB,
    SRC_BASE_TORQUE,
    SRC_LAST_TORQUE,
    SRC_LAW_ERROR,
    SRC_MEASUREMENT,
    SRC_REFERENCE,
    STATUS_DIVERGED,
    STATUS_OK,
    X_BIT_SPEED,
    X_TOP_DRIVE_SPEED,
)
from drill_env.limits import MAX_SPEED_RAD_S, MAX_TWIST_RAD
from drill_env.rewards import tracking_error
from drill_env.scenarios import profile_value

__all__ = [
    "BatchArrays",
    "LoopSettings",
    "advance_batch",
    "advance_batch_parallel",
    "fast_entry",
    "fill_sources",
    "write_observation",
    "write_report",
]


class BatchArrays(NamedTuple):
    """The per-string arrays of a batch of N strings (K profile knots, B noise rows); the
    kernel updates them in place.

    Attributes:
        x: States, (N, 7) float64, rad/s and rad.
        mode: Slip modes, (N,) int64 (0 stuck, +1/-1 slipping).
        step_index: Plant steps taken so far, (N,) int64; time is ``step_index * dt``.
        status: (N,) int64 ``STATUS_*``; strings not OK at the start are not advanced
            (records NaN, reward sums 0).
        plant: Plant parameter vectors, (N, N_PLANT_PARAMS).
        wob_t, wob_v, wob_n: WOB knot times (s), values (N) and counts, (N, K), (N, K), (N,).
        ref_t, ref_v, ref_n: Reference-speed knots (s, rad/s), same shapes.
        noise: Standard normal draws, (N, B, 4), B > noise_pos + n_sub: row noise_pos + j is
            the speed noise at step j, row noise_pos + n_sub that of the final measurement
            (which is also the next call's first step: the same instant).
        noise_pos: (N,) int64, the row of the current measurement; advanced by n_sub.
        noise_std: Measurement noise on the speeds, (N,), rad/s.
        law_params, law_state: (N, P) and (N, S) vectors of the compiled law.
        measurement: Scratch, (N, N_MEASUREMENT): the measurement vector the law reads.
        command: Torque added to the base torque (the whole torque without one), (N,), N m.
        base_torque: The base torque when there is no compiled law, (N,), N m.
        last_u: Torque applied in the step before this call, (N,), N m; updated.
        records: Output, (N, n_sub, N_RECORD): the pre-step record of every plant step (NaN
            for steps not taken).
        report: Output, (N, N_REPORT): the reward sums of this call and the end state.
        sources: Scratch, (N, N_SOURCES): what the observation entries show.
        obs: Output, (N, obs_size) float32: the observation at the end.
    """

    x: npt.NDArray[np.float64]
    mode: npt.NDArray[np.int64]
    step_index: npt.NDArray[np.int64]
    status: npt.NDArray[np.int64]
    plant: npt.NDArray[np.float64]
    wob_t: npt.NDArray[np.float64]
    wob_v: npt.NDArray[np.float64]
    wob_n: npt.NDArray[np.int64]
    ref_t: npt.NDArray[np.float64]
    ref_v: npt.NDArray[np.float64]
    ref_n: npt.NDArray[np.int64]
    noise: npt.NDArray[np.float64]
    noise_pos: npt.NDArray[np.int64]
    noise_std: npt.NDArray[np.float64]
    law_params: npt.NDArray[np.float64]
    law_state: npt.NDArray[np.float64]
    measurement: npt.NDArray[np.float64]
    command: npt.NDArray[np.float64]
    base_torque: npt.NDArray[np.float64]
    last_u: npt.NDArray[np.float64]
    records: npt.NDArray[np.float64]
    report: npt.NDArray[np.float64]
    sources: npt.NDArray[np.float64]
    obs: npt.NDArray[np.float32]


class LoopSettings(NamedTuple):
    """What every string of the batch shares.

    Attributes:
        law_address: Address of the compiled law (:class:`drill_env.control.CompiledLaw`); 0
            for none.
        error_slot: State index of the law's error signal, -1 for none.
        gain_slot: State index of the law's adaptive gain, -1 for none.
        u_min, u_max: Top-drive torque limits, N m.
        n_sub: Plant steps per call.
        dt: Plant step, s.
        obs_source: Source-vector entry of each observation entry, (obs_size,) int64.
        obs_scale: Factor of each observation entry, (obs_size,).
    """

    law_address: int
    error_slot: int
    gain_slot: int
    u_min: float
    u_max: float
    n_sub: int
    dt: float
    obs_source: npt.NDArray[np.int64]
    obs_scale: npt.NDArray[np.float64]


@njit(cache=True)
def _in_bounds(x) -> bool:
    for k in range(N_STATE):
        v = x[k]
        if not math.isfinite(v):
            return False
        limit = MAX_SPEED_RAD_S if k % 2 == 0 else MAX_TWIST_RAD
        if abs(v) > limit:
            return False
    return True


@njit(cache=True)
def _measure(out, x, noise_std: float, noise_row) -> None:
    """The measurement vector: speeds with their noise, twists exact."""
    out[M_STATE] = x[0] + noise_std * noise_row[0]
    out[M_STATE + 1] = x[1]
    out[M_STATE + 2] = x[2] + noise_std * noise_row[1]
    out[M_STATE + 3] = x[3]
    out[M_STATE + 4] = x[4] + noise_std * noise_row[2]
    out[M_STATE + 5] = x[5]
    out[M_STATE + 6] = x[6] + noise_std * noise_row[3]


@njit(cache=True)
def _slot(ls, slot: int) -> float:
    return ls[slot] if slot >= 0 else 0.0


@njit(cache=True)
def _advance_one(i, b, s):
    p = b.plant[i]
    xs = b.x[i]
    xi = (xs[0], xs[1], xs[2], xs[3], xs[4], xs[5], xs[6])
    mi = b.mode[i]
    lp = b.law_params[i]
    ls = b.law_state[i]
    meas = b.measurement[i]
    rep = b.report[i]
    mu_a_r = p[P_MU_A] * p[P_R]
    mu_0_r = p[P_MU_0] * p[P_R]
    k = b.step_index[i]
    row = b.noise_pos[i]
    active = b.status[i] == STATUS_OK
    command = b.command[i]
    u_prev = b.last_u[i]
    u_base_last = rep[REP_BASE_TORQUE]
    wob = rep[REP_WOB]
    tracking = 0.0
    variation = 0.0
    torque_squared = 0.0
    residual_squared = 0.0
    stuck = 0.0
    n_done = 0
    for j in range(s.n_sub):
        if b.status[i] != STATUS_OK:
            for c in range(N_RECORD):
                b.records[i, j, c] = math.nan
            continue
        t = k * s.dt
        wob = profile_value(b.wob_t[i], b.wob_v[i], b.wob_n[i], t)
        ref = profile_value(b.ref_t[i], b.ref_v[i], b.ref_n[i], t)
        _measure(meas, xi, b.noise_std[i], b.noise[i, row + j])
        gain = _slot(ls, s.gain_slot)  # the gain this step's torque uses (the law advances it)
        u_base: float
        if s.law_address != 0:
            u_base = call_law(s.law_address, lp, ls, meas, ref, s.dt)  # type: ignore[call-arg]
        else:
            u_base = b.base_torque[i]
        u = min(max(u_base + command, s.u_min), s.u_max)
        rec = b.records[i, j]
        for c in range(N_STATE):
            rec[REC_X0 + c] = xi[c]
        rec[REC_TORQUE] = u
        rec[REC_REFERENCE] = ref
        rec[REC_BASE_TORQUE] = u_base
        rec[REC_STUCK] = 1.0 if mi == STUCK else 0.0
        rec[REC_WOB] = wob
        rec[REC_LAW_ERROR] = _slot(ls, s.error_slot)
        rec[REC_LAW_GAIN] = gain
        tracking += tracking_error(ref, xi[X_BIT_SPEED])
        variation += abs(u - u_prev)
        torque_squared += u * u
        residual_squared += (u - u_base) * (u - u_base)
        u_prev = u
        u_base_last = u_base
        if mi == STUCK:
            stuck += 1.0
        n_done += 1
        xn, mn = plant_step(xi, mi, u, p, mu_a_r * wob, mu_0_r * wob, s.dt)
        if _in_bounds(xn) and math.isfinite(u):
            xi, mi = xn, mn
            k += 1
        else:
            b.status[i] = STATUS_DIVERGED
    rep[REP_TRACKING_SUM] = tracking
    rep[REP_VARIATION] = variation
    rep[REP_STUCK_STEPS] = stuck
    rep[REP_STEPS] = n_done
    rep[REP_TORQUE_SQUARED] = torque_squared
    rep[REP_RESIDUAL_SQUARED] = residual_squared
    if not active:
        return
    for c in range(N_STATE):
        xs[c] = xi[c]
    b.mode[i] = mi
    b.step_index[i] = k
    b.last_u[i] = u_prev
    row += s.n_sub
    b.noise_pos[i] = row
    ref_end = profile_value(b.ref_t[i], b.ref_v[i], b.ref_n[i], k * s.dt)
    _measure(meas, xi, b.noise_std[i], b.noise[i, row])
    error = _slot(ls, s.error_slot)
    fill_sources(b.sources[i], meas, ref_end, u_prev, u_base_last, error)
    write_observation(b.obs[i], b.sources[i], s.obs_source, s.obs_scale)
    write_report(
        rep, xi, mi, k * s.dt, ref_end, u_prev, wob, u_base_last, error,
        _slot(ls, s.gain_slot), b.status[i],
    )  # fmt: skip


@njit(cache=True)
def write_report(out, xi, mi, t, ref, u_last, wob, u_base, error, gain, state_status):
    """Fill the state part of one report row (everything but the reward sums)."""
    out[REP_TIME] = t
    out[REP_BIT_SPEED] = xi[X_BIT_SPEED]
    out[REP_TOP_DRIVE_SPEED] = xi[X_TOP_DRIVE_SPEED]
    out[REP_REFERENCE] = ref
    out[REP_TORQUE] = u_last
    out[REP_WOB] = wob
    out[REP_BIT_STUCK] = 1.0 if mi == STUCK else 0.0
    out[REP_BASE_TORQUE] = u_base
    out[REP_LAW_ERROR] = error
    out[REP_LAW_GAIN] = gain
    out[REP_STATUS] = state_status


@njit(cache=True)
def fill_sources(out, meas, ref: float, u_last: float, u_base: float, error: float) -> None:
    """Fill one source vector (``drill_env.layout.SRC_*``)."""
    for c in range(N_STATE):
        out[SRC_MEASUREMENT + c] = meas[M_STATE + c]
    out[SRC_REFERENCE] = ref
    out[SRC_LAST_TORQUE] = u_last
    out[SRC_BASE_TORQUE] = u_base
    out[SRC_LAW_ERROR] = error


@njit(cache=True)
def write_observation(out, sources, source_index, scale) -> None:
    """Fill one observation row: entry ``c`` is ``sources[source_index[c]] * scale[c]``; NaN
    becomes 0 and everything is clipped to ``+-OBS_BOUND``."""
    for c in range(out.shape[0]):
        v = sources[source_index[c]] * scale[c]
        if not math.isfinite(v):
            v = 0.0 if math.isnan(v) else (OBS_BOUND if v > 0 else -OBS_BOUND)
        out[c] = min(max(v, -OBS_BOUND), OBS_BOUND)


@njit(cache=True)
def _check_noise_room(noise, noise_pos, n_sub):
    for i in range(noise_pos.shape[0]):
        if noise_pos[i] < 0 or noise_pos[i] + n_sub >= noise.shape[1]:
            raise ValueError("noise block too short for n_sub steps: refill it first")


@njit(cache=True)
def advance_batch(b, s):
    """Advance every string of the batch ``b`` (:class:`BatchArrays`) by ``s.n_sub`` plant steps
    of ``s.dt`` seconds under the settings ``s`` (:class:`LoopSettings`)."""
    _check_noise_room(b.noise, b.noise_pos, s.n_sub)
    for i in range(b.x.shape[0]):
        _advance_one(i, b, s)


@njit(cache=True, parallel=True)
def advance_batch_parallel(b, s):
    """:func:`advance_batch` with the strings spread over numba's threads (large batches)."""
    _check_noise_room(b.noise, b.noise_pos, s.n_sub)
    for i in prange(b.x.shape[0]):
        _advance_one(i, b, s)


def fast_entry(dispatcher: Any, *args: Any) -> Callable[..., None]:
    """The compiled entry point of ``dispatcher`` for the types of ``args`` (compiled, or loaded
    from numba's cache, now), which skips numba's per-call type dispatch (about 1 us for the
    kernel's arguments). Every later call must pass arguments of the same types."""
    signature = tuple(numba.typeof(a) for a in args)
    entry = dispatcher.compile(signature)
    return entry if callable(entry) else dispatcher
