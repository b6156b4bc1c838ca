"""The keywords of ``DrillString-v0`` (docs/specification.md section 5), validated in one frozen
dataclass, the per-episode ``reset(options=...)`` rule, and the scenario of an episode.

The same names are accepted by ``gym.make`` and, per episode (the scenario ones), by
``reset(options=...)``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np

from drill_env.control import Controller
from drill_env.limits import (
    DEFAULT_TORQUE_LIMITS,
    MAX_REFERENCE_RAD_S,
    MAX_TORQUE_ABS_NM,
    TorqueLimits,
)
from drill_env.parameters import PLANT_DT_S, DrillStringParameters, resolve_parameters
from drill_env.rewards import RewardWeights
from drill_env.scenarios import (
    Randomization,
    Scenario,
    SpeedProfile,
    UncertaintyReading,
    WobProfile,
)
from drill_env.validation import check_bool, check_range, check_unknown

__all__ = ["PER_EPISODE_KEYWORDS", "EnvConfig", "episode_config"]

PER_EPISODE_KEYWORDS: Final = (
    "parameters",
    "randomize",
    "wob_n",
    "wob_step_time_s",
    "wob_final_n",
    "reference_speed_rad_s",
    "uncertainty",
    "uncertainty_reading",
    "noise_std_rad_s",
    "episode_s",
    "randomization",
)
"""Keywords that ``reset(options=...)`` may change for one episode; the others shape the
spaces or the compiled loop and are fixed at ``make``."""


@dataclass(frozen=True)
class EnvConfig:
    """Every keyword of the environment; see :class:`drill_env.env.DrillStringEnv`.

    ``randomization`` and ``reward_weights`` also take a plain mapping of their fields (from
    YAML or JSON), validated like the dataclass.
    """

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
    min_torque_nm: float = DEFAULT_TORQUE_LIMITS.min_nm
    max_torque_nm: float = DEFAULT_TORQUE_LIMITS.max_nm
    randomization: Randomization = field(default_factory=Randomization)
    reward_weights: RewardWeights = field(default_factory=RewardWeights)

    def __post_init__(self) -> None:
        # The dataclass keywords also take plain mappings of their fields (YAML, JSON).
        for name, kind in (("randomization", Randomization), ("reward_weights", RewardWeights)):
            value = getattr(self, name)
            if isinstance(value, Mapping):
                check_unknown(value, [f.name for f in dataclasses.fields(kind)], "field", name)
                fields = {k: tuple(v) if isinstance(v, list) else v for k, v in value.items()}
                object.__setattr__(self, name, kind(**fields))  # type: ignore[arg-type]
        check_bool("randomize", self.randomize)
        self.fixed_scenario()  # validates the scenario keywords
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

    # ------------------------------------------------------------------ derived values
    @property
    def substeps(self) -> int:
        """Plant steps per decision period."""
        return round(self.control_dt_s / PLANT_DT_S)

    @property
    def max_steps(self) -> int:
        """Decisions per episode."""
        return round(self.episode_s / self.control_dt_s)

    @property
    def duration_s(self) -> float:
        """Episode length rounded down to the plant step, s (so that a time compares exactly)."""
        return round(self.episode_s / PLANT_DT_S) * PLANT_DT_S

    @property
    def residual(self) -> bool:
        """Whether a base controller runs (residual mode)."""
        return self.base_controller is not None

    @property
    def torque_limits(self) -> TorqueLimits:
        """The top drive's torque range, N m."""
        return TorqueLimits(float(self.min_torque_nm), float(self.max_torque_nm))

    @property
    def torque_scale_nm(self) -> float:
        """Scale of torques in the observation, N m."""
        return max(abs(self.min_torque_nm), abs(self.max_torque_nm))

    def fixed_scenario(self) -> Scenario:
        """The scenario the keywords describe (the one used when ``randomize`` is off)."""
        ref = self.reference_speed_rad_s
        if not isinstance(ref, SpeedProfile):
            check_range("reference_speed_rad_s", ref, 0.0, MAX_REFERENCE_RAD_S)
            ref = SpeedProfile.constant(ref)
        return Scenario(
            wob=WobProfile(self.wob_n, self.wob_step_time_s, self.wob_final_n),
            reference=ref,
            uncertainty=self.uncertainty,  # type: ignore[arg-type]
            reading=self.uncertainty_reading,  # type: ignore[arg-type]
            noise_std_rad_s=self.noise_std_rad_s,
            parameters=resolve_parameters(self.parameters),
        )

    @property
    def reading(self) -> UncertaintyReading:
        """The uncertainty reading."""
        return "controller" if self.uncertainty_reading == "controller" else "plant"

    def scenario(self, generators: dict[str, np.random.Generator]) -> Scenario:
        """The episode's scenario: drawn from ``randomization`` when ``randomize``, else
        :meth:`fixed_scenario`."""
        if not self.randomize:
            return self.fixed_scenario()
        return self.randomization.draw(
            generators,
            self.episode_s,
            resolve_parameters(self.parameters),
            self.reading,
            self.noise_std_rad_s,
        )

    # ------------------------------------------------------------------ construction
    @classmethod
    def keywords(cls) -> list[str]:
        """The valid keyword names."""
        return [f.name for f in dataclasses.fields(cls)]

    @classmethod
    def from_kwargs(cls, kwargs: dict[str, Any], base: EnvConfig | None = None) -> EnvConfig:
        """Validate ``kwargs`` (unknown names are a ``TypeError`` listing the valid ones)."""
        check_unknown(kwargs, cls.keywords())
        if base is None:
            return cls(**kwargs)
        return dataclasses.replace(base, **kwargs)


def episode_config(base: EnvConfig, options: dict[str, Any] | None) -> EnvConfig:
    """``base`` with the per-episode ``options`` applied and validated."""
    if not options:
        return base
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict, got {type(options).__name__}")
    fixed = sorted(set(options) & (set(EnvConfig.keywords()) - set(PER_EPISODE_KEYWORDS)))
    if fixed:
        raise ValueError(
            f"option(s) {', '.join(fixed)} cannot change per episode: set them at make; "
            f"per-episode options: {', '.join(PER_EPISODE_KEYWORDS)}"
        )
    unknown = sorted(set(options) - set(EnvConfig.keywords()))
    if unknown:
        raise ValueError(
            f"unknown option(s): {', '.join(unknown)}; valid options: "
            f"{', '.join(PER_EPISODE_KEYWORDS)}"
        )
    return EnvConfig.from_kwargs(options, base)
