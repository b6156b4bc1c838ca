"""Every index of the engine's vectors, named once: the plant state, the plant parameter
vector, what a compiled control law measures, the per-plant-step records, the per-call
report, the run status and the observation.

The compiled code reads these module constants (numba freezes them at compile time), and the
Python side reads the same names, so a column is never written as a bare number twice.
"""

from __future__ import annotations

from typing import Final, NamedTuple

import numpy as np
import numpy.typing as npt

from drill_env.validation import shown

__all__ = [
    "N_FIXED_SOURCES",
    "MEASUREMENT_NAMES",
    "N_MEASUREMENT",
    "ESTIMATE_FIELDS",
    "OBSERVATION_MODES",
    "N_PLANT_PARAMS",
    "N_RECORD",
    "N_REPORT",
    "N_STATE",
    "OBS_BOUND",
    "SPEED_INDICES",
    "SPEED_SCALE_RAD_S",
    "STATE_NAMES",
    "TWIST_SCALE_RAD",
    "ObservationField",
    "chain_state_fields",
    "observation_fields",
    "observation_scales",
    "observation_size",
    "observation_sources",
    "unscale_measurement",
]

# ------------------------------------------------------------------------------ plant state
STATE_NAMES: Final = (
    "top_drive_speed_rad_s",
    "top_drive_pipe_twist_rad",
    "pipe_speed_rad_s",
    "pipe_collar_twist_rad",
    "collar_speed_rad_s",
    "collar_bit_twist_rad",
    "bit_speed_rad_s",
)
"""The 4-DOF state ``x1..x7``: speeds (rad/s) at even indices, twists (rad) at odd ones."""
N_STATE: Final = 7
X_TOP_DRIVE_SPEED: Final = 0
X_PIPE_SPEED: Final = 2
X_COLLAR_SPEED: Final = 4
X_BIT_SPEED: Final = 6
SPEED_INDICES: Final = (0, 2, 4, 6)
"""Indices of the four speeds in the state (the measured ones carry noise)."""

# -------------------------------------------------------------------- plant parameter vector
# Layout of the plant parameter vector the compiled kernels read: the 17 fields of
# DrillStringParameters in order, then the reciprocals of the four inertias.
P_J_DT, P_J_PI, P_J_CO, P_J_BI = 0, 1, 2, 3
P_C_DT, P_C_PI, P_C_CO, P_C_BI, P_C_BIT = 4, 5, 6, 7, 8
P_K_PI, P_K_CO, P_K_BI = 9, 10, 11
P_R, P_MU_A, P_MU_0, P_XI, P_DW = 12, 13, 14, 15, 16
P_INV_J_DT, P_INV_J_PI, P_INV_J_CO, P_INV_J_BI = 17, 18, 19, 20
N_PLANT_PARAMS: Final = 21

# ------------------------------------------------------------- what a compiled law measures
# A compiled law reads a measurement vector of N_MEASUREMENT float64 values at every plant
# step (drill_env.sensors): what the observation mode makes available, NaN for the rest.
M_STATE: Final = 0  # entries 0..6: the measured 4-DOF state x1..x7 ("state" mode; else NaN)
M_TOP_DRIVE_SPEED: Final = 7  # measured top-drive speed, rad/s
M_SURFACE_TORQUE: Final = 8  # measured torque at the top of the string, N m
M_TELEMETRY_BIT_SPEED: Final = 9  # last bit speed received by telemetry, rad/s (NaN: none)
M_TELEMETRY_AGE: Final = 10  # its age, s (NaN: none)
M_APPLIED_TORQUE: Final = 11  # the torque the drive applied over the last step, N m
N_MEASUREMENT: Final = 12
MEASUREMENT_NAMES: Final = (
    *STATE_NAMES,  # M_STATE..M_STATE + 6: the measured state ("state" mode)
    "surface_top_drive_speed_rad_s",  # M_TOP_DRIVE_SPEED
    "surface_torque_nm",  # M_SURFACE_TORQUE
    "telemetry_bit_speed_rad_s",  # M_TELEMETRY_BIT_SPEED
    "telemetry_age_s",  # M_TELEMETRY_AGE
    "applied_torque_nm",  # M_APPLIED_TORQUE
)
"""The name of each entry of the measurement vector, with its unit (``drill_env.control
.Measurement`` reads them as attributes)."""

