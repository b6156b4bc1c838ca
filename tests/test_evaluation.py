"""``rollout`` traces and ``episode_metrics``: shapes, time base, independence of the decision
period, and episodes that end early."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import Trace, ZeroAction, episode_metrics, rollout
from drill_env.metrics import METRIC_KEYS


def make(**kwargs: Any) -> gym.Env[Any, Any]:
    base = dict(randomize=False, max_episode_steps=-1)
    return gym.make("DrillString-v0", **{**base, **kwargs})


class Constant:
    """A policy acting ``value`` always."""

    def __init__(self, value: float) -> None:
        self.value = value

    def predict(self, observation, state=None, episode_start=None, deterministic=True):  # type: ignore[no-untyped-def]
        return np.full(1, self.value, dtype=np.float32), state


@pytest.fixture(scope="module")
def trace() -> Trace:
    """The proposed controller in residual mode, noise off, 2 s at a 50 ms decision period."""
    env = make(base_controller="proposed", episode_s=2.0, control_dt_s=0.05, noise_std_rad_s=0.0)
    return rollout(env, ZeroAction(), seed=3)


class TestTraceShapes:
    def test_plant_rate_arrays(self, trace: Trace) -> None:
        n = 2000
        assert trace.time_s.shape == (n,)
        assert trace.states.shape == (n, 7)
        for name in (
            "torque_nm",
            "base_torque_nm",
            "reference_rad_s",
            "wob_n",
            "bit_stuck",
            "sliding_variable",
            "adaptive_gain",
        ):
            assert getattr(trace, name).shape == (n,), name
        assert trace.bit_stuck.dtype == np.bool_

    def test_time_base(self, trace: Trace) -> None:
        np.testing.assert_allclose(trace.time_s, np.arange(2000) * 1e-3)
        assert trace.plant_dt_s == 1e-3
        assert trace.duration_s == pytest.approx(2.0)

    def test_decision_rate_arrays(self, trace: Trace) -> None:
        m = 40  # 2 s / 0.05 s
        np.testing.assert_allclose(trace.decision_time_s, np.arange(m) * 0.05, atol=1e-12)
        assert trace.observations.shape == (m, 11)  # residual mode
        assert trace.actions.shape == (m, 1)
        assert trace.rewards.shape == (m,)
        assert not np.any(trace.actions)

    def test_start_and_scenario(self, trace: Trace) -> None:
        np.testing.assert_array_equal(trace.states[0], np.zeros(7))
        assert trace.bit_stuck[0]
        np.testing.assert_array_equal(trace.reference_rad_s, 12.0)
        np.testing.assert_array_equal(trace.wob_n, 97_347.0)
        assert trace.termination_reason is None
        # ZeroAction in residual mode: the applied torque is the base controller's.
        np.testing.assert_array_equal(trace.torque_nm, trace.base_torque_nm)
        # The law's s at each step and the gain its torque used: s(0) = -V_ref, k(0) = 0.2.
        assert trace.sliding_variable[0] == -12.0
        assert trace.adaptive_gain[0] == 0.2  # the gain k(0) that the first torque used
        assert trace.adaptive_gain[1] == pytest.approx(0.2 + 3.0 * 12.0**0.125 * 1e-3)

    def test_views(self, trace: Trace) -> None:
        np.testing.assert_array_equal(trace.bit_speed_rad_s, trace.states[:, 6])
        np.testing.assert_array_equal(trace.top_drive_speed_rad_s, trace.states[:, 0])

    def test_metrics_keys(self, trace: Trace) -> None:
        m = episode_metrics(trace)
        assert set(m) == {*METRIC_KEYS, "diverged"}
        assert m["diverged"] is False


class TestDecisionPeriod:
    """The metrics come from plant-rate samples: the decision period does not change them."""

    @pytest.mark.parametrize("noise", [0.0, 0.1], ids=["noise-off", "noise-on"])
    @pytest.mark.parametrize("name", ["csmc", "proposed"])
    def test_same_metrics(self, name: str, noise: float) -> None:
        runs = [
            rollout(
                make(
                    base_controller=name,
                    noise_std_rad_s=noise,
                    uncertainty="condition2",
                    episode_s=10.0,
                    control_dt_s=dt,
                ),
                ZeroAction(),
                seed=11,
            )
            for dt in (0.05, 0.5)
        ]
        a, b = (episode_metrics(t) for t in runs)
        assert a == b
        np.testing.assert_array_equal(runs[0].states, runs[1].states)
        np.testing.assert_array_equal(runs[0].torque_nm, runs[1].torque_nm)

    def test_seed_changes_only_noisy_runs(self) -> None:
        def run(seed: int, noise: float) -> dict[str, Any]:
            env = make(base_controller="csmc", noise_std_rad_s=noise, episode_s=2.0)
            return episode_metrics(rollout(env, ZeroAction(), seed=seed))

        assert run(1, 0.0) == run(2, 0.0)
        assert run(1, 0.1) != run(2, 0.1)
        assert run(1, 0.1) == run(1, 0.1)


class TestEarlyEnd:
    def test_diverged_episode(self) -> None:
        # Full torque of 1 MN m spins the string past the 1000 rad/s bound within seconds.
        env = make(episode_s=20.0, control_dt_s=0.5, max_torque_nm=1e6, noise_std_rad_s=0.0)
        trace = rollout(env, Constant(1.0), seed=0)
        assert trace.termination_reason == "diverged"
        assert 0 < trace.time_s.shape[0] < 20_000
        assert np.all(np.isfinite(trace.states))
        assert trace.actions.shape[0] == trace.rewards.shape[0] == trace.observations.shape[0]
        m = episode_metrics(trace)
        assert m["diverged"] is True
        assert m["settling_time_s"] is None

    def test_truncation_at_episode_length(self) -> None:
        env = make(episode_s=1.5, control_dt_s=0.5)
        trace = rollout(env, Constant(-0.5), seed=0)
        assert trace.termination_reason is None
        assert trace.time_s.shape == (1500,)
        np.testing.assert_allclose(trace.torque_nm, 12_500.0)  # (a + 1) / 2 x 50 kN m
