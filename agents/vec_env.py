"""A Gymnasium ``VectorEnv`` seen through Stable-Baselines3's ``VecEnv`` API.

The two APIs differ in how an episode ends. Gymnasium's native vector env of
``DrillString-v0`` (``gym.make_vec``) autoresets in *next-step* mode: the step that ends an
episode returns its last observation, and the following ``step`` call resets that string
(ignoring its action, reward 0). SB3 expects *same-step* autoreset: the step that ends an
episode returns ``done=True``, the first observation of the next episode, and the last one in
``infos[i]["terminal_observation"]``.

:class:`GymnasiumVecEnv` converts by resetting the strings that ended at once, with
Gymnasium's partial reset ``reset(options={"reset_mask": done})`` (no seed: each string
continues its own seed sequence, exactly as the vector env's own autoreset would). The vector
env then has nothing left to autoreset, so no step is lost and no transition is approximate.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import numpy.typing as npt
from gymnasium.vector import AutoresetMode, VectorEnv
from stable_baselines3.common.running_mean_std import RunningMeanStd
from stable_baselines3.common.vec_env import VecNormalize
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from drill_env.validation import shown

__all__ = ["GymnasiumVecEnv", "LeanVecNormalize"]


class GymnasiumVecEnv(VecEnv):
    """SB3 ``VecEnv`` over a Gymnasium ``VectorEnv`` with next-step autoreset and partial
    reset (``reset(options={"reset_mask": mask})``).

    Args:
        env: The vector env (``gym.make_vec("DrillString-v0", num_envs=N, ...)``); this adapter
            owns it and closes it.
        info_keys: Keys of the vector env's ``infos`` copied into SB3's per-env info dicts (a
            few scalars; converting every key at every step costs time).
    """

    def __init__(
        self,
        env: VectorEnv,
        info_keys: Sequence[str] = (),
    ) -> None:
        mode = env.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if mode != AutoresetMode.NEXT_STEP:
            raise ValueError(
                f"GymnasiumVecEnv needs a vector env with autoreset mode NEXT_STEP, got {mode}"
            )
        self.env = env
        self.info_keys = tuple(info_keys)
        # A native vector env of this project steps without building infos when none is read
        # (drill_env.vector.DrillStringVectorEnv.step_without_info: the same transitions).
        self._step_without_info = (
            None if self.info_keys else getattr(env, "step_without_info", None)
        )
        self._actions: npt.NDArray[np.float32] | None = None
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)

    # ------------------------------------------------------------------ SB3 API
    def reset(self) -> VecEnvObs:
        seeds = list(self._seeds)
        # The native vector env takes one seed per string (a list), as SyncVectorEnv does.
        seed: Any = None if all(s is None for s in seeds) else seeds
        options = self._options[0] or None
        obs, _ = self.env.reset(seed=seed, options=options)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return np.asarray(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self) -> VecEnvStepReturn:
        assert self._actions is not None, "step_async() must come first"
        if self._step_without_info is not None:  # no info to copy: the env builds none
            obs, rewards, terminated, truncated = self._step_without_info(self._actions)
            info_list: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        else:
            obs, rewards, terminated, truncated, infos = self.env.step(self._actions)
            info_list = [
                {key: infos[key][i] for key in self.info_keys if key in infos}
                for i in range(self.num_envs)
            ]
        self._actions = None
        obs = np.asarray(obs)
        rewards = np.asarray(rewards, dtype=np.float32)
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        dones = terminated | truncated
        if dones.any():
            for i in np.flatnonzero(dones):
                info_list[i]["terminal_observation"] = obs[i].copy()
                info_list[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            obs, _ = self.env.reset(options={"reset_mask": dones})
            obs = np.asarray(obs)
        return obs, rewards, dones, info_list

    def close(self) -> None:
        self.env.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        if attr_name == "render_mode":
            return [None for _ in self._get_indices(indices)]
        value = getattr(self.env, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(
            f"cannot set {shown(attr_name)} on single strings of a native vector env; "
            "set it on the vector env itself"
        )

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **kwargs: Any
    ) -> list[Any]:
        raise AttributeError(
            f"cannot call {shown(method_name)} on single strings of a native vector env; "
            "call it on the vector env itself"
        )

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper[Any, Any, Any, Any]], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def _get_indices(self, indices: VecEnvIndices) -> Iterable[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return indices


def _update_statistics(statistics: RunningMeanStd, batch: npt.NDArray[Any]) -> None:
    """``statistics.update(batch)`` (the running mean and variance over the first axis) with
    the ufunc calls of ``np.mean`` and ``np.var`` themselves, without their Python wrappers:
    the same numbers, bit for bit."""
    count = np.intp(batch.shape[0])
    total = np.add.reduce(batch, 0)
    if isinstance(total, np.ndarray):
        mean = np.true_divide(total, count, out=total, casting="unsafe")
    else:  # a 1-D batch: numpy scalars
        mean = total.dtype.type(total / count)
    centre = np.add.reduce(batch, 0, keepdims=True)
    centre = np.true_divide(centre, count, out=centre, casting="unsafe")
    deviation = np.subtract(batch, centre)
    np.square(deviation, out=deviation)
    variance = np.add.reduce(deviation, 0)
    if isinstance(variance, np.ndarray):
        variance = np.true_divide(variance, count, out=variance, casting="unsafe")
    else:
        variance = variance.dtype.type(variance / count)
    statistics.update_from_moments(mean, variance, batch.shape[0])


class LeanVecNormalize(VecNormalize):
    """SB3's ``VecNormalize`` for array observations, with fewer Python operations per step:
    the statistics, observations and rewards are the same, bit for bit (the same ufuncs in
    the same order, without ``np.mean``'s, ``np.var``'s and ``np.clip``'s wrappers or the
    copy of the observations that ``normalize_obs`` discards)."""

    def __init__(self, venv: VecEnv, **kwargs: Any) -> None:
        super().__init__(venv, **kwargs)
        if not isinstance(self.obs_rms, RunningMeanStd):
            raise ValueError("LeanVecNormalize needs array (Box) observations")

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        assert isinstance(obs, np.ndarray)
        self.old_obs = obs
        self.old_reward = rewards
        if self.training and self.norm_obs:
            _update_statistics(self._obs_statistics(), obs)
        obs = self.normalize_obs(obs)
        if self.training:
            self.returns = self.returns * self.gamma + rewards
            _update_statistics(self.ret_rms, self.returns)
        rewards = self.normalize_reward(rewards)
        for index in np.flatnonzero(dones).tolist():
            if "terminal_observation" in infos[index]:
                terminal = infos[index]["terminal_observation"]
                infos[index]["terminal_observation"] = self.normalize_obs(terminal)
        self.returns[dones] = 0
        return obs, rewards, dones, infos

    def normalize_obs(self, obs: Any) -> Any:
        """``VecNormalize.normalize_obs`` of an array (a new array); anything else as SB3."""
        if not (self.norm_obs and isinstance(obs, np.ndarray)):
            return super().normalize_obs(obs)
        rms = self._obs_statistics()
        scaled = (obs - rms.mean) / np.sqrt(rms.var + self.epsilon)
        return np.clip(scaled, -self.clip_obs, self.clip_obs, out=scaled).astype(np.float32)

    def _obs_statistics(self) -> RunningMeanStd:
        rms = self.obs_rms
        assert isinstance(rms, RunningMeanStd)
        return rms

    def normalize_reward(self, reward: npt.NDArray[Any]) -> npt.NDArray[np.float32]:
        """``VecNormalize.normalize_reward``."""
        if self.norm_reward:
            scaled = reward / np.sqrt(self.ret_rms.var + self.epsilon)
            reward = np.clip(scaled, -self.clip_reward, self.clip_reward, out=scaled)
        return reward.astype(np.float32)
