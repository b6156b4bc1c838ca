"""Limits, in one place: the top drive's torque range, the accepted ranges of the scenario
inputs and the physical bounds beyond which a run counts as diverged.
"""

from __future__ import annotations

from typing import Final, NamedTuple

__all__ = [
    "DEFAULT_TORQUE_LIMITS",
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
