"""The built-in controllers by name, registered with the core's registry
(:func:`drill_env.control.register_controller`) when :mod:`baselines` is imported; installed,
the same names are offered through the ``drill_string_gym.controllers`` entry points, so that
``gym.make("DrillString-v0", base_controller="proposed")`` finds them without an import."""

from __future__ import annotations

from typing import Final

from baselines.asmc import ASMC
from baselines.base import CompiledLawController
from baselines.csmc import CSMC
from baselines.msmc import MSMC
from baselines.proposed import ProposedASMC
from baselines.soft_speed import SoftSpeed
from baselines.stiff_pi import StiffPI
from baselines.z_torque import ZTorque
from drill_env.control import register_controller

__all__ = ["BUILT_IN", "COMPILED_LAWS"]

BUILT_IN: Final[dict[str, type[CompiledLawController]]] = {
    "csmc": CSMC,
    "msmc": MSMC,
    "asmc": ASMC,
    "proposed": ProposedASMC,
    "stiff_pi": StiffPI,
    "soft_speed": SoftSpeed,
    "z_torque": ZTorque,
}
"""The built-in controller classes by name; each takes gain keywords (and ``model``)."""

COMPILED_LAWS: Final = {name: cls.law for name, cls in BUILT_IN.items()}
"""The compiled law (a numba ``cfunc``) each built-in controller runs in the plant loop."""

for _name, _factory in BUILT_IN.items():
    register_controller(_name, _factory)
