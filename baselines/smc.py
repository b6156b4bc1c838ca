"""The sliding-mode family of docs/specification.md section 3: one compiled law, four variants.

All four share the surface ``s = (x1 - xd) + lam I1 + lam I2`` and the equivalent control
``u_eq = c_pi (x1 - x3) + k_pi x2 + c_dt x1 - J_dt lam (x1 - xd) - J_dt lam (x1 - x7)``,
computed from measured signals with the controller's own model of the string; they differ in
the discontinuous part (see each gains class). :func:`smc_torque` is the law; each controller
module compiles its variant of it into a ``cfunc`` that the env's plant loop calls.

Parameter vector (``SMC_*``)::

    lp = [J_dt, c_dt, c_pi, k_pi, lam, delta, g0, g1, g2, g3, g4]

State vector (``S_*``)::

    ls = [I1, I2, k_adaptive, s_last]
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Final

import numpy as np
import numpy.typing as npt
from numba import carray, njit

from baselines.base import CompiledLawController, Gains, Model
from drill_env.distributed import DistributedStringParameters
from drill_env.layout import M_STATE, N_MEASUREMENT
from drill_env.limits import TorqueLimits
from drill_env.modes import lumped_equivalent

__all__ = [
    "N_SMC_PARAMS",
    "N_SMC_STATE",
    "VARIANT_ASMC",
    "VARIANT_CSMC",
    "VARIANT_MSMC",
    "VARIANT_PROPOSED",
    "SlidingModeController",
    "SurfaceGains",
    "smc_law",
    "smc_torque",
]

VARIANT_CSMC: Final = 1
VARIANT_MSMC: Final = 2
VARIANT_ASMC: Final = 3
VARIANT_PROPOSED: Final = 4
VARIANTS: Final = (VARIANT_CSMC, VARIANT_MSMC, VARIANT_ASMC, VARIANT_PROPOSED)

# Parameter vector.
SMC_J_DT, SMC_C_DT, SMC_C_PI, SMC_K_PI, SMC_LAM, SMC_DELTA, SMC_G0 = 0, 1, 2, 3, 4, 5, 6
N_SMC_PARAMS: Final = 11
# State vector.
S_I1, S_I2, S_GAIN, S_SLIDING = 0, 1, 2, 3
N_SMC_STATE: Final = 4


@njit(cache=True)
def _sign(v: float) -> float:
    if v > 0.0:
        return 1.0
    if v < 0.0:
        return -1.0
    return 0.0


@njit(cache=True)
def smc_torque(variant: int, lp, ls, m, ref: float, dt: float) -> float:
    """Sliding-mode torque ``u = u_eq + u_disc``, N m (NaN for an unknown ``variant``).

    Computes ``s = (x1 - xd) + lam I1 + lam I2`` from the measured state ``m``
    (``drill_env.layout.M_STATE``) and the current integrals, returns the torque, then
    advances ``I1``, ``I2`` and the adaptive gain by forward Euler over ``dt`` seconds.
    ``ls[S_SLIDING]`` keeps the last ``s`` (rad/s).
    """
    x1, x2, x3, x7 = m[M_STATE], m[M_STATE + 1], m[M_STATE + 2], m[M_STATE + 6]
    j_dt, c_dt, c_pi, k_pi = lp[SMC_J_DT], lp[SMC_C_DT], lp[SMC_C_PI], lp[SMC_K_PI]
    lam, delta = lp[SMC_LAM], lp[SMC_DELTA]
    e1 = x1 - ref
    e17 = x1 - x7
    s = e1 + lam * ls[S_I1] + lam * ls[S_I2]
    u_eq = c_pi * (x1 - x3) + k_pi * x2 + c_dt * x1 - j_dt * lam * e1 - j_dt * lam * e17
    abs_s = abs(s)
    sgn_s = _sign(s)
    gain = ls[S_GAIN]
    if variant == VARIANT_CSMC:
        u_disc = -lp[SMC_G0] * sgn_s
    elif variant == VARIANT_MSMC:
        u_disc = -lp[SMC_G0] * math.sqrt(abs_s) * sgn_s - lp[SMC_G0 + 1] * s
    elif variant == VARIANT_ASMC:
        u_disc = -gain * sgn_s
        mu11, mu22 = lp[SMC_G0], lp[SMC_G0 + 1]
        rate = mu11 * abs_s * _sign(abs_s - delta) if gain > mu22 else mu22
        ls[S_GAIN] = gain + rate * dt
    elif variant == VARIANT_PROPOSED:
        mu1, mu2, alpha, a, b = (
            lp[SMC_G0], lp[SMC_G0 + 1], lp[SMC_G0 + 2], lp[SMC_G0 + 3], lp[SMC_G0 + 4]
        )  # fmt: skip
        u_disc = -gain * math.sqrt(abs_s) * sgn_s - a * gain * s
        rate = mu1 * abs_s**b * _sign(abs_s - delta) if gain > alpha else mu2
        ls[S_GAIN] = gain + rate * dt
    else:
        return math.nan
    ls[S_I1] += e1 * dt
    ls[S_I2] += e17 * dt
    ls[S_SLIDING] = s
    return u_eq + u_disc


@njit(cache=True)
def smc_law(variant: int, lp_ptr, ls_ptr, m_ptr, ref: float, dt: float) -> float:
    """:func:`smc_torque` on the raw vectors of the compiled-law signature."""
    lp = carray(lp_ptr, (N_SMC_PARAMS,))
    ls = carray(ls_ptr, (N_SMC_STATE,))
    m = carray(m_ptr, (N_MEASUREMENT,))
    return smc_torque(variant, lp, ls, m, ref, dt)


@dataclass(frozen=True)
class SurfaceGains(Gains):
    """Gains shared by the sliding-mode controllers.

    Attributes:
        lam: Surface gain lambda, 1/s (> 0).
        delta: Boundary of ``|s|`` where the adaptive gains switch from growing to shrinking,
            rad/s (> 0).
    """

    lam: float = 1.0
    delta: float = 0.5

    def __post_init__(self) -> None:
        self._check_finite()
        self._check("lam", "> 0", self.lam > 0)
        self._check("delta", "> 0", self.delta > 0)

    def law_gains(self) -> tuple[float, ...]:
        """The law-specific gains in the order of the compiled parameter vector."""
        return ()

    def initial_gain(self) -> float:
        """Adaptive gain at t = 0 (0 for the non-adaptive laws)."""
        return 0.0


class SlidingModeController(CompiledLawController):
    """A sliding-mode top-drive controller with its own model of the string (used in ``u_eq``).

    Subclasses set ``name``, ``gains_type``, ``variant`` (``VARIANT_*``) and ``law`` (their
    compiled variant of :func:`smc_torque`).

    Args:
        gains: The controller's gains (its class fixes the law); defaults when omitted.
        model: The controller's model of the string (preset name or parameters); the env
            replaces it under the ``controller`` uncertainty reading.
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    gains_type: ClassVar[type[SurfaceGains]]
    variant: ClassVar[int]
    error_slot = S_SLIDING
    gain_slot = S_GAIN

    def _pack(self, model: Model, torque_limits: TorqueLimits) -> npt.NDArray[np.float64]:
        if isinstance(model, DistributedStringParameters):
            model = lumped_equivalent(model)  # the 4-DOF model the law is written for
        p = np.zeros(N_SMC_PARAMS)
        g = self.gains
        head = (model.J_dt, model.c_dt, model.c_pi, model.k_pi, g.lam, g.delta)
        values = head + g.law_gains()
        p[: len(values)] = values
        return p

    def _initial_state(self) -> npt.NDArray[np.float64]:
        state = np.zeros(N_SMC_STATE)
        state[S_GAIN] = self.gains.initial_gain()
        return state

    def _python_torque(self, m: npt.NDArray[np.float64], ref: float, dt: float) -> float:
        return float(smc_torque(self.variant, self._params, self._state, m, ref, dt))

    @property
    def sliding_variable(self) -> float:
        """The last sliding variable ``s``, rad/s."""
        return float(self._state[S_SLIDING])

    @property
    def adaptive_gain(self) -> float:
        """The current adaptive gain (0 for the fixed-gain laws)."""
        return float(self._state[S_GAIN])
