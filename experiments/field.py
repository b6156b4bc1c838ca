"""The environments the studies run on, and the field string's scenario sets as data.

``drill-gym compare``, ``map`` and ``evaluate`` take ``--env`` (:data:`ENV_IDS`): the paper's
4-DOF string (``DrillString-v0``, the default, whose scenarios are the paper's) or the
distributed field string (``DrillStringField-v0``). On the field string the uncertainty is not
the paper's parametric conditions of the 4-DOF plant but the bit-rock friction and the mud
damping (:class:`FieldCondition`); the geometry is known, so the controllers' model is the
nominal string at the scenario's depth (``controller_model="nominal"``) unless a study gives
them the exact one (``"exact"``).

Everything here is data and small pure helpers; the studies' code paths are the same for both
envs. Which observation each controller runs with on the field string
(:func:`observations_of`): the paper's sliding-mode controllers need the whole state (they are
run with ``observation="state"``: every node speed and twist measured), the speed loops run
with both the full state and the rig's surface signals.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

import gymnasium as gym

from baselines.registry import BUILT_IN, needs_full_state
from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    with_measured_depth,
)
from drill_env.evaluation import Policy, Trace, rollout
from drill_env.ids import ENV_ID, FIELD_ENV_ID
from drill_env.scenarios import RPM, FieldRandomization, Scenario, SpeedProfile, WobProfile
from drill_env.validation import shown

__all__ = [
    "COMPARE_CASES",
    "COMPARE_CONDITIONS",
    "COMPARE_DEPTHS_M",
    "COMPARE_POINTS",
    "CONTROLLER_MODELS",
    "ENV_IDS",
    "FIELD_CONDITIONS",
    "FIELD_ENV",
    "HELD_OUT_CASES",
    "HELD_OUT_CONDITIONS",
    "HELD_OUT_EPISODE_S",
    "HELD_OUT_FIGURES",
    "OBSERVATIONS",
    "PAPER_ENV",
    "STATE_ONLY",
    "FieldCase",
    "FieldCondition",
    "case_name",
    "compare_cases",
    "figure_cases",
    "file_label",
    "is_field",
    "observations_of",
    "prone",
    "run_label",
    "run_on",
]

PAPER_ENV: Final = ENV_ID
"""The paper's 4-DOF string (the studies' default)."""
FIELD_ENV: Final = FIELD_ENV_ID
"""The distributed field string with surface sensors, telemetry and a realistic actuator."""
ENV_IDS: Final = (PAPER_ENV, FIELD_ENV)
"""The envs the studies run on."""

OBSERVATIONS: Final = ("state", "surface")
"""The field env's observation modes a controller can run with."""
STATE_ONLY: Final = tuple(name for name in BUILT_IN if needs_full_state(name))
"""Controllers that need the whole measured state (the paper's sliding-mode controllers:
their law is written on the 4-DOF state, read at the field string's probe nodes)."""
CONTROLLER_MODELS: Final = ("nominal", "exact")
"""What the controllers know of a field string: the nominal friction and damping (the
geometry is known on a rig), or the exact string."""


def is_field(env_id: str) -> bool:
    """Whether ``env_id`` is the field string's env.

    Raises:
        ValueError: for an id that is not in :data:`ENV_IDS`.
    """
    if env_id not in ENV_IDS:
        raise ValueError(f"env = {shown(env_id)} is not a known env: allowed {', '.join(ENV_IDS)}")
    return env_id == FIELD_ENV


def observations_of(controller: str, allowed: Sequence[str] = OBSERVATIONS) -> tuple[str, ...]:
    """The observation modes ``controller`` runs with on the field string: ``state`` for the
    paper's SMCs (:data:`STATE_ONLY`, whatever ``allowed`` says: they need the whole state),
    every mode of ``allowed`` for the others."""
    if controller in STATE_ONLY:
        return ("state",)
    return tuple(m for m in OBSERVATIONS if m in allowed)


def run_label(row: Mapping[str, Any]) -> str:
    """The label of a run in tables and figures: its controller, with the observation mode in
    brackets when the row has one (``stiff_pi (surface)``)."""
    observation = row.get("observation")
    return str(row["controller"]) if observation is None else f"{row['controller']} ({observation})"


def file_label(label: str) -> str:
    """``label`` as a file-name part: ``stiff_pi (surface)`` -> ``stiff_pi_surface``."""
    return "_".join(label.replace("(", " ").replace(")", " ").replace(":", " ").split())


