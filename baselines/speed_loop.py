"""The top-drive speed-loop family shared by the industry baselines.

``stiff_pi``, ``soft_speed`` and ``z_torque`` are all one compiled law,
:func:`drill_env.control_laws.speed_loop_torque`: a PI loop on the measured top-drive speed
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
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from baselines.base import CompiledLawController, check_gain, check_numbers
from drill_env.control_laws import (
    N_LAW_PARAMS,
    PI_C_PI,
    PI_J_FF,
    PI_K_PI,
    PI_KI,
    PI_KP,
    PI_TAU,
    PI_U_MAX,
    PI_U_MIN,
    PI_Z,
    PS_ERROR,
    PS_INT,
)
from drill_env.parameters import DrillStringParameters

__all__ = ["DriveLimits", "SpeedLoopController", "SpeedLoopTuning"]


@dataclass(frozen=True)
class DriveLimits:
    """Torque limits of the top drive as the controller knows them (anti-windup only).

    The law stops integrating while its output is beyond these limits and the error would push
    it further out; it still returns the unclipped torque, which the env clips to its own
    ``min_torque_nm``/``max_torque_nm``. Keep the two pairs equal (the defaults are the env's).

    Attributes:
        u_min_nm: Lowest top-drive torque, N m.
        u_max_nm: Highest top-drive torque, N m (> ``u_min_nm``).
    """

    u_min_nm: float = 0.0
    u_max_nm: float = 50_000.0

    def __post_init__(self) -> None:
        check_numbers(self)
        check_gain(self, "u_max_nm", f"> u_min_nm = {self.u_min_nm}", self.u_max_nm > self.u_min_nm)


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

    def tuning(self, model: DrillStringParameters | None = None) -> SpeedLoopTuning:
        """The gains derived from ``model`` (the controller's own model when omitted)."""
        raise NotImplementedError

    def _pack(self, model: DrillStringParameters) -> npt.NDArray[np.float64]:
        t = self.tuning(model)
        limits: DriveLimits = self.gains.limits
        p = np.zeros(N_LAW_PARAMS)
        p[PI_KP], p[PI_KI], p[PI_J_FF], p[PI_Z] = t.kp, t.ki, t.j_ff, t.z
        p[PI_K_PI], p[PI_C_PI], p[PI_TAU] = t.k_pi, t.c_pi, t.tau_mean_s
        p[PI_U_MIN], p[PI_U_MAX] = limits.u_min_nm, limits.u_max_nm
        return p

    @property
    def speed_error(self) -> float:
        """The last top-drive speed error ``x1 - w_set``, rad/s."""
        return float(self._state[PS_ERROR])

    @property
    def integral(self) -> float:
        """The integral of the speed error ``w_set - x1``, rad."""
        return float(self._state[PS_INT])
