"""The residual PPO agent in RL Baselines3 Zoo (``rl_zoo3``, the ``[zoo]`` extra).

``residual_ppo.yml`` beside this file holds the hyperparameters of ``drill-gym train`` (the
defaults of :class:`agents.config.TrainConfig`) in the zoo's format::

    python -m rl_zoo3.train --algo ppo --env DrillString-v0 --gym-packages drill_env \\
        --conf-file agents/zoo/residual_ppo.yml --seed 1 --num-threads 1 --device cpu \\
        --eval-freq -1 -f runs/zoo

(``--conf-file agents.zoo`` loads the same file from an installed package: the zoo reads a
package's ``hyperparams``.) Two project settings have no hyperparameter in the zoo and come
from this module, named in the file:

* :class:`TrainingReward` (``env_wrapper``): scores each decision as ``drill-gym train`` does,
  from the env's own reward terms with the training weights (a ``RewardWeights`` object cannot
  be written in YAML) minus the training-only torque and residual penalties;
* :class:`ZeroInitAction` (``callback``): zeroes the policy's action layer before the first
  update, so that the untrained residual agent is the base controller.

Importing this module imports Stable-Baselines3 (it is meant for the zoo, which has it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Final, SupportsFloat

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from agents.config import TrainConfig
from agents.train import _torque_penalty, env_kwargs
from drill_env import kernel
from drill_env.rewards import reward_terms, total_reward

__all__ = ["HYPERPARAMS_FILE", "REWARD_FIELDS", "TrainingReward", "ZeroInitAction"]

HYPERPARAMS_FILE: Final = Path(__file__).with_name("residual_ppo.yml")
"""The zoo hyperparameter file of the residual agent."""

REWARD_FIELDS: Final = (
    "reward_tracking",
    "reward_chattering",
    "reward_chattering_scale_nm",
    "reward_stuck",
    "reward_torque",
    "reward_residual",
)
"""The :class:`agents.config.TrainConfig` fields that :class:`TrainingReward` takes."""


class TrainingReward(gym.Wrapper[Any, Any, Any, Any]):
    """``DrillString-v0`` scored as ``drill-gym train`` scores it.

    Each decision's reward is recomputed from the env's own reward terms (``batch.report``:
    mean tracking error, torque variation, stuck share) with the training weights, ``-1`` when
    the step diverged, minus the training-only penalties ``reward_torque * mean(u^2) /
    (50 kN m)^2 + reward_residual * mean((u - u_base)^2) / residual_scale_nm^2`` over the
    decision's plant steps (the ``reward_fn`` of :mod:`agents.train`, called here on a batch of
    one). The keywords are the reward fields of :class:`agents.config.TrainConfig`, with its
    defaults; ``base_controller`` and ``residual_scale_nm`` are read from the env.

    Raises:
        TypeError: for a keyword that is not a reward field (the message lists them), or an
            env that is not ``DrillString-v0`` with a named base controller (or none).
    """

    def __init__(self, env: gym.Env[Any, Any], **weights: float) -> None:
        super().__init__(env)
        unknown = sorted(set(weights) - set(REWARD_FIELDS))
        if unknown:
            raise TypeError(
                f"unrecognized TrainingReward keyword(s): {', '.join(unknown)}; valid: "
                f"{', '.join(REWARD_FIELDS)}"
            )
        base = env.unwrapped
        config = getattr(base, "config", None)
        if config is None or not hasattr(base, "batch"):
            raise TypeError(f"TrainingReward wraps DrillString-v0, got {type(base).__name__}")
        controller = config.base_controller
        if controller is not None and not isinstance(controller, str):
            raise TypeError(
                "TrainingReward needs base_controller as a registered name or None, got "
                f"{type(controller).__name__}"
            )
        train = TrainConfig(
            base_controller="none" if controller is None else controller,
            control_dt_s=config.control_dt_s,
            residual_scale_nm=config.residual_scale_nm,
            **weights,  # type: ignore[arg-type]
        )
        self.train_config = train
        self.weights = env_kwargs(train)["reward_weights"]
        shaped = train.reward_torque > 0 or (train.reward_residual > 0 and controller is not None)
        self._penalty = _torque_penalty(train) if shaped else None

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.env.step(action)
        base: Any = self.env.unwrapped
        report = base.batch.report[0]
        if terminated:
            value = -1.0
        else:
            terms = reward_terms(
                float(report[kernel.REP_TRACKING]),
                float(report[kernel.REP_VARIATION]),
                float(report[kernel.REP_STUCK_FRACTION]),
                self.weights,
            )
            value = float(total_reward(terms, self.weights))
        if self._penalty is not None:
            value = float(self._penalty(base, np.array([value]))[0])
        return obs, value, terminated, truncated, info


class ZeroInitAction(BaseCallback):
    """Zero the weights and bias of the policy's action layer when training starts on a model
    that has never been updated (a model loaded to continue training is left alone): the
    action mean is then exactly 0 for every observation, as with ``zero_init_action``."""

    def _on_training_start(self) -> None:
        import torch as th

        if getattr(self.model, "_n_updates", 0) != 0:
            return
        with th.no_grad():
            for parameter in self.model.policy.action_net.parameters():  # type: ignore[union-attr]
                parameter.zero_()

    def _on_step(self) -> bool:
        return True


def __getattr__(name: str) -> Any:
    """``hyperparams``: the content of :data:`HYPERPARAMS_FILE`, for ``--conf-file
    agents.zoo`` (the zoo reads a package's ``hyperparams``)."""
    if name == "hyperparams":
        import yaml  # the zoo's dependency

        return yaml.safe_load(HYPERPARAMS_FILE.read_text())
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
