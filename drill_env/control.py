"""The controller hook of the environment: what a base controller must provide.

Any object with ``reset()`` and ``torque(measurement, reference_speed_rad_s, dt_s)`` can be a
base controller; the env then calls it from Python at every plant step (the slow path). A
controller that also has ``compiled_law(model)`` runs inside the compiled plant loop instead,
state and all, at full speed: the built-in controllers of :mod:`baselines` all do.
"""

from __future__ import annotations

from typing import NamedTuple, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from drill_env.parameters import DrillStringParameters

__all__ = ["CompiledLaw", "CompiledController", "Controller"]


class CompiledLaw(NamedTuple):
    """A law of :mod:`drill_env.control_laws` with its packed vectors.

    Attributes:
        law_id: The law's id (``LAW_*`` of :mod:`drill_env.control_laws`).
        params: Parameter vector, length ``N_LAW_PARAMS``.
        initial_state: State vector at the start of an episode, length ``N_LAW_STATE``.
    """

    law_id: int
    params: npt.NDArray[np.float64]
    initial_state: npt.NDArray[np.float64]


@runtime_checkable
class Controller(Protocol):
    """A top-drive torque controller driven at every plant step."""

    def reset(self) -> None:
        """Forget the state of the last episode (integrals, adaptive gains)."""

    def torque(
        self, measurement: npt.NDArray[np.float64], reference_speed_rad_s: float, dt_s: float
    ) -> float:
        """Top-drive torque (N m) from the measured state (7,), the reference (rad/s) and the
        time until the next call (s)."""
        ...


@runtime_checkable
class CompiledController(Controller, Protocol):
    """A controller that can run inside the compiled plant loop."""

    def compiled_law(self, model: DrillStringParameters | None = None) -> CompiledLaw:
        """The packed law, using ``model`` as the controller's model of the string when given
        (the ``controller`` uncertainty reading) and its own otherwise."""
        ...
