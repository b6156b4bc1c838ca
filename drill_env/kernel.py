"""The compiled closed-loop engine: a batch of strings, their exogenous signals, measurement
noise and an in-loop controller, advanced by many plant steps in one call.

Per plant step ``j`` of string ``i`` (time ``t_j = step_index * dt``):

1. WOB and reference speed are read from piecewise-linear knot tables (a repeated knot time
   makes a step change);
2. the measured state is the true state plus ``noise_std * noise[i, j]`` on the four speeds;
3. the base torque ``u_base`` comes from the compiled law ``law`` (0 N m for ``LAW_NONE``);
4. the applied torque is ``clip(u_base + command[i], u_min, u_max)`` held over the step;
5. the pre-step state, torques, reference, WOB, stuck flag and the law's sliding variable and
   adaptive gain are written to ``records``, the reward terms and end state to ``report``;
6. :func:`drill_env.integration.plant_step` advances the state.

A state that is not finite or leaves the physical bounds (speeds beyond ``MAX_SPEED_RAD_S``,
twists beyond ``MAX_TWIST_RAD``) is not accepted: the string keeps its last good state, its
``status`` becomes ``STATUS_DIVERGED`` and it is not advanced again.
"""

from __future__ import annotations

import math
from typing import Final

from numba import njit, prange

from drill_env.control_laws import control_torque
from drill_env.friction import STUCK
from drill_env.integration import plant_step
from drill_env.observation import OBS_BOUND
from drill_env.scenarios import profile_value

__all__ = [
    "MAX_SPEED_RAD_S",
    "MAX_TWIST_RAD",
    "N_RECORD",
    "STATUS_DIVERGED",
    "STATUS_OK",
    "advance_batch",
    "advance_batch_parallel",
]

MAX_SPEED_RAD_S: Final = 1000.0
"""Physical bound on every speed, rad/s; beyond it the run counts as diverged."""
MAX_TWIST_RAD: Final = 1000.0
"""Physical bound on every twist, rad; beyond it the run counts as diverged."""

STATUS_OK: Final = 0
STATUS_DIVERGED: Final = 1
STATUS_PAUSED: Final = 2  # skipped by the kernel (a string that is being reset)

# Columns of the per-plant-step records.
REC_X0: Final = 0  # columns 0..6: state at the start of the step
REC_TORQUE: Final = 7  # applied top-drive torque, N m
REC_REFERENCE: Final = 8  # reference bit speed, rad/s
REC_BASE_TORQUE: Final = 9  # base controller torque before the command, N m
REC_STUCK: Final = 10  # 1.0 when the bit is stuck at the start of the step
REC_WOB: Final = 11  # weight on bit, N
REC_SLIDING: Final = 12  # the law's sliding variable at this step (or 0), rad/s
REC_GAIN: Final = 13  # the law's adaptive gain used at this step (or 0)
N_RECORD: Final = 14

# Columns of the per-string report written at the end of every call (one .tolist() gives the
# env everything it needs for reward and info).
REP_TRACKING: Final = 0  # mean of min(|V_ref - x7| / max(V_ref, 1 rad/s), 1) over the steps
REP_VARIATION: Final = 1  # total variation of the applied torque over the steps, N m
REP_STUCK_FRACTION: Final = 2  # share of the steps with the bit stuck
REP_TIME: Final = 3  # time at the end, s
REP_BIT_SPEED: Final = 4  # true bit speed, rad/s
REP_TOP_DRIVE_SPEED: Final = 5  # true top-drive speed, rad/s
REP_REFERENCE: Final = 6  # reference bit speed at the end, rad/s
REP_TORQUE: Final = 7  # last applied torque, N m
REP_WOB: Final = 8  # weight on bit of the last step, N
REP_BIT_STUCK: Final = 9  # 1.0 when the bit is stuck at the end
REP_BASE_TORQUE: Final = 10  # last base-controller torque, N m
REP_SLIDING: Final = 11  # the law's sliding variable, rad/s
REP_GAIN: Final = 12  # the law's adaptive gain
REP_STATUS: Final = 13  # STATUS_* as a float
N_REPORT: Final = 14


@njit(cache=True)
def _in_bounds(x) -> bool:
    for k in range(7):
        v = x[k]
        if not math.isfinite(v):
            return False
        limit = MAX_SPEED_RAD_S if k % 2 == 0 else MAX_TWIST_RAD
        if abs(v) > limit:
            return False
    return True


