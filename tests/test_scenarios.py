"""Scenario profiles and draws (drill_env/scenarios.py), checked on hand-computed values."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from drill_env.layout import REC_REFERENCE
from drill_env.scenarios import (
    COMPONENTS,
    CarriedSeedSequence,
    Randomization,
    SpeedProfile,
    WobProfile,
    carried_seed_sequence,
    resolve_uncertainty,
    spawn_generators,
)


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


def _numpy_sequence(entropy: int, key: list[int]) -> np.random.SeedSequence:
    """numpy's own SeedSequence with spawn key ``key``, given as one uint32 array: numpy hashes
    the same words as for the tuple of ints, without converting each int on its own (which
    makes a deep key slow)."""
    return np.random.SeedSequence(entropy, spawn_key=(np.array(key, dtype=np.uint32),))


def test_an_array_spawn_key_is_hashed_as_the_tuple_of_ints() -> None:
    key = [0, *range(4, 4 * 60, 4)]
    for depth in (1, 2, 5, 59):
        as_ints = np.random.SeedSequence(77, spawn_key=tuple(key[:depth]))
        np.testing.assert_array_equal(_numpy_sequence(77, key[:depth]).pool, as_ints.pool)


@pytest.mark.parametrize("entropy", [0, 5, 2**32 - 1, 2**32, 2**63 - 1, 3**80])
def test_carried_seed_sequence_is_numpys(entropy: int) -> None:
    """Over thousands of episodes (each the next child of the last: what an unseeded reset
    does), the carried sequence and every generator spawned from it are numpy's, bit for bit."""
    episodes = 3000 if entropy == 5 else 200
    sequence = carried_seed_sequence(np.random.SeedSequence(entropy))
    assert isinstance(sequence, CarriedSeedSequence)
    key: list[int] = []
    for episode in range(episodes):
        reference = _numpy_sequence(entropy, key)
        np.testing.assert_array_equal(sequence.pool, reference.pool)
        for dtype in (np.uint32, np.uint64):
            np.testing.assert_array_equal(
                sequence.generate_state(3, dtype), reference.generate_state(3, dtype)
            )
        expected = spawn_generators(reference)
        got = spawn_generators(sequence)
        assert list(got) == list(expected)
        for name, generator in got.items():
            draws = generator.standard_normal(2), generator.integers(2**40)
            assert draws[0].tolist() == expected[name].standard_normal(2).tolist(), (episode, name)
            assert draws[1] == expected[name].integers(2**40), (episode, name)
        key.append(sequence.n_children_spawned)  # the index of the next child
        sequence = sequence.spawn(1)[0]
        assert sequence.depth == len(key)


def test_carried_seed_sequence_of_a_spawned_sequence() -> None:
    """From numpy's sequence at any depth and with children already spawned."""
    original = np.random.SeedSequence(9, spawn_key=(3, 1, 4))
    original.spawn(2)
    sequence = carried_seed_sequence(original)
    assert isinstance(sequence, CarriedSeedSequence)
    assert sequence.depth == 3
    for got, expected in zip(sequence.spawn(3), original.spawn(3), strict=True):
        np.testing.assert_array_equal(got.pool, expected.pool)
        assert got.spawn(1)[0].pool.tolist() == expected.spawn(1)[0].pool.tolist()


def test_carried_seed_sequence_keeps_what_it_cannot_carry() -> None:
    """Entropy that is not ints, or another pool size: numpy's own sequence is kept."""
    for original in (
        np.random.SeedSequence(np.array([1, 2], dtype=np.uint32)),
        np.random.SeedSequence(1, pool_size=8),
    ):
        assert carried_seed_sequence(original) is original
    with pytest.raises(ValueError, match="uint32 or uint64"):
        carried_seed_sequence(np.random.SeedSequence(1)).generate_state(2, np.int64)


def test_unseeded_resets_continue_numpys_sequence() -> None:
    """An env's episodes after ``reset(seed=s)`` are those of numpy's SeedSequence(s) and its
    chain of children (each episode spawns its components, then the next episode)."""
    env = gym.make("DrillString-v0", randomize=True, episode_s=1.0)
    batch = env.unwrapped.batch  # type: ignore[attr-defined]
    config = batch.config
    env.reset(seed=21)
    key: list[int] = []
    for _ in range(40):
        reference = np.random.SeedSequence(21, spawn_key=tuple(key))
        assert batch.episodes[0].scenario == config.scenario(spawn_generators(reference))
        key.append(len(COMPONENTS))
        env.reset()


def test_reset_cost_benchmark_prints_its_table() -> None:
    """``benchmarks/reset_cost.py`` as a user runs it, on a short budget."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    result = subprocess.run(
        [sys.executable, "benchmarks/reset_cost.py", "--episodes", "0", "30", "--repeat", "3"],
        cwd=root, env=dict(os.environ, PYTHONPATH=str(root)), capture_output=True, text=True,
        check=True, timeout=300,
    )  # fmt: skip
    lines = result.stdout.splitlines()
    assert lines[1].split() == [
        "episode",
        "reset()",
        "us",
        "sequences",
        "us",
        "numpy",
        "us",
        "ratio",
    ]
    assert [line.split()[0] for line in lines[2:]] == ["0", "30"]
    assert all(float(line.split()[-1]) > 0 for line in lines[2:])
