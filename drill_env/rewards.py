"""The per-step reward of ``DrillString-v0``: dimensionless, in [-1, 0], with named terms."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TypeVar

import numpy as np
import numpy.typing as npt

__all__ = ["RewardWeights", "reward_terms", "total_reward"]

Term = TypeVar("Term", float, npt.NDArray[np.float64])


@dataclass(frozen=True)
class RewardWeights:
    """Non-negative weights of the reward terms (normalised by their sum; not all zero).

    Attributes:
        tracking: Weight of the relative bit-speed tracking error.
        chattering: Weight of the top-drive torque variation.
        stuck: Weight of the time the bit spends stuck.
        chattering_scale_nm: Torque variation within one decision period that saturates the
            chattering term, N m.
    """

    tracking: float = 1.0
    chattering: float = 0.1
    stuck: float = 0.5
    chattering_scale_nm: float = 5000.0

    def __post_init__(self) -> None:
        for name in ("tracking", "chattering", "stuck"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"reward weight {name} = {value!r} is out of range: allowed >= 0")
        if self.tracking + self.chattering + self.stuck <= 0:
            raise ValueError("reward weights are all zero: at least one must be > 0")
        s = self.chattering_scale_nm
        if not (isinstance(s, (int, float)) and math.isfinite(s) and s > 0):
            raise ValueError(f"chattering_scale_nm = {s!r} is out of range: allowed > 0")


def reward_terms(
    mean_tracking: float, torque_variation_nm: float, stuck_fraction: float, weights: RewardWeights
) -> dict[str, float]:
    """The three terms, each in [0, 1], over one decision period.

    Args:
        mean_tracking: Mean over the plant steps of ``min(|V_ref - w_bit| / max(V_ref, 1), 1)``.
        torque_variation_nm: Total variation of the applied torque over the period, N m.
        stuck_fraction: Share of the plant steps with the bit stuck.
        weights: Reward weights (for the chattering scale).
    """
    return {
        "tracking": mean_tracking,
        "chattering": min(torque_variation_nm / weights.chattering_scale_nm, 1.0),
        "stuck": stuck_fraction,
    }


def total_reward(terms: Mapping[str, Term], weights: RewardWeights) -> Term:
    """``-(w_t tracking + w_c chattering + w_s stuck) / (w_t + w_c + w_s)``, in [-1, 0].

    The terms are floats (one env) or arrays (a vector env, elementwise)."""
    num = (
        weights.tracking * terms["tracking"]
        + weights.chattering * terms["chattering"]
        + weights.stuck * terms["stuck"]
    )
    return -num / (weights.tracking + weights.chattering + weights.stuck)
