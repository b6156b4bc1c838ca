"""The paper's sliding-mode controllers as fixed policies, behind one registry.

``make_controller(name, **gains)`` builds a controller; every controller can run inside
``DrillString-v0`` as its ``base_controller`` (compiled, at every plant step) or drive it as a
policy through :class:`ControllerPolicy`.
"""

from __future__ import annotations

from baselines.asmc import ASMC, ASMCGains
from baselines.csmc import CSMC, CSMCGains
from baselines.msmc import MSMC, MSMCGains
from baselines.policy import ControllerPolicy
from baselines.proposed import ProposedASMC, ProposedGains
from baselines.registry import CONTROLLERS, controller_names, make_controller, register_controller
from baselines.smc import SlidingModeController, SurfaceGains

__all__ = [
    "ASMC",
    "CONTROLLERS",
    "CSMC",
    "MSMC",
    "ASMCGains",
    "CSMCGains",
    "ControllerPolicy",
    "MSMCGains",
    "ProposedASMC",
    "ProposedGains",
    "SlidingModeController",
    "SurfaceGains",
    "controller_names",
    "make_controller",
    "register_controller",
]
