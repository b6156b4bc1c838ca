"""The compiled closed-loop engine: a batch of strings, their exogenous signals, measurement
noise and an in-loop controller, advanced by many plant steps in one call.

Per plant step ``j`` of string ``i`` (time ``t_j = step_index * dt``):

1. WOB and reference speed are read from piecewise-linear knot tables (a repeated knot time
   makes a step change);
2. the measured state is the true state plus ``noise_std * noise[i, j]`` on the four speeds;
3. the base torque ``u_base`` comes from the compiled law ``law`` (0 N m for ``LAW_NONE``);
4. the applied torque is ``clip(u_base + command[i], u_min, u_max)`` held over the step;
5. the pre-step state, torques, reference, WOB, stuck flag and the law's sliding variable and
   adaptive gain are written to ``records``, and the step's reward terms to ``summary``;
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

__all__ = [
    "MAX_SPEED_RAD_S",
    "MAX_TWIST_RAD",
    "N_RECORD",
    "STATUS_DIVERGED",
    "STATUS_OK",
    "advance_batch",
    "advance_batch_parallel",
    "profile_value",
]

MAX_SPEED_RAD_S: Final = 1000.0
"""Physical bound on every speed, rad/s; beyond it the run counts as diverged."""
MAX_TWIST_RAD: Final = 1000.0
"""Physical bound on every twist, rad; beyond it the run counts as diverged."""

STATUS_OK: Final = 0
STATUS_DIVERGED: Final = 1

# Columns of the per-plant-step records.
REC_X0: Final = 0  # columns 0..6: state at the start of the step
REC_TORQUE: Final = 7  # applied top-drive torque, N m
REC_REFERENCE: Final = 8  # reference bit speed, rad/s
REC_BASE_TORQUE: Final = 9  # base controller torque before the command, N m
REC_STUCK: Final = 10  # 1.0 when the bit is stuck at the start of the step
REC_WOB: Final = 11  # weight on bit, N
REC_SLIDING: Final = 12  # the law's sliding variable (or 0), rad/s
REC_GAIN: Final = 13  # the law's adaptive gain (or 0)
N_RECORD: Final = 14

# Columns of the per-call step summary.
SUM_TRACKING: Final = 0  # mean of min(|V_ref - x7| / max(V_ref, 1 rad/s), 1) over the steps
SUM_VARIATION: Final = 1  # total variation of the applied torque, N m
SUM_STUCK: Final = 2  # share of the steps with the bit stuck
N_SUMMARY: Final = 3


@njit(cache=True)
def profile_value(times, values, n: int, t: float) -> float:
    """Piecewise-linear profile through ``n`` knots; constant outside, right-continuous steps."""
    if n == 1 or t <= times[0]:
        return values[0]
    j = 0
    while j + 1 < n and t >= times[j + 1]:
        j += 1
    if j == n - 1:
        return values[n - 1]
    span = times[j + 1] - times[j]
    return values[j] + (values[j + 1] - values[j]) * (t - times[j]) / span


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
    noise, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
    records, meas_out, last_u, summary,
):  # fmt: skip
    p = plant[i]
    xi = (x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5], x[i, 6])
    mi = mode[i]
    lp = law_params[i]
    ls = law_state[i]
    mu_a_r = p[13] * p[12]
    mu_0_r = p[14] * p[12]
    k = step_index[i]
    u_prev = last_u[i]
    tracking = 0.0
    variation = 0.0
    stuck = 0.0
    n_done = 0
    for j in range(n_sub):
        if status[i] != STATUS_OK:
            for c in range(N_RECORD):
                records[i, j, c] = records[i, j - 1, c] if j > 0 else math.nan
            continue
        t = k * dt
        wob = profile_value(wob_t[i], wob_v[i], wob_n[i], t)
        ref = profile_value(ref_t[i], ref_v[i], ref_n[i], t)
        m = _measure(xi, noise_std[i], noise[i, j])
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
        records[i, j, REC_GAIN] = ls[2]
        tracking += min(abs(ref - xi[6]) / max(ref, 1.0), 1.0)
        variation += abs(u - u_prev)
        u_prev = u
        if mi == STUCK:
            stuck += 1.0
        n_done += 1
        xn, mn = plant_step(xi, mi, u, p, mu_a_r * wob, mu_0_r * wob, dt)
        if _in_bounds(xn) and math.isfinite(u):
            xi, mi = xn, mn
            k += 1
        else:
            status[i] = STATUS_DIVERGED
    for c in range(7):
        x[i, c] = xi[c]
    mode[i] = mi
    step_index[i] = k
    last_u[i] = u_prev
    summary[i, SUM_TRACKING] = tracking / max(n_done, 1)
    summary[i, SUM_VARIATION] = variation
    summary[i, SUM_STUCK] = stuck / max(n_done, 1)
    m = _measure(xi, noise_std[i], noise[i, n_sub])
    for c in range(7):
        meas_out[i, c] = m[c]


@njit(cache=True)
def advance_batch(
    x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
    noise, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
    records, meas_out, last_u, summary,
):  # fmt: skip
    """Advance every string of the batch by ``n_sub`` plant steps of ``dt`` seconds.

    Args (N strings, K knots, P/S law vector lengths; arrays are updated in place):
        x: States, (N, 7) float64, rad/s and rad.
        mode: Slip modes, (N,) int64 (0 stuck, +1/-1 slipping).
        step_index: Plant steps taken so far, (N,) int64; time is ``step_index * dt``.
        status: (N,) int64, ``STATUS_OK`` or ``STATUS_DIVERGED``.
        plant: Plant parameter vectors, (N, 17).
        wob_t, wob_v, wob_n: WOB knot times (s), values (N) and counts, (N, K), (N, K), (N,).
        ref_t, ref_v, ref_n: Reference-speed knots (s, rad/s), same shapes.
        noise: Standard normal draws, (N, n_sub + 1, 4); row j is the speed noise at step j,
            row n_sub the noise of the final measurement.
        noise_std: Measurement noise on speeds, (N,), rad/s.
        law: Compiled law id (shared by the batch).
        law_params, law_state: (N, P) and (N, S) law vectors.
        command: Torque added to the base torque (the whole torque without a law), (N,), N m.
        u_min, u_max: Top-drive torque limits, N m.
        n_sub: Plant steps to take.
        dt: Plant step, s.
        records: Output, (N, n_sub, N_RECORD): the pre-step record of every plant step.
        meas_out: Output, (N, 7): the measured state at the end.
        last_u: Torque applied in the step before this call, (N,), N m; updated.
        summary: Output, (N, N_SUMMARY): the reward terms of this call (``SUM_*`` columns).
    """
    for i in range(x.shape[0]):
        _advance_one(
            i, x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
            noise, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
            records, meas_out, last_u, summary,
        )  # fmt: skip


@njit(cache=True, parallel=True)
def advance_batch_parallel(
    x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
    noise, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
    records, meas_out, last_u, summary,
):  # fmt: skip
    """:func:`advance_batch` with the strings spread over numba's threads (large batches)."""
    for i in prange(x.shape[0]):
        _advance_one(
            i, x, mode, step_index, status, plant, wob_t, wob_v, wob_n, ref_t, ref_v, ref_n,
            noise, noise_std, law, law_params, law_state, command, u_min, u_max, n_sub, dt,
            records, meas_out, last_u, summary,
        )  # fmt: skip
