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

__all__ = ["AXIAL_BUILT_IN", "BUILT_IN", "COMPILED_LAWS"]

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

for _name, _factory in BUILT_IN.items():
    register_controller(_name, _factory)

AXIAL_BUILT_IN: Final[dict[str, type[AxialController]]] = {"autodriller": Autodriller}
"""The built-in axial (driller's) loops by name: the ``force_loop`` of
``DrillStringCoupled-v0`` (:func:`drill_env.coupled_env.register_axial_controller`)."""

for _name, _axial in AXIAL_BUILT_IN.items():
    register_axial_controller(_name, _axial)
