"""Cost of an unseeded reset as episodes go by.

Each unseeded reset continues the string's seed sequence: its generators come from the next
child of the last episode's sequence, so the sequence's spawn key is one word longer per
episode. numpy's ``SeedSequence`` hashes the whole key again for every sequence it makes (about
2 us per word on this machine, seven sequences per episode); the env's sequences carry the hash
forward (:class:`drill_env.scenarios.CarriedSeedSequence`, numpy's bit for bit).

Printed, for episodes 0, 100, 1,000 and 5,000 of one ``DrillString-v0`` env (residual on
``proposed``, randomised, as in training): the median ``reset()`` of the 20 episodes from there,
and the median cost of the episode's sequences alone, this version's against numpy's own (what
the previous version made at every reset).

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/reset_cost.py``.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import drill_env
from drill_env.scenarios import COMPONENTS, carried_seed_sequence, spawn_generators

SEED = 5


def seeding_us(sequence: np.random.bit_generator.ISpawnableSeedSequence, repeat: int) -> float:
    """Median microseconds to make an episode's generators and the next episode's sequence."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        spawn_generators(sequence)
        sequence.spawn(1)
        times.append(time.perf_counter() - start)
    return 1e6 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--episodes", type=int, nargs="+", default=[0, 100, 1000, 5000], help="where to measure"
    )
    parser.add_argument("--repeat", type=int, default=20, help="resets timed at each episode")
    args = parser.parse_args()
    print(f"drill_env from {drill_env.__file__}")
    env = gym.make("DrillString-v0", base_controller="proposed", randomize=True, episode_s=1.0)
    env.reset(seed=SEED)
    episode = 0
    print(f"{'episode':>8} {'reset() us':>11} {'sequences us':>13} {'numpy us':>9} {'ratio':>6}")
    for target in sorted(args.episodes):
        while episode < target:
            env.reset()
            episode += 1
        times = []
        for _ in range(args.repeat):
            start = time.perf_counter()
            env.reset()
            times.append(time.perf_counter() - start)
        episode += args.repeat
        # The sequence of episode `target` after reset(seed=SEED): numpy's spawn key has one
        # word per episode (the index of the next child: len(COMPONENTS) after the first).
        key = (len(COMPONENTS),) * target
        numpy_us = seeding_us(np.random.SeedSequence(SEED, spawn_key=key), args.repeat)
        carried = carried_seed_sequence(np.random.SeedSequence(SEED, spawn_key=key))
        carried_us = seeding_us(carried, args.repeat)
        print(
            f"{target:>8,} {1e6 * statistics.median(times):>11,.0f} {carried_us:>13,.0f} "
            f"{numpy_us:>9,.0f} {numpy_us / carried_us:>6.1f}"
        )
    env.close()


if __name__ == "__main__":
    main()
