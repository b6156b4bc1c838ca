"""The built-in controllers by name, registered with the core's registry
(:func:`drill_env.control.register_controller`) when :mod:`baselines` is imported; installed,
the same names are offered through the ``drill_string_gym.controllers`` entry points, so that
``gym.make("DrillString-v0", base_controller="proposed")`` finds them without an import."""

from __future__ import annotations

from typing import Final

from baselines.asmc import ASMC
from baselines.autodriller import Autodriller
from baselines.base import CompiledLawController
from baselines.csmc import CSMC
from baselines.msmc import MSMC
from baselines.proposed import ProposedASMC
from baselines.soft_speed import SoftSpeed
from baselines.stiff_pi import StiffPI
from baselines.tuned import SoftSpeedTuned, StiffPITuned, ZTorqueTuned
from baselines.z_torque import ZTorque
from drill_env.control import register_controller
from drill_env.coupled_env import AxialController, register_axial_controller
from drill_env.ids import COUPLED_ENV_ID, ENV_ID, FIELD_ENV_ID

__all__ = [
    "AXIAL_BUILT_IN",
    "BUILT_IN",
    "COMPILED_LAWS",
    "REFERENCE_CONTROLLER",
    "controller_family",
    "needs_full_state",
    "family_members",
    "rig_loops",
]

BUILT_IN: Final[dict[str, type[CompiledLawController]]] = {
    "csmc": CSMC,
    "msmc": MSMC,
    "asmc": ASMC,
    "proposed": ProposedASMC,
    "stiff_pi": StiffPI,
    "stiff_pi_tuned": StiffPITuned,
    "soft_speed": SoftSpeed,
    "soft_speed_tuned": SoftSpeedTuned,
    "z_torque": ZTorque,
    "z_torque_tuned": ZTorqueTuned,
}
"""The built-in controller classes by name; each takes gain keywords (and ``model``). A
``*_tuned`` loop follows its default one (``controller_names()`` keeps this order, and so do
the tables): the same law with the factors of ``baselines/tuned_gains.json``
(:mod:`baselines.tuned`)."""

COMPILED_LAWS: Final = {name: cls.law for name, cls in BUILT_IN.items()}
"""The compiled law (a numba ``cfunc``) each built-in controller runs in the plant loop."""

REFERENCE_CONTROLLER: Final = {
    ENV_ID: "proposed",
    FIELD_ENV_ID: "soft_speed",
    COUPLED_ENV_ID: "stiff_pi",
}
"""The reference controller of each env: the one a from-scratch agent is measured against by
default (the paper's proposed SMC; the field string's SoftSpeed rig loop; the coupled string's
top-drive PI loop)."""


def controller_family(name: str) -> str:
    """The family of a built-in controller (``sliding_mode``, ``speed_loop``); ``other`` for
    any other name."""
    factory = BUILT_IN.get(name)
    return factory.family if factory is not None else "other"


def needs_full_state(name: str) -> bool:
    """Whether the built-in controller ``name`` needs the whole measured state (``False`` for
    any other name)."""
    factory = BUILT_IN.get(name)
    return factory is not None and factory.needs_full_state


def family_members(family: str, tuned: bool = True) -> tuple[str, ...]:
    """The built-in controllers of ``family`` in their order (without the ``*_tuned`` loops
    when ``tuned`` is false)."""
    return tuple(
        name
        for name, factory in BUILT_IN.items()
        if factory.family == family and (tuned or not hasattr(factory, "base_name"))
    )


def rig_loops() -> tuple[str, ...]:
    """The rig software's stick-slip loops, the default ones first, then their tuned copies."""
    loops = [name for name, factory in BUILT_IN.items() if factory.rig_loop]
    return tuple(sorted(loops, key=lambda name: hasattr(BUILT_IN[name], "base_name")))


for _name, _factory in BUILT_IN.items():
    register_controller(_name, _factory)

AXIAL_BUILT_IN: Final[dict[str, type[AxialController]]] = {"autodriller": Autodriller}
"""The built-in axial (driller's) loops by name: the ``force_loop`` of
``DrillStringCoupled-v0`` (:func:`drill_env.coupled_env.register_axial_controller`)."""

for _name, _axial in AXIAL_BUILT_IN.items():
    register_axial_controller(_name, _axial)
