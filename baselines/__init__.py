"""Fixed controllers behind one registry: the paper's four sliding-mode controllers (``csmc``,
``msmc``, ``asmc``, ``proposed``) and three industry top-drive speed loops (``stiff_pi``,
``soft_speed``, ``z_torque``).

``make_controller(name, **gains)`` builds a controller; every controller can run inside
``DrillString-v0`` as its ``base_controller`` (compiled, at every plant step) or drive it as a
policy through :class:`ControllerPolicy`.
"""

from __future__ import annotations

from baselines.asmc import ASMC, ASMCGains
from baselines.base import CompiledLawController
from baselines.csmc import CSMC, CSMCGains
from baselines.msmc import MSMC, MSMCGains
from baselines.policy import ControllerPolicy
from baselines.proposed import ProposedASMC, ProposedGains
from baselines.registry import CONTROLLERS, controller_names, make_controller, register_controller
from baselines.smc import SlidingModeController, SurfaceGains
from baselines.soft_speed import SoftSpeed, SoftSpeedGains
from baselines.speed_loop import DriveLimits, SpeedLoopController, SpeedLoopTuning
from baselines.stiff_pi import StiffPI, StiffPIGains
from baselines.z_torque import ZTorque, ZTorqueGains

__all__ = [
    "ASMC",
    "CONTROLLERS",
    "CSMC",
    "CompiledLawController",
    "MSMC",
    "ASMCGains",
    "CSMCGains",
    "ControllerPolicy",
    "DriveLimits",
    "MSMCGains",
    "ProposedASMC",
    "ProposedGains",
    "SlidingModeController",
    "SoftSpeed",
    "SoftSpeedGains",
    "SpeedLoopController",
    "SpeedLoopTuning",
    "StiffPI",
    "StiffPIGains",
    "SurfaceGains",
    "ZTorque",
    "ZTorqueGains",
    "controller_names",
    "make_controller",
    "register_controller",
]
