"""The compiled closed-loop engine: a batch of strings, their exogenous signals, measurement
channel, in-loop controller and actuator, advanced by many plant steps in one call.

One loop, :func:`_string_loop`, is written once and compiled once per plant, chosen by the
type of the state it carries: :func:`advance_batch` for the 4-DOF plant (its state a tuple of
floats, in registers) and :func:`advance_chain_batch` for a distributed string (its speeds and
twists as two contiguous rows of its scratch array for the whole call, advanced in place by
:func:`drill_env.chain.chain_step_rows`); the few lines that differ are the
small functions of each plant below. Per plant step ``j`` of string ``i`` (time
``t_j = step_index * dt``):

1. WOB and reference speed are read from piecewise-linear knot tables (a repeated knot time
   makes a step change);
2. the measurement channel (:mod:`drill_env.sensors`) samples the surface signals and the
   downhole telemetry and fills the measurement vector (``drill_env.layout.M_*``): in
   ``state`` mode the true 4-DOF state (a distributed string's at its probe nodes) plus
   ``noise_std * noise[i, j]`` on the four speeds; NaN there in ``surface`` mode;
3. the base torque ``u_base`` comes from the compiled law at ``law_address``
   (:mod:`drill_env.control`), or from ``base_torque[i]`` when there is none (0 N m without a
   base controller; a Python controller's torque on the slow path);
4. the command ``clip(u_base + command[i], u_min, u_max)`` passes through the actuator
   (:mod:`drill_env.actuator`; the identity when ideal) to the applied torque, held over the
   step;
5. the pre-step (4-DOF) state, torques, reference, WOB, stuck flag and the law's error signal
   and adaptive gain are written to ``records``, the reward sums and end state to ``report``;
6. the plant advances one step.

A state that is not finite or leaves the physical bounds (``drill_env.limits``) is not
accepted: the string keeps its last good state, its status becomes ``STATUS_DIVERGED`` and it
is not advanced again. At the end of the call the observation of every string is written from
its source vector (``drill_env.layout.SRC_*``) through the observation's source indices and
scales.

The kernel's inputs travel as two named tuples, :class:`BatchArrays` (the per-string arrays,
updated in place) and :class:`LoopSettings` (what the batch shares). The batch passes its arrays
as a :class:`PackedArrays` (one int64 array of their addresses and shapes): a call then unboxes
one array instead of twenty, and the views the loop takes of them carry no reference counts
(together about half the fixed cost of a call, which the single env pays at every decision). Each entry point has one
signature (every batch of a plant has the same argument types), so it is compiled once and then
loaded from numba's cache; the start of an episode (:func:`observe`) runs the same entry for no
plant step on the views of one string instead of compiling a loop of its own.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any, Final, NamedTuple

import numba
import numpy as np
import numpy.typing as npt
from numba import njit, prange, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from drill_env.actuator import actuator_step
from drill_env.chain import (
    CHAIN_SPEED_ROW,
    CHAIN_TWIST_ROW,
    CP_MU_0,
    CP_MU_A,
    CP_N,
    CP_R,
    chain_load_rows,
    chain_probe_rows,
    chain_probe_state,
    chain_step_rows,
    chain_store_rows,
    chain_surface_torque,
    chain_surface_torque_rows,
)
from drill_env.control import call_law
from drill_env.friction import STUCK
from drill_env.integration import plant_step
from drill_env.layout import (
    CH_ACTUATOR,
    CH_HOLD,
    CH_TELEMETRY,
    F_BASE_TORQUE,
    F_COMMAND,
    F_LAST_COMMAND,
    F_LAST_TORQUE,
    F_NOISE_STD,
    F_TELEMETRY_NOISE_STD,
    F_TORQUE_NOISE_STD,
    I_MODE,
    I_NOISE_POS,
    I_REF_KNOTS,
    I_STATUS,
    I_STEP,
    I_WOB_KNOTS,
    M_APPLIED_TORQUE,
    M_STATE,
    M_SURFACE_TORQUE,
    M_TELEMETRY_AGE,
    M_TELEMETRY_BIT_SPEED,
    M_TOP_DRIVE_SPEED,
    N_CHANNEL,
    N_RECORD,
    N_STATE,
    OBS_BOUND,
    P_C_PI,
    P_K_PI,
    P_MU_0,
    P_MU_A,
    P_R,
    PROF_REF_T,
    PROF_REF_V,
    PROF_WOB_T,
    PROF_WOB_V,
    REC_BASE_TORQUE,
    REC_COMMAND,
    REC_LAW_ERROR,
    REC_LAW_GAIN,
    REC_REFERENCE,
    REC_STUCK,
    REC_SURFACE_TORQUE,
    REC_TORQUE,
    REC_WOB,
    REC_X0,
    REP_BASE_TORQUE,
    REP_BIT_SPEED,
    REP_BIT_STUCK,
    REP_COMMAND,
    REP_LAW_ERROR,
    REP_LAW_GAIN,
    REP_REFERENCE,
    REP_RESIDUAL_SQUARED,
    REP_STATUS,
    REP_STEPS,
    REP_STUCK_STEPS,
    REP_SURFACE_TORQUE,
    REP_TELEMETRY_AGE,
    REP_TELEMETRY_BIT_SPEED,
    REP_TELEMETRY_RECEIVED,
    REP_TIME,
    REP_TOP_DRIVE_SPEED,
    REP_TORQUE,
    REP_TORQUE_SQUARED,
    REP_TRACKING_SUM,
    REP_VARIATION,
    REP_WOB,
    SRC_BASE_TORQUE,
    SRC_LAST_COMMAND,
    SRC_LAST_TORQUE,
    SRC_LAW_ERROR,
    SRC_REFERENCE,
    SRC_STATE,
    SRC_SURFACE_TORQUE,
    SRC_TELEMETRY_AGE,
    SRC_TELEMETRY_BIT_SPEED,
    SRC_TOP_DRIVE_SPEED,
    STATUS_DIVERGED,
    STATUS_OK,
    X_BIT_SPEED,
    X_TOP_DRIVE_SPEED,
)
from drill_env.limits import MAX_SPEED_RAD_S, MAX_TWIST_RAD
from drill_env.rewards import tracking_error
from drill_env.scenarios import profile_value
from drill_env.sensors import (
    HOLD_SPEED,
    HOLD_TORQUE,
    sense_surface,
    sense_telemetry,
    telemetry_reading,
)

__all__ = [
    "BatchArrays",
    "LoopSettings",
    "PackedArrays",
    "advance_batch",
    "advance_batch_parallel",
    "advance_chain_batch",
    "advance_chain_batch_parallel",
    "fast_entry",
    "measure",
    "observe",
    "residual_base",
    "write_observation",
    "write_report",
]


class BatchArrays(NamedTuple):
    """The per-string arrays of a batch of N strings (K profile knots, B noise rows); the
    kernel updates them in place. Columns are named in :mod:`drill_env.layout`.

    Attributes:
        x: States, (N, NX) float64, rad/s and rad: the 4-DOF state (NX = 7) or a distributed
            string's node speeds and element twists (NX = 2 n_max - 1, zero-padded).
        ints: Counters, (N, N_INTS) int64 (``I_*``: slip mode, plant steps taken, status,
            noise row, profile knot counts); strings not OK at the start are not advanced
            (records NaN, reward sums 0).
        scalars: Per-string numbers, (N, N_SCALARS) (``F_*``: noise levels, the agent's
            command, the external base torque, the last applied torque and command).
        plant: Plant parameter vectors, (N, P): the 4-DOF vector (``P_*``) or the chain vector
            of :func:`drill_env.chain.chain_parameter_vector`, zero-padded.
        work: Scratch of :func:`drill_env.chain.chain_step`, (N, CHAIN_WORK_ROWS, n_max).
        probes: The nodes read as the 4-DOF coordinates, (N, 4) int64
            (:func:`drill_env.modes.probe_nodes`; 0..3 for the 4-DOF plant).
        profiles: WOB and reference knots, (N, N_PROFILES, K) (``PROF_*``; s, N, rad/s).
        noise: Standard normal draws, (N, B, 4), B > noise row + n_sub: row r + j is the speed
            noise at step j, row r + n_sub that of the final measurement (which is also the next
            call's first step: the same instant).
        sensor_noise: Standard normal draws for the surface torque and the telemetry, (N, B, 2),
            the same rows.
        node_noise: Standard normal draws of a distributed string's node-speed noise at the end
            of the call (``state`` observation), (N, n_max).
        law_params, law_state: (N, P) and (N, S) vectors of the compiled law.
        measurement: Scratch, (N, N_MEASUREMENT): the measurement vector the law reads.
        channel: Measurement channel and actuator states, (N, N_CHANNEL) (``CH_*``).
        delay_line: The actuator's dead-time lines, (N, dead_steps + 1), N m.
        telemetry_buffer: Telemetry samples in flight, (N, capacity, 2).
        records: Output, (N, n_sub, N_RECORD): the pre-step record of every plant step (NaN
            for steps not taken).
        report: Output, (N, N_REPORT): the reward sums of this call and the end state.
        sources: Scratch, (N, N_FIXED_SOURCES + NX): what the observation entries show.
        obs: Output, (N, obs_size) float32: the observation at the end.
    """

    x: npt.NDArray[np.float64]
    ints: npt.NDArray[np.int64]
    scalars: npt.NDArray[np.float64]
    plant: npt.NDArray[np.float64]
    work: npt.NDArray[np.float64]
    probes: npt.NDArray[np.int64]
    profiles: npt.NDArray[np.float64]
    noise: npt.NDArray[np.float64]
    sensor_noise: npt.NDArray[np.float64]
    node_noise: npt.NDArray[np.float64]
    law_params: npt.NDArray[np.float64]
    law_state: npt.NDArray[np.float64]
    measurement: npt.NDArray[np.float64]
    channel: npt.NDArray[np.float64]
    delay_line: npt.NDArray[np.float64]
    telemetry_buffer: npt.NDArray[np.float64]
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
        state_mode: Whether the law measures the state (``state`` observation mode).
        sensor_steps: Plant steps between two surface samples (1: every step).
        telemetry_period: Plant steps between two telemetry samples (0: no telemetry).
        telemetry_delay: Plant steps from a telemetry sample to its delivery.
        ideal_actuator: No dead time, lag or rate limit: the applied torque is the command.
        lag: The actuator's lag factor (:func:`drill_env.actuator.lag_factor`).
        rate_step: Largest change of the applied torque per step, N m (``inf``: none).
        chain: Whether the strings are distributed (:func:`advance_chain_batch`).
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
    state_mode: bool
    sensor_steps: int
    telemetry_period: int
    telemetry_delay: int
    ideal_actuator: bool
    lag: float
    rate_step: float
    chain: bool


_FIELD_TYPES: Final = (
    ("x", np.float64, 2), ("ints", np.int64, 2), ("scalars", np.float64, 2),
    ("plant", np.float64, 2), ("work", np.float64, 3), ("probes", np.int64, 2),
    ("profiles", np.float64, 3), ("noise", np.float64, 3), ("sensor_noise", np.float64, 3),
    ("node_noise", np.float64, 2), ("law_params", np.float64, 2), ("law_state", np.float64, 2),
    ("measurement", np.float64, 2), ("channel", np.float64, 2), ("delay_line", np.float64, 2),
    ("telemetry_buffer", np.float64, 3), ("records", np.float64, 3), ("report", np.float64, 2),
    ("sources", np.float64, 2), ("obs", np.float32, 2),
)  # fmt: skip
"""The dtype and dimensions of each :class:`BatchArrays` field, in order (:func:`_unpack`
builds them in this order)."""
assert tuple(name for name, _, _ in _FIELD_TYPES) == BatchArrays._fields


class PackedArrays:
    """A :class:`BatchArrays` as the compiled kernel takes it fastest: one ``(20, 4)`` int64
    array ``meta``, each row an array's address and shape (zero-padded to 3 dimensions).

    The object holds the arrays, so the addresses stay valid while it lives; pass ``meta`` only
    with the object in hand (the batch keeps both).

    Raises:
        ValueError: naming the field whose array is not of its dtype and dimensions,
            C-contiguous, aligned and writeable.
    """

    def __init__(self, arrays: BatchArrays) -> None:
        meta = np.zeros((len(_FIELD_TYPES), 4), dtype=np.int64)
        for row, (name, dtype, ndim) in enumerate(_FIELD_TYPES):
            array = getattr(arrays, name)
            flags = array.flags
            if not (
                type(array) is np.ndarray
                and array.dtype == dtype
                and array.ndim == ndim
                and flags.c_contiguous
                and flags.aligned
                and flags.writeable
            ):
                raise ValueError(
                    f"{name} must be a C-contiguous writeable {np.dtype(dtype).name} array of "
                    f"{ndim} dimensions, got {array.dtype} with shape {array.shape}"
                )
            meta[row, 0] = array.__array_interface__["data"][0]
            meta[row, 1 : 1 + ndim] = array.shape
        self.arrays = arrays
        self.meta = meta

    def row(self, i: int) -> PackedArrays:
        """String ``i``'s rows (views of shape ``(1, ...)``), packed."""
        return PackedArrays(BatchArrays._make(array[i : i + 1] for array in self.arrays))

    def __reduce__(self) -> tuple[type[PackedArrays], tuple[BatchArrays]]:
        """Pickled as its arrays: unpickling packs the new arrays (their own addresses)."""
        return PackedArrays, (self.arrays,)

    def __deepcopy__(self, memo: dict[int, Any]) -> PackedArrays:
        """The copies of the arrays, packed: the copy's ``meta`` holds the copies' addresses
        (a copy of this ``meta`` would point into this object's arrays). A holder of ``meta``
        copied in the same :func:`copy.deepcopy` gets the new ``meta`` (or, when it was copied
        first, its copy is rewritten with the new addresses)."""
        twin = PackedArrays(copy.deepcopy(self.arrays, memo))
        copied_meta = memo.get(id(self.meta))
        if copied_meta is not None:
            copied_meta[...] = twin.meta
            twin.meta = copied_meta
        else:
            memo[id(self.meta)] = twin.meta
        return twin


@intrinsic
def _void_pointer(typingctx, address):
    """The int64 ``address`` as a ``void *`` (for :func:`numba.carray`)."""

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return types.voidptr(address), codegen


@njit(cache=True, inline="always")
def _array2(meta, row, dtype):
    shape = (meta[row, 1], meta[row, 2])
    return numba.carray(_void_pointer(meta[row, 0]), shape, dtype)  # type: ignore[call-arg]


@njit(cache=True, inline="always")
def _array3(meta, row, dtype):
    shape = (meta[row, 1], meta[row, 2], meta[row, 3])
    return numba.carray(_void_pointer(meta[row, 0]), shape, dtype)  # type: ignore[call-arg]


@njit(cache=True, inline="always")
def _unpack(m):
    """The :class:`BatchArrays` of a :class:`PackedArrays` ``meta`` (fields of _FIELD_TYPES)."""
    f, i = np.float64, np.int64
    return BatchArrays(
        _array2(m, 0, f), _array2(m, 1, i), _array2(m, 2, f), _array2(m, 3, f),
        _array3(m, 4, f), _array2(m, 5, i), _array3(m, 6, f), _array3(m, 7, f),
        _array3(m, 8, f), _array2(m, 9, f), _array2(m, 10, f), _array2(m, 11, f),
        _array2(m, 12, f), _array2(m, 13, f), _array2(m, 14, f), _array3(m, 15, f),
        _array3(m, 16, f), _array2(m, 17, f), _array2(m, 18, f), _array2(m, 19, np.float32),
    )  # fmt: skip


def _arrays(b):  # pragma: no cover
    """The kernel's arrays from a :class:`BatchArrays` or a :class:`PackedArrays` ``meta``."""
    raise NotImplementedError


@overload(_arrays, inline="always")
def _arrays_impl(b):
    if isinstance(b, types.Array):
        return lambda b: _unpack(b)
    return lambda b: b


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


@njit(cache=True, inline="always")
def _slot(ls, slot: int) -> float:
    return ls[slot] if slot >= 0 else 0.0


@njit(cache=True, inline="always")
def _sense(meas, hold, tel, tel_buf, s, k, x, surface, std, torque_std, tel_std, applied,
           noise, sensor, r) -> None:  # fmt: skip
    """The measurement channel at plant step ``k`` of a string whose 4-DOF (probe) state is
    ``x`` and top torque ``surface``: sample the surface signals and the telemetry, then fill
    the measurement vector ``meas``. ``noise``, ``sensor``: the string's noise blocks, ``r``
    the row of this instant. (Every array is a row of the batch, taken once per call: a view
    made at every step costs a reference count.)"""
    top_speed = x[0] + std * noise[r, 0]
    if sense_surface(hold, k, s.sensor_steps, top_speed, surface + torque_std * sensor[r, 0]):
        bit = x[X_BIT_SPEED] + tel_std * sensor[r, 1]
        sense_telemetry(tel, tel_buf, k, s.telemetry_period, s.telemetry_delay, bit)
    if s.state_mode:
        meas[M_STATE] = top_speed
        meas[M_STATE + 1] = x[1]
        meas[M_STATE + 2] = x[2] + std * noise[r, 1]
        meas[M_STATE + 3] = x[3]
        meas[M_STATE + 4] = x[4] + std * noise[r, 2]
        meas[M_STATE + 5] = x[5]
        meas[M_STATE + 6] = x[6] + std * noise[r, 3]
    else:
        for c in range(N_STATE):
            meas[M_STATE + c] = math.nan
    meas[M_TOP_DRIVE_SPEED] = hold[HOLD_SPEED]
    meas[M_SURFACE_TORQUE] = hold[HOLD_TORQUE]
    value, age = telemetry_reading(tel, k, s.dt)
    meas[M_TELEMETRY_BIT_SPEED] = value
    meas[M_TELEMETRY_AGE] = age
    meas[M_APPLIED_TORQUE] = applied


@njit(cache=True, inline="always")
def _sense_ideal(meas, hold, k, x, surface, std, torque_std, applied, noise, sensor, r) -> None:
    """:func:`_sense` for a channel that samples the surface at every step, has no telemetry
    and measures the state: the same values, without the telemetry's work (its entries stay
    as the last full sensing left them: no value)."""
    top_speed = x[0] + std * noise[r, 0]
    sense_surface(hold, k, 1, top_speed, surface + torque_std * sensor[r, 0])
    meas[M_STATE] = top_speed
    meas[M_STATE + 1] = x[1]
    meas[M_STATE + 2] = x[2] + std * noise[r, 1]
    meas[M_STATE + 3] = x[3]
    meas[M_STATE + 4] = x[4] + std * noise[r, 2]
    meas[M_STATE + 5] = x[5]
    meas[M_STATE + 6] = x[6] + std * noise[r, 3]
    meas[M_TOP_DRIVE_SPEED] = hold[HOLD_SPEED]
    meas[M_SURFACE_TORQUE] = hold[HOLD_TORQUE]
    meas[M_APPLIED_TORQUE] = applied


@njit(cache=True, inline="always")
def _command_and_torque(s, act, line, u_base: float, command: float):
    """The clipped command and the torque the actuator applies over this step, N m."""
    u_command = min(max(u_base + command, s.u_min), s.u_max)
    if s.ideal_actuator:
        return u_command, u_command
    applied = actuator_step(act, line, u_command, s.lag, s.rate_step, s.u_min, s.u_max)
    return u_command, applied


@njit(cache=True, inline="always")
def _base_torque(s, lp, ls, meas, external: float, ref: float) -> float:
    if s.law_address != 0:
        value: float = call_law(s.law_address, lp, ls, meas, ref, s.dt)  # type: ignore[call-arg]
        return value
    return external


@njit(cache=True, inline="always")
def residual_base(s, u_base: float) -> float:
    """The base torque the residual reward term compares the applied torque with, N m: the
    base controller's torque clipped to the top drive's range (a base torque beyond it, even
    1e200 N m, then costs at most the range, and the term stays finite)."""
    return min(max(u_base, s.u_min), s.u_max)


@njit(cache=True, inline="always")
def _record(rec, j, x, mi, u, u_command, ref, u_base, wob, error, gain, surface) -> None:
    for c in range(N_STATE):
        rec[j, REC_X0 + c] = x[c]
    rec[j, REC_TORQUE] = u
    rec[j, REC_REFERENCE] = ref
    rec[j, REC_BASE_TORQUE] = u_base
    rec[j, REC_STUCK] = 1.0 if mi == STUCK else 0.0
    rec[j, REC_WOB] = wob
    rec[j, REC_LAW_ERROR] = error
    rec[j, REC_LAW_GAIN] = gain
    rec[j, REC_COMMAND] = u_command
    rec[j, REC_SURFACE_TORQUE] = surface


@njit(cache=True, inline="always")
def _sums(rep, tracking, variation, stuck, n_done, torque_squared, residual_squared) -> None:
    rep[REP_TRACKING_SUM] = tracking
    rep[REP_VARIATION] = variation
    rep[REP_STUCK_STEPS] = stuck
    rep[REP_STEPS] = n_done
    rep[REP_TORQUE_SQUARED] = torque_squared
    rep[REP_RESIDUAL_SQUARED] = residual_squared


@njit(cache=True)
def _sense_string(i, b, s, k, x, surface, r) -> None:
    """:func:`_sense` for string ``i`` of the batch (outside the per-step loops)."""
    f = b.scalars[i]
    ch = b.channel[i]
    _sense(
        b.measurement[i], ch[CH_HOLD:CH_TELEMETRY], ch[CH_TELEMETRY:CH_ACTUATOR],
        b.telemetry_buffer[i], s, k, x, surface, f[F_NOISE_STD], f[F_TORQUE_NOISE_STD],
        f[F_TELEMETRY_NOISE_STD], f[F_LAST_TORQUE], b.noise[i], b.sensor_noise[i], r,
    )  # fmt: skip


@njit(cache=True)
def _finish(i, b, s, x, mi, k, wob, u_base_last, command_last) -> None:
    """The end of a call for string ``i``: the observation and the report at step ``k``."""
    ls = b.law_state[i]
    prof = b.profiles[i]
    ints = b.ints[i]
    last_u = b.scalars[i, F_LAST_TORQUE]
    ref_end = profile_value(prof[PROF_REF_T], prof[PROF_REF_V], ints[I_REF_KNOTS], k * s.dt)
    error = _slot(ls, s.error_slot)
    src = b.sources[i]
    meas = b.measurement[i]
    src[SRC_REFERENCE] = ref_end
    src[SRC_LAST_TORQUE] = last_u
    src[SRC_BASE_TORQUE] = u_base_last
    src[SRC_LAW_ERROR] = error
    src[SRC_TOP_DRIVE_SPEED] = meas[M_TOP_DRIVE_SPEED]
    src[SRC_SURFACE_TORQUE] = meas[M_SURFACE_TORQUE]
    received = not math.isnan(meas[M_TELEMETRY_BIT_SPEED])
    value = meas[M_TELEMETRY_BIT_SPEED] if received else 0.0
    age = meas[M_TELEMETRY_AGE] if received else k * s.dt
    src[SRC_TELEMETRY_BIT_SPEED] = value
    src[SRC_TELEMETRY_AGE] = age
    src[SRC_LAST_COMMAND] = command_last
    write_observation(b.obs[i], src, s.obs_source, s.obs_scale)
    rep = b.report[i]
    write_report(
        rep, x, mi, k * s.dt, ref_end, last_u, wob, u_base_last, error,
        _slot(ls, s.gain_slot), ints[I_STATUS],
    )  # fmt: skip
    rep[REP_COMMAND] = command_last
    rep[REP_SURFACE_TORQUE] = meas[M_SURFACE_TORQUE]
    rep[REP_TELEMETRY_BIT_SPEED] = value
    rep[REP_TELEMETRY_AGE] = age
    rep[REP_TELEMETRY_RECEIVED] = 1.0 if received else 0.0


# ------------------------------------------------------------------ the two plants
# The string loop below is written once for both plants; what differs is chosen at compile time
# by the type of the state: a tuple of 7 floats for the 4-DOF plant (kept in registers), a row
# of the batch advanced in place for a distributed string. Each function here is a stub that
# numba replaces by the implementation for that type.


def _plant_probe(state, p, probes):  # pragma: no cover
    """The 4-DOF (probe) state and the true torque at the top of the string, N m."""
    raise NotImplementedError


def _friction(state, p):  # pragma: no cover
    """``(mu_a R, mu_0 R)``, m: the static and sliding bit torques per newton of WOB."""
    raise NotImplementedError


def _step(state, mi, u, p, t_a, t_0, dt, work):  # pragma: no cover
    """One checked plant step: ``(state, mode, accepted)``; a state that is not finite or
    out of bounds, or a torque that is not finite, is not accepted (the old state returns)."""
    raise NotImplementedError


def _store(state, xs, p) -> None:  # pragma: no cover
    """Write the carried state back to the string's row."""
    raise NotImplementedError


def _measured_state(src, state, std, noise, row, node_noise, p) -> None:  # pragma: no cover
    """The measured state into the sources: speeds with their noise, twists exact."""
    raise NotImplementedError


def _is_lumped(state: Any) -> bool:
    return isinstance(state, types.BaseTuple)


@overload(_plant_probe, inline="always")
def _probe_impl(state, p, probes):
    if _is_lumped(state):

        def lumped(state, p, probes):
            return state, p[P_K_PI] * state[1] + p[P_C_PI] * (state[0] - state[2])

        return lumped

    def chain(state, p, probes):
        return chain_probe_rows(state, probes), chain_surface_torque_rows(state, p)

    return chain


@overload(_friction, inline="always")
def _friction_impl(state, p):
    if _is_lumped(state):
        return lambda state, p: (p[P_MU_A] * p[P_R], p[P_MU_0] * p[P_R])
    return lambda state, p: (p[CP_MU_A] * p[CP_R], p[CP_MU_0] * p[CP_R])


@overload(_step, inline="always")
def _step_impl(state, mi, u, p, t_a, t_0, dt, work):
    if _is_lumped(state):

        def lumped(state, mi, u, p, t_a, t_0, dt, work):
            xn, mn = plant_step(state, mi, u, p, t_a, t_0, dt)
            if _in_bounds(xn) and math.isfinite(u):
                return xn, mn, True
            return state, mi, False

        return lumped

    def chain(state, mi, u, p, t_a, t_0, dt, work):
        if math.isfinite(u):
            mn, accepted = chain_step_rows(
                mi, u, p, t_a, t_0, dt, state, MAX_SPEED_RAD_S, MAX_TWIST_RAD
            )
            return state, mn, accepted
        return state, mi, False

    return chain


@overload(_store, inline="always")
def _store_impl(state, xs, p):
    if _is_lumped(state):

        def lumped(state, xs, p):
            for c in range(N_STATE):
                xs[c] = state[c]

        return lumped
    return lambda state, xs, p: chain_store_rows(state, p, xs)


@overload(_measured_state, inline="always")
def _measured_state_impl(src, state, std, noise, row, node_noise, p):
    if _is_lumped(state):

        def lumped(src, state, std, noise, row, node_noise, p):
            for c in range(N_STATE):
                src[SRC_STATE + c] = state[c] + std * noise[row, c // 2] if c % 2 == 0 else state[c]

        return lumped

    def chain(src, state, std, noise, row, node_noise, p):
        w, t = state[CHAIN_SPEED_ROW], state[CHAIN_TWIST_ROW]
        for c in range(2 * int(p[CP_N]) - 1):  # every node
            e = c // 2
            src[SRC_STATE + c] = w[e] + std * node_noise[e] if c % 2 == 0 else t[e]

    return chain


# ------------------------------------------------------------------------ the loop
@njit(cache=True)
def _string_loop(i, b, s, state):
    """String ``i`` of the batch by ``s.n_sub`` plant steps (none: only its observation and
    report now, the start of an episode), from its ``state`` (the plant's kind, above)."""
    p = b.plant[i]
    xs = b.x[i]
    work = b.work[i]
    probes = b.probes[i]
    ints = b.ints[i]
    f = b.scalars[i]
    ch = b.channel[i]
    prof = b.profiles[i]
    mi = ints[I_MODE]
    lp = b.law_params[i]
    ls = b.law_state[i]
    rep = b.report[i]
    rec = b.records[i]
    meas = b.measurement[i]
    hold = ch[CH_HOLD:CH_TELEMETRY]
    tel = ch[CH_TELEMETRY:CH_ACTUATOR]
    tel_buf = b.telemetry_buffer[i]
    act = ch[CH_ACTUATOR:N_CHANNEL]
    line = b.delay_line[i]
    noise = b.noise[i]
    sensor = b.sensor_noise[i]
    wob_t, wob_v, wob_n = prof[PROF_WOB_T], prof[PROF_WOB_V], ints[I_WOB_KNOTS]
    ref_t, ref_v, ref_n = prof[PROF_REF_T], prof[PROF_REF_V], ints[I_REF_KNOTS]
    std, torque_std, tel_std = f[F_NOISE_STD], f[F_TORQUE_NOISE_STD], f[F_TELEMETRY_NOISE_STD]
    command = f[F_COMMAND]
    external = f[F_BASE_TORQUE]
    mu_a_r, mu_0_r = _friction(state, p)
    k = ints[I_STEP]
    row = ints[I_NOISE_POS]
    active = ints[I_STATUS] == STATUS_OK
    ok = active
    u_prev = f[F_LAST_TORQUE]
    u_base_last = rep[REP_BASE_TORQUE]
    command_last = f[F_LAST_COMMAND]
    wob = profile_value(wob_t, wob_v, wob_n, k * s.dt)  # each step's when there are steps
    tracking = 0.0
    variation = 0.0
    torque_squared = 0.0
    residual_squared = 0.0
    stuck = 0.0
    n_done = 0
    ideal_channel = s.state_mode and s.sensor_steps == 1 and s.telemetry_period <= 0
    for j in range(s.n_sub):
        if not ok:
            for c in range(N_RECORD):
                rec[j, c] = math.nan
            continue
        t = k * s.dt
        wob = profile_value(wob_t, wob_v, wob_n, t)
        ref = profile_value(ref_t, ref_v, ref_n, t)
        xi, surface = _plant_probe(state, p, probes)
        if ideal_channel:
            _sense_ideal(meas, hold, k, xi, surface, std, torque_std, u_prev, noise, sensor,
                         row + j)  # fmt: skip
        else:
            _sense(meas, hold, tel, tel_buf, s, k, xi, surface, std, torque_std, tel_std,
                   u_prev, noise, sensor, row + j)  # fmt: skip
        gain = _slot(ls, s.gain_slot)  # the gain this step's torque uses (the law advances it)
        u_base = _base_torque(s, lp, ls, meas, external, ref)
        u_command, u = _command_and_torque(s, act, line, u_base, command)
        _record(rec, j, xi, mi, u, u_command, ref, u_base, wob, _slot(ls, s.error_slot), gain,
                surface)  # fmt: skip
        tracking += tracking_error(ref, xi[X_BIT_SPEED])
        variation += abs(u - u_prev)
        torque_squared += u * u
        residual = u - residual_base(s, u_base)
        residual_squared += residual * residual
        u_prev = u
        u_base_last = u_base
        command_last = u_command
        if mi == STUCK:
            stuck += 1.0
        n_done += 1
        state, mi, accepted = _step(state, mi, u, p, mu_a_r * wob, mu_0_r * wob, s.dt, work)
        if accepted:
            k += 1
        else:
            ok = False
            ints[I_STATUS] = STATUS_DIVERGED
    _sums(rep, tracking, variation, stuck, n_done, torque_squared, residual_squared)
    if not active:
        return
    _store(state, xs, p)
    ints[I_MODE] = mi
    ints[I_STEP] = k
    f[F_LAST_TORQUE] = u_prev
    f[F_LAST_COMMAND] = command_last
    row += s.n_sub
    ints[I_NOISE_POS] = row
    xi, surface = _plant_probe(state, p, probes)
    _sense(meas, hold, tel, tel_buf, s, k, xi, surface, std, torque_std, tel_std, u_prev,
           noise, sensor, row)  # fmt: skip
    _measured_state(b.sources[i], state, std, noise, row, b.node_noise[i], p)
    _finish(i, b, s, xi, mi, k, wob, u_base_last, command_last)


@njit(cache=True, inline="always")
def _advance_lumped(i, b, s) -> None:
    xs = b.x[i]
    _string_loop(i, b, s, (xs[0], xs[1], xs[2], xs[3], xs[4], xs[5], xs[6]))


@njit(cache=True, inline="always")
def _string_probe(i, b, s):
    """The 4-DOF (probe) state of string ``i`` and the true torque at the top of its string."""
    xs = b.x[i]
    p = b.plant[i]
    if s.chain:
        return chain_probe_state(xs, b.probes[i]), chain_surface_torque(xs, p)
    xi = (xs[0], xs[1], xs[2], xs[3], xs[4], xs[5], xs[6])
    return xi, p[P_K_PI] * xi[1] + p[P_C_PI] * (xi[0] - xi[2])


@njit(cache=True)
def measure(b, s, i) -> None:
    """Fill the measurement vector of string ``i`` at its current step (the slow path reads it
    before each plant step; an instant already sensed is not sampled again)."""
    xi, surface = _string_probe(i, b, s)
    _sense_string(i, b, s, b.ints[i, I_STEP], xi, surface, b.ints[i, I_NOISE_POS])


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
def write_observation(out, sources, source_index, scale) -> None:
    """Fill one observation row: entry ``c`` is ``sources[source_index[c]] * scale[c]``; NaN
    becomes 0 and everything is clipped to ``+-OBS_BOUND``."""
    for c in range(out.shape[0]):
        v = sources[source_index[c]] * scale[c]
        if not math.isfinite(v):
            v = 0.0 if math.isnan(v) else (OBS_BOUND if v > 0 else -OBS_BOUND)
        out[c] = min(max(v, -OBS_BOUND), OBS_BOUND)


@njit(cache=True)
def _check_noise_room(noise, ints, n_sub):
    for i in range(ints.shape[0]):
        row = ints[i, I_NOISE_POS]
        if row < 0 or row + n_sub >= noise.shape[1]:
            raise ValueError("noise block too short for n_sub steps: refill it first")


@njit(cache=True)
def advance_batch(b, s):
    """Advance every string of the batch ``b`` (:class:`BatchArrays`, or the ``meta`` of a
    :class:`PackedArrays`) by ``s.n_sub`` plant steps of ``s.dt`` seconds under the settings
    ``s`` (:class:`LoopSettings`)."""
    arrays = _arrays(b)
    _check_noise_room(arrays.noise, arrays.ints, s.n_sub)
    for i in range(arrays.x.shape[0]):
        _advance_lumped(i, arrays, s)


@njit(cache=True, parallel=True)
def advance_batch_parallel(b, s):
    """:func:`advance_batch` with the strings spread over numba's threads (large batches)."""
    arrays = _arrays(b)
    _check_noise_room(arrays.noise, arrays.ints, s.n_sub)
    for i in prange(arrays.x.shape[0]):
        _advance_lumped(i, arrays, s)


@njit(cache=True)
def advance_chain_batch(b, s):
    """:func:`advance_batch` for distributed strings."""
    arrays = _arrays(b)
    _check_noise_room(arrays.noise, arrays.ints, s.n_sub)
    for i in range(arrays.x.shape[0]):
        chain_load_rows(arrays.x[i], arrays.plant[i], arrays.work[i])
        _string_loop(i, arrays, s, arrays.work[i])


@njit(cache=True, parallel=True)
def advance_chain_batch_parallel(b, s):
    """:func:`advance_chain_batch` with the strings spread over numba's threads."""
    arrays = _arrays(b)
    _check_noise_room(arrays.noise, arrays.ints, s.n_sub)
    for i in prange(arrays.x.shape[0]):
        chain_load_rows(arrays.x[i], arrays.plant[i], arrays.work[i])
        _string_loop(i, arrays, s, arrays.work[i])


def observe(
    advance: Callable[..., None], b: BatchArrays | PackedArrays, s: LoopSettings, i: int
) -> None:
    """The observation and the report of string ``i`` at its current step without stepping
    (the start of an episode): ``advance`` (the batch's entry point, :func:`fast_entry`) for no
    plant step on a batch of the views of string ``i`` (packed when ``b`` is)."""
    if isinstance(b, PackedArrays):
        row = b.row(i)  # holds the views while the kernel runs on their addresses
        advance(row.meta, s._replace(n_sub=0))
        return
    one = BatchArrays._make(array[i : i + 1] for array in b)
    advance(one, s._replace(n_sub=0))


def fast_entry(dispatcher: Any, *args: Any) -> Callable[..., None]:
    """The compiled entry point of ``dispatcher`` for the types of ``args`` (compiled, or loaded
    from numba's cache, now), which skips numba's per-call type dispatch (about 1 us for the
    kernel's arguments). Every later call must pass arguments of the same types."""
    signature = tuple(numba.typeof(a) for a in args)
    entry = dispatcher.compile(signature)
    return entry if callable(entry) else dispatcher