# ------------------------------------------------------------------- per-plant-step records
REC_X0: Final = 0  # columns 0..6: the true state at the start of the step
REC_TORQUE: Final = 7  # applied top-drive torque, N m
REC_REFERENCE: Final = 8  # reference bit speed, rad/s
REC_BASE_TORQUE: Final = 9  # base controller torque before the command, N m
REC_STUCK: Final = 10  # 1.0 when the bit is stuck at the start of the step
REC_WOB: Final = 11  # weight on bit, N
REC_LAW_ERROR: Final = 12  # the law's error signal at this step (its sliding variable), rad/s
REC_LAW_GAIN: Final = 13  # the law's adaptive gain used at this step (or 0)
REC_COMMAND: Final = 14  # torque command (base + agent, clipped) before the actuator, N m
REC_SURFACE_TORQUE: Final = 15  # true torque at the top of the string, N m
N_RECORD: Final = 16

# ------------------------------------------------------------------------ per-call report
# Written for every string at the end of every kernel call. The first six columns are sums
# over the plant steps of the call, from which drill_env.rewards forms the reward terms.
REP_TRACKING_SUM: Final = 0  # sum of the tracking integrand (drill_env.rewards.tracking_error)
REP_VARIATION: Final = 1  # total variation of the applied torque, N m
REP_STUCK_STEPS: Final = 2  # plant steps with the bit stuck
REP_STEPS: Final = 3  # plant steps taken
REP_TORQUE_SQUARED: Final = 4  # sum of the squared applied torque, (N m)^2
REP_RESIDUAL_SQUARED: Final = 5  # sum of the squared (applied - base) torque, (N m)^2
REP_TIME: Final = 6  # time at the end, s
REP_BIT_SPEED: Final = 7  # true bit speed, rad/s
REP_TOP_DRIVE_SPEED: Final = 8  # true top-drive speed, rad/s
REP_REFERENCE: Final = 9  # reference bit speed at the end, rad/s
REP_TORQUE: Final = 10  # last applied torque, N m
REP_WOB: Final = 11  # weight on bit of the last step, N
REP_BIT_STUCK: Final = 12  # 1.0 when the bit is stuck at the end
REP_BASE_TORQUE: Final = 13  # last base-controller torque, N m
REP_LAW_ERROR: Final = 14  # the law's error signal (sliding variable), rad/s
REP_LAW_GAIN: Final = 15  # the law's adaptive gain
REP_STATUS: Final = 16  # STATUS_* as a float
REP_COMMAND: Final = 17  # last torque command, N m
REP_SURFACE_TORQUE: Final = 18  # measured surface torque at the end, N m
REP_TELEMETRY_BIT_SPEED: Final = 19  # last bit speed received by telemetry, rad/s (0: none yet)
REP_TELEMETRY_AGE: Final = 20  # its age, s (the time since the start before the first value)
REP_TELEMETRY_RECEIVED: Final = 21  # 1.0 once a telemetry value has arrived
N_REPORT: Final = 22

# ---------------------------------------------------------------- per-string engine state
# The engine keeps each string's counters, scalars, profiles and measurement-channel state in
# a few arrays with named columns (fewer arrays to hand to the compiled code per call).
I_MODE: Final = 0  # slip mode of the bit (drill_env.friction: 0 stuck, +1/-1 slipping)
I_STEP: Final = 1  # plant steps taken; the time is I_STEP * plant_dt
I_STATUS: Final = 2  # STATUS_*
I_NOISE_POS: Final = 3  # the noise row of the current measurement
I_WOB_KNOTS: Final = 4  # knots of the WOB profile
I_REF_KNOTS: Final = 5  # knots of the reference profile
N_INTS: Final = 6

F_NOISE_STD: Final = 0  # noise of the measured speeds, rad/s
F_TORQUE_NOISE_STD: Final = 1  # noise of the measured surface torque, N m
F_TELEMETRY_NOISE_STD: Final = 2  # noise of the telemetry's bit speed, rad/s
F_COMMAND: Final = 3  # the agent's torque command of this step (the residual), N m
F_BASE_TORQUE: Final = 4  # the base torque when there is no compiled law, N m
F_LAST_TORQUE: Final = 5  # the torque applied over the last step, N m
F_LAST_COMMAND: Final = 6  # the torque command of the last step, N m
N_SCALARS: Final = 7

