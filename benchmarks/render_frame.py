"""Cost of rendering ``DrillString-v0``, in one process.

Prints:

(a) the time of one ``render()`` frame (800 x 480, rgb_array) when every decision of an
    episode is rendered, as ``gymnasium.wrappers.RecordVideo`` does: median, 95th percentile
    and maximum over the episode (the maximum is a full redraw of axes and ticks, needed when
    an axis range changes; the other frames redraw only what moves), for the 4-DOF plant and
    for a synthetic 100-node history (the renderer is generic over the node count);
(b) steps per second of the env with ``render_mode=None`` and with ``render_mode="rgb_array"``
    but no ``render()`` call (the history ring buffer alone), and their ratio.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python benchmarks/render_frame.py``. The first frame of a
process (font loading) is left out.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.render import History, StringRenderer

SCENARIO = {
    "randomize": False,
    "base_controller": "proposed",
    "wob_n": 150e3,
    "reference_speed_rad_s": 6.0,  # stick-slip under the SMC: moving traces, changing axes
}


def frame_times_env(steps: int) -> tuple[np.ndarray, int]:
    """Seconds per render() when every one of ``steps`` decisions is rendered, and how many
    of those frames redrew the axes."""
    env = gym.make("DrillString-v0", render_mode="rgb_array", max_episode_steps=-1, **SCENARIO)
    env.reset(seed=0)
    env.render()  # fonts, first full draw
    renderer = env.unwrapped._rendering._renderer  # type: ignore[attr-defined]
    zero = np.zeros(1, dtype=np.float32)
    times = []
    redraws = 0
    for _ in range(steps):
        env.step(zero)
        layout = renderer._layout
        start = time.perf_counter()
        env.render()
        times.append(time.perf_counter() - start)
        redraws += renderer._layout != layout
    env.close()
    return np.array(times), redraws


def frame_times_many_nodes(n_nodes: int, frames: int) -> np.ndarray:
    """Seconds per frame of a travelling torsional wave on an ``n_nodes`` string."""
    dt = 0.05
    history = History(n_nodes, round(20.0 / dt) + 2)
    renderer = StringRenderer(n_nodes)
    depth = np.linspace(0.0, 1.0, n_nodes)
    x = np.zeros(2 * n_nodes - 1)
    times = []
    for k in range(frames + 1):
        t = k * dt
        x[0::2] = 10.0 + 3.0 * np.sin(2 * np.pi * (0.3 * t - depth))
        x[1::2] = 2.0 + np.sin(2 * np.pi * (0.3 * t - depth[:-1]))
        history.append(t, x, 12e3 + 2e3 * np.sin(t), 10.0, 100e3, bool(np.sin(t) > 0.8))
        start = time.perf_counter()
        renderer.frame(history)
        if k:
            times.append(time.perf_counter() - start)
    return np.array(times)


def steps_per_second(render_mode: str | None, seconds: float) -> float:
    """Decisions per wall second of one env, render() never called."""
    env = gym.make("DrillString-v0", render_mode=render_mode, **SCENARIO)
    env.reset(seed=0)
    zero = np.zeros(1, dtype=np.float32)
    for _ in range(50):
        env.step(zero)
    steps = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        for _ in range(200):
            _, _, terminated, truncated, _ = env.step(zero)
            if terminated or truncated:
                env.reset()
        steps += 200
    return steps / (time.perf_counter() - start)


def _row(name: str, times: np.ndarray) -> str:
    ms = times * 1e3
    return (
        f"{name:<40} {np.median(ms):>8.1f} {np.percentile(ms, 95):>8.1f} {ms.max():>8.1f}"
        f" {ms.size:>7}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=600, help="rendered decisions (30 s)")
    parser.add_argument("--seconds", type=float, default=3.0, help="wall time per step rate")
    args = parser.parse_args()
    print(f"{'(a) frame time, ms':<40} {'median':>8} {'p95':>8} {'max':>8} {'frames':>7}")
    times, redraws = frame_times_env(args.steps)
    print(_row("4-DOF env, every decision rendered", times), f"({redraws} redrew the axes)")
    print(_row("100-node history", frame_times_many_nodes(100, args.steps // 2)))
    rates = {}
    for mode in (None, "rgb_array", None, "rgb_array"):  # interleaved against drift
        rates.setdefault(mode, []).append(steps_per_second(mode, args.seconds))
    plain = max(rates[None])
    recorded = max(rates["rgb_array"])
    print(f"(b) steps/s, render_mode=None:              {plain:>10,.0f}")
    print(f"    steps/s, rgb_array, history only:       {recorded:>10,.0f}")
    print(f"    ratio (history only / None):            {recorded / plain:>10.3f}")


if __name__ == "__main__":
    main()
