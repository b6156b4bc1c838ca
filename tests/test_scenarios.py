"""Scenario profiles and draws (drill_env/scenarios.py), checked on hand-computed values."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from drill_env.layout import REC_REFERENCE
from drill_env.scenarios import Randomization, SpeedProfile, WobProfile, resolve_uncertainty


def test_constant_reference() -> None:
    profile = SpeedProfile.constant(12.0)
    assert [profile.value(t) for t in (0.0, 5.0, 1e4)] == [12.0, 12.0, 12.0]


def test_step_reference_is_right_continuous() -> None:
    profile = SpeedProfile.steps(4.0, [(10.0, 8.0), (20.0, 6.0)])
    values = [profile.value(t) for t in (0.0, 9.999, 10.0, 15.0, 20.0, 100.0)]
    assert values == [4.0, 4.0, 8.0, 8.0, 6.0, 6.0]


def test_ramp_reference() -> None:
    profile = SpeedProfile.ramp(4.0, 12.0, 10.0, 30.0)
    assert profile.value(0.0) == 4.0
    assert profile.value(20.0) == pytest.approx(8.0)
    assert profile.value(25.0) == pytest.approx(10.0)
    assert profile.value(40.0) == 12.0


def test_wob_step_knots() -> None:
    assert WobProfile(1e5).knots() == ((0.0,), (1e5,))
    assert WobProfile(1e5, 50.0, 1.8e5).knots() == ((50.0, 50.0), (1e5, 1.8e5))


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: SpeedProfile.ramp(4.0, 8.0, 10.0, 5.0), "ramp end time 5.0 must be after"),
        (lambda: SpeedProfile((0.0, 5.0), (4.0,)), "one value per time"),
        (lambda: SpeedProfile((5.0, 1.0), (4.0, 6.0)), "knot times must not decrease"),
        (lambda: SpeedProfile.constant(-1.0), r"reference_speed_rad_s\[0\] = -1.0 is out of range"),
        (lambda: WobProfile(-5.0), r"wob_n = -5.0 is out of range"),
        (lambda: WobProfile(1e5, 10.0), "wob_step_time_s and wob_final_n must be given together"),
        (lambda: Randomization(wob_range_n=(2e5, 6e4)), "wob_range_n .* is inverted"),
        (lambda: resolve_uncertainty("condition9"), "not a known condition"),
    ],
    ids=[
        "ramp-times",
        "lengths",
        "decreasing",
        "negative-ref",
        "negative-wob",
        "half-step",
        "inverted-range",
        "condition",
    ],  # fmt: skip
)
def test_bad_profiles(make, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=match):
        make()


def test_env_follows_a_step_reference_at_plant_rate() -> None:
    """The plant loop reads the reference profile at every 1 ms step (the records), and the
    observation and info report it at the end of each decision."""
    profile = SpeedProfile.steps(5.0, [(0.12, 9.0)])
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        reference_speed_rad_s=profile,
        episode_s=1.0,
        control_dt_s=0.1,
    )
    env.reset(seed=0)
    env.step(np.zeros(1, dtype=np.float32))
    _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    records = env.unwrapped.batch.records[0]  # plant steps at t = 0.100 .. 0.199 s
    np.testing.assert_array_equal(records[:20, REC_REFERENCE], 5.0)
    np.testing.assert_array_equal(records[20:, REC_REFERENCE], 9.0)
    assert info["reference_speed_rad_s"] == 9.0