PROF_WOB_T: Final = 0  # WOB knot times, s
PROF_WOB_V: Final = 1  # WOB knot values, N
PROF_REF_T: Final = 2  # reference knot times, s
PROF_REF_V: Final = 3  # reference knot values, rad/s
N_PROFILES: Final = 4

# The measurement channel's and the actuator's state of one string, one vector: the held
# surface samples (drill_env.sensors.HOLD_*), the telemetry state (TEL_*) and the actuator
# state (drill_env.actuator.ACT_*), in this order.
CH_HOLD: Final = 0
CH_TELEMETRY: Final = 3
CH_ACTUATOR: Final = 7
N_CHANNEL: Final = 9

# ------------------------------------------------------------------------------- run status
STATUS_OK: Final = 0
STATUS_DIVERGED: Final = 1
STATUS_PAUSED: Final = 2  # skipped by the kernel (a string that is being reset)

# ------------------------------------------------------------------------------ observation
SPEED_SCALE_RAD_S: Final = 20.0
"""Speeds (and the reference and the law's error signal) are divided by this, rad/s."""
TWIST_SCALE_RAD: Final = 20.0
"""Twists are divided by this, rad."""
OBS_BOUND: Final = 50.0
"""Every scaled observation entry is clipped to [-OBS_BOUND, OBS_BOUND]."""

TIME_SCALE_S: Final = 10.0
"""Ages (of the telemetry) are divided by this, s."""
ELEMENT_TWIST_SCALE_RAD: Final = 1.0
"""Element twists of a distributed string are divided by this, rad."""
FORCE_SCALE_N: Final = 1e5
"""Forces (the weight on bit of the RGD bit) are divided by this, N."""
ROP_SCALE_M_S: Final = 0.01
"""Rates of penetration are divided by this, m/s."""

# Sources an observation entry can show, in the source vector the kernel fills at the end of
# every call: fixed entries, then the measured state of the string (variable length).
SRC_REFERENCE: Final = 0
SRC_LAST_TORQUE: Final = 1  # the torque applied over the last step
SRC_BASE_TORQUE: Final = 2
SRC_LAW_ERROR: Final = 3
SRC_TOP_DRIVE_SPEED: Final = 4  # measured
SRC_SURFACE_TORQUE: Final = 5  # measured
SRC_TELEMETRY_BIT_SPEED: Final = 6  # 0 before the first value arrives
SRC_TELEMETRY_AGE: Final = 7  # the time since the start before the first value arrives
SRC_LAST_COMMAND: Final = 8
SRC_STATE: Final = 9  # from here: the measured state (speeds with noise, twists exact)
N_FIXED_SOURCES: Final = 9

OBSERVATION_MODES: Final = ("state", "surface", "estimate")
"""``state``: the whole measured state; ``surface``: what a rig measures at surface (plus the
downhole telemetry when there is any); ``estimate``: ``surface`` plus the base controller's
observer estimate of the bit speed and the bit-rock torque, computed from those same signals
(:data:`ESTIMATE_FIELDS`)."""
ESTIMATE_FIELDS: Final = (
    ("estimated_bit_speed_rad_s", "speed"),
    ("estimated_bit_torque_nm", "torque"),
)
"""The entries ``observation="estimate"`` adds at the end of the observation, ``(name, scale
kind)``: the base controller's observer estimates, reported under the same names in ``info``
(the env fills them from the law's state after every decision)."""


class ObservationField(NamedTuple):
    """One entry of the observation vector.

    Attributes:
        name: What it shows, with its unit.
        source: Its entry in the kernel's source vector (``SRC_*``).
        scale: ``"speed"`` (divided by ``SPEED_SCALE_RAD_S``), ``"twist"``
            (``TWIST_SCALE_RAD``), ``"element_twist"`` (``ELEMENT_TWIST_SCALE_RAD``), ``"time"``
            (``TIME_SCALE_S``), ``"torque"`` (the env's torque scale), ``"force"``
            (``FORCE_SCALE_N``) or ``"rop"`` (``ROP_SCALE_M_S``).
    """

    name: str
    source: int
    scale: str


_STATE_FIELDS: Final = tuple(
    ObservationField(
        ("measured_" if k % 2 == 0 else "") + name,
        SRC_STATE + k,
        "speed" if k % 2 == 0 else "twist",
    )
    for k, name in enumerate(STATE_NAMES)
)


