"""Fixed controllers behind one registry: the paper's four sliding-mode controllers (``csmc``,
``msmc``, ``asmc``, ``proposed``), three industry top-drive speed loops (``stiff_pi``,
``soft_speed``, ``z_torque``) and the same loops with the factors tuned by ``drill-gym tune``
(``stiff_pi_tuned``, ``soft_speed_tuned``, ``z_torque_tuned``, :mod:`baselines.tuned`), and
the driller's axial loop of ``DrillStringCoupled-v0`` (``autodriller``,
:mod:`baselines.autodriller`, its ``force_loop``).

``make_controller(name, **gains)`` builds a controller; every controller can run inside
``DrillString-v0`` as its ``base_controller`` (compiled, at every plant step) or drive it as a
policy through :class:`ControllerPolicy`.
"""

from __future__ import annotations

from pathlib import Path

import drill_env
from drill_env._cache import invalidate_stale_cache

# before any compiled module is imported; the laws call compiled code of the core
invalidate_stale_cache(Path(__file__).parent, Path(drill_env.__file__).parent)

from baselines.asmc import ASMC, ASMCGains  # noqa: E402
from baselines.autodriller import Autodriller, AutodrillerGains  # noqa: E402
from baselines.base import CompiledLawController  # noqa: E402
from baselines.csmc import CSMC, CSMCGains  # noqa: E402
from baselines.msmc import MSMC, MSMCGains  # noqa: E402
from baselines.policy import ControllerPolicy  # noqa: E402
from baselines.proposed import ProposedASMC, ProposedGains  # noqa: E402
from baselines.registry import AXIAL_BUILT_IN, BUILT_IN, COMPILED_LAWS  # noqa: E402
from baselines.smc import SlidingModeController, SurfaceGains  # noqa: E402
from baselines.soft_speed import SoftSpeed, SoftSpeedGains  # noqa: E402
from baselines.speed_loop import DriveLimits, SpeedLoopController, SpeedLoopTuning  # noqa: E402
from baselines.stiff_pi import StiffPI, StiffPIGains  # noqa: E402
from baselines.tuned import SoftSpeedTuned, StiffPITuned, ZTorqueTuned  # noqa: E402
from baselines.z_torque import ZTorque, ZTorqueGains  # noqa: E402
from drill_env.control import controller_names, make_controller, register_controller  # noqa: E402

__all__ = [
    "ASMC",
    "AXIAL_BUILT_IN",
    "Autodriller",
    "AutodrillerGains",
    "BUILT_IN",
    "COMPILED_LAWS",
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
    "SoftSpeedTuned",
    "SpeedLoopController",
    "SpeedLoopTuning",
    "StiffPI",
    "StiffPIGains",
    "StiffPITuned",
    "SurfaceGains",
    "ZTorque",
    "ZTorqueGains",
    "ZTorqueTuned",
    "controller_names",
    "make_controller",
    "register_controller",
]
