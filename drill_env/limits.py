"""Limits, in one place: the top drive's torque range, the accepted ranges of the scenario
inputs, the physical bounds beyond which a run counts as diverged, and the sizes (string length,
elements, strings per batch, episode length) that bound what an env allocates, each refused
before anything is allocated.
"""

from __future__ import annotations

from typing import Final, NamedTuple

__all__ = [
    "DEFAULT_TORQUE_LIMITS",
    "HOOK_STIFFNESS_RANGE_N_M",
    "MAX_BATCH_BYTES",
    "MAX_ELEMENTS",
    "MAX_EPISODE_S",
    "MAX_MEASURED_DEPTH_M",
    "MAX_NUM_ENVS",
    "MAX_SECTIONS",
    "MIN_ELEMENT_LENGTH_M",
    "MAX_REFERENCE_RAD_S",
    "MAX_SPEED_RAD_S",
    "MAX_TORQUE_ABS_NM",
    "MAX_TWIST_RAD",
    "MAX_WOB_N",
    "TorqueLimits",
]


class TorqueLimits(NamedTuple):
    """The top drive's torque range, N m: the env clips every applied torque to it, and a
    controller that integrates (a PI loop) stops integrating while its output is beyond it."""

    min_nm: float
    max_nm: float


DEFAULT_TORQUE_LIMITS: Final = TorqueLimits(0.0, 50_000.0)
"""The top-drive torque range of ``DrillString-v0`` by default, N m."""

HOOK_STIFFNESS_RANGE_N_M: Final = (1e3, 1e10)
"""Accepted finite axial stiffness of the string between hook and bit (an elastic hook), N/m:
``DrillStringCoupled-v0``'s ``hook_stiffness_n_m``, and ``DrillStringField-v0``'s with
``bit="rgd"`` (which also takes ``inf``, a rigid hook). A stiffer spring is no longer resolved
by the plant step: the coupled chain diverges at its first step."""

MAX_TORQUE_ABS_NM: Final = 1e6
"""Largest accepted torque limit or residual scale, N m."""
MAX_WOB_N: Final = 1e6
"""Largest accepted weight on bit, N."""
MAX_REFERENCE_RAD_S: Final = 100.0
"""Largest accepted reference bit speed, rad/s."""
MAX_SPEED_RAD_S: Final = 1000.0
"""Physical bound on every speed, rad/s; beyond it the run counts as diverged."""
MAX_TWIST_RAD: Final = 1000.0
"""Physical bound on every twist, rad; beyond it the run counts as diverged."""

# ------------------------------------------------------------------------------------ sizes
MAX_MEASURED_DEPTH_M: Final = 20_000.0
"""Longest accepted string (measured depth, and any one section), m. The longest wells drilled
reach about 15 km of measured depth (extended-reach wells of the Sakhalin-1 project's Chayvo
field, 2017); 20 km leaves room above them."""
MIN_ELEMENT_LENGTH_M: Final = 1.0
"""Shortest accepted element of a distributed string, m. The plant step of 1 ms already needs
elements of about 4 m or more on steel pipe (the highest mode of the chain is about
``2 c / l`` with ``c`` = 3.2 km/s, and RK4 needs ``h omega <= 2``); shorter elements would
only make the chain larger."""
MAX_ELEMENTS: Final = 5_000
"""Most elements of a distributed string's chain (20 km at 4 m). Mode analyses use dense
eigenproblems of this size: 5,000 nodes take seconds and 200 MB; the env's own plant-step
check is linear in the size."""
MAX_SECTIONS: Final = 100
"""Most sections of a distributed string (a real string has a few: pipe, heavy-weight pipe,
collars, tools)."""
MAX_NUM_ENVS: Final = 100_000
"""Most strings of one vector env (``gym.make_vec(..., num_envs=N)``)."""
MAX_BATCH_BYTES: Final = 4 * 2**30
"""Most bytes of per-string arrays a batch of strings may allocate (records of one decision
period, noise blocks, telemetry and actuator delay lines, chain state); a larger ``num_envs``
for the given keywords is refused before allocating."""
MAX_EPISODE_S: Final = 1e5
"""Longest accepted episode, s (28 hours of drilling)."""
