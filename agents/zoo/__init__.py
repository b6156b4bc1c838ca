"""The residual PPO agent in RL Baselines3 Zoo (``rl_zoo3``, the ``[zoo]`` extra).

``residual_ppo.yml`` beside this file holds the hyperparameters of ``drill-gym train`` (the
defaults of :class:`agents.config.TrainConfig`) in the zoo's format::

    python -m rl_zoo3.train --algo ppo --env DrillString-v0 --gym-packages drill_env \\
        --conf-file agents/zoo/residual_ppo.yml --seed 1 --num-threads 1 --device cpu \\
        --eval-freq -1 -f runs/zoo

(``--conf-file agents.zoo`` loads the same file from an installed package: the zoo reads a
package's ``hyperparams``.) The training reward is the env's own, with the training weights
given as a mapping in ``env_kwargs.reward_weights``. One project setting has no hyperparameter
in the zoo and comes from this module: :class:`ZeroInitAction` (``callback``) zeroes the
policy's action layer before the first update, so that the untrained residual agent is the
base controller.

Importing this module imports Stable-Baselines3 (it is meant for the zoo, which has it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Final

from stable_baselines3.common.callbacks import BaseCallback

from drill_env.validation import shown

__all__ = ["HYPERPARAMS_FILE", "ZeroInitAction"]

HYPERPARAMS_FILE: Final = Path(__file__).with_name("residual_ppo.yml")
"""The zoo hyperparameter file of the residual agent."""


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
    raise AttributeError(f"module {shown(__name__)} has no attribute {shown(name)}")
