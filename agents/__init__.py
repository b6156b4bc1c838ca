"""The residual PPO agent of drill-string-gym.

Loading and running a trained agent needs only the core install: the model files
(``config.json``, ``policy.safetensors``, ``obs_norm.safetensors``; ``docs/model-files.md``)
hold no code and the policy network runs in NumPy (:mod:`agents.inference`). Training, and
converting Stable-Baselines3 models, need the ``[rl]`` extra (torch, Stable-Baselines3),
imported only when used.

* :func:`load_policy` / :func:`load_default_policy`: a trained agent as a policy with SB3's
  ``predict()`` and the ``env_kwargs`` it needs (``gym.make("DrillString-v0", **scenario,
  **policy.env_kwargs)``);
* :func:`export_policy`: an SB3 PPO model and its normalisation statistics as a model folder;
* ``drill-gym train`` (:mod:`agents.train`) and ``drill-gym evaluate`` (:mod:`experiments.evaluate`).
"""

from __future__ import annotations

from agents.policy import (
    DEFAULT_MODEL_DIR,
    ResidualPolicy,
    export_policy,
    load_default_policy,
    load_policy,
)

__all__ = [
    "DEFAULT_MODEL_DIR",
    "ResidualPolicy",
    "export_policy",
    "load_default_policy",
    "load_policy",
]