def chain_state_fields(n_nodes: int) -> tuple[ObservationField, ...]:
    """The measured state of a distributed string of ``n_nodes`` nodes: node speeds and element
    twists, alternating from the top drive (``2 n - 1`` entries)."""
    fields = []
    for k in range(2 * n_nodes - 1):
        if k % 2 == 0:
            fields.append(
                ObservationField(f"measured_node{k // 2}_speed_rad_s", SRC_STATE + k, "speed")
            )
        else:
            fields.append(
                ObservationField(f"element{k // 2}_twist_rad", SRC_STATE + k, "element_twist")
            )
    return tuple(fields)


def observation_fields(
    residual: bool,
    mode: str = "state",
    telemetry: bool = False,
    state: tuple[ObservationField, ...] = _STATE_FIELDS,
) -> tuple[ObservationField, ...]:
    """The observation's entries in order.

    Args:
        residual: Residual mode: the base controller's torque and error signal are added last.
        mode: ``"state"``: the measured ``state`` entries; ``"surface"`` and ``"estimate"``:
            the measured top-drive speed and surface torque instead (the estimate's entries
            need the law's state: the batch adds them, :data:`ESTIMATE_FIELDS`).
        telemetry: Whether downhole telemetry arrives: its last bit speed and that value's age
            follow the last torque.
        state: The state entries of the plant (the 4-DOF state by default;
            :func:`chain_state_fields` for a distributed string).

    With the defaults: 9 entries, 11 in residual mode (the layout of ``DrillString-v0``).
    """
    if mode not in OBSERVATION_MODES:
        raise ValueError(
            f"observation = {shown(mode)} is not a known mode: allowed {list(OBSERVATION_MODES)}"
        )
    if mode == "state":
        head = state
    else:
        head = (
            ObservationField("measured_top_drive_speed_rad_s", SRC_TOP_DRIVE_SPEED, "speed"),
            ObservationField("measured_surface_torque_nm", SRC_SURFACE_TORQUE, "torque"),
        )
    fields = [
        *head,
        ObservationField("reference_speed_rad_s", SRC_REFERENCE, "speed"),
        ObservationField("last_torque_nm", SRC_LAST_TORQUE, "torque"),
    ]
    if telemetry:
        fields += [
            ObservationField("telemetry_bit_speed_rad_s", SRC_TELEMETRY_BIT_SPEED, "speed"),
            ObservationField("telemetry_age_s", SRC_TELEMETRY_AGE, "time"),
        ]
    if residual:
        fields += [
            ObservationField("base_torque_nm", SRC_BASE_TORQUE, "torque"),
            ObservationField("base_error_rad_s", SRC_LAW_ERROR, "speed"),
        ]
    return tuple(fields)


def observation_size(residual: bool) -> int:
    """Length of the observation of ``DrillString-v0`` in its default mode: 9, or 11 in
    residual mode."""
    return len(observation_fields(residual))


def observation_scales(
    fields: tuple[ObservationField, ...], torque_scale_nm: float
) -> npt.NDArray[np.float64]:
    """The factor each entry is multiplied by (1 / its scale), (len(fields),)."""
    per_kind = {
        "speed": 1.0 / SPEED_SCALE_RAD_S,
        "twist": 1.0 / TWIST_SCALE_RAD,
        "element_twist": 1.0 / ELEMENT_TWIST_SCALE_RAD,
        "time": 1.0 / TIME_SCALE_S,
        "torque": 1.0 / torque_scale_nm,
        "force": 1.0 / FORCE_SCALE_N,
        "rop": 1.0 / ROP_SCALE_M_S,
    }
    return np.array([per_kind[f.scale] for f in fields])


def observation_sources(fields: tuple[ObservationField, ...]) -> npt.NDArray[np.int64]:
    """The source-vector entry of each observation entry, (len(fields),) int64."""
    return np.array([f.source for f in fields], dtype=np.int64)


def unscale_measurement(
    observation: npt.ArrayLike,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Recover the measured state (..., 7) and the reference speed (...,) from observations
    of ``DrillString-v0`` in its default ``state`` mode (either length)."""
    obs = np.asarray(observation, dtype=np.float64)
    scale = {"speed": SPEED_SCALE_RAD_S, "twist": TWIST_SCALE_RAD}
    state = np.array([scale[f.scale] for f in _STATE_FIELDS])
    fields = observation_fields(False)
    reference = next(k for k, f in enumerate(fields) if f.source == SRC_REFERENCE)
    return obs[..., :N_STATE] * state, obs[..., reference] * SPEED_SCALE_RAD_S
