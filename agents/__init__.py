"""The residual PPO agent of drill-string-gym (needs the ``[rl]`` extra: torch, SB3).

Importing this package is cheap and works without torch; torch and Stable-Baselines3 are
imported when a model is loaded, trained or evaluated.

* :func:`load_policy` / :func:`load_default_policy`: a trained agent as a policy with SB3's
  ``predict()`` and the ``env_kwargs`` it needs (``gym.make("DrillString-v0", **scenario,
  **policy.env_kwargs)``);
* ``drill-gym train`` (:mod:`agents.train`) and ``drill-gym evaluate`` (:mod:`agents.evaluate`).
"""

from __future__ import annotations

from agents.policy import DEFAULT_MODEL_DIR, ResidualPolicy, load_default_policy, load_policy

__all__ = ["DEFAULT_MODEL_DIR", "ResidualPolicy", "load_default_policy", "load_policy"]
