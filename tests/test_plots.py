"""The studies' figures (:mod:`experiments.plots`)."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import ZeroAction, rollout


@pytest.fixture(scope="module")
def short_trace():  # type: ignore[no-untyped-def]
    """1 s of CSMC in residual mode (1,000 plant steps)."""
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller="csmc",
        episode_s=1.0,
        control_dt_s=0.5,
        max_episode_steps=-1,
    )
    return rollout(env, ZeroAction(), seed=0)


class TestFigureHelpers:
    """The figure helpers of experiments.plots that the comparison relies on."""

    def test_downsample_keeps_chattering(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        import dataclasses

        from experiments.plots import downsample

        # A torque switching by +-1 kN m at every step must not alias to a flat line.
        chatter = 13_000.0 + 1_000.0 * (-1.0) ** np.arange(1000)
        small = downsample(dataclasses.replace(short_trace, torque_nm=chatter), 10)
        assert small.time_s.shape == (100,)
        assert small.plant_dt_s == pytest.approx(0.01)
        assert small.duration_s == pytest.approx(short_trace.duration_s)
        np.testing.assert_array_equal(small.torque_nm[0::2], 14_000.0)
        np.testing.assert_array_equal(small.torque_nm[1::2], 12_000.0)
        np.testing.assert_array_equal(small.bit_speed_rad_s, short_trace.bit_speed_rad_s[::10])

    def test_downsample_bad_factor(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        from experiments.plots import downsample

        with pytest.raises(ValueError, match=r"every = 0 is out of range"):
            downsample(short_trace, 0)

    def test_time_window(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        from experiments.plots import time_window

        tail = time_window(short_trace, 0.8)
        assert tail.time_s.shape == (200,)
        assert tail.time_s[0] == pytest.approx(0.8)
        np.testing.assert_array_equal(tail.torque_nm, short_trace.torque_nm[800:])

    def test_panel_without_traces(self, short_trace, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
        from experiments.plots import plot_panels

        with pytest.raises(ValueError, match=r"panel\(s\) 'csmc' have no traces"):
            plot_panels({"csmc": {}, "msmc": {"a": short_trace}}, tmp_path / "x.png")
        with pytest.raises(ValueError, match=r"quantity = 'power' is not valid"):
            plot_panels({"msmc": {"a": short_trace}}, tmp_path / "x.png", quantity="power")
