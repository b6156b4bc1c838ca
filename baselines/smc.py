"""The sliding-mode family of SPEC section 3: one class runs any of the four laws.

All four share the surface ``s = (x1 - xd) + lam I1 + lam I2`` and the equivalent control
``u_eq = c_pi (x1 - x3) + k_pi x2 + c_dt x1 - J_dt lam (x1 - xd) - J_dt lam (x1 - x7)``,
computed from measured signals with the controller's own model of the string; they differ in
the discontinuous part (see each gains class). The compiled law lives in
:func:`drill_env.control_laws.smc_torque` and runs inside the plant loop; :meth:`torque` calls
the very same function from Python.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from drill_env.control import CompiledLaw
from drill_env.control_laws import N_LAW_PARAMS, N_LAW_STATE, S_GAIN, S_SLIDING, smc_torque
from drill_env.parameters import DrillStringParameters, resolve_parameters

__all__ = ["SlidingModeController", "SurfaceGains", "check_gain", "check_numbers"]


def check_numbers(owner: object) -> None:
    """Raise ``ValueError`` naming the first field of the dataclass ``owner`` that is not a
    finite real number (run before the range checks, which compare the values)."""
    for field in dataclasses.fields(owner):  # type: ignore[arg-type]
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
    value = getattr(owner, name)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{type(owner).__name__}.{name} must be a finite number, got {value!r}")
    if not ok:
        raise ValueError(
            f"{type(owner).__name__}.{name} = {value!r} is out of range: allowed {allowed}"
        )


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


class SlidingModeController:
    """A sliding-mode top-drive controller with its own model of the string.

    Args:
        gains: The controller's gains (its class fixes the law); defaults when omitted.
        model: The controller's model of the string (preset name or parameters), used in
            ``u_eq``; the env replaces it under the ``controller`` uncertainty reading.
        **overrides: Individual gains replacing those of ``gains`` (validated).
    """

    name: ClassVar[str]
    law_id: ClassVar[int]
    gains_type: ClassVar[type[SurfaceGains]]

    def __init__(
        self,
        gains: SurfaceGains | None = None,
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

    def compiled_law(self, model: DrillStringParameters | None = None) -> CompiledLaw:
        """The law for the compiled loop; ``model`` replaces the controller's own model."""
        params = self._params if model is None else self._pack(model)
        return CompiledLaw(self.law_id, params, self._initial_state())

    def reset(self) -> None:
        """Zero the integrals and restore the initial adaptive gain."""
        self._state = self._initial_state()

    def torque(
        self, measurement: npt.ArrayLike, reference_speed_rad_s: float, dt_s: float
    ) -> float:
        """Top-drive torque (N m) from the measured state (7,) and the reference (rad/s);
        advances the integrals and the adaptive gain by ``dt_s`` seconds."""
        m = np.asarray(measurement, dtype=np.float64)
        if m.shape != (7,):
            raise ValueError(f"measurement must have shape (7,), got {m.shape}")
        return float(
            smc_torque(
                self.law_id,
                self._params,
                self._state,
                (m[0], m[1], m[2], m[3], m[4], m[5], m[6]),
                float(reference_speed_rad_s),
                float(dt_s),
            )  # fmt: skip
        )

    @property
    def sliding_variable(self) -> float:
        """The last sliding variable ``s``, rad/s."""
        return float(self._state[S_SLIDING])

    @property
    def adaptive_gain(self) -> float:
        """The current adaptive gain (0 for the fixed-gain laws)."""
        return float(self._state[S_GAIN])