def run_on(env_id: str, env_kwargs: Mapping[str, Any], policy: Policy, seed: int | None) -> Trace:
    """One episode of ``gym.make(env_id, **env_kwargs)`` under ``policy`` (made, rolled out and
    closed; ``drill_env.evaluation.run_episode`` for either env)."""
    env = gym.make(env_id, **env_kwargs)
    try:
        return rollout(env, policy, seed)
    finally:
        env.close()


# ---------------------------------------------------------------------- field conditions
@dataclass(frozen=True)
class FieldCondition:
    """The bit-rock friction and the mud damping of a field string: its uncertainty.

    Attributes:
        name: Short name.
        mu_a: Static friction coefficient.
        mu_0_ratio: ``mu_0 / mu_a``, in (0, 1].
        xi: Stribeck decline rate, s/rad.
        mud_damping_factor: Factor on the nominal mud damping rate.
    """

    name: str
    mu_a: float
    mu_0_ratio: float
    xi: float
    mud_damping_factor: float

    def apply(self, string: DistributedStringParameters) -> DistributedStringParameters:
        """``string`` with this friction and mud damping (its geometry kept)."""
        damping = dataclasses.replace(
            string.damping,
            mud_rate_per_s=string.damping.mud_rate_per_s * self.mud_damping_factor,
        )
        return dataclasses.replace(
            string, mu_a=self.mu_a, mu_0=self.mu_0_ratio * self.mu_a, xi=self.xi, damping=damping
        )

    def in_range(self, ranges: FieldRandomization) -> bool:
        """Whether every value lies in the env's randomisation ranges."""
        return all(
            lo <= v <= hi
            for v, (lo, hi) in (
                (self.mu_a, ranges.mu_a_range),
                (self.mu_0_ratio, ranges.mu_0_ratio_range),
                (self.xi, ranges.xi_range),
                (self.mud_damping_factor, ranges.mud_damping_factor_range),
            )
        )


_NOMINAL = DISTRIBUTED_PRESETS["field_2500m"]

FIELD_CONDITIONS: Final[dict[str, FieldCondition]] = {
    # The presets' own values: mu_a 0.8, mu_0 0.5, xi 0.5 s/rad, the Well B mud damping.
    "nominal": FieldCondition(
        "nominal", _NOMINAL.mu_a, _NOMINAL.mu_0 / _NOMINAL.mu_a, _NOMINAL.xi, 1.0
    ),
    # The corner of the env's randomisation ranges that favours stick-slip: the highest static
    # friction, the largest drop to sliding friction, the fastest drop, the least mud damping.
    "severe": FieldCondition("severe", 1.0, 0.5, 1.0, 0.5),
    # The opposite corner: low friction, a small and slow drop, twice the mud damping.
    "mild": FieldCondition("mild", 0.6, 0.8, 0.3, 2.0),
}
"""The named friction and damping conditions of the field studies."""


