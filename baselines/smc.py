"""The sliding-mode family of docs/specification.md section 3: one compiled law, four variants.

All four share the surface ``s = (x1 - xd) + lam I1 + lam I2`` and the equivalent control
``u_eq = c_pi (x1 - x3) + k_pi x2 + c_dt x1 - J_dt lam (x1 - xd) - J_dt lam (x1 - x7)``,
computed from measured signals with the controller's own model of the string; they differ in
the discontinuous part (see each gains class). :func:`smc_torque` is the law; each controller
module compiles its variant of it into a ``cfunc`` that the env's plant loop calls.

When the state is not measured (``drill_env.layout.M_STATE + 1`` is NaN: the env's
``surface`` observation), the law runs a state observer (:mod:`baselines.observer`,
docs/observer.md) inside the same compiled call and computes ``s`` and ``u_eq`` from its
estimate of ``x1, x2, x3, x7``; with the state measured the observer does not run and the law
is the one of docs/specification.md section 3 on the measured state.

Parameter vector (``SMC_*``), then the observer's block (:func:`baselines.observer.
pack_observer`) when there is one::

    lp = [J_dt, c_dt, c_pi, k_pi, lam, delta, g0, g1, g2, g3, g4, len(lp), len(ls), ...]

State vector (``S_*``), then the observer's block (``S_OBSERVER + baselines.observer.OS_*``;
the estimate ``x1..x7`` at ``S_OBSERVER + OS_ESTIMATE``, the bit-rock torque at
``S_OBSERVER + OS_BIT_TORQUE``)::

    ls = [I1, I2, k_adaptive, s_last, ...]
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any, ClassVar, Final

import numpy as np
import numpy.typing as npt
from numba import carray, njit

from baselines.base import CompiledLawController, Gains, Model
from baselines.observer import (
    OS_BIT_TORQUE,
    OS_ESTIMATE,
    ObserverDesign,
    ObserverGains,
    design_observer,
    initial_observer_state,
    observer_update,
    pack_observer,
)
from drill_env.control import CompiledLaw
from drill_env.distributed import DistributedStringParameters
from drill_env.layout import M_STATE, N_MEASUREMENT, N_STATE
from drill_env.limits import TorqueLimits
from drill_env.modes import lumped_equivalent
from drill_env.options import FieldEnvConfig
from drill_env.sensors import MeasurementChannel

__all__ = [
    "N_SMC_PARAMS",
    "N_SMC_STATE",
    "VARIANT_ASMC",
    "VARIANT_CSMC",
    "VARIANT_MSMC",
    "VARIANT_PROPOSED",
    "SlidingModeController",
    "SurfaceGains",
    "default_channel",
    "smc_core",
    "smc_law",
    "smc_step",
    "smc_torque",
]

VARIANT_CSMC: Final = 1
VARIANT_MSMC: Final = 2
VARIANT_ASMC: Final = 3
VARIANT_PROPOSED: Final = 4
VARIANTS: Final = (VARIANT_CSMC, VARIANT_MSMC, VARIANT_ASMC, VARIANT_PROPOSED)

# Parameter vector.
SMC_J_DT, SMC_C_DT, SMC_C_PI, SMC_K_PI, SMC_LAM, SMC_DELTA, SMC_G0 = 0, 1, 2, 3, 4, 5, 6
SMC_PARAMS_SIZE: Final = 11  # the length of the whole parameter vector
SMC_STATE_SIZE: Final = 12  # the length of the whole state vector
N_SMC_PARAMS: Final = 13  # the law's own entries; the observer's block follows
# State vector.
S_I1, S_I2, S_GAIN, S_SLIDING = 0, 1, 2, 3
N_SMC_STATE: Final = 4  # the law's own entries; the observer's block follows
S_OBSERVER: Final = N_SMC_STATE


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
    return smc_core(variant, lp, ls, x1, x2, x3, x7, ref, dt)


@njit(cache=True)
def smc_step(variant: int, lp, ls, m, ref: float, dt: float) -> float:
    """The law on the measurement vector ``m`` (``drill_env.layout.M_*``, an array):
    :func:`smc_torque` on the measured state, or, when the state is not measured
    (``m[M_STATE + 1]`` NaN) and ``lp`` has an observer block, on the estimate of the observer,
    advanced by one step first (without an observer the torque is then NaN)."""
    if math.isnan(m[M_STATE + 1]) and lp[SMC_PARAMS_SIZE] > N_SMC_PARAMS:
        observer_update(lp, N_SMC_PARAMS, ls, S_OBSERVER, m, dt)
        o = S_OBSERVER + OS_ESTIMATE
        return smc_core(variant, lp, ls, ls[o], ls[o + 1], ls[o + 2], ls[o + 6], ref, dt)
    return smc_torque(variant, lp, ls, m, ref, dt)


@njit(cache=True)
def smc_core(
    variant: int, lp, ls, x1: float, x2: float, x3: float, x7: float, ref: float, dt: float
) -> float:
    """:func:`smc_torque` on given ``x1, x2, x3, x7`` (rad/s, rad, rad/s, rad/s)."""
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
    """:func:`smc_step` on the raw vectors of the compiled-law signature."""
    head = carray(lp_ptr, (N_SMC_PARAMS,))
    lp = carray(lp_ptr, (max(int(head[SMC_PARAMS_SIZE]), N_SMC_PARAMS),))
    ls = carray(ls_ptr, (max(int(head[SMC_STATE_SIZE]), N_SMC_STATE),))
    m = carray(m_ptr, (N_MEASUREMENT,))
    return smc_step(variant, lp, ls, m, ref, dt)


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


@functools.cache
def default_channel() -> MeasurementChannel:
    """The measurement channel an observer is designed for when no env names its own: that of
    ``DrillStringField-v0``'s defaults (a rig's surface sensors and mud-pulse telemetry)."""
    return FieldEnvConfig().measurement_channel()


class SlidingModeController(CompiledLawController):
    """A sliding-mode top-drive controller with its own model of the string (used in ``u_eq``).

    Subclasses set ``name``, ``gains_type``, ``variant`` (``VARIANT_*``) and ``law`` (their
    compiled variant of :func:`smc_torque`).

    Args:
        gains: The controller's gains (its class fixes the law); defaults when omitted.
        model: The controller's model of the string (preset name or parameters); the env
            replaces it under the ``controller`` uncertainty reading.
        observer: The design of the state observer that runs when the state is not measured
            (:class:`baselines.observer.ObserverGains`; its defaults when omitted).
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    gains_type: ClassVar[type[SurfaceGains]]
    variant: ClassVar[int]
    family = "sliding_mode"
    needs_full_state = True
    error_slot = S_SLIDING
    gain_slot = S_GAIN
    _design: ObserverDesign | None = None

    def __init__(
        self,
        gains: Any = None,
        model: str | Model = "zribi2024",
        observer: ObserverGains | None = None,
        **overrides: Any,
    ) -> None:
        observer = ObserverGains() if observer is None else observer
        if not isinstance(observer, ObserverGains):
            raise TypeError(f"observer must be an ObserverGains, got {type(observer).__name__}")
        self.observer = observer
        super().__init__(gains, model, **overrides)

    def _pack(self, model: Model, torque_limits: TorqueLimits) -> npt.NDArray[np.float64]:
        # The controller's own vectors (run from Python): the observer for default_channel().
        params, self._design = self._pack_for(model, None)
        return params

    def _pack_for(
        self, model: Model, channel: MeasurementChannel | None
    ) -> tuple[npt.NDArray[np.float64], ObserverDesign | None]:
        """The parameter vector for ``model`` and the observer's design for ``channel``
        (:func:`default_channel` when ``None``; no observer when the state is measured)."""
        channel = default_channel() if channel is None else channel
        design = None
        if channel.observation != "state":
            design = design_observer(model, channel, self.observer)
        lumped = (
            lumped_equivalent(model) if isinstance(model, DistributedStringParameters) else model
        )
        g = self.gains
        head = (lumped.J_dt, lumped.c_dt, lumped.c_pi, lumped.k_pi, g.lam, g.delta)
        values = head + g.law_gains()
        p = np.zeros(N_SMC_PARAMS)
        p[: len(values)] = values
        if design is not None:
            p = np.concatenate([p, pack_observer(design)])
        p[SMC_PARAMS_SIZE] = p.size
        p[SMC_STATE_SIZE] = self._state_for(design).size
        return p, design

    def _state_for(self, design: ObserverDesign | None) -> npt.NDArray[np.float64]:
        state = np.zeros(N_SMC_STATE)
        state[S_GAIN] = self.gains.initial_gain()
        if design is None:
            return state
        return np.concatenate([state, initial_observer_state(design)])

    def _initial_state(self) -> npt.NDArray[np.float64]:
        return self._state_for(self._design)

    def compiled_law(
        self,
        model: Model | None = None,
        torque_limits: TorqueLimits | None = None,
        channel: MeasurementChannel | None = None,
    ) -> CompiledLaw:
        """The law for the compiled loop; ``model`` replaces the controller's own model (the
        env passes its model of the string), ``channel`` is the env's measurement channel,
        for which the observer is designed (none when the state is measured). With a channel
        whose state is not measured, the law names its estimate's slots for the env's
        ``info`` (``estimated_*``, ``estimate_error_*``, ``estimated_bit_torque_nm``)."""
        if model is None and channel is None:
            params, design = self._params, self._design
        else:
            params, design = self._pack_for(self.model if model is None else model, channel)
        info: tuple[tuple[str, int], ...] = ()
        estimates: tuple[tuple[int, int], ...] = ()
        if design is not None and channel is not None:
            info = (("estimated_bit_torque_nm", S_OBSERVER + OS_BIT_TORQUE),)
            estimates = tuple((x, S_OBSERVER + OS_ESTIMATE + x) for x in range(N_STATE))
        return CompiledLaw(
            self.law, params, self._state_for(design), self.error_slot, self.gain_slot, info,
            estimates,
        ).validated()  # fmt: skip

    def _python_torque(self, m: npt.NDArray[np.float64], ref: float, dt: float) -> float:
        return float(smc_step(self.variant, self._params, self._state, m, ref, dt))

    @property
    def estimate(self) -> npt.NDArray[np.float64] | None:
        """The observer's last estimate of ``x1..x7`` (rad/s and rad) on the Python path, or
        ``None`` without an observer (a copy)."""
        if self._design is None:
            return None
        o = S_OBSERVER + OS_ESTIMATE
        return self._state[o : o + N_STATE].copy()

    @property
    def sliding_variable(self) -> float:
        """The last sliding variable ``s``, rad/s."""
        return float(self._state[S_SLIDING])

    @property
    def adaptive_gain(self) -> float:
        """The current adaptive gain (0 for the fixed-gain laws)."""
        return float(self._state[S_GAIN])
