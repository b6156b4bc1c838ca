"""One code path to score any policy: ``rollout(env, policy, seed)`` then ``episode_metrics``.

A policy is anything with SB3's ``predict(observation, state=None, episode_start=None,
deterministic=True) -> (action, state)``: an SB3 model, :class:`baselines.ControllerPolicy`,
a loaded residual agent, or :class:`ZeroAction` (the base controller alone in residual mode).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from drill_env.ids import ENV_ID
from drill_env.layout import (
    N_RECORD,
    N_STATE,
    REC_BASE_TORQUE,
    REC_LAW_ERROR,
    REC_LAW_GAIN,
    REC_REFERENCE,
    REC_STUCK,
    REC_TORQUE,
    REC_WOB,
    REC_X0,
    X_BIT_SPEED,
    X_TOP_DRIVE_SPEED,
)
from drill_env.metrics import episode_metrics_from_samples
from drill_env.parameters import PLANT_DT_S
from drill_env.validation import shown

__all__ = [
    "PlantSamples",
    "Policy",
    "Trace",
    "ZeroAction",
    "episode_metrics",
    "reset_each",
    "rollout",
    "run_episode",
    "termination_note",
]


class Policy(Protocol):
    """SB3's policy interface."""

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[Any, Any]: ...


class ZeroAction:
    """The policy that always acts 0: in residual mode, the base controller alone."""

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[npt.NDArray[np.float32], Any]:
        obs = np.asarray(observation)
        shape = (1,) if obs.ndim == 1 else (obs.shape[0], 1)
        return np.zeros(shape, dtype=np.float32), state


@dataclass(frozen=True)
class PlantSamples:
    """Plant-rate samples of one or many strings: the state at the start of every plant step
    and what held over it. Arrays are ``(n,)`` (``(n, 7)`` for ``states``) for one string and
    ``(num_envs, n, ...)`` for a vector env; read from the env's records, they are views, valid
    until the next ``step`` (copy what you keep).

    Attributes:
        states: True state, rad/s and rad.
        torque_nm: Applied top-drive torque, N m.
        base_torque_nm: Base controller torque (0 without one), N m.
        reference_rad_s: Reference bit speed, rad/s.
        wob_n: Weight on bit, N.
        bit_stuck: Whether the bit is stuck.
        sliding_variable: The base controller's error signal (its sliding variable), rad/s;
            0 when it has none.
        adaptive_gain: The base controller's adaptive gain used at the step (0 when none).
    """

    states: npt.NDArray[np.float64]
    torque_nm: npt.NDArray[np.float64]
    base_torque_nm: npt.NDArray[np.float64]
    reference_rad_s: npt.NDArray[np.float64]
    wob_n: npt.NDArray[np.float64]
    bit_stuck: npt.NDArray[np.bool_]
    sliding_variable: npt.NDArray[np.float64]
    adaptive_gain: npt.NDArray[np.float64]

    @classmethod
    def from_records(cls, records: npt.NDArray[np.float64]) -> PlantSamples:
        """Decode kernel records ``(..., n, N_RECORD)`` (``drill_env.layout.REC_*``)."""
        return cls(
            states=records[..., REC_X0 : REC_X0 + N_STATE],
            torque_nm=records[..., REC_TORQUE],
            base_torque_nm=records[..., REC_BASE_TORQUE],
            reference_rad_s=records[..., REC_REFERENCE],
            wob_n=records[..., REC_WOB],
            bit_stuck=records[..., REC_STUCK] > 0.5,
            sliding_variable=records[..., REC_LAW_ERROR],
            adaptive_gain=records[..., REC_LAW_GAIN],
        )

    @property
    def bit_speed_rad_s(self) -> npt.NDArray[np.float64]:
        """True bit speed, rad/s."""
        return self.states[..., X_BIT_SPEED]


@dataclass(frozen=True)
class Trace:
    """One episode, sampled at every plant step (1 ms) and at every decision.

    Plant-rate arrays (n samples at ``time_s = k * plant_dt_s``, the state at the start of the
    step and the torque held over it): ``states`` (n, 7) true state (rad/s, rad),
    ``torque_nm``, ``base_torque_nm`` (0 without a base controller), ``reference_rad_s``,
    ``wob_n``, ``bit_stuck``, ``sliding_variable`` (s at the step) and ``adaptive_gain`` (the
    gain the step's torque used) of the base
    controller (0 when it has none).

    Decision-rate arrays (m decisions): ``decision_time_s``, ``observations`` (m, obs_size),
    ``actions`` (m, 1), ``rewards`` (m,).
    """

    time_s: npt.NDArray[np.float64]
    states: npt.NDArray[np.float64]
    torque_nm: npt.NDArray[np.float64]
    base_torque_nm: npt.NDArray[np.float64]
    reference_rad_s: npt.NDArray[np.float64]
    wob_n: npt.NDArray[np.float64]
    bit_stuck: npt.NDArray[np.bool_]
    sliding_variable: npt.NDArray[np.float64]
    adaptive_gain: npt.NDArray[np.float64]
    decision_time_s: npt.NDArray[np.float64]
    observations: npt.NDArray[np.float32]
    actions: npt.NDArray[np.float32]
    rewards: npt.NDArray[np.float64]
    termination_reason: str | None
    plant_dt_s: float = PLANT_DT_S

    @property
    def bit_speed_rad_s(self) -> npt.NDArray[np.float64]:
        """True bit speed, rad/s."""
        return self.states[:, X_BIT_SPEED]

    @property
    def top_drive_speed_rad_s(self) -> npt.NDArray[np.float64]:
        """True top-drive speed, rad/s."""
        return self.states[:, X_TOP_DRIVE_SPEED]

    @property
    def duration_s(self) -> float:
        """Simulated length, s."""
        return len(self.time_s) * self.plant_dt_s


