"""The keywords of ``DrillString-v0`` (SPEC section 5), validated in one frozen dataclass.

The same names are accepted by ``gym.make`` and, per episode, by ``reset(options=...)``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Final

from drill_env.control import Controller
from drill_env.parameters import PLANT_DT_S, DrillStringParameters, resolve_parameters
from drill_env.rewards import RewardWeights
from drill_env.scenarios import (
    MAX_REFERENCE_RAD_S,
    MAX_WOB_N,
    Randomization,
    SpeedProfile,
    check_range,
    resolve_uncertainty,
)

__all__ = ["EnvConfig"]

READINGS: Final = ("plant", "controller")
MAX_TORQUE_ABS_NM: Final = 1e6


@dataclass(frozen=True)
class EnvConfig:
    """Every keyword of the environment; see :class:`drill_env.env.DrillStringEnv`."""

    parameters: str | DrillStringParameters = "zribi2024"
    randomize: bool = True
    wob_n: float = 97_347.0
    wob_step_time_s: float | None = None
    wob_final_n: float | None = None
    reference_speed_rad_s: float | SpeedProfile = 12.0
    uncertainty: str | tuple[float, float, float] = "nominal"
    uncertainty_reading: str = "plant"
    noise_std_rad_s: float = 0.1
    episode_s: float = 100.0
    control_dt_s: float = 0.05
    base_controller: str | Controller | None = None
    residual_scale_nm: float = 5_000.0
    min_torque_nm: float = 0.0
    max_torque_nm: float = 50_000.0
    randomization: Randomization = field(default_factory=Randomization)
    reward_weights: RewardWeights = field(default_factory=RewardWeights)

    def __post_init__(self) -> None:
        resolve_parameters(self.parameters)
        if not isinstance(self.randomize, bool):
            raise TypeError(f"randomize must be True or False, got {self.randomize!r}")
        check_range("wob_n", self.wob_n, 1e-9, MAX_WOB_N)
        if self.wob_step_time_s is not None:
            check_range("wob_step_time_s", self.wob_step_time_s, 0.0, math.inf)
        if self.wob_final_n is not None:
            check_range("wob_final_n", self.wob_final_n, 1e-9, MAX_WOB_N)
        if (self.wob_step_time_s is None) != (self.wob_final_n is None):
            raise ValueError("wob_step_time_s and wob_final_n must be given together")
        if not isinstance(self.reference_speed_rad_s, SpeedProfile):
            check_range(
                "reference_speed_rad_s", self.reference_speed_rad_s, 0.0, MAX_REFERENCE_RAD_S
            )
        resolve_uncertainty(self.uncertainty)
        if self.uncertainty_reading not in READINGS:
            raise ValueError(
                f"uncertainty_reading = {self.uncertainty_reading!r} is not valid: allowed {list(READINGS)}"
            )
        check_range("noise_std_rad_s", self.noise_std_rad_s, 0.0, 10.0)
        check_range("control_dt_s", self.control_dt_s, PLANT_DT_S, 10.0)
        if abs(self.control_dt_s / PLANT_DT_S - self.substeps) > 1e-6:
            raise ValueError(
                f"control_dt_s = {self.control_dt_s!r} is out of range: allowed a multiple of "
                f"plant_dt = {PLANT_DT_S} s"
            )
        check_range("episode_s", self.episode_s, self.control_dt_s, 1e5)
        if abs(self.episode_s / self.control_dt_s - self.max_steps) > 1e-6:
            raise ValueError(
                f"episode_s = {self.episode_s!r} is out of range: allowed a multiple of "
                f"control_dt_s = {self.control_dt_s}"
            )
        bc = self.base_controller
        if bc is not None and not isinstance(bc, str) and not isinstance(bc, Controller):
            raise TypeError(
                "base_controller must be None, a controller name or an object with reset() and "
                f"torque(measurement, reference_speed_rad_s, dt_s), got {type(bc).__name__}"
            )
        check_range("residual_scale_nm", self.residual_scale_nm, 0.0, MAX_TORQUE_ABS_NM)
        check_range("min_torque_nm", self.min_torque_nm, -MAX_TORQUE_ABS_NM, MAX_TORQUE_ABS_NM)
        check_range("max_torque_nm", self.max_torque_nm, -MAX_TORQUE_ABS_NM, MAX_TORQUE_ABS_NM)
        if not self.min_torque_nm < self.max_torque_nm:
            raise ValueError(
                f"min_torque_nm = {self.min_torque_nm!r} must be below "
                f"max_torque_nm = {self.max_torque_nm!r}"
            )
        if not isinstance(self.randomization, Randomization):
            raise TypeError(f"randomization must be a Randomization, got {self.randomization!r}")
        if not isinstance(self.reward_weights, RewardWeights):
            raise TypeError(f"reward_weights must be a RewardWeights, got {self.reward_weights!r}")

    @property
    def substeps(self) -> int:
        """Plant steps per decision period."""
        return round(self.control_dt_s / PLANT_DT_S)

    @property
    def max_steps(self) -> int:
        """Decisions per episode."""
        return round(self.episode_s / self.control_dt_s)

    @property
    def residual(self) -> bool:
        """Whether a base controller runs (residual mode)."""
        return self.base_controller is not None

    @property
    def torque_scale_nm(self) -> float:
        """Scale of torques in the observation, N m."""
        return max(abs(self.min_torque_nm), abs(self.max_torque_nm))

    @classmethod
    def keywords(cls) -> list[str]:
        """The valid keyword names."""
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_kwargs(cls, kwargs: dict[str, Any], base: EnvConfig | None = None) -> EnvConfig:
        """Validate ``kwargs`` (unknown names are a ``TypeError`` listing the valid ones)."""
        unknown = sorted(set(kwargs) - set(cls.keywords()))
        if unknown:
            raise TypeError(
                f"unrecognized keyword(s): {', '.join(unknown)}; valid keywords: "
                f"{', '.join(cls.keywords())}"
            )
        if base is None:
            return cls(**kwargs)
        return dataclasses.replace(base, **kwargs)
