"""What every built-in controller shares: validated gains, its own model of the string, and a
compiled law of :mod:`drill_env.control_laws` that it runs from Python or hands to the env."""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from drill_env.control import CompiledLaw
from drill_env.control_laws import N_LAW_STATE, control_torque
from drill_env.parameters import DrillStringParameters, resolve_parameters

__all__ = ["CompiledLawController", "check_gain", "check_numbers"]


def check_numbers(owner: object) -> None:
    """Raise ``ValueError`` naming the first ``float`` field of the dataclass ``owner`` that is
    not a finite real number (run it before the range checks, which compare the values)."""
    for field in dataclasses.fields(owner):  # type: ignore[arg-type]
        if field.type not in ("float", float):
            continue
        value = getattr(owner, field.name)
        if (
            isinstance(value, (bool, np.bool_))
            or not isinstance(value, numbers.Real)
            or not math.isfinite(value)
        ):
            raise ValueError(
                f"{type(owner).__name__}.{field.name} must be a finite number, got {value!r}"
            )


def check_gain(owner: object, name: str, allowed: str, ok: bool) -> None:
    """Raise ``ValueError`` naming ``owner.name``, its value and the allowed range unless ``ok``."""
    if not ok:
        raise ValueError(
            f"{type(owner).__name__}.{name} = {getattr(owner, name)!r} is out of range: "
            f"allowed {allowed}"
        )


class CompiledLawController:
    """A top-drive controller whose law is compiled and runs inside the plant loop.

    Subclasses set ``name``, ``law_id`` and ``gains_type`` and implement :meth:`_pack` (the law's
    parameter vector for a model of the string) and, when the law starts from a non-zero state,
    :meth:`_initial_state`.

    Args:
        gains: The controller's gains (an instance of ``gains_type``); defaults when omitted.
        model: The controller's model of the string (preset name or parameters); the env
            replaces it through :meth:`compiled_law` under the ``controller`` uncertainty reading.
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    name: ClassVar[str]
    law_id: ClassVar[int]
    gains_type: ClassVar[type[Any]]

    def __init__(
        self,
        gains: Any = None,
        model: str | DrillStringParameters = "zribi2024",
        **overrides: Any,
    ) -> None:
        base = self.gains_type() if gains is None else gains
        if not isinstance(base, self.gains_type):
            raise TypeError(
                f"{self.name} needs {self.gains_type.__name__}, got {type(base).__name__}"
            )
        valid = [f.name for f in dataclasses.fields(base)]
        unknown = sorted(set(overrides) - set(valid))
        if unknown:
            raise TypeError(
                f"unrecognized gain(s) for {self.name}: {', '.join(unknown)}; "
                f"valid gains: {', '.join(valid)}"
            )
        self.gains = dataclasses.replace(base, **overrides) if overrides else base
        self.model = resolve_parameters(model)
        self._params = self._pack(self.model)
        self._state = self._initial_state()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.gains!r})"

    def _pack(self, model: DrillStringParameters) -> npt.NDArray[np.float64]:
        """The law's parameter vector for ``model`` (length ``N_LAW_PARAMS``)."""
        raise NotImplementedError

    def _initial_state(self) -> npt.NDArray[np.float64]:
        """The law's state at the start of an episode (length ``N_LAW_STATE``)."""
        return np.zeros(N_LAW_STATE)

    def compiled_law(self, model: DrillStringParameters | None = None) -> CompiledLaw:
        """The law for the compiled loop; ``model`` replaces the controller's own model."""
        params = self._params if model is None else self._pack(model)
        return CompiledLaw(self.law_id, params, self._initial_state())

    def reset(self) -> None:
        """Restore the law's initial state (integrals, adaptive gains, filters)."""
        self._state = self._initial_state()

    def torque(
        self, measurement: npt.ArrayLike, reference_speed_rad_s: float, dt_s: float
    ) -> float:
        """Top-drive torque (N m) from the measured state (7,) and the reference bit speed
        (rad/s); advances the law's state by ``dt_s`` seconds. The same compiled function
        runs inside the env's plant loop."""
        m = np.asarray(measurement, dtype=np.float64)
        if m.shape != (7,):
            raise ValueError(f"measurement must have shape (7,), got {m.shape}")
        return float(
            control_torque(
                self.law_id,
                self._params,
                self._state,
                (m[0], m[1], m[2], m[3], m[4], m[5], m[6]),
                float(reference_speed_rad_s),
                float(dt_s),
            )
        )