def rollout(
    env: gym.Env[Any, Any],
    policy: Policy,
    seed: int | None,
    options: dict[str, Any] | None = None,
    deterministic: bool = True,
) -> Trace:
    """Run one episode of ``env`` (a ``DrillString-v0``, wrapped or not) under ``policy``.

    Args:
        env: The environment; its records of every plant step are collected.
        policy: Anything with SB3's ``predict``.
        seed: Reset seed.
        options: Reset options (per-episode scenario keywords).
        deterministic: Passed to ``predict``.

    Returns:
        The episode's :class:`Trace`.
    """
    records_of = env.unwrapped.batch.records  # type: ignore[attr-defined]
    obs, _ = env.reset(seed=seed, options=options)
    chunks: list[npt.NDArray[np.float64]] = []
    observations = [obs]
    actions: list[npt.NDArray[np.float32]] = []
    rewards: list[float] = []
    times = [0.0]
    reason: str | None = None
    state: Any = None
    start = True
    while True:
        action, state = policy.predict(
            obs, state=state, episode_start=np.array([start]), deterministic=deterministic
        )
        start = False
        action = np.asarray(action, dtype=np.float32).reshape(1)
        obs, reward, terminated, truncated, info = env.step(action)
        records = records_of[0]
        if terminated:
            valid = ~np.isnan(records[:, 0])
            records = records[valid]
            reason = str(info.get("termination_reason", "terminated"))
        chunks.append(records.copy())
        actions.append(action)
        rewards.append(float(reward))
        if terminated or truncated:
            break
        observations.append(obs)
        times.append(float(info["time_s"]))
    rec = np.concatenate(chunks) if chunks else np.zeros((0, N_RECORD))
    n = rec.shape[0]
    samples = PlantSamples.from_records(rec)
    return Trace(
        time_s=np.arange(n, dtype=np.float64) * PLANT_DT_S,
        **{f.name: getattr(samples, f.name) for f in dataclasses.fields(samples)},
        decision_time_s=np.array(times[: len(actions)]),
        observations=np.array(observations[: len(actions)], dtype=np.float32),
        actions=np.array(actions, dtype=np.float32),
        rewards=np.array(rewards),
        termination_reason=reason,
    )


def episode_metrics(trace: Trace) -> dict[str, Any]:
    """The docs/specification.md section 4 metrics of ``trace`` (see
    :func:`drill_env.metrics.episode_metrics_from_samples`), plus ``diverged``: whether the
    episode was terminated (a state that left its bounds, a base controller's NaN or infinite
    torque) or its base controller returned a torque that is not finite at any step (a
    compiled law's infinite torque is held at the torque limit and does not end the episode);
    :func:`termination_note` says why. The metrics of a diverged run cover only the steps
    before its end."""
    metrics = episode_metrics_from_samples(
        trace.bit_speed_rad_s,
        trace.reference_rad_s,
        trace.torque_nm,
        trace.bit_stuck,
        trace.plant_dt_s,
    )
    metrics["diverged"] = (
        trace.termination_reason is not None or _first_non_finite(trace.base_torque_nm) is not None
    )
    return metrics


def _first_non_finite(values: npt.NDArray[np.float64]) -> float | None:
    """The first value of ``values`` that is NaN or infinite, or None."""
    bad = ~np.isfinite(values)
    return float(values[int(np.argmax(bad))]) if bad.any() else None


def termination_note(trace: Trace) -> str:
    """Why the run of ``trace`` diverged when more is known than that its state left its
    bounds: the env's reason (``"base_controller Name returned nan N m"``), or the first NaN or
    infinite torque its base controller returned (a compiled law's). Empty when the run did
    not diverge, or its state left its bounds with every torque finite."""
    reason = trace.termination_reason
    if reason is not None and reason != "diverged":
        return reason
    value = _first_non_finite(trace.base_torque_nm)
    if value is not None:
        return f"the base controller returned a non-finite torque ({shown(value)} N m)"
    return ""


def run_episode(
    env_kwargs: dict[str, Any],
    policy: Policy,
    seed: int | None,
    options: dict[str, Any] | None = None,
) -> Trace:
    """One episode of ``gym.make("DrillString-v0", **env_kwargs)`` under ``policy`` (the env
    is made, rolled out and closed)."""
    env = gym.make(ENV_ID, **env_kwargs)
    try:
        return rollout(env, policy, seed, options)
    finally:
        env.close()


def reset_each(
    venv: Any,
    seeds: Sequence[int],
    options: Sequence[dict[str, Any]],
) -> npt.NDArray[np.float32]:
    """Reset every string ``i`` of the vector env ``venv`` with its own seed and reset options
    (Gymnasium's partial reset, one string at a time); returns the observations."""
    n = venv.num_envs
    if len(seeds) != n or len(options) != n:
        raise ValueError(
            f"reset_each needs {n} seeds and {n} option dicts, got {len(seeds)} and {len(options)}"
        )
    obs, _ = venv.reset(seed=list(seeds))
    for i, opts in enumerate(options):
        if opts:
            mask = np.zeros(n, dtype=bool)
            mask[i] = True
            obs, _ = venv.reset(seed=list(seeds), options={**opts, "reset_mask": mask})
    return np.asarray(obs)
