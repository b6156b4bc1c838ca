"""``DrillString-v0`` as a native vector env: all strings advance in one compiled call.

``gym.make_vec("DrillString-v0", num_envs=N)`` builds this class (the registered
``vector_entry_point``). ``reset(seed=s)`` seeds string ``i`` with ``s + i``, as Gymnasium's
``SyncVectorEnv`` does, so string ``i`` reproduces a single env reset with ``seed=s + i`` bit for
bit. Autoreset follows Gymnasium's next-step mode.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from drill_env import kernel
from drill_env.batch import StringBatch
from drill_env.config import EnvConfig
from drill_env.env import validate_actions
from drill_env.observation import OBS_BOUND, observation_size
from drill_env.rewards import RewardWeights

__all__ = ["DrillStringVectorEnv"]


class DrillStringVectorEnv(VectorEnv):
    """``num_envs`` drill strings stepped together; the keywords are those of
    :class:`drill_env.env.DrillStringEnv` (shared by all strings)."""

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP}  # noqa: RUF012

    def __init__(
        self, num_envs: int = 1, max_episode_steps: int | None = None, **kwargs: Any
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs = {num_envs!r} is out of range: allowed an integer >= 1")
        self.config = EnvConfig.from_kwargs(kwargs)
        if max_episode_steps is not None and (
            isinstance(max_episode_steps, bool)
            or not isinstance(max_episode_steps, int)
            or max_episode_steps < 1
        ):
            raise ValueError(
                f"max_episode_steps = {max_episode_steps!r} is out of range: allowed an integer >= 1"
            )
        # Like gym.make's TimeLimit on the single env: an episode also ends after this many steps.
        self.max_episode_steps = max_episode_steps
        self.num_envs = num_envs
        self._batch = StringBatch(self.config, num_envs)
        size = observation_size(self.config.residual)
        self.single_observation_space = gym.spaces.Box(-OBS_BOUND, OBS_BOUND, (size,), np.float32)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self._started = False

    @property
    def batch(self) -> StringBatch:
        """The engine; its ``records`` hold the last step's plant samples of every string."""
        return self._batch

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float32], dict[str, Any]]:
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed list must have {self.num_envs} entries, got {len(seeds)}")
        if seed is not None:
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(
                seed if isinstance(seed, int) else None
            )
        for i, s in enumerate(seeds):
            root = None
            if s is None and self._batch.episodes[i] is None:
                root = np.random.SeedSequence(int(self.np_random.integers(2**63)))
            self._batch.reset_string(i, s, options, previous_root=root)
        self._needs_reset[:] = False
        self._started = True
        zeros = np.zeros(self.num_envs)
        return self._batch.observations(), self._infos(zeros, zeros, zeros)

    def step(
        self, actions: Any
    ) -> tuple[
        npt.NDArray[np.float32],
        npt.NDArray[np.float64],
        npt.NDArray[np.bool_],
        npt.NDArray[np.bool_],
        dict[str, Any],
    ]:
        if not self._started:
            raise RuntimeError("call reset() before step()")
        a, clipped = validate_actions(actions, self.num_envs)
        b = self._batch
        resetting = self._needs_reset.copy()
        for i in np.flatnonzero(resetting):
            b.reset_string(int(i), None, None)
        a[resetting] = 0.0
        clipped[resetting] = False
        for i in np.flatnonzero(clipped):
            episode = b.episodes[int(i)]
            assert episode is not None
            episode.actions_clipped += 1
        # Strings being reset stay put this step: step the others only when some are resetting.
        active = ~resetting
        if active.all():
            b.step(a)
        elif active.any():
            self._step_subset(a, active)
        s = b.summary
        weights = [e.config.reward_weights for e in b.episodes if e is not None]
        tracking = s[:, kernel.SUM_TRACKING]
        chattering = np.minimum(
            s[:, kernel.SUM_VARIATION] / np.array([w.chattering_scale_nm for w in weights]), 1.0
        )
        stuck = s[:, kernel.SUM_STUCK]
        rewards = _weighted(weights, tracking, chattering, stuck)
        terminated = (b.status != kernel.STATUS_OK) & active
        rewards[terminated] = -1.0
        episode_steps = np.array(
            [round(e.config.episode_s * 1000) for e in b.episodes if e is not None]
        )
        if self.max_episode_steps is not None:
            episode_steps = np.minimum(episode_steps, self.max_episode_steps * b.substeps)
        truncated = (b.step_index >= episode_steps) & ~terminated & active
        rewards[resetting] = 0.0
        self._needs_reset = terminated | truncated
        infos = self._infos(tracking, chattering, stuck)
        infos["action_clipped"] = clipped
        infos["_action_clipped"] = np.ones(self.num_envs, dtype=bool)
        reasons = np.where(terminated, "diverged", "")
        infos["termination_reason"] = reasons
        infos["_termination_reason"] = terminated
        return b.observations(), rewards, terminated, truncated, infos

    def _step_subset(self, a: npt.NDArray[np.float64], active: npt.NDArray[np.bool_]) -> None:
        """Step only the ``active`` strings (the others are starting a new episode)."""
        b = self._batch
        saved = (
            b.x.copy(), b.mode.copy(), b.step_index.copy(), b.status.copy(), b.law_state.copy(),
            b.last_u.copy(), b.meas.copy(), b.noise[:, -1].copy(),
        )  # fmt: skip
        rngs_state = [
            e.noise_rng.bit_generator.state if e is not None else None for e in b.episodes
        ]
        b.step(a)
        idle = ~active
        b.x[idle], b.mode[idle], b.step_index[idle], b.status[idle] = (
            saved[0][idle], saved[1][idle], saved[2][idle], saved[3][idle],
        )  # fmt: skip
        b.law_state[idle], b.last_u[idle], b.meas[idle] = (
            saved[4][idle],
            saved[5][idle],
            saved[6][idle],
        )
        b.noise[idle, -1] = saved[7][idle]
        b.summary[idle] = 0.0
        for i in np.flatnonzero(idle):
            episode = b.episodes[int(i)]
            assert episode is not None
            episode.noise_rng.bit_generator.state = rngs_state[int(i)]  # type: ignore[assignment]

    def _infos(
        self,
        tracking: npt.NDArray[np.float64],
        chattering: npt.NDArray[np.float64],
        stuck: npt.NDArray[np.float64],
    ) -> dict[str, Any]:
        b = self._batch
        n = self.num_envs
        mask = np.ones(n, dtype=bool)
        started = b.step_index > 0
        values: dict[str, Any] = {
            "time_s": b.time_s(),
            "bit_speed_rad_s": b.x[:, 6].copy(),
            "top_drive_speed_rad_s": b.x[:, 0].copy(),
            "reference_speed_rad_s": b.reference_now(),
            "top_drive_torque_nm": b.last_u.copy(),
            "wob_n": np.where(
                started,
                b.records[:, -1, kernel.REC_WOB],
                np.array([e.scenario.wob.initial_n for e in b.episodes if e is not None]),
            ),
            "bit_stuck": b.mode == 0,
            "actions_clipped_total": np.array(
                [e.actions_clipped for e in b.episodes if e is not None]
            ),
        }
        if b.residual:
            values["base_torque_nm"] = np.where(
                started, b.records[:, -1, kernel.REC_BASE_TORQUE], 0.0
            )
            values["residual_torque_nm"] = b.command.copy()
            values["sliding_variable_rad_s"] = b.law_state[:, 3].copy()
            values["adaptive_gain"] = b.law_state[:, 2].copy()
        infos: dict[str, Any] = {}
        for key, value in values.items():
            infos[key] = value
            infos["_" + key] = mask
        infos["reward_terms"] = {
            "tracking": tracking,
            "chattering": chattering,
            "stuck": stuck,
            "_tracking": mask,
            "_chattering": mask,
            "_stuck": mask,
        }
        infos["_reward_terms"] = mask
        return infos


def _weighted(
    weights: list[RewardWeights],
    tracking: npt.NDArray[np.float64],
    chattering: npt.NDArray[np.float64],
    stuck: npt.NDArray[np.float64],
) -> npt.NDArray[np.float64]:
    wt = np.array([w.tracking for w in weights])
    wc = np.array([w.chattering for w in weights])
    ws = np.array([w.stuck for w in weights])
    return -(wt * tracking + wc * chattering + ws * stuck) / (wt + wc + ws)
