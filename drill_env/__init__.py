"""drill-string-gym: a 4-DOF torsional drill string with Karnopp bit-rock friction, and the
Gymnasium environment ``DrillString-v0`` around it.

Importing this package registers ``DrillString-v0``.
"""

from __future__ import annotations

from pathlib import Path

from drill_env._cache import invalidate_stale_cache

invalidate_stale_cache(Path(__file__).parent)  # before any compiled module is imported

from typing import Any  # noqa: E402

import gymnasium as gym  # noqa: E402
from gymnasium.envs.registration import register, registry  # noqa: E402

from drill_env.config import EnvConfig  # noqa: E402
from drill_env.control import CompiledController, CompiledLaw, Controller  # noqa: E402
from drill_env.distributed import (  # noqa: E402
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    StringDamping,
    StringSection,
)
from drill_env.parameters import PLANT_DT_S, PRESETS, DrillStringParameters  # noqa: E402
from drill_env.rewards import RewardWeights  # noqa: E402
from drill_env.scenarios import Randomization, SpeedProfile, WobProfile  # noqa: E402

__all__ = [
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
    "SpeedProfile",
    "StringDamping",
    "StringSection",
    "WobProfile",
    "make",
]

__version__ = "0.1.0"

ENV_ID = "DrillString-v0"


def make(**kwargs: Any) -> gym.Env[Any, Any]:
    """``gym.make("DrillString-v0", **kwargs)`` with the time limit set from the keywords.

    ``gym.make`` applies the registered limit of 2000 decisions (100 s at 50 ms) whatever
    ``episode_s`` and ``control_dt_s`` say; this sets ``max_episode_steps`` to
    ``episode_s / control_dt_s`` (the env also truncates itself at ``episode_s``).
    """
    config = EnvConfig.from_kwargs(kwargs)
    return gym.make(ENV_ID, max_episode_steps=config.max_steps, **kwargs)


if ENV_ID not in registry:
    register(
        id=ENV_ID,
        entry_point="drill_env.env:DrillStringEnv",
        vector_entry_point="drill_env.vector:DrillStringVectorEnv",
        max_episode_steps=round(EnvConfig().episode_s / EnvConfig().control_dt_s),
    )
