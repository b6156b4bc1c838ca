"""The reward (:mod:`drill_env.rewards`): the integrand, the terms from the loop's sums, the
total and the weights' validation."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env import layout
from drill_env.rewards import TERMS, RewardWeights, reward_terms, total_reward, tracking_error


@pytest.mark.parametrize(
    ("ref", "bit", "expected"),
    [(12.0, 12.0, 0.0), (12.0, 9.0, 0.25), (12.0, 40.0, 1.0), (0.5, 0.0, 0.5), (4.0, 0.0, 1.0)],
)
def test_tracking_integrand(ref: float, bit: float, expected: float) -> None:
    """``min(|V_ref - w| / max(V_ref, 1 rad/s), 1)``."""
    assert tracking_error(ref, bit) == pytest.approx(expected)


def _report(**sums: float) -> list[float]:
    row = [0.0] * layout.N_REPORT
    for key, value in sums.items():
        row[getattr(layout, key)] = value
    return row


def test_terms_from_the_sums() -> None:
    row = _report(
        REP_TRACKING_SUM=10.0, REP_VARIATION=25_000.0, REP_STUCK_STEPS=25.0, REP_STEPS=50.0,
        REP_TORQUE_SQUARED=50 * 25e6, REP_RESIDUAL_SQUARED=50 * 1e6,
    )  # fmt: skip
    weights = RewardWeights()
    terms = reward_terms(row, weights, 50_000.0, 5_000.0)
    assert set(terms) == set(TERMS)
    assert terms == pytest.approx(
        {"tracking": 0.2, "chattering": 0.5, "stuck": 0.5, "torque": 0.01, "residual": 0.04}
    )
    assert reward_terms(row, weights, 50_000.0, None)["residual"] == 0.0
    saturated = reward_terms(_report(REP_VARIATION=1e9, REP_STEPS=1.0), weights, 5e4, None)
    assert saturated["chattering"] == 1.0


def test_terms_of_many_rows_are_elementwise() -> None:
    rows = np.array([_report(REP_TRACKING_SUM=5.0, REP_STEPS=10.0), _report(REP_STEPS=0.0)])
    terms = reward_terms(rows, RewardWeights(), 5e4, 5e3)
    np.testing.assert_allclose(terms["tracking"], [0.5, 0.0])
    assert terms["residual"].shape == (2,)


def test_total_reward() -> None:
    terms = {"tracking": 0.2, "chattering": 0.5, "stuck": 0.4, "torque": 0.3, "residual": 0.1}
    weights = RewardWeights(tracking=1.0, chattering=0.1, stuck=0.5, torque=0.0)
    assert total_reward(terms, weights) == pytest.approx(-(0.2 + 0.05 + 0.2) / 1.6)
    penalised = RewardWeights(stuck=0.5, torque=2.0, residual=0.5)
    assert total_reward(terms, penalised) == pytest.approx(-(0.45 / 1.6) - 0.6 - 0.05)
    # the defaults: tracking 1, chattering 0.1, stuck 0, torque 1, residual 0
    assert total_reward(terms, RewardWeights()) == pytest.approx(-(0.2 + 0.05) / 1.1 - 0.3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"tracking": -1.0}, r"reward weight tracking = -1.0 is out of range"),
        ({"torque": math.nan}, r"reward weight torque = nan is out of range"),
        ({"tracking": 0.0, "chattering": 0.0, "stuck": 0.0}, "are all zero"),
        ({"chattering_scale_nm": 0.0}, r"chattering_scale_nm = 0.0 is out of range"),
    ],
    ids=["negative", "nan", "all-zero", "scale"],
)
def test_bad_weights(kwargs: dict[str, float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        RewardWeights(**kwargs)


def test_env_reward_is_the_total_of_its_terms() -> None:
    """Every step's reward is ``total_reward`` of ``info["reward_terms"]``, in [-2, 0] with the
    default weights (the torque penalty's weight is 1) and lower with larger penalties."""
    weights = RewardWeights(torque=0.5, residual=0.2)
    for kwargs in ({}, {"base_controller": "proposed", "reward_weights": weights}):
        env = gym.make("DrillString-v0", episode_s=3.0, **kwargs)  # type: ignore[arg-type]
        env.reset(seed=1)
        rng = np.random.default_rng(0)
        for _ in range(30):
            _, reward, _, _, info = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
            used = env.unwrapped.config.reward_weights  # type: ignore[attr-defined]
            assert reward == pytest.approx(total_reward(info["reward_terms"], used))
            assert reward <= 0.0
            if not kwargs:
                assert reward >= -2.0


@pytest.mark.parametrize(
    "weights, residual_scale",
    [
        (RewardWeights(), None),
        (RewardWeights(stuck=0.5, torque=2.0, residual=0.5), 10_000.0),
        (RewardWeights(tracking=0.0, chattering=1.0, torque=0.0), 0.5),
    ],
)
def test_the_single_envs_reward_is_that_of_the_terms(
    weights: RewardWeights, residual_scale: float | None
) -> None:
    """``report_reward`` (the single env's hot path) gives the terms and the total of
    ``reward_terms`` and ``total_reward``, bit for bit, on random report rows."""
    from drill_env.rewards import report_reward

    rng = np.random.default_rng(0)
    reward = report_reward(weights, 50_000.0, residual_scale)
    for _ in range(200):
        row = rng.uniform(0.0, 1e6, layout.N_REPORT)
        row[layout.REP_STEPS] = float(rng.integers(0, 200))
        report = row.tolist()
        terms, total = reward(report)
        expected = reward_terms(report, weights, 50_000.0, residual_scale)
        assert terms == expected
        assert total == total_reward(expected, weights)
