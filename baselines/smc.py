"""The sliding-mode family of SPEC section 3: one class runs any of the four laws.

All four share the surface ``s = (x1 - xd) + lam I1 + lam I2`` and the equivalent control
``u_eq = c_pi (x1 - x3) + k_pi x2 + c_dt x1 - J_dt lam (x1 - xd) - J_dt lam (x1 - x7)``,
computed from measured signals with the controller's own model of the string; they differ in
the discontinuous part (see each gains class). The compiled law is
:func:`drill_env.control_laws.smc_torque`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from baselines.base import CompiledLawController, check_gain, check_numbers
from drill_env.control_laws import N_LAW_PARAMS, N_LAW_STATE, S_GAIN, S_SLIDING
from drill_env.parameters import DrillStringParameters

__all__ = ["SlidingModeController", "SurfaceGains"]


@dataclass(frozen=True)
class SurfaceGains:
    """Gains shared by the sliding-mode controllers.

    Attributes:
        lam: Surface gain lambda, 1/s (> 0).
        delta: Boundary of ``|s|`` where the adaptive gains switch from growing to shrinking,
            rad/s (> 0).
    """

    lam: float = 1.0
    delta: float = 0.5

    def __post_init__(self) -> None:
        check_numbers(self)
        check_gain(self, "lam", "> 0", self.lam > 0)
        check_gain(self, "delta", "> 0", self.delta > 0)

    def law_gains(self) -> tuple[float, ...]:
        """The law-specific gains in the order of the compiled parameter vector."""
        return ()

    def initial_gain(self) -> float:
        """Adaptive gain at t = 0 (0 for the non-adaptive laws)."""
        return 0.0


class SlidingModeController(CompiledLawController):
    """A sliding-mode top-drive controller with its own model of the string (used in ``u_eq``).

    Args:
        gains: The controller's gains (its class fixes the law); defaults when omitted.
        model: The controller's model of the string (preset name or parameters); the env
            replaces it under the ``controller`` uncertainty reading.
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    gains_type: ClassVar[type[SurfaceGains]]

    def _pack(self, model: DrillStringParameters) -> npt.NDArray[np.float64]:
        p = np.zeros(N_LAW_PARAMS)
        g = self.gains
        head = (model.J_dt, model.c_dt, model.c_pi, model.k_pi, g.lam, g.delta)
        values = head + g.law_gains()
        p[: len(values)] = values
        return p

    def _initial_state(self) -> npt.NDArray[np.float64]:
        state = np.zeros(N_LAW_STATE)
        state[S_GAIN] = self.gains.initial_gain()
        return state

    @property
    def sliding_variable(self) -> float:
        """The last sliding variable ``s``, rad/s."""
        return float(self._state[S_SLIDING])

    @property
    def adaptive_gain(self) -> float:
        """The current adaptive gain (0 for the fixed-gain laws)."""
        return float(self._state[S_GAIN])
