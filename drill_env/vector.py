"""``DrillString-v0`` as a native vector env: all strings advance in one compiled call.

``gym.make_vec("DrillString-v0", num_envs=N)`` builds this class (the registered
``vector_entry_point``). ``reset(seed=s)`` seeds string ``i`` with ``s + i``, as Gymnasium's
``SyncVectorEnv`` does, so string ``i`` reproduces a single env reset with ``seed=s + i`` bit for
bit. Autoreset follows Gymnasium's next-step mode.
"""

from __future__ import annotations

from typing import Any, ClassVar, NoReturn

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from drill_env.batch import StringBatch
from drill_env.env import copy_batch_env, refuse_pickling, report_info, validate_actions
from drill_env.evaluation import PlantSamples
from drill_env.layout import (
    OBS_BOUND,
    REP_TIME,
    STATUS_DIVERGED,
    STATUS_OK,
    STATUS_PAUSED,
)
from drill_env.limits import MAX_EPISODE_S, MAX_NUM_ENVS
from drill_env.options import EnvConfig, FieldEnvConfig
from drill_env.parameters import PLANT_DT_S
from drill_env.rewards import DIVERGED_REWARD, TERMS, report_rewards
from drill_env.validation import check_int, check_seeds, shown

__all__ = ["DrillStringFieldVectorEnv", "DrillStringVectorEnv"]


