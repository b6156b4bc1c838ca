"""drill-string-gym: torsional drill strings with Karnopp bit-rock friction, the paper's
4-DOF string and a field-length distributed one, and the Gymnasium environments around them.

Importing this package registers ``DrillString-v0`` (the 4-DOF string) and
``DrillStringField-v0`` (the distributed string as a rig sees it);
``gym.make("drill_env:DrillString-v0")`` imports it for you.
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
    "COUPLED_ENV_ID",
    "ENV_ID",
    "FIELD_ENV_ID",
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

from drill_env.ids import COUPLED_ENV_ID, ENV_ID, FIELD_ENV_ID  # noqa: E402

# No registered step limit: the envs truncate themselves after ``episode_s`` and report the
# number of decisions that takes as ``env.spec.max_episode_steps``. No wrappers either: the envs
# refuse a step before reset() themselves, and pass Gymnasium's env checker in the tests (each
# wrapper layer costs every decision a Python call).
# The entry points are functions (drill_env.creators), so that the env's constructor, not
# Gymnasium, checks render_mode first.
for _id, _name, _creator in (
    (ENV_ID, "DrillString", "make_drill_string_env"),
    (FIELD_ENV_ID, "DrillStringField", "make_field_env"),
):
    if _id not in registry:
        register(
            id=_id,
            entry_point=f"drill_env.creators:{_creator}",
            vector_entry_point=f"drill_env.vector:{_name}VectorEnv",
            order_enforce=False,
            disable_env_checker=True,
        )

if COUPLED_ENV_ID not in registry:
    register(
        id=COUPLED_ENV_ID,
        entry_point="drill_env.creators:make_coupled_env",
        vector_entry_point="drill_env.coupled_env:DrillStringCoupledVectorEnv",
    )
