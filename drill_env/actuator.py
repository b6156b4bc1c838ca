"""The top drive as an actuator: what happens between the torque command and the torque the
motor puts on the string, as pure compiled functions.

A command ``u_cmd`` (N m), already clipped to the drive's torque range, passes in turn through

1. a dead time of ``delay_steps`` plant steps (the drive's and the control network's latency):
   the command issued ``delay_steps`` steps ago is the one that acts now (0 N m before any);
2. a first-order lag of time constant ``tau`` (the torque loop of the drive), discretised
   exactly for a command held over the step: ``u += (u_delayed - u) (1 - exp(-dt / tau))``;
3. a rate limit: the applied torque changes by at most ``rate_limit dt`` per step;
4. the torque range again.

With no dead time, no lag and no rate limit the applied torque is the command, exactly.

State of one string (a float64 vector ``ACT_*``): the applied torque of the last step and the
delay line's write position; the delay line itself is a separate vector of
``delay_steps + 1`` commands.
"""

from __future__ import annotations

import math
from typing import Final

from numba import njit

__all__ = [
    "ACT_APPLIED",
    "ACT_HEAD",
    "N_ACTUATOR_STATE",
    "actuator_step",
    "lag_factor",
]

ACT_APPLIED: Final = 0  # the torque applied over the last step, N m
ACT_HEAD: Final = 1  # the delay line's next write position (an integer stored as float)
N_ACTUATOR_STATE: Final = 2


def lag_factor(lag_s: float, dt_s: float) -> float:
    """The exact discrete step ``1 - exp(-dt / tau)`` of a first-order lag held over ``dt``;
    1 for no lag (``tau = 0``)."""
    return 1.0 if lag_s <= 0.0 else -math.expm1(-dt_s / lag_s)


@njit(cache=True)
def actuator_step(
    state, line, u_command: float, lag: float, rate_step_nm: float, u_min: float, u_max: float
) -> float:
    """The torque applied over this step for the command ``u_command`` (N m).

    Args:
        state: The actuator state ``ACT_*`` (updated).
        line: The delay line, ``delay_steps + 1`` commands (updated); length 1 for no dead time.
        u_command: The command of this step, N m (within the torque range).
        lag: :func:`lag_factor` of the drive's lag (1 for none).
        rate_step_nm: Largest change of the applied torque per step, N m (``inf`` for none).
        u_min, u_max: The torque range, N m.

    Returns:
        The applied torque, N m.
    """
    n = line.shape[0]
    head = int(state[ACT_HEAD])
    line[head] = u_command
    head = (head + 1) % n
    state[ACT_HEAD] = head
    delayed = line[head]  # the command written n - 1 steps ago (this one when n = 1)
    previous = state[ACT_APPLIED]
    if lag == 1.0 and math.isinf(rate_step_nm):
        applied = delayed
    else:
        change = (delayed - previous) * lag
        applied = previous + min(max(change, -rate_step_nm), rate_step_nm)
    applied = min(max(applied, u_min), u_max)
    state[ACT_APPLIED] = applied
    return applied
