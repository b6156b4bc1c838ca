"""What every built-in controller shares: validated gains, its own model of the string, and a
compiled law (a numba ``cfunc`` of :data:`drill_env.control.LAW_SIGNATURE`) that it runs from
Python or hands to the env's plant loop."""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from drill_env.control import CompiledLaw
from drill_env.distributed import DistributedStringParameters, resolve_plant
from drill_env.layout import M_STATE, M_TOP_DRIVE_SPEED, N_MEASUREMENT, N_STATE
from drill_env.limits import DEFAULT_TORQUE_LIMITS, TorqueLimits
from drill_env.parameters import DrillStringParameters
from drill_env.validation import check_finite_fields, check_unknown, require

__all__ = ["CompiledLawController", "Gains", "Model", "measurement_vector", "resolve_model"]

Model = DrillStringParameters | DistributedStringParameters
"""A controller's model of the string: the 4-DOF parameters or a distributed string."""


def resolve_model(value: str | Model) -> Model:
    """A controller's model from a preset name (either kind) or the parameters themselves."""
    model = resolve_plant(value)
    if not isinstance(model, (DrillStringParameters, DistributedStringParameters)):
        raise TypeError(
            "model must be a preset name, a DrillStringParameters or a "
            f"DistributedStringParameters, got {type(value).__name__}"
        )
    return model


def measurement_vector(measurement: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The measurement vector (``drill_env.layout.M_*``) from either a measured 4-DOF state
    (7,) (the surface signals then unknown, NaN, but the top-drive speed) or a whole
    measurement vector."""
    m = np.ascontiguousarray(measurement, dtype=np.float64)
    if m.shape == (N_MEASUREMENT,):
        return m
    if m.shape != (N_STATE,):
        raise ValueError(
            f"measurement must have shape ({N_STATE},) (the measured state) or "
            f"({N_MEASUREMENT},) (the measurement vector), got {m.shape}"
        )
    full = np.full(N_MEASUREMENT, np.nan)
    full[M_STATE : M_STATE + N_STATE] = m
    full[M_TOP_DRIVE_SPEED] = m[0]
    return full


class Gains:
    """Base of the controllers' frozen gain dataclasses: checks whose messages name
    ``Class.field``, the value and the allowed range."""

    def _check_finite(self) -> None:
        """Every float field a finite number (stored as a Python float)."""
        check_finite_fields(self, f"{type(self).__name__}.")

    def _check(self, name: str, allowed: str, ok: bool) -> None:
        """``ValueError`` naming ``Class.name``, its value and ``allowed`` unless ``ok``."""
        require(f"{type(self).__name__}.{name}", getattr(self, name), allowed, ok)


class CompiledLawController:
    """A top-drive controller whose law is compiled and runs inside the plant loop.

    Subclasses set ``name``, ``gains_type``, ``law`` (the compiled law) and the state slots the
    env reports (``error_slot``, ``gain_slot``; -1 for none), and implement :meth:`_pack` (the
    law's parameter vector for a model of the string and the top drive's torque limits),
    :meth:`_initial_state` and :meth:`_python_torque` (the same law called from Python).

    Args:
        gains: The controller's gains (an instance of ``gains_type``); defaults when omitted.
        model: The controller's model of the string (preset name or parameters); the env
            replaces it through :meth:`compiled_law` under the ``controller`` uncertainty reading.
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    name: ClassVar[str]
    gains_type: ClassVar[type[Any]]
    law: ClassVar[Any]
    error_slot: ClassVar[int] = -1
    gain_slot: ClassVar[int] = -1
    family: ClassVar[str] = "other"
    """The controller's family: ``sliding_mode`` (the paper's), ``speed_loop`` (the industry
    top-drive speed loops) or ``other``."""
    needs_full_state: ClassVar[bool] = False
    """Whether the law is written on the whole 4-DOF state (on the field string read at its
    probe nodes), so that it cannot run on surface signals alone."""
    rig_loop: ClassVar[bool] = False
    """Whether it is a stick-slip mitigation loop of rig software (SoftSpeed, Z-Torque)."""

    def __init__(
        self,
        gains: Any = None,
        model: str | Model = "zribi2024",
        **overrides: Any,
    ) -> None:
        base = self.gains_type() if gains is None else gains
        if not isinstance(base, self.gains_type):
            raise TypeError(
                f"{self.name} needs {self.gains_type.__name__}, got {type(base).__name__}"
            )
        valid = [f.name for f in dataclasses.fields(base)]
        check_unknown(overrides, valid, "gain", self.name)
        self.gains = dataclasses.replace(base, **overrides) if overrides else base
        self.model = resolve_model(model)
        self._params = self._pack(self.model, self._own_torque_limits())
        self._state = self._initial_state()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.gains!r})"

    def _pack(self, model: Model, torque_limits: TorqueLimits) -> npt.NDArray[np.float64]:
        """The law's parameter vector for ``model`` and the top drive's ``torque_limits``."""
        raise NotImplementedError

    def _own_torque_limits(self) -> TorqueLimits:
        """The torque range the controller assumes when no env tells it its own, N m."""
        return DEFAULT_TORQUE_LIMITS

    def _initial_state(self) -> npt.NDArray[np.float64]:
        """The law's state at the start of an episode."""
        raise NotImplementedError

    def _python_torque(self, m: npt.NDArray[np.float64], ref: float, dt: float) -> float:
        """The law on this controller's own vectors, from Python."""
        raise NotImplementedError

    def compiled_law(
        self,
        model: Model | None = None,
        torque_limits: TorqueLimits | None = None,
    ) -> CompiledLaw:
        """The law for the compiled loop; ``model`` replaces the controller's own model and
        ``torque_limits`` (N m) its default torque range (the env passes its own)."""
        if model is None and torque_limits is None:
            params = self._params
        else:
            params = self._pack(
                self.model if model is None else model, torque_limits or self._own_torque_limits()
            )
        return CompiledLaw(
            self.law, params, self._initial_state(), self.error_slot, self.gain_slot
        ).validated()

    def reset(self) -> None:
        """Restore the law's initial state (integrals, adaptive gains, filters)."""
        self._state = self._initial_state()

    def torque(
        self, measurement: npt.ArrayLike, reference_speed_rad_s: float, dt_s: float
    ) -> float:
        """Top-drive torque (N m) from the measured state (7,) or the env's measurement vector
        (``drill_env.layout.M_*``) and the reference bit speed (rad/s); advances the law's
        state by ``dt_s`` seconds. The same compiled function runs inside the env's plant
        loop."""
        m = measurement_vector(measurement)
        return self._python_torque(m, float(reference_speed_rad_s), float(dt_s))