@dataclass(frozen=True)
class FieldCase:
    """One fixed scenario on a field string.

    Attributes:
        id: Short name (the row's ``scenario``).
        parameters: Distributed preset name.
        measured_depth_m: Depth of the bit along the hole, m (the drill pipe's length changes).
        wob: Weight-on-bit profile.
        reference_rpm: Constant reference bit speed, rpm.
        condition: Friction and mud damping of the true string.
        seed: Reset seed of the run (it drives the noise).
    """

    id: str
    parameters: str
    measured_depth_m: float
    wob: WobProfile
    reference_rpm: float
    condition: FieldCondition
    seed: int = 0

    @property
    def reference_speed_rad_s(self) -> float:
        """The reference bit speed, rad/s."""
        return self.reference_rpm * RPM

    def nominal_string(self) -> DistributedStringParameters:
        """The preset at this depth with its nominal friction and damping."""
        return with_measured_depth(self.parameters, self.measured_depth_m)

    def string(self) -> DistributedStringParameters:
        """The true string: the nominal one with this case's friction and damping."""
        return self.condition.apply(self.nominal_string())

    def scenario(self, noise_std_rad_s: float, controller_model: str = "nominal") -> Scenario:
        """The scenario of a run: the true string, and the controllers' model of it (the
        nominal string, or the exact one)."""
        if controller_model not in CONTROLLER_MODELS:
            raise ValueError(
                f"controller_model = {shown(controller_model)} is not valid: allowed "
                f"{', '.join(CONTROLLER_MODELS)}"
            )
        plant = self.string()
        return Scenario(
            wob=self.wob,
            reference=SpeedProfile.constant(self.reference_speed_rad_s),
            noise_std_rad_s=float(noise_std_rad_s),
            parameters=plant,
            model=self.nominal_string() if controller_model == "nominal" else plant,
        )

    def in_range(self, ranges: FieldRandomization | None = None) -> bool:
        """Whether the env's randomisation could draw this case (depth, WOB, speed, friction
        and damping within its ranges; the string is the env's default preset)."""
        r = ranges or FieldRandomization()
        wobs = [self.wob.initial_n] + ([self.wob.final_n] if self.wob.final_n else [])
        lo_v, hi_v = r.reference_range_rad_s
        return (
            self.parameters == "field_2500m"
            and r.measured_depth_range_m[0] <= self.measured_depth_m <= r.measured_depth_range_m[1]
            and all(r.wob_range_n[0] <= w <= r.wob_range_n[1] for w in wobs)
            and lo_v - 1e-9 <= self.reference_speed_rad_s <= hi_v + 1e-9
            and self.condition.in_range(r)
        )

    def columns(self) -> dict[str, Any]:
        """The scenario's columns of a result row."""
        return {
            "parameters": self.parameters,
            "measured_depth_m": self.measured_depth_m,
            "reference_speed_rad_s": self.reference_speed_rad_s,
            "wob_n": self.wob.initial_n,
            "wob_step_time_s": self.wob.step_time_s,
            "wob_final_n": self.wob.final_n,
            "condition": self.condition.name,
            "mu_a": self.condition.mu_a,
            "mu_0": self.condition.mu_0_ratio * self.condition.mu_a,
            "xi": self.condition.xi,
            "mud_damping_factor": self.condition.mud_damping_factor,
        }


COMPARE_DEPTHS_M: Final = (1_500.0, 2_500.0, 4_000.0)
"""Depths of the field comparison, m: a short, the preset's and a deep string."""
COMPARE_POINTS: Final = ((150.0, 60.0), (100.0, 120.0))
"""(WOB kN, reference rpm) of the field comparison: a stick-slip-prone point (high WOB, low
speed) and an ordinary drilling point."""
COMPARE_CONDITIONS: Final = ("nominal", "severe")
"""Friction and damping conditions of the field comparison."""


def case_name(depth_m: float, wob_kn: float, rpm: float, condition: str) -> str:
    """The name of a field comparison case: ``2.5km-150kN-60rpm-nominal``."""
    return f"{depth_m / 1e3:g}km-{wob_kn:g}kN-{rpm:g}rpm-{condition}"


def compare_cases(
    depths_m: Sequence[float] = COMPARE_DEPTHS_M,
    conditions: Sequence[str] = COMPARE_CONDITIONS,
    points: Sequence[tuple[float, float]] = COMPARE_POINTS,
    parameters: str = "field_2500m",
) -> tuple[FieldCase, ...]:
    """The field comparison's scenarios: ``parameters`` at every depth x operating point
    (WOB kN, rpm) x condition, conditions outermost, depths innermost.

    Raises:
        ValueError: for an unknown condition name.
    """
    for name in conditions:
        if name not in FIELD_CONDITIONS:
            raise ValueError(
                f"condition = {shown(name)} is not a field condition: allowed "
                f"{', '.join(FIELD_CONDITIONS)}"
            )
    return tuple(
        FieldCase(
            case_name(depth, wob, rpm, condition),
            parameters,
            float(depth),
            WobProfile(wob * 1e3),
            rpm,
            FIELD_CONDITIONS[condition],
        )
        for condition in conditions
        for wob, rpm in points
        for depth in depths_m
    )


COMPARE_CASES: Final[tuple[FieldCase, ...]] = compare_cases()
"""The default field comparison: ``field_2500m`` at 1,500 / 2,500 / 4,000 m x the two
operating points x the two conditions (12 cases)."""


