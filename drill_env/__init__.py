"""drill-string-gym: a 4-DOF torsional drill string with Karnopp bit-rock friction, and the
Gymnasium environment ``DrillString-v0`` around it.

Importing this package registers ``DrillString-v0``.
"""

from __future__ import annotations

from pathlib import Path

from drill_env._cache import invalidate_stale_cache

invalidate_stale_cache(Path(__file__).parent)  # before any compiled module is imported

from gymnasium.envs.registration import register, registry  # noqa: E402

from drill_env.config import EnvConfig  # noqa: E402
from drill_env.control import CompiledController, CompiledLaw, Controller  # noqa: E402
from drill_env.parameters import PLANT_DT_S, PRESETS, DrillStringParameters  # noqa: E402
from drill_env.rewards import RewardWeights  # noqa: E402
from drill_env.scenarios import Randomization, SpeedProfile, WobProfile  # noqa: E402

__all__ = [
    "PLANT_DT_S",
    "PRESETS",
    "CompiledController",
    "CompiledLaw",
    "Controller",
    "DrillStringParameters",
    "EnvConfig",
    "Randomization",
    "RewardWeights",
    "SpeedProfile",
    "WobProfile",
]

__version__ = "0.1.0"

ENV_ID = "DrillString-v0"

if ENV_ID not in registry:
    register(
        id=ENV_ID,
        entry_point="drill_env.env:DrillStringEnv",
        vector_entry_point="drill_env.vector:DrillStringVectorEnv",
        max_episode_steps=round(EnvConfig().episode_s / EnvConfig().control_dt_s),
    )
