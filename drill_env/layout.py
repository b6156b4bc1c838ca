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

__all__ = [
    "N_MEASUREMENT",
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
# step: the measured state (speeds with noise, twists exact).
M_STATE: Final = 0  # entries 0..6: the measured state x1..x7
N_MEASUREMENT: Final = 7

# ------------------------------------------------------------------- per-plant-step records
REC_X0: Final = 0  # columns 0..6: the true state at the start of the step
REC_TORQUE: Final = 7  # applied top-drive torque, N m
REC_REFERENCE: Final = 8  # reference bit speed, rad/s
REC_BASE_TORQUE: Final = 9  # base controller torque before the command, N m
REC_STUCK: Final = 10  # 1.0 when the bit is stuck at the start of the step
REC_WOB: Final = 11  # weight on bit, N
REC_LAW_ERROR: Final = 12  # the law's error signal at this step (its sliding variable), rad/s
REC_LAW_GAIN: Final = 13  # the law's adaptive gain used at this step (or 0)
N_RECORD: Final = 14

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
N_REPORT: Final = 17

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

# Sources an observation entry can show, in the source vector the kernel fills at the end of
# every call: the measured state, then the reference, the last applied torque, the base
# controller's torque and the base controller's error signal.
SRC_MEASUREMENT: Final = 0  # entries 0..6: the measured state
SRC_REFERENCE: Final = 7
SRC_LAST_TORQUE: Final = 8
SRC_BASE_TORQUE: Final = 9
SRC_LAW_ERROR: Final = 10
N_SOURCES: Final = 11


class ObservationField(NamedTuple):
    """One entry of the observation vector.

    Attributes:
        name: What it shows, with its unit.
        source: Its entry in the kernel's source vector (``SRC_*``).
        scale: ``"speed"`` (divided by ``SPEED_SCALE_RAD_S``), ``"twist"``
            (``TWIST_SCALE_RAD``) or ``"torque"`` (the env's torque scale).
    """

    name: str
    source: int
    scale: str


_STATE_FIELDS: Final = tuple(
    ObservationField(
        ("measured_" if k % 2 == 0 else "") + name,
        SRC_MEASUREMENT + k,
        "speed" if k % 2 == 0 else "twist",
    )
    for k, name in enumerate(STATE_NAMES)
)
_DIRECT_FIELDS: Final = (
    *_STATE_FIELDS,
    ObservationField("reference_speed_rad_s", SRC_REFERENCE, "speed"),
    ObservationField("last_torque_nm", SRC_LAST_TORQUE, "torque"),
)
_RESIDUAL_FIELDS: Final = (
    *_DIRECT_FIELDS,
    ObservationField("base_torque_nm", SRC_BASE_TORQUE, "torque"),
    ObservationField("base_error_rad_s", SRC_LAW_ERROR, "speed"),
)


def observation_fields(residual: bool) -> tuple[ObservationField, ...]:
    """The observation's entries in order: 9 without a base controller, 11 in residual mode
    (the base controller's torque and error signal added)."""
    return _RESIDUAL_FIELDS if residual else _DIRECT_FIELDS


def observation_size(residual: bool) -> int:
    """Length of the observation: 9, or 11 in residual mode."""
    return len(observation_fields(residual))


def observation_scales(
    fields: tuple[ObservationField, ...], torque_scale_nm: float
) -> npt.NDArray[np.float64]:
    """The factor each entry is multiplied by (1 / its scale), (len(fields),)."""
    per_kind = {
        "speed": 1.0 / SPEED_SCALE_RAD_S,
        "twist": 1.0 / TWIST_SCALE_RAD,
        "torque": 1.0 / torque_scale_nm,
    }
    return np.array([per_kind[f.scale] for f in fields])


def observation_sources(fields: tuple[ObservationField, ...]) -> npt.NDArray[np.int64]:
    """The source-vector entry of each observation entry, (len(fields),) int64."""
    return np.array([f.source for f in fields], dtype=np.int64)


def unscale_measurement(
    observation: npt.ArrayLike,
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Recover the measured state (..., 7) and the reference speed (...,) from observations
    of ``DrillString-v0`` (either length)."""
    obs = np.asarray(observation, dtype=np.float64)
    scale = {"speed": SPEED_SCALE_RAD_S, "twist": TWIST_SCALE_RAD}
    state = np.array([scale[f.scale] for f in _STATE_FIELDS])
    reference = next(k for k, f in enumerate(_DIRECT_FIELDS) if f.source == SRC_REFERENCE)
    return obs[..., :N_STATE] * state, obs[..., reference] * SPEED_SCALE_RAD_S