class DrillStringVectorEnv(VectorEnv):
    """``num_envs`` drill strings stepped together; the keywords are those of
    :class:`drill_env.env.DrillStringEnv` (shared by all strings)."""

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    config_type: ClassVar[type[EnvConfig]] = EnvConfig
    """The keywords this env takes."""

    def __init__(
        self, num_envs: int = 1, max_episode_steps: int | None = None, **kwargs: Any
    ) -> None:
        num_envs = check_int("num_envs", num_envs, 1, MAX_NUM_ENVS)
        self.config = self.config_type.from_kwargs(kwargs)
        if max_episode_steps is not None:
            # An episode has at most MAX_EPISODE_S / plant step decisions: a longer limit is moot.
            most = round(MAX_EPISODE_S / PLANT_DT_S)
            max_episode_steps = check_int("max_episode_steps", max_episode_steps, 1, most)
        # Like gym.make's TimeLimit on the single env: an episode also ends after this many steps.
        self.max_episode_steps = max_episode_steps
        self.num_envs = num_envs
        self._batch = StringBatch(self.config, num_envs)
        size = self._batch.obs_size
        self.single_observation_space = gym.spaces.Box(-OBS_BOUND, OBS_BOUND, (size,), np.float32)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        residual_scale = self.config.residual_scale_nm if self.config.residual else None
        # The reward weights are fixed at make: the same for every string.
        self._report_rewards = report_rewards(
            self.config.reward_weights, self.config.torque_scale_nm, residual_scale
        )
        self._needs_reset = np.zeros(num_envs, dtype=bool)
        self._started = False
        # Each string's report time from which its episode is truncated (set at reset: the
        # episode's length, or the step limit, less a rounding margin), s.
        self._end_s = np.zeros(num_envs)
        self._rewards = np.zeros(num_envs)  # the last step's (set by _advance)
        self._terminated = np.zeros(num_envs, dtype=bool)
        self._truncated = np.zeros(num_envs, dtype=bool)
        self._no_reasons = np.array([""] * num_envs)  # termination_reason when none ended

    @property
    def batch(self) -> StringBatch:
        """The engine."""
        return self._batch

    def __deepcopy__(self, memo: dict[int, Any]) -> DrillStringVectorEnv:
        """Independent strings in the same state (:func:`drill_env.env.copy_batch_env`)."""
        return copy_batch_env(self, memo)

    def __reduce_ex__(self, protocol: Any) -> NoReturn:
        refuse_pickling(self)

    @property
    def observation_names(self) -> tuple[str, ...]:
        """The name of each observation entry, in order (``drill_env.layout.observation_fields``)."""
        return tuple(f.name for f in self._batch.fields)

    def plant_samples(self) -> PlantSamples:
        """The last step's samples of every string at every plant step, arrays
        ``(num_envs, n, ...)`` (views, valid until the next step; NaN where a string did not
        move: diverged, or resetting)."""
        return PlantSamples.from_records(self._batch.records)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[npt.NDArray[np.float32], dict[str, Any]]:
        """Reset every string, or only those of ``options["reset_mask"]`` (a bool array of
        ``num_envs``, Gymnasium's partial reset); the other options apply to the strings reset.
        Seeds: ``s`` gives string ``i`` the seed ``s + i``; a list gives each its own."""
        mask = np.ones(self.num_envs, dtype=bool)
        if options and "reset_mask" in options:
            options = dict(options)
            mask = np.asarray(options.pop("reset_mask"))
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
                raise ValueError(
                    f"reset_mask must be a bool array of shape ({self.num_envs},), got {shown(mask)}"
                )
            if not self._started and not mask.all():
                raise ValueError("the first reset must reset every string (reset_mask all True)")
        seeds = check_seeds(seed, self.num_envs)
        if isinstance(seed, np.integer):
            seed = int(seed)
        if seed is not None:
            self._np_random, self._np_random_seed = gym.utils.seeding.np_random(
                seed if isinstance(seed, int) else None
            )
        for i, s in enumerate(seeds):
            if not mask[i]:
                continue
            root = None
            if s is None and self._batch.episodes[i] is None:
                root = np.random.SeedSequence(int(self.np_random.integers(2**63)))
            self._batch.reset_string(i, s, options, previous_root=root)
            self._set_episode_end(i)
        self._needs_reset[mask] = False
        self._started = True
        zeros = np.zeros(self.num_envs)
        return self._batch.observations(), self._infos(dict.fromkeys(TERMS, zeros))

    def step(
        self, actions: Any
    ) -> tuple[
        npt.NDArray[np.float32],
        npt.NDArray[np.float64],
        npt.NDArray[np.bool_],
        npt.NDArray[np.bool_],
        dict[str, Any],
    ]:
        term_rows, clipped = self._advance(actions)
        terms = dict(zip(TERMS, term_rows, strict=True))
        b = self._batch
        terminated, truncated = self._terminated, self._truncated
        infos = self._infos(terms)
        infos["action_clipped"] = clipped
        infos["_action_clipped"] = np.ones(self.num_envs, dtype=bool)
        infos["termination_reason"] = (
            np.array(
                [b.end_reason(i) if ended else "" for i, ended in enumerate(terminated.tolist())]
            )
            if terminated.any()
            else self._no_reasons.copy()
        )
        infos["_termination_reason"] = terminated
        return b.observations(), self._rewards, terminated, truncated, infos

    def step_without_info(
        self, actions: Any
    ) -> tuple[
        npt.NDArray[np.float32],
        npt.NDArray[np.float64],
        npt.NDArray[np.bool_],
        npt.NDArray[np.bool_],
    ]:
        """:meth:`step` without building ``infos`` (for a trainer that reads none of them):
        the same transitions, observations, rewards, terminated and truncated, bit for bit."""
        self._advance(actions)
        return self._batch.observations(), self._rewards, self._terminated, self._truncated

    def _advance(self, actions: Any) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
        """One step of every string (next-step autoreset first); sets the step's rewards,
        terminated and truncated, and returns the reward terms (a row per name of
        ``drill_env.rewards.TERMS``) and which actions were clipped."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        a, clipped = validate_actions(actions, self.num_envs, batched=True)
        b = self._batch
        needs_reset = self._needs_reset
        resetting = needs_reset.any()
        if resetting:
            reset = needs_reset.copy()
            for i in np.flatnonzero(reset).tolist():
                b.reset_string(i, None, None)
                self._set_episode_end(i)
            a[reset] = 0.0
            clipped[reset] = False
        if clipped.any():
            for i in np.flatnonzero(clipped).tolist():
                episode = b.episodes[i]
                assert episode is not None
                episode.actions_clipped += 1
        if resetting:  # strings starting a new episode (next-step autoreset) sit this step out
            b.status[reset] = STATUS_PAUSED
            b.step(a)
            b.status[reset] = STATUS_OK
        else:
            b.step(a)
        report = b.report
        terms, rewards = self._report_rewards(report)
        terminated = b.status == STATUS_DIVERGED
        if terminated.any():
            rewards[terminated] = DIVERGED_REWARD
        truncated = report[:, REP_TIME] >= self._end_s
        truncated &= ~terminated
        if resetting:
            rewards[reset] = 0.0
            terminated &= ~reset
            truncated &= ~reset
        self._needs_reset = terminated | truncated
        self._rewards, self._terminated, self._truncated = rewards, terminated, truncated
        return terms, clipped

    def _set_episode_end(self, i: int) -> None:
        """Note the report time that truncates string ``i``'s new episode."""
        duration = self._episode_duration_s(i)
        if self.max_episode_steps is not None:
            duration = min(duration, self.max_episode_steps * self.config.control_dt_s)
        self._end_s[i] = duration - 1e-9

    def _episode_duration_s(self, i: int) -> float:
        """The length of string ``i``'s episode, s (it may change at reset with ``options``)."""
        episode = self._batch.episodes[i]
        assert episode is not None
        return episode.duration_s

    def _infos(self, terms: dict[str, npt.NDArray[np.float64]]) -> dict[str, Any]:
        b = self._batch
        mask = np.ones(self.num_envs, dtype=bool)
        values = report_info(b.report, b.residual, self.config.telemetry)
        values["actions_clipped_total"] = np.array(
            [e.actions_clipped for e in b.episodes if e is not None]
        )
        if b.residual:
            values["residual_torque_nm"] = b.command.copy()
        values.update(b.law_info())
        values.update(b.coupled_info())
        infos: dict[str, Any] = {}
        for key, value in values.items():
            infos[key] = value
            infos["_" + key] = mask
        infos["reward_terms"] = {key: np.array(value, copy=True) for key, value in terms.items()}
        infos["reward_terms"].update({"_" + key: mask for key in terms})
        infos["_reward_terms"] = mask
        return infos


class DrillStringFieldVectorEnv(DrillStringVectorEnv):
    """``DrillStringField-v0`` as a native vector env (the keywords of
    :class:`drill_env.env.DrillStringFieldEnv`)."""

    config_type: ClassVar[type[EnvConfig]] = FieldEnvConfig
