"""The top-drive speed-loop family shared by the industry baselines.

``stiff_pi``, ``soft_speed`` and ``z_torque`` are all one compiled law,
:func:`speed_loop_torque`: a PI loop on the measured top-drive speed
``x1`` with an optional set-point feed-forward and an optional torque feedback that moves the
set-point. They differ in how the gains are derived from the controller's model of the string
(see each controller's module). All of them track the reference *bit* speed with the top drive:
at steady rotation every inertia turns at one speed, so ``x1 = x7``.

Each controller derives its gains in :meth:`SpeedLoopController.tuning` from the model it is
given: its own (``model=`` at construction, ``zribi2024`` by default) or, inside
``DrillString-v0``, the model the env passes to :meth:`compiled_law` (the nominal parameters, or
the scaled ones under the ``controller`` uncertainty reading).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from numba import carray, njit

from baselines.base import CompiledLawController, Gains, Model
from baselines.observer import (
    OS_BIT_TORQUE,
    OS_ESTIMATE,
    ObserverGains,
    design_observer,
    initial_observer_state,
    observer_update,
    pack_observer,
)
from drill_env.control import CompiledLaw, compiled_law_function
from drill_env.distributed import DistributedStringParameters
from drill_env.layout import (
    M_STATE,
    M_SURFACE_TORQUE,
    M_TOP_DRIVE_SPEED,
    N_MEASUREMENT,
    N_STATE,
)
from drill_env.limits import DEFAULT_TORQUE_LIMITS, TorqueLimits
from drill_env.parameters import DrillStringParameters
from drill_env.sensors import MeasurementChannel

__all__ = [
    "DriveLimits",
    "SpeedLoopController",
    "SpeedLoopTuning",
    "speed_loop_law",
    "speed_loop_observer_law",
    "speed_loop_torque",
]

# Parameter vector.
PI_KP, PI_KI, PI_J_FF, PI_Z, PI_K_PI, PI_C_PI, PI_TAU, PI_U_MIN, PI_U_MAX = range(9)
N_PI_PARAMS: Final = 9
# State vector.
PS_INT, PS_SET_PREV, PS_ERROR, PS_T_MEAN, PS_STARTED = range(5)
N_PI_STATE: Final = 5
# With a state observer beside the loop (speed_loop_observer_law): two more parameters, the
# sizes of both vectors, then the observer's parameter block; its state block follows the
# loop's state.
PI_PARAMS_SIZE, PI_STATE_SIZE = N_PI_PARAMS, N_PI_PARAMS + 1
PI_OBSERVER: Final = N_PI_PARAMS + 2
PS_OBSERVER: Final = N_PI_STATE


@njit(cache=True)
def speed_loop_torque(lp, ls, m, ref: float, dt: float) -> float:
    """Top-drive speed PI loop with optional set-point feed-forward and torque feedback, N m.

    With the string torque at the top drive ``T`` (from the measured state,
    ``T = k_pi x2 + c_pi (x1 - x3)``, or, when only surface signals are measured, the measured
    surface torque) and its running mean ``T_mean`` (first-order low-pass, time constant
    ``tau_mean``), ``x1`` the measured top-drive speed::

        w_set = ref - (T - T_mean) / z              (z = 0: no torque feedback, w_set = ref)
        e     = w_set - x1
        u     = kp e + ki I + j_ff d(w_set)/dt       I = integral of e (forward Euler)

    ``stiff_pi`` and ``soft_speed`` use ``z = 0``; ``z_torque`` feeds the torque back through
    the pipe impedance ``z``. ``d(w_set)/dt`` is the backward difference of the set-point over
    ``dt`` (0 at the first call). The integral is clamped (conditional integration) while the
    unclipped output is beyond ``[u_min, u_max]`` and the error would push it further out. The
    torque is returned unclipped (the env clips it); then ``I``, ``T_mean`` and the previous
    set-point advance by ``dt``. ``ls[PS_ERROR]`` keeps the speed error ``x1 - w_set`` (rad/s).
    """
    x1 = m[M_TOP_DRIVE_SPEED]
    kp, ki, j_ff, z = lp[PI_KP], lp[PI_KI], lp[PI_J_FF], lp[PI_Z]
    w_set = ref
    if math.isnan(m[M_STATE + 1]):  # surface signals only: the measured torque
        t_string = m[M_SURFACE_TORQUE]
    else:  # the whole state: the torque from the model's top spring
        t_string = lp[PI_K_PI] * m[M_STATE + 1] + lp[PI_C_PI] * (m[M_STATE] - m[M_STATE + 2])
    first = ls[PS_STARTED] == 0.0
    if first:
        ls[PS_T_MEAN] = t_string
    if z > 0.0:
        w_set = ref - (t_string - ls[PS_T_MEAN]) / z
    feed = 0.0 if first else j_ff * (w_set - ls[PS_SET_PREV]) / dt
    e = w_set - x1
    u = kp * e + ki * ls[PS_INT] + feed
    saturated = (u > lp[PI_U_MAX] and e > 0.0) or (u < lp[PI_U_MIN] and e < 0.0)
    if not saturated:
        ls[PS_INT] += e * dt
    tau = lp[PI_TAU]
    if tau > 0.0:
        ls[PS_T_MEAN] += (t_string - ls[PS_T_MEAN]) * min(dt / tau, 1.0)
    ls[PS_SET_PREV] = w_set
    ls[PS_ERROR] = -e
    ls[PS_STARTED] = 1.0
    return u


@compiled_law_function
def speed_loop_law(lp_ptr, ls_ptr, m_ptr, ref, dt):
    """The compiled law of every speed-loop controller (:func:`speed_loop_torque`)."""
    lp = carray(lp_ptr, (N_PI_PARAMS,))
    ls = carray(ls_ptr, (N_PI_STATE,))
    m = carray(m_ptr, (N_MEASUREMENT,))
    return speed_loop_torque(lp, ls, m, ref, dt)


@compiled_law_function
def speed_loop_observer_law(lp_ptr, ls_ptr, m_ptr, ref, dt):
    """:func:`speed_loop_torque` with a state observer (:mod:`baselines.observer`) advanced
    one step first on the same measurements. The loop's torque does not read the estimate:
    the observer only reports it (``observation="estimate"``)."""
    head = carray(lp_ptr, (PI_OBSERVER,))
    lp = carray(lp_ptr, (int(head[PI_PARAMS_SIZE]),))
    ls = carray(ls_ptr, (int(head[PI_STATE_SIZE]),))
    m = carray(m_ptr, (N_MEASUREMENT,))
    observer_update(lp, PI_OBSERVER, ls, PS_OBSERVER, m, dt)
    return speed_loop_torque(lp, ls, m, ref, dt)


@dataclass(frozen=True)
class DriveLimits(Gains):
    """Torque limits of the top drive as the controller knows them when it runs on its own (as
    a policy), for anti-windup only. Inside ``DrillString-v0`` the env hands the controller its
    own ``min_torque_nm``/``max_torque_nm`` instead.

    The law stops integrating while its output is beyond these limits and the error would push
    it further out; it still returns the unclipped torque, which the env clips.

    Attributes:
        u_min_nm: Lowest top-drive torque, N m.
        u_max_nm: Highest top-drive torque, N m (> ``u_min_nm``).
    """

    u_min_nm: float = DEFAULT_TORQUE_LIMITS.min_nm
    u_max_nm: float = DEFAULT_TORQUE_LIMITS.max_nm

    def __post_init__(self) -> None:
        self._check_finite()
        self._check("u_max_nm", f"> u_min_nm = {self.u_min_nm}", self.u_max_nm > self.u_min_nm)


@dataclass(frozen=True)
class SpeedLoopTuning:
    """The numbers a speed-loop controller runs with, derived from a model of the string.

    Attributes:
        kp: Proportional gain on the top-drive speed error, N m s/rad.
        ki: Integral gain, N m/rad.
        j_ff: Inertia of the set-point acceleration feed-forward ``j_ff d(w_set)/dt``, kg m^2
            (0: none).
        z: Impedance of the torque feedback ``w_set = ref - (T - T_mean) / z``, N m s/rad
            (0: none).
        k_pi: Pipe stiffness used to measure the string torque, N m/rad.
        c_pi: Top drive-pipe damping used to measure the string torque, N m s/rad.
        tau_mean_s: Time constant of the running mean ``T_mean`` of the string torque, s.
        pipe_impedance: The model's pipe impedance ``sqrt(k_pi J_pi)``, N m s/rad (reported).
        stick_slip_rad_s: The model's stick-slip frequency, rad/s (reported).
    """

    kp: float
    ki: float
    j_ff: float = 0.0
    z: float = 0.0
    k_pi: float = 0.0
    c_pi: float = 0.0
    tau_mean_s: float = 0.0
    pipe_impedance: float = 0.0
    stick_slip_rad_s: float = 0.0

    def as_dict(self) -> dict[str, float]:
        """The tuning as a plain dict (for reports)."""
        return dataclasses.asdict(self)


class SpeedLoopController(CompiledLawController):
    """A top-drive speed-loop controller with its own model of the string, from which
    :meth:`tuning` derives the gains.

    Args:
        gains: The controller's gains (its class fixes the type); defaults when omitted.
        model: The controller's model of the string (preset name or parameters); the env
            replaces it through :meth:`compiled_law`.
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    family = "speed_loop"

    def tuning(
        self, model: DrillStringParameters | DistributedStringParameters | None = None
    ) -> SpeedLoopTuning:
        """The gains derived from ``model`` (the controller's own model when omitted)."""
        raise NotImplementedError

    def gains_for(self, model: DrillStringParameters | DistributedStringParameters) -> Any:
        """The gains :meth:`tuning` derives the numbers from for ``model``: the controller's
        own gains (the tuned variants of :mod:`baselines.tuned` pick theirs by the kind of
        model)."""
        return self.gains

    law = speed_loop_law
    error_slot = PS_ERROR
    observer_gains = ObserverGains()
    """The design of the state observer that runs beside the loop when the env's observation
    asks for its estimate (``observation="estimate"``)."""

    def compiled_law(
        self,
        model: Model | None = None,
        torque_limits: TorqueLimits | None = None,
        channel: MeasurementChannel | None = None,
    ) -> CompiledLaw:
        """The law for the compiled loop (:meth:`CompiledLawController.compiled_law`). With a
        ``channel`` whose observation is ``"estimate"``, a state observer designed for that
        channel and ``model`` runs beside the loop (:func:`speed_loop_observer_law`) and the
        law names its estimate's slots for the env (``estimated_*``,
        ``estimated_bit_torque_nm``); the torque is the loop's either way."""
        if channel is None or channel.observation != "estimate":
            return super().compiled_law(model, torque_limits)
        model = self.model if model is None else model
        design = design_observer(model, channel, self.observer_gains)
        loop = self._pack(model, torque_limits or self._own_torque_limits())
        state = np.concatenate([self._initial_state(), initial_observer_state(design)])
        params = np.concatenate([loop, np.zeros(2), pack_observer(design)])
        params[PI_PARAMS_SIZE] = params.size
        params[PI_STATE_SIZE] = state.size
        info = (("estimated_bit_torque_nm", PS_OBSERVER + OS_BIT_TORQUE),)
        estimates = tuple((x, PS_OBSERVER + OS_ESTIMATE + x) for x in range(N_STATE))
        return CompiledLaw(
            speed_loop_observer_law, params, state, self.error_slot, self.gain_slot, info,
            estimates,
        ).validated()  # fmt: skip

    def _pack(
        self,
        model: DrillStringParameters | DistributedStringParameters,
        torque_limits: TorqueLimits,
    ) -> npt.NDArray[np.float64]:
        t = self.tuning(model)
        p = np.zeros(N_PI_PARAMS)
        p[PI_KP], p[PI_KI], p[PI_J_FF], p[PI_Z] = t.kp, t.ki, t.j_ff, t.z
        p[PI_K_PI], p[PI_C_PI], p[PI_TAU] = t.k_pi, t.c_pi, t.tau_mean_s
        p[PI_U_MIN], p[PI_U_MAX] = torque_limits
        return p

    def _own_torque_limits(self) -> TorqueLimits:
        limits: DriveLimits = self.gains.limits
        return TorqueLimits(limits.u_min_nm, limits.u_max_nm)

    def _initial_state(self) -> npt.NDArray[np.float64]:
        return np.zeros(N_PI_STATE)

    def _python_torque(self, m: npt.NDArray[np.float64], ref: float, dt: float) -> float:
        return float(speed_loop_torque(self._params, self._state, m, ref, dt))

    @property
    def speed_error(self) -> float:
        """The last top-drive speed error ``x1 - w_set``, rad/s."""
        return float(self._state[PS_ERROR])

    @property
    def integral(self) -> float:
        """The integral of the speed error ``w_set - x1``, rad."""
        return float(self._state[PS_INT])
