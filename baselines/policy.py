"""An SB3-style ``predict()`` adapter that drives ``DrillString-v0`` with a controller."""

from __future__ import annotations

import copy
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from baselines.base import measurement_vector
from drill_env.control import Controller, Measurement
from drill_env.layout import (
    M_STATE,
    M_TOP_DRIVE_SPEED,
    MEASUREMENT_NAMES,
    N_STATE,
    unscale_measurement,
)
from drill_env.limits import DEFAULT_TORQUE_LIMITS
from drill_env.validation import shown

__all__ = ["ControllerPolicy"]

_NOT_OBSERVED: Final = frozenset(
    name
    for k, name in enumerate(MEASUREMENT_NAMES)
    if not (M_STATE <= k < M_STATE + N_STATE or k == M_TOP_DRIVE_SPEED)
)
"""The signals an observation of the default ``state`` mode does not carry."""


class ControllerPolicy:
    """Run a controller as a policy of an env in direct mode (no base controller).

    The measured state and the reference are recovered from the observation and handed to the
    controller as a :class:`drill_env.control.Measurement` (the state entries and the top-drive
    speed by name; the other signals are not in the observation); the torque is
    mapped to the action ``a = 2 (u - min_torque) / (max_torque - min_torque) - 1`` and
    clipped to [-1, 1]. Run it with ``control_dt_s = 0.001`` to reproduce the controller inside
    the plant loop.

    Args:
        controller: The controller (copied once per env of a batch of observations).
        control_dt_s: The env's decision period, s (the controller's integration step).
        min_torque_nm: The env's lower torque limit, N m.
        max_torque_nm: The env's upper torque limit, N m.
    """

    def __init__(
        self,
        controller: Controller,
        control_dt_s: float = 0.001,
        min_torque_nm: float = DEFAULT_TORQUE_LIMITS.min_nm,
        max_torque_nm: float = DEFAULT_TORQUE_LIMITS.max_nm,
    ) -> None:
        if not control_dt_s > 0:
            raise ValueError(f"control_dt_s = {shown(control_dt_s)} is out of range: allowed > 0")
        if not min_torque_nm < max_torque_nm:
            raise ValueError("min_torque_nm must be below max_torque_nm")
        self.controller = controller
        self.control_dt_s = control_dt_s
        self.min_torque_nm = min_torque_nm
        self.max_torque_nm = max_torque_nm
        self._controllers: list[Controller] = []

    @classmethod
    def for_env(cls, controller: Controller, env: Any) -> ControllerPolicy:
        """An adapter with the decision period and torque limits of ``env``."""
        config = env.unwrapped.config
        if config.residual:
            raise ValueError("ControllerPolicy drives an env without base_controller")
        return cls(controller, config.control_dt_s, config.min_torque_nm, config.max_torque_nm)

    def reset(self, num: int = 1) -> None:
        """Fresh controller copies for ``num`` envs."""
        self._controllers = [copy.deepcopy(self.controller) for _ in range(num)]
        for c in self._controllers:
            c.reset()

    def predict(
        self,
        observation: npt.ArrayLike,
        state: Any = None,
        episode_start: npt.ArrayLike | None = None,
        deterministic: bool = True,
    ) -> tuple[npt.NDArray[np.float32], Any]:
        """Actions for one observation (obs_size,) or a batch (n, obs_size).

        ``episode_start`` (bool per env) resets the matching controllers; the first call resets
        all of them.
        """
        obs = np.asarray(observation, dtype=np.float64)
        single = obs.ndim == 1
        batch = obs[None] if single else obs
        n = batch.shape[0]
        if len(self._controllers) != n:
            self.reset(n)
        elif episode_start is not None:
            starts = np.atleast_1d(np.asarray(episode_start, dtype=bool))
            for index in np.flatnonzero(starts).tolist():
                self._controllers[index].reset()
        meas, ref = unscale_measurement(batch)
        span = self.max_torque_nm - self.min_torque_nm
        actions = np.empty((n, 1), dtype=np.float32)
        for k, controller in enumerate(self._controllers):
            measured = Measurement(measurement_vector(meas[k]), _NOT_OBSERVED)
            u = controller.torque(measured, float(ref[k]), self.control_dt_s)
            actions[k, 0] = np.clip(2.0 * (u - self.min_torque_nm) / span - 1.0, -1.0, 1.0)
        return (actions[0] if single else actions), state
