"""Registry of the built-in controllers: ``make_controller(name, **gains)``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from baselines.asmc import ASMC
from baselines.csmc import CSMC
from baselines.msmc import MSMC
from baselines.proposed import ProposedASMC
from baselines.soft_speed import SoftSpeed
from baselines.stiff_pi import StiffPI
from baselines.z_torque import ZTorque
from drill_env.control import Controller

__all__ = ["CONTROLLERS", "controller_names", "make_controller", "register_controller"]

CONTROLLERS: dict[str, Callable[..., Controller]] = {
    "csmc": CSMC,
    "msmc": MSMC,
    "asmc": ASMC,
    "proposed": ProposedASMC,
    "stiff_pi": StiffPI,
    "soft_speed": SoftSpeed,
    "z_torque": ZTorque,
}
"""Factories by name; each takes gain keywords (and ``model``)."""


def controller_names() -> list[str]:
    """The registered controller names, in registration order."""
    return list(CONTROLLERS)


def register_controller(name: str, factory: Callable[..., Controller]) -> None:
    """Add a controller factory under ``name`` (an error if the name is taken)."""
    if name in CONTROLLERS:
        raise ValueError(f"controller name {name!r} is already registered")
    CONTROLLERS[name] = factory


def make_controller(name: str, **gains: Any) -> Controller:
    """A new controller ``name`` with default gains, overridden by ``gains``.

    Raises:
        ValueError: for an unknown name, listing the valid ones.
    """
    try:
        factory = CONTROLLERS[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"unknown controller {name!r}: valid names are {', '.join(CONTROLLERS)}"
        ) from None
    return factory(**gains)
