"""The keywords of ``DrillString-v0`` (docs/specification.md section 5), validated in one frozen
dataclass, the per-episode ``reset(options=...)`` rule, and the scenario of an episode.

The same names are accepted by ``gym.make`` and, per episode (the scenario ones), by
``reset(options=...)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any, ClassVar, Final

import numpy as np

from drill_env.control import Controller
from drill_env.coupled import RgdParameters
from drill_env.coupled_chain import check_bit_keywords
from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    resolve_distributed_parameters,
    with_measured_depth,
)
from drill_env.layout import OBSERVATION_MODES
from drill_env.limits import (
    DEFAULT_TORQUE_LIMITS,
    HOOK_STIFFNESS_RANGE_N_M,
    MAX_EPISODE_S,
    MAX_REFERENCE_RAD_S,
    MAX_TORQUE_ABS_NM,
    TorqueLimits,
)
from drill_env.modes import check_step_bound
from drill_env.parameters import (
    PLANT_DT_S,
    PRESETS,
    DrillStringParameters,
    resolve_parameters,
)
from drill_env.rewards import FIELD_REWARD_WEIGHTS, RewardWeights
from drill_env.scenarios import (
    RPM,
    FieldRandomization,
    Randomization,
    Scenario,
    SpeedProfile,
    UncertaintyReading,
    WobProfile,
)
from drill_env.sensors import MeasurementChannel
from drill_env.validation import (
    check_bool,
    check_choice,
    check_range,
    check_real,
    check_unknown,
    input_type_errors,
    printable,
    require,
    shown,
)

__all__ = [
    "FIELD_MAX_TORQUE_NM",
    "check_episode_s",
    "PER_EPISODE_KEYWORDS",
    "REALISM_KEYWORDS",
    "REALISM_LEVELS",
    "EnvConfig",
    "FieldEnvConfig",
    "episode_config",
    "realism_keywords",
    "steps_of",
]

FIELD_MAX_TORQUE_NM: Final = 50_800.0
"""Continuous drilling torque of a 500-ton class AC top drive (37,500 ft lbf), N m."""

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
    "torque_noise_std_nm",
    "telemetry_noise_std_rad_s",
    "episode_s",
    "randomization",
    "measured_depth_m",
    "controller_parameters",
)
"""Keywords that ``reset(options=...)`` may change for one episode; the others shape the
spaces or the compiled loop and are fixed at ``make``."""

FIELD_ONLY: Final = ("measured_depth_m", "controller_parameters")
"""Keywords of ``DrillStringField-v0`` only."""
LUMPED_ONLY: Final = ("uncertainty", "uncertainty_reading")
"""Keywords of ``DrillString-v0`` only (the paper's parametric uncertainty of the 4-DOF plant)."""

REALISM_KEYWORDS: Final = (
    "observation",
    "torque_noise_std_nm",
    "sensor_period_s",
    "telemetry_period_s",
    "telemetry_delay_s",
    "telemetry_noise_std_rad_s",
    "actuator_dead_time_s",
    "actuator_lag_s",
    "torque_rate_limit_nm_per_s",
)
"""The keywords of the measurement channel and the actuator: what a controller can see of the
string and how the top drive responds."""

REALISM_LEVELS: Final = ("ideal", "wired_pipe", "field", "surface_only")
"""Named settings of :data:`REALISM_KEYWORDS` (:func:`realism_keywords`)."""

MAX_DEAD_TIME_S: Final = 2.0
"""Longest accepted actuator dead time, s."""


@dataclass(frozen=True)
class EnvConfig:
    """Every keyword of the environment; see :class:`drill_env.env.DrillStringEnv`.

    ``randomization`` and ``reward_weights`` also take a plain mapping of their fields (from
    YAML or JSON), validated like the dataclass.
    """

    parameters: str | DrillStringParameters | DistributedStringParameters = "zribi2024"
    randomize: bool = True
    wob_n: float = 97_347.0
    wob_step_time_s: float | None = None
    wob_final_n: float | None = None
    reference_speed_rad_s: float | SpeedProfile = 12.0
    uncertainty: str | tuple[float, float, float] = "nominal"
    uncertainty_reading: str = "plant"
    noise_std_rad_s: float = 0.1
    episode_s: float = 100.0
    control_dt_s: float = 0.1  # the shipped agent's (agents/models/residual_ppo)
    base_controller: str | Controller | None = None
    residual_scale_nm: float = 20_000.0  # the shipped agent's
    min_torque_nm: float = DEFAULT_TORQUE_LIMITS.min_nm
    max_torque_nm: float = DEFAULT_TORQUE_LIMITS.max_nm
    randomization: Randomization | FieldRandomization = field(default_factory=Randomization)
    reward_weights: RewardWeights = field(default_factory=RewardWeights)
    observation: str = "state"
    torque_noise_std_nm: float = 0.0
    sensor_period_s: float = PLANT_DT_S
    telemetry_period_s: float | None = None
    telemetry_delay_s: float = 0.0
    telemetry_noise_std_rad_s: float = 0.0
    actuator_dead_time_s: float = 0.0
    actuator_lag_s: float = 0.0
    torque_rate_limit_nm_per_s: float | None = None
    measured_depth_m: float | None = None
    controller_parameters: str | DistributedStringParameters | None = None

    def __post_init__(self) -> None:
        if self.distributed and not self.is_field:
            raise ValueError(
                f"parameters = {shown(self.parameters)} is a distributed string: use "
                "DrillStringField-v0; DrillString-v0 takes a 4-DOF preset "
                f"{sorted(PRESETS)} or a DrillStringParameters"
            )
        # The dataclass keywords also take plain mappings of their fields (YAML, JSON).
        randomization_type = FieldRandomization if self.distributed else Randomization
        for name, kind in (
            ("randomization", randomization_type),
            ("reward_weights", RewardWeights),
        ):
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
                f"control_dt_s = {shown(self.control_dt_s)} is out of range: allowed a multiple of "
                f"plant_dt = {PLANT_DT_S} s"
            )
        check_episode_s(self.episode_s, self.control_dt_s)
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
                f"min_torque_nm = {shown(self.min_torque_nm)} must be below "
                f"max_torque_nm = {shown(self.max_torque_nm)}"
            )
        if not isinstance(self.randomization, randomization_type):
            raise TypeError(
                f"randomization must be a {randomization_type.__name__}, got {shown(self.randomization)}"
            )
        if not isinstance(self.reward_weights, RewardWeights):
            raise TypeError(
                f"reward_weights must be a RewardWeights, got {shown(self.reward_weights)}"
            )
        check_choice("observation", self.observation, OBSERVATION_MODES, "mode")
        check_range("torque_noise_std_nm", self.torque_noise_std_nm, 0.0, 1e5)
        check_range("telemetry_noise_std_rad_s", self.telemetry_noise_std_rad_s, 0.0, 10.0)
        _check_steps("sensor_period_s", self.sensor_period_s, PLANT_DT_S, 10.0)
        if self.telemetry_period_s is not None:
            _check_steps("telemetry_period_s", self.telemetry_period_s, PLANT_DT_S, 600.0)
        _check_steps("telemetry_delay_s", self.telemetry_delay_s, 0.0, 600.0)
        _check_steps("actuator_dead_time_s", self.actuator_dead_time_s, 0.0, MAX_DEAD_TIME_S)
        check_range("actuator_lag_s", self.actuator_lag_s, 0.0, 10.0)
        if self.torque_rate_limit_nm_per_s is not None:
            rate = check_real("torque_rate_limit_nm_per_s", self.torque_rate_limit_nm_per_s)
            require(
                "torque_rate_limit_nm_per_s", self.torque_rate_limit_nm_per_s,
                "(0, 1e+09] (or None: no limit)", math.isfinite(rate) and 0 < rate <= 1e9,
            )  # fmt: skip
        if not self.distributed:
            for name in FIELD_ONLY:
                if getattr(self, name) is not None:
                    raise TypeError(
                        f"{name} is a keyword of the distributed string (DrillStringField-v0)"
                    )

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
    def distributed(self) -> bool:
        """Whether the plant is a distributed string (``DrillStringField-v0``)."""
        return _is_distributed(self.parameters)

    @property
    def telemetry(self) -> bool:
        """Whether downhole telemetry arrives."""
        return self.telemetry_period_s is not None

    @property
    def ideal_actuator(self) -> bool:
        """No dead time, lag or rate limit: the applied torque is the command."""
        return (
            self.actuator_dead_time_s == 0.0
            and self.actuator_lag_s == 0.0
            and self.torque_rate_limit_nm_per_s is None
        )

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

    def measurement_channel(self, speed_noise_std_rad_s: float | None = None) -> MeasurementChannel:
        """The measurement channel these keywords describe; ``speed_noise_std_rad_s`` (rad/s)
        replaces ``noise_std_rad_s`` (an episode's scenario may have its own)."""
        return MeasurementChannel(
            observation=self.observation,
            speed_noise_std_rad_s=float(
                self.noise_std_rad_s if speed_noise_std_rad_s is None else speed_noise_std_rad_s
            ),
            torque_noise_std_nm=float(self.torque_noise_std_nm),
            sensor_period_s=float(self.sensor_period_s),
            telemetry_period_s=(
                None if self.telemetry_period_s is None else float(self.telemetry_period_s)
            ),
            telemetry_delay_s=float(self.telemetry_delay_s),
            telemetry_noise_std_rad_s=float(self.telemetry_noise_std_rad_s),
        )

    def string(self) -> DistributedStringParameters:
        """The distributed string of the keywords (at ``measured_depth_m`` when given)."""
        string = resolve_distributed_parameters(self.parameters)  # type: ignore[arg-type]
        if self.measured_depth_m is not None:
            string = with_measured_depth(string, self.measured_depth_m)
        return string

    def fixed_scenario(self) -> Scenario:
        """The scenario the keywords describe (the one used when ``randomize`` is off)."""
        ref = self.reference_speed_rad_s
        if not isinstance(ref, SpeedProfile):
            check_range("reference_speed_rad_s", ref, 0.0, MAX_REFERENCE_RAD_S)
            ref = SpeedProfile.constant(ref)
        if self.distributed:
            model = None
            if self.controller_parameters is not None:
                model = resolve_distributed_parameters(
                    self.controller_parameters, "controller_parameters"
                )
            return Scenario(
                wob=WobProfile(self.wob_n, self.wob_step_time_s, self.wob_final_n),
                reference=ref,
                noise_std_rad_s=self.noise_std_rad_s,
                parameters=self.string(),
                model=model,
            )
        return Scenario(
            wob=WobProfile(self.wob_n, self.wob_step_time_s, self.wob_final_n),
            reference=ref,
            uncertainty=self.uncertainty,  # type: ignore[arg-type]
            reading=self.uncertainty_reading,  # type: ignore[arg-type]
            noise_std_rad_s=self.noise_std_rad_s,
            parameters=resolve_parameters(self.parameters),  # type: ignore[arg-type]
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
        if isinstance(self.randomization, FieldRandomization):
            return self.randomization.draw(
                generators, self.episode_s, self.string(), self.noise_std_rad_s
            )
        return self.randomization.draw(
            generators,
            self.episode_s,
            resolve_parameters(self.parameters),  # type: ignore[arg-type]
            self.reading,
            self.noise_std_rad_s,
        )

    # ------------------------------------------------------------------ construction
    @classmethod
    def keywords(cls) -> list[str]:
        """The valid keyword names."""
        excluded = LUMPED_ONLY if cls.is_field else FIELD_ONLY
        return [f.name for f in dataclasses.fields(cls) if f.name not in excluded]

    is_field: ClassVar[bool] = False
    """Whether this is the configuration of ``DrillStringField-v0``."""

    @classmethod
    def from_kwargs(cls, kwargs: dict[str, Any], base: EnvConfig | None = None) -> EnvConfig:
        """Validate ``kwargs`` (unknown names are a ``TypeError`` listing the valid ones)."""
        check_unknown(kwargs, cls.keywords())
        with input_type_errors():  # Gymnasium's make adds the raw keywords to a TypeError
            if base is None:
                return cls(**kwargs)
            return dataclasses.replace(base, **kwargs)


def episode_config(base: EnvConfig, options: dict[str, Any] | None) -> EnvConfig:
    """``base`` with the per-episode ``options`` applied and validated."""
    if not options:
        return base
    if not isinstance(options, dict):
        raise TypeError(f"options must be a dict, got {type(options).__name__}")
    keywords = type(base).keywords()
    per_episode = [k for k in PER_EPISODE_KEYWORDS if k in keywords]
    fixed = sorted(set(options) & (set(keywords) - set(per_episode)))
    if fixed:
        raise ValueError(
            f"option(s) {', '.join(fixed)} cannot change per episode: set them at make; "
            f"per-episode options: {', '.join(per_episode)}"
        )
    unknown = sorted(printable(name) for name in set(options) - set(keywords))
    if unknown:
        raise ValueError(
            f"unknown option(s): {', '.join(unknown)}; valid options: {', '.join(per_episode)}"
        )
    return type(base).from_kwargs(options, base)


def _is_distributed(parameters: object) -> bool:
    if isinstance(parameters, DistributedStringParameters):
        return True
    return isinstance(parameters, str) and parameters in DISTRIBUTED_PRESETS


def _check_steps(name: str, value: object, low: float, high: float) -> float:
    """``value`` (s) in ``[low, high]`` and a whole number of plant steps."""
    v = check_range(name, value, low, high)
    if abs(v / PLANT_DT_S - round(v / PLANT_DT_S)) > 1e-6:
        raise ValueError(
            f"{name} = {shown(value)} is out of range: allowed a multiple of plant_dt = {PLANT_DT_S} s"
        )
    return v


def check_episode_s(episode_s: object, control_dt_s: float) -> int:
    """``episode_s`` (s) in ``[control_dt_s, MAX_EPISODE_S]`` and a whole number of decision
    periods of ``control_dt_s`` (s); returns that number.

    Raises:
        ValueError: naming ``episode_s`` and what is allowed.
    """
    v = check_range("episode_s", episode_s, control_dt_s, MAX_EPISODE_S)
    steps = round(v / control_dt_s)
    if abs(v / control_dt_s - steps) > 1e-6:
        raise ValueError(
            f"episode_s = {shown(episode_s)} is out of range: allowed a multiple of "
            f"control_dt_s = {control_dt_s}"
        )
    return steps


def steps_of(seconds: float) -> int:
    """A duration in whole plant steps."""
    return round(seconds / PLANT_DT_S)


@dataclass(frozen=True)
class FieldEnvConfig(EnvConfig):
    """Every keyword of ``DrillStringField-v0`` (the distributed string); the defaults are a
    rig's, with their sources in docs/specification.md section 18."""

    parameters: str | DrillStringParameters | DistributedStringParameters = "field_2500m"
    randomization: Randomization | FieldRandomization = field(default_factory=FieldRandomization)
    reference_speed_rad_s: float | SpeedProfile = 100 * RPM
    wob_n: float = 100e3
    noise_std_rad_s: float = 0.05
    max_torque_nm: float = FIELD_MAX_TORQUE_NM
    observation: str = "surface"
    torque_noise_std_nm: float = 250.0
    sensor_period_s: float = 0.01
    telemetry_period_s: float | None = 5.0
    telemetry_delay_s: float = 5.0
    telemetry_noise_std_rad_s: float = 0.1
    actuator_dead_time_s: float = 0.02
    actuator_lag_s: float = 0.02
    torque_rate_limit_nm_per_s: float | None = 100e3
    episode_s: float = 100.0
    control_dt_s: float = 0.2  # the shipped field agent's (agents/models/field_agent)
    residual_scale_nm: float = 10_000.0  # the shipped field agent's
    reward_weights: RewardWeights = field(default_factory=lambda: FIELD_REWARD_WEIGHTS)
    bit: str = "karnopp"
    rgd_parameters: str | RgdParameters = "rgd_a"
    axial_top: str = "force"
    hook_speed_m_s: float | None = None
    hook_stiffness_n_m: float = math.inf

    is_field: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not self.distributed:
            raise ValueError(
                f"parameters = {shown(self.parameters)} is not a distributed string: allowed "
                f"{sorted(DISTRIBUTED_PRESETS)} or a DistributedStringParameters"
            )
        super().__post_init__()
        check_step_bound(self.string(), PLANT_DT_S)
        check_bit_keywords(
            self.bit, self.rgd_parameters, self.axial_top, self.hook_speed_m_s,
            self.hook_stiffness_n_m,
        )  # fmt: skip
        if self.bit == "rgd":  # a known bit law (checked above)
            stiffness = float(self.hook_stiffness_n_m)  # a real number > 0 (checked above)
            low, high = HOOK_STIFFNESS_RANGE_N_M
            require(
                "hook_stiffness_n_m", self.hook_stiffness_n_m,
                f"[{low:g}, {high:g}] N/m or inf (a rigid hook)",
                math.isinf(stiffness) or low <= stiffness <= high,
            )  # fmt: skip

    def bit_parameters(self) -> RgdParameters | None:
        """The RGD bit's parameters with ``bit="rgd"``, else ``None``."""
        return check_bit_keywords(
            self.bit, self.rgd_parameters, self.axial_top, self.hook_speed_m_s,
            self.hook_stiffness_n_m,
        )  # fmt: skip


def realism_keywords(level: str) -> dict[str, Any]:
    """The :data:`REALISM_KEYWORDS` of a named level of realism, for either env.

    * ``ideal``: the full state at every plant step and an ideal actuator (the defaults of
      ``DrillString-v0``);
    * ``field``: surface signals, mud-pulse telemetry and a rig's top drive (the defaults of
      ``DrillStringField-v0``, docs/specification.md section 18);
    * ``wired_pipe``: ``field`` with wired-drill-pipe telemetry (a value every 0.05 s, 0.02 s
      late);
    * ``surface_only``: ``field`` with no downhole data.

    Raises:
        ValueError: for an unknown level.
    """
    if level not in REALISM_LEVELS:
        raise ValueError(
            f"realism = {shown(level)} is not a known level: allowed {list(REALISM_LEVELS)}"
        )
    source = EnvConfig if level == "ideal" else FieldEnvConfig
    defaults = {f.name: f.default for f in fields(source) if f.name in REALISM_KEYWORDS}
    if level == "wired_pipe":
        defaults.update(telemetry_period_s=0.05, telemetry_delay_s=0.02)
    elif level == "surface_only":
        defaults["telemetry_period_s"] = None
    return {k: defaults[k] for k in REALISM_KEYWORDS}
