"""The reward of ``DrillString-v0``, in one place: the per-plant-step tracking integrand the
compiled loop sums, the named terms formed from the loop's sums over a decision period, and
their weighted total.

Terms (each in [0, 1]) over one decision period of n plant steps::

    tracking   = mean over the steps of min(|V_ref - w_bit| / max(V_ref, 1 rad/s), 1)
    chattering = min(TV(u) / chattering_scale_nm, 1)        TV: total variation of the torque
    stuck      = share of the steps with the bit stuck
    torque     = mean(u^2) / torque_scale_nm^2               (the paper's RMSD measure)
    residual   = mean((u - u_base)^2) / residual_scale_nm^2  (residual mode; 0 otherwise)

with ``torque_scale_nm = max(|min_torque_nm|, |max_torque_nm|)`` (the torque range's largest
magnitude) and ``u_base`` the base controller's torque clipped to the torque range
(:func:`drill_env.kernel.residual_base`). The residual term is in [0, 1] where the applied
torque follows the command; behind a top drive with dead time, lag or a rate limit the applied
torque ``u`` can stray from ``u_base`` by more than the residual scale, and the term exceed 1
(``benchmarks/reward_terms.py`` prints its range on ``DrillStringField-v0``).

Total::

    r = -(w_t tracking + w_c chattering + w_s stuck) / (w_t + w_c + w_s)
        - w_torque torque - w_residual residual

in ``[-1 - w_torque - w_residual, 0]``: ``[-2, 0]`` with the default weights, which are the
shipped agent's training recipe (``agents/models/residual_ppo``): tracking 1, chattering 0.1
with a 50 kN m scale, stuck 0, torque 1, residual 0. ``DrillStringField-v0``'s defaults are its
shipped agent's (``agents/models/field_agent``, :data:`FIELD_REWARD_WEIGHTS`): tracking 3,
stuck 0.5, torque 2, residual 0.5, so its reward is in ``[-3.5, 0]``. The 50 kN m
scale keeps the chattering term below its cap under the default 0.1 rad/s measurement noise
(a 5 kN m scale was exceeded at every decision by a controller that reacts to the noise).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, TypeVar

import numpy as np
import numpy.typing as npt
from numba import njit

from drill_env.layout import (
    REP_RESIDUAL_SQUARED,
    REP_STEPS,
    REP_STUCK_STEPS,
    REP_TORQUE_SQUARED,
    REP_TRACKING_SUM,
    REP_VARIATION,
)
from drill_env.validation import check_range, check_real, require

__all__ = [
    "DIVERGED_REWARD",
    "FIELD_REWARD_WEIGHTS",
    "TERMS",
    "RewardWeights",
    "report_reward",
    "report_rewards",
    "reward_terms",
    "total_reward",
    "tracking_error",
]

Term = TypeVar("Term", float, npt.NDArray[np.float64])

TERMS = ("tracking", "chattering", "stuck", "torque", "residual")
"""The names of the reward terms, as in ``info["reward_terms"]``."""

DIVERGED_REWARD: Final = -1.0
"""The reward of a step that ends the episode by diverging (every env)."""


@njit(cache=True, inline="always")
def tracking_error(reference_rad_s: float, bit_speed_rad_s: float) -> float:
    """The tracking integrand of one plant step: ``min(|V_ref - w_bit| / max(V_ref, 1), 1)``."""
    return min(abs(reference_rad_s - bit_speed_rad_s) / max(reference_rad_s, 1.0), 1.0)


@dataclass(frozen=True)
class RewardWeights:
    """Non-negative weights of the reward terms (the first three normalised by their sum, not
    all zero).

    The defaults are the shipped agents' training recipe.

    Attributes:
        tracking: Weight of the relative bit-speed tracking error.
        chattering: Weight of the top-drive torque variation.
        stuck: Weight of the time the bit spends stuck (0 by default: the tracking term
            already counts a stuck bit as a full error; the term stays in ``info``).
        chattering_scale_nm: Torque variation within one decision period that saturates the
            chattering term, N m (> 0).
        torque: Weight of the mean squared torque over the squared largest torque magnitude
            of the range, ``max(|min_torque_nm|, |max_torque_nm|)`` (an energy penalty, the
            paper's RMSD).
        residual: Weight of the mean squared torque added to the base controller's (clipped to
            the torque range), over the squared residual scale (residual mode only; 0 by
            default).
    """

    tracking: float = 1.0
    chattering: float = 0.1
    stuck: float = 0.0
    chattering_scale_nm: float = 50_000.0
    torque: float = 1.0
    residual: float = 0.0

    def __post_init__(self) -> None:
        for name in ("tracking", "chattering", "stuck", "torque", "residual"):
            value = getattr(self, name)
            check_range(f"reward weight {name}", value, 0.0, float("inf"))
        if self.tracking + self.chattering + self.stuck <= 0:
            raise ValueError(
                "reward weights tracking, chattering and stuck are all zero: at least one must "
                "be > 0"
            )
        s = check_real("chattering_scale_nm", self.chattering_scale_nm, "> 0 and finite")
        require("chattering_scale_nm", self.chattering_scale_nm, "> 0 and finite", 0 < s < np.inf)


FIELD_REWARD_WEIGHTS: Final = RewardWeights(tracking=3.0, stuck=0.5, torque=2.0, residual=0.5)
"""The default weights of ``DrillStringField-v0``: its shipped agent's recipe (the stuck term
counts the time the bit sticks, the torque and residual terms hold the agent at no more RMS
torque than its base loop, the tracking weight of 3 makes a ripple of the bit speed cost more
against them)."""


def reward_terms(
    report: Sequence[float] | npt.NDArray[np.float64],
    weights: RewardWeights,
    torque_scale_nm: float,
    residual_scale_nm: float | None,
) -> dict[str, Any]:
    """The terms over one decision period from the kernel's report (``drill_env.layout.REP_*``
    sums): one report row (a list of floats, for one env) or an array of rows (a vector env,
    elementwise).

    Args:
        report: A report row or rows.
        weights: The reward weights (for the chattering scale).
        torque_scale_nm: Scale of the torque term, N m (the torque range's largest
            magnitude, ``EnvConfig.torque_scale_nm``).
        residual_scale_nm: Scale of the residual term, N m; ``None`` outside residual mode
            (the term is then 0).
    """
    if isinstance(report, np.ndarray):
        rows = report.reshape(-1, report.shape[-1])
        steps = np.maximum(rows[:, REP_STEPS], 1)
        chattering = np.minimum(rows[:, REP_VARIATION] / weights.chattering_scale_nm, 1.0)
        tracking, stuck = rows[:, REP_TRACKING_SUM] / steps, rows[:, REP_STUCK_STEPS] / steps
        torque = rows[:, REP_TORQUE_SQUARED] / steps / torque_scale_nm**2
        residual = np.zeros_like(steps)
        if residual_scale_nm is not None:
            residual = rows[:, REP_RESIDUAL_SQUARED] / steps / max(residual_scale_nm, 1.0) ** 2
        return {
            "tracking": tracking, "chattering": chattering, "stuck": stuck, "torque": torque,
            "residual": residual,
        }  # fmt: skip
    n = max(report[REP_STEPS], 1)
    return {
        "tracking": report[REP_TRACKING_SUM] / n,
        "chattering": min(report[REP_VARIATION] / weights.chattering_scale_nm, 1.0),
        "stuck": report[REP_STUCK_STEPS] / n,
        "torque": report[REP_TORQUE_SQUARED] / n / torque_scale_nm**2,
        "residual": 0.0
        if residual_scale_nm is None
        else report[REP_RESIDUAL_SQUARED] / n / max(residual_scale_nm, 1.0) ** 2,
    }


def total_reward(terms: Mapping[str, Term], weights: RewardWeights) -> Term:
    """``-(w_t tracking + w_c chattering + w_s stuck) / (w_t + w_c + w_s) - w_torque torque
    - w_residual residual``; the terms are floats (one env) or arrays (a vector env)."""
    num = (
        weights.tracking * terms["tracking"]
        + weights.chattering * terms["chattering"]
        + weights.stuck * terms["stuck"]
    )
    reward = -num / (weights.tracking + weights.chattering + weights.stuck)
    if weights.torque > 0:
        reward = reward - weights.torque * terms["torque"]
    if weights.residual > 0:
        reward = reward - weights.residual * terms["residual"]
    return reward


def report_reward(
    weights: RewardWeights, torque_scale_nm: float, residual_scale_nm: float | None
) -> Callable[[Sequence[float]], tuple[dict[str, float], float]]:
    """:func:`reward_terms` and :func:`total_reward` of one report row (a list of floats) as
    one function, with the constants of ``weights`` and the scales taken once (the single env's
    hot path): it returns ``(terms, reward)``, the same floats bit for bit.

    Args:
        weights: The reward weights.
        torque_scale_nm: Scale of the torque term, N m (the torque range's largest
            magnitude, ``EnvConfig.torque_scale_nm``).
        residual_scale_nm: Scale of the residual term, N m; ``None`` outside residual mode.
    """
    chattering_scale = weights.chattering_scale_nm
    torque_squared = torque_scale_nm**2
    residual_squared = None if residual_scale_nm is None else max(residual_scale_nm, 1.0) ** 2
    w_tracking, w_chattering, w_stuck = weights.tracking, weights.chattering, weights.stuck
    w_sum = w_tracking + w_chattering + w_stuck
    w_torque = weights.torque if weights.torque > 0 else None
    w_residual = weights.residual if weights.residual > 0 else None

    def reward(report: Sequence[float]) -> tuple[dict[str, float], float]:
        n = max(report[REP_STEPS], 1)
        tracking = report[REP_TRACKING_SUM] / n
        chattering = min(report[REP_VARIATION] / chattering_scale, 1.0)
        stuck = report[REP_STUCK_STEPS] / n
        torque = report[REP_TORQUE_SQUARED] / n / torque_squared
        residual = 0.0 if residual_squared is None else (
            report[REP_RESIDUAL_SQUARED] / n / residual_squared
        )  # fmt: skip
        total = -(w_tracking * tracking + w_chattering * chattering + w_stuck * stuck) / w_sum
        if w_torque is not None:
            total = total - w_torque * torque
        if w_residual is not None:
            total = total - w_residual * residual
        terms = {
            "tracking": tracking, "chattering": chattering, "stuck": stuck, "torque": torque,
            "residual": residual,
        }  # fmt: skip
        return terms, total

    return reward


def report_rewards(
    weights: RewardWeights, torque_scale_nm: float, residual_scale_nm: float | None
) -> Callable[[npt.NDArray[np.float64]], tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]]:
    """:func:`report_reward` for the report rows of a batch (a vector env's hot path), in one
    compiled call: it returns ``(terms, rewards)``, ``terms`` of shape ``(len(TERMS), num)``
    (rows in the order of :data:`TERMS`) and ``rewards`` ``(num,)``, the same floats bit for
    bit as :func:`reward_terms` and :func:`total_reward` on the rows.

    Args:
        weights: The reward weights.
        torque_scale_nm: Scale of the torque term, N m (the torque range's largest
            magnitude, ``EnvConfig.torque_scale_nm``).
        residual_scale_nm: Scale of the residual term, N m; ``None`` outside residual mode.
    """
    assert TERMS == ("tracking", "chattering", "stuck", "torque", "residual")
    constants = np.array(
        [
            weights.chattering_scale_nm,
            torque_scale_nm**2,
            0.0 if residual_scale_nm is None else max(residual_scale_nm, 1.0) ** 2,
            weights.tracking,
            weights.chattering,
            weights.stuck,
            weights.tracking + weights.chattering + weights.stuck,
            weights.torque if weights.torque > 0 else 0.0,
            weights.residual if weights.residual > 0 else 0.0,
        ]
    )

    def rewards(
        report: npt.NDArray[np.float64],
    ) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        terms = np.empty((len(TERMS), report.shape[0]))
        total = np.empty(report.shape[0])
        _report_rewards(report, constants, terms, total)
        return terms, total

    return rewards


@njit(cache=True)
def _report_rewards(report, constants, terms, total) -> None:
    """The compiled body of :func:`report_rewards`: numpy's operations, in numpy's order (NaN
    propagates through the bounds as through ``np.maximum`` and ``np.minimum``)."""
    chattering_scale, torque_squared, residual_squared = constants[0], constants[1], constants[2]
    w_tracking, w_chattering, w_stuck, w_sum = (
        constants[3],
        constants[4],
        constants[5],
        constants[6],
    )
    w_torque, w_residual = constants[7], constants[8]
    for i in range(report.shape[0]):
        steps = report[i, REP_STEPS]
        if steps < 1.0:
            steps = 1.0
        tracking = report[i, REP_TRACKING_SUM] / steps
        chattering = report[i, REP_VARIATION] / chattering_scale
        if chattering > 1.0:
            chattering = 1.0
        stuck = report[i, REP_STUCK_STEPS] / steps
        torque = report[i, REP_TORQUE_SQUARED] / steps / torque_squared
        residual = 0.0
        if residual_squared > 0.0:
            residual = report[i, REP_RESIDUAL_SQUARED] / steps / residual_squared
        terms[0, i] = tracking
        terms[1, i] = chattering
        terms[2, i] = stuck
        terms[3, i] = torque
        terms[4, i] = residual
        num = w_tracking * tracking + w_chattering * chattering + w_stuck * stuck
        reward = -num / w_sum
        if w_torque > 0.0:
            reward = reward - w_torque * torque
        if w_residual > 0.0:
            reward = reward - w_residual * residual
        total[i] = reward
