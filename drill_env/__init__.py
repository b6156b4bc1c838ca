"""drill-string-gym: a 4-DOF torsional drill string with Karnopp bit-rock friction, and the
Gymnasium environment ``DrillString-v0`` around it.

Importing this package registers ``DrillString-v0``; ``gym.make("drill_env:DrillString-v0")``
imports it for you.
"""

from __future__ import annotations

from pathlib import Path

from drill_env._cache import invalidate_stale_cache

invalidate_stale_cache(Path(__file__).parent)  # before any compiled module is imported

from gymnasium.envs.registration import register, registry  # noqa: E402

from drill_env.control import (  # noqa: E402
    CompiledController,
    CompiledLaw,
    Controller,
    controller_names,
    make_controller,
    register_controller,
)
from drill_env.distributed import (  # noqa: E402
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    StringDamping,
    StringSection,
)
from drill_env.limits import DEFAULT_TORQUE_LIMITS, TorqueLimits  # noqa: E402
from drill_env.options import EnvConfig  # noqa: E402
from drill_env.parameters import PLANT_DT_S, PRESETS, DrillStringParameters  # noqa: E402
from drill_env.rewards import RewardWeights  # noqa: E402
from drill_env.scenarios import Randomization, Scenario, SpeedProfile, WobProfile  # noqa: E402

__all__ = [
    "DEFAULT_TORQUE_LIMITS",
    "ENV_ID",
    "DISTRIBUTED_PRESETS",
    "PLANT_DT_S",
    "PRESETS",
    "CompiledController",
    "CompiledLaw",
    "Controller",
    "DistributedStringParameters",
    "DrillStringParameters",
    "EnvConfig",
    "Randomization",
    "RewardWeights",
    "Scenario",
    "SpeedProfile",
    "TorqueLimits",
    "StringDamping",
    "StringSection",
    "WobProfile",
    "controller_names",
    "make_controller",
    "register_controller",
]

__version__ = "0.1.0"

ENV_ID = "DrillString-v0"

if ENV_ID not in registry:
    # No registered step limit: the env truncates itself after ``episode_s`` and reports the
    # number of decisions that takes as ``env.spec.max_episode_steps``.
    register(
        id=ENV_ID,
        entry_point="drill_env.env:DrillStringEnv",
        vector_entry_point="drill_env.vector:DrillStringVectorEnv",
    )