@njit(cache=True)
def _measure(x, noise_std: float, noise_row):
    return (
        x[0] + noise_std * noise_row[0],
        x[1],
        x[2] + noise_std * noise_row[1],
        x[3],
        x[4] + noise_std * noise_row[2],
        x[5],
        x[6] + noise_std * noise_row[3],
    )


@njit(cache=True)
def _advance_one(
    i, x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
    noise, noise_pos, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
    records, last_u, report, obs_scale, obs_out,
):  # fmt: skip
    p = plant[i]
    xi = (x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5], x[i, 6])
    mi = mode[i]
    lp = law_params[i]
    ls = law_state[i]
    mu_a_r = p[13] * p[12]
    mu_0_r = p[14] * p[12]
    k = step_index[i]
    row = noise_pos[i]
    active = status[i] == STATUS_OK
    u_prev = last_u[i]
    u_base_last = report[i, REP_BASE_TORQUE]
    wob = report[i, REP_WOB]
    tracking = 0.0
    variation = 0.0
    stuck = 0.0
    n_done = 0
    for j in range(n_sub):
        if status[i] != STATUS_OK:
            for c in range(N_RECORD):
                records[i, j, c] = math.nan
            continue
        t = k * dt
        wob = profile_value(wob_t[i], wob_v[i], wob_n[i], t)
        ref = profile_value(ref_t[i], ref_v[i], ref_n[i], t)
        m = _measure(xi, noise_std[i], noise[i, row + j])
        gain = ls[2]  # the adaptive gain this step's torque uses (the law advances it)
        u_base = control_torque(law, lp, ls, m, ref, dt)
        u = min(max(u_base + command[i], u_min), u_max)
        for c in range(7):
            records[i, j, REC_X0 + c] = xi[c]
        records[i, j, REC_TORQUE] = u
        records[i, j, REC_REFERENCE] = ref
        records[i, j, REC_BASE_TORQUE] = u_base
        records[i, j, REC_STUCK] = 1.0 if mi == STUCK else 0.0
        records[i, j, REC_WOB] = wob
        records[i, j, REC_SLIDING] = ls[3]
        records[i, j, REC_GAIN] = gain
        tracking += min(abs(ref - xi[6]) / max(ref, 1.0), 1.0)
        variation += abs(u - u_prev)
        u_prev = u
        u_base_last = u_base
        if mi == STUCK:
            stuck += 1.0
        n_done += 1
        xn, mn = plant_step(xi, mi, u, p, mu_a_r * wob, mu_0_r * wob, dt)
        if _in_bounds(xn) and math.isfinite(u):
            xi, mi = xn, mn
            k += 1
        else:
            status[i] = STATUS_DIVERGED
    if not active:
        report[i, REP_TRACKING] = 0.0
        report[i, REP_VARIATION] = 0.0
        report[i, REP_STUCK_FRACTION] = 0.0
        return
    for c in range(7):
        x[i, c] = xi[c]
    mode[i] = mi
    step_index[i] = k
    last_u[i] = u_prev
    row += n_sub
    noise_pos[i] = row
    ref_end = profile_value(ref_t[i], ref_v[i], ref_n[i], k * dt)
    m = _measure(xi, noise_std[i], noise[i, row])
    write_observation(obs_out[i], m, ref_end, u_prev, u_base_last, ls[3], obs_scale)
    report[i, REP_TRACKING] = tracking / max(n_done, 1)
    report[i, REP_VARIATION] = variation
    report[i, REP_STUCK_FRACTION] = stuck / max(n_done, 1)
    write_report(report[i], xi, mi, k * dt, ref_end, u_prev, wob, u_base_last, ls, status[i])


@njit(cache=True)
def write_report(out, xi, mi, t, ref, u_last, wob, u_base, ls, state_status):
    """Fill the state part of one report row (everything but the reward terms)."""
    out[REP_TIME] = t
    out[REP_BIT_SPEED] = xi[6]
    out[REP_TOP_DRIVE_SPEED] = xi[0]
    out[REP_REFERENCE] = ref
    out[REP_TORQUE] = u_last
    out[REP_WOB] = wob
    out[REP_BIT_STUCK] = 1.0 if mi == STUCK else 0.0
    out[REP_BASE_TORQUE] = u_base
    out[REP_SLIDING] = ls[3]
    out[REP_GAIN] = ls[2]
    out[REP_STATUS] = state_status