def figure_cases(cases: Sequence[FieldCase]) -> tuple[list[str], str]:
    """The cases a comparison draws one controller at a time (the first operating point under
    the first condition, at every depth), and the one it draws every controller on (of those,
    the one at the middle depth)."""
    first = cases[0]
    chosen = [
        c
        for c in cases
        if c.condition == first.condition
        and c.wob == first.wob
        and c.reference_rpm == first.reference_rpm
    ]
    by_depth = sorted(chosen, key=lambda c: c.measured_depth_m)
    return [c.id for c in chosen], by_depth[(len(by_depth) - 1) // 2].id


# ------------------------------------------------------------------- held-out scenarios
HELD_OUT_CONDITIONS: Final[dict[str, FieldCondition]] = {
    **FIELD_CONDITIONS,
    "sticky": FieldCondition("sticky", 0.9, 0.6, 0.8, 0.7),
    "smooth": FieldCondition("smooth", 0.7, 0.75, 0.4, 1.5),
    "worn": FieldCondition("worn", 0.85, 0.55, 0.9, 0.8),
    # Outside every range of the randomisation: more friction, a larger and faster drop, less
    # mud damping than it ever draws.
    "outside": FieldCondition("outside", 1.1, 0.45, 1.2, 0.4),
}
"""The friction and damping conditions of the field's held-out scenarios."""

HELD_OUT_EPISODE_S: Final = 100.0
"""Length of every held-out run on the field string, s (at least eight of the longest
stick-slip cycles, about 12 s at 6 km)."""


def _held_out(
    k: int,
    parameters: str,
    depth_m: float,
    wob_kn: float,
    rpm: float,
    condition: str,
    step: tuple[float, float] | None = None,
) -> FieldCase:
    wob = WobProfile(wob_kn * 1e3)
    if step is not None:
        wob = WobProfile(wob_kn * 1e3, step[0], step[1] * 1e3)
    return FieldCase(
        f"f{k:02d}", parameters, depth_m, wob, rpm, HELD_OUT_CONDITIONS[condition], 9_100 + k
    )


HELD_OUT_CASES: Final[tuple[FieldCase, ...]] = (
    # Draws the env's randomisation could make (field_2500m, 1-5 km, 50-200 kN, 40-160 rpm,
    # friction and damping within their ranges).
    _held_out(1, "field_2500m", 1_200.0, 60.0, 50.0, "nominal"),
    _held_out(2, "field_2500m", 1_800.0, 120.0, 80.0, "sticky", (50.0, 180.0)),
    _held_out(3, "field_2500m", 2_500.0, 100.0, 100.0, "nominal"),
    _held_out(4, "field_2500m", 2_500.0, 160.0, 60.0, "severe"),
    _held_out(5, "field_2500m", 3_000.0, 80.0, 120.0, "smooth", (40.0, 140.0)),
    _held_out(6, "field_2500m", 3_500.0, 190.0, 150.0, "worn"),
    _held_out(7, "field_2500m", 4_500.0, 140.0, 70.0, "mild"),
    _held_out(8, "field_2500m", 2_000.0, 200.0, 140.0, "sticky", (60.0, 90.0)),
    # Another string: 5 in API pipe of deep_5000m (softer, lighter, lower impedance).
    _held_out(9, "deep_5000m", 3_800.0, 150.0, 90.0, "nominal"),
    _held_out(10, "deep_5000m", 5_000.0, 120.0, 60.0, "nominal"),
    _held_out(11, "deep_5000m", 5_500.0, 150.0, 80.0, "nominal"),
    _held_out(12, "deep_5000m", 6_000.0, 100.0, 100.0, "worn"),
    # field_2500m outside the ranges: deeper, shallower, heavier and slower, faster.
    _held_out(13, "field_2500m", 5_500.0, 150.0, 60.0, "nominal"),
    _held_out(14, "field_2500m", 800.0, 150.0, 40.0, "nominal"),
    _held_out(15, "field_2500m", 2_500.0, 220.0, 30.0, "outside"),
    _held_out(16, "field_2500m", 2_500.0, 80.0, 180.0, "nominal"),
)
"""The held-out scenarios of ``drill-gym evaluate --env DrillStringField-v0``: f01-f08 lie in
the env's randomisation ranges, f09-f12 are on the other string (``deep_5000m``, 3.8-6 km),
f13-f16 leave the ranges (5.5 km and 800 m of ``field_2500m``, 220 kN at 30 rpm with friction
outside every range, 180 rpm). Each has its own reset seed ``9100 + k``."""

HELD_OUT_FIGURES: Final = ("f04", "f10", "f13", "f15")
"""Field held-out scenarios drawn one by one."""


def prone(case: FieldCase) -> bool:
    """Stick-slip prone on the field string: a reference of at most 80 rpm, or a WOB of at
    least 150 kN at some time."""
    wob_max = max(case.wob.initial_n, case.wob.final_n or 0.0)
    return case.reference_rpm <= 80.0 or wob_max >= 150e3