@njit(cache=True)
def write_observation(out, m, ref: float, u_last: float, u_base: float, sliding: float, scale):
    """Fill one observation row: scaled measured state, reference, last torque and (when the
    row is 11 long) base torque and sliding variable; NaN becomes 0, all clipped to the bound."""
    n = out.shape[0]
    for c in range(n):
        if c < 7:
            v = m[c]
        elif c == 7:
            v = ref
        elif c == 8:
            v = u_last
        elif c == 9:
            v = u_base
        else:
            v = sliding
        v *= scale[c]
        if not math.isfinite(v):
            v = 0.0 if math.isnan(v) else (OBS_BOUND if v > 0 else -OBS_BOUND)
        out[c] = min(max(v, -OBS_BOUND), OBS_BOUND)


@njit(cache=True)
def _check_noise_room(noise, noise_pos, n_sub):
    for i in range(noise_pos.shape[0]):
        if noise_pos[i] < 0 or noise_pos[i] + n_sub >= noise.shape[1]:
            raise ValueError("noise block too short for n_sub steps: refill it first")


@njit(cache=True)
def advance_batch(
    x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
    noise, noise_pos, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
    records, last_u, report, obs_scale, obs_out,
):  # fmt: skip
    """Advance every string of the batch by ``n_sub`` plant steps of ``dt`` seconds.

    Args (N strings, K knots, P/S law vector lengths; arrays are updated in place):
        x: States, (N, 7) float64, rad/s and rad.
        mode: Slip modes, (N,) int64 (0 stuck, +1/-1 slipping).
        step_index: Plant steps taken so far, (N,) int64; time is ``step_index * dt``.
        status: (N,) int64, ``STATUS_OK``, ``STATUS_DIVERGED`` or ``STATUS_PAUSED``; strings
            not OK at the start are not advanced (records NaN, reward terms 0).
        plant: Plant parameter vectors, (N, N_PLANT_PARAMS).
        wob_t, wob_v, wob_n: WOB knot times (s), values (N) and counts, (N, K), (N, K), (N,).
        ref_t, ref_v, ref_n: Reference-speed knots (s, rad/s), same shapes.
        noise: Standard normal draws, (N, B, 4), B > noise_pos + n_sub: row noise_pos + j is
            the speed noise at step j, row noise_pos + n_sub that of the final measurement
            (which is also the next call's first step: the same instant).
        noise_pos: (N,) int64, the row of the current measurement; advanced by n_sub.
        noise_std: Measurement noise on speeds, (N,), rad/s.
        law: Compiled law id (shared by the batch).
        law_params, law_state: (N, P) and (N, S) law vectors.
        command: Torque added to the base torque (the whole torque without a law), (N,), N m.
        u_min, u_max: Top-drive torque limits, N m.
        n_sub: Plant steps to take.
        dt: Plant step, s.
        records: Output, (N, n_sub, N_RECORD): the pre-step record of every plant step (NaN
            for steps not taken).
        last_u: Torque applied in the step before this call, (N,), N m; updated.
        report: (N, N_REPORT): the reward terms of this call and the end state (``REP_*``).
        obs_scale: Observation scales, (obs_size,) (see :mod:`drill_env.observation`).
        obs_out: Output, (N, obs_size) float32: the observation at the end.
    """
    _check_noise_room(noise, noise_pos, n_sub)
    for i in range(x.shape[0]):
        _advance_one(
            i, x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
            noise, noise_pos, noise_std, law, law_params, law_state, command, u_min, u_max,
            n_sub, dt, records, last_u, report, obs_scale, obs_out,
        )  # fmt: skip


@njit(cache=True, parallel=True)
def advance_batch_parallel(
    x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
    noise, noise_pos, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
    records, last_u, report, obs_scale, obs_out,
):  # fmt: skip
    """:func:`advance_batch` with the strings spread over numba's threads (large batches)."""
    _check_noise_room(noise, noise_pos, n_sub)
    for i in prange(x.shape[0]):
        _advance_one(
            i, x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
            noise, noise_pos, noise_std, law, law_params, law_state, command, u_min, u_max,
            n_sub, dt, records, last_u, report, obs_scale, obs_out,
        )  # fmt: skip
