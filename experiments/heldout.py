"""The held-out scenario sets: explicit lists of runs, none of them a training draw, each fixed
before any agent was trained on it.

``DrillString-v0`` (100 s from rest, 0.1 rad/s measurement noise, each run its own reset seed):

* :data:`HELD_OUT` (set ``heldout``, h01-h20): WOB 60-200 kN (eight with one step change at
  40, 50 or 60 s), V_ref 4-16 rad/s, the paper's four uncertainty conditions;
* :data:`CORNERS` (set ``corners``, c01-c16): at and beyond the edges of the training
  randomisation (``drill_env.scenarios.Randomization``: V_ref 4-16 rad/s, WOB 60-200 kN, each
  Delta 0-0.75, a WOB step at 50 s in half the episodes): the lowest speeds (3-5 rad/s), the
  highest WOB (up to 230 kN), the largest uncertainty (every Delta 0.75, and 1.0 beyond the
  range), and WOB steps up or down at any time from 5 s to 95 s.

``DrillStringField-v0``: :data:`FIELD_HELD_OUT` (set ``heldout``, f01-f16), the cases of
:data:`experiments.field.HELD_OUT_CASES`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

from drill_env.scenarios import UNCERTAINTY_CONDITIONS, Scenario, SpeedProfile, WobProfile
from drill_env.validation import shown
from experiments.field import (
    FIELD_ENV,
    HELD_OUT_CASES,
    HELD_OUT_EPISODE_S,
    PAPER_ENV,
    FieldCase,
    is_field,
)
from experiments.field import prone as field_prone

__all__ = [
    "CORNERS",
    "EPISODE_S",
    "FIELD_HELD_OUT",
    "FIELD_NOISE_STD_RAD_S",
    "HELD_OUT",
    "NOISE_STD_RAD_S",
    "SCENARIO_SETS",
    "HeldOutScenario",
    "held_out_scenario",
    "held_out_set",
]

EPISODE_S: Final = 100.0
"""Length of every held-out run of ``DrillString-v0``, s."""
NOISE_STD_RAD_S: Final = 0.1
"""Measurement noise on the speeds in the runs of ``DrillString-v0``, rad/s."""
PRONE_SPEED_RAD_S: Final = 6.0
"""A run of ``DrillString-v0`` is stick-slip prone at or below this reference speed, rad/s ..."""
PRONE_WOB_N: Final = 150e3
"""... or when its WOB reaches this value at some time, N."""


@dataclass(frozen=True)
class HeldOutScenario:
    """One held-out run: its id, its reset seed (which drives the noise), the name of its
    uncertainty condition and the scenario.

    Attributes:
        id: ``h01``, ``c01``, ... (``f01``, ... on the field string).
        seed: Reset seed of the run.
        condition: The paper's parametric-uncertainty condition (``nominal``,
            ``condition1``..``condition3``), ``d=(D1,D2,D3)`` for other Deltas, or the field
            string's friction and damping condition.
        scenario: The scenario (from rest).
        field: The field scenario it was made from (``None`` on the paper's string).
    """

    id: str
    seed: int
    condition: str
    scenario: Scenario
    field: FieldCase | None = None

    @property
    def reference_speed_rad_s(self) -> float:
        """The (constant) reference bit speed, rad/s."""
        return self.scenario.reference.value(0.0)

    @property
    def prone(self) -> bool:
        """Stick-slip prone: V_ref <= 6 rad/s, or a WOB of at least 150 kN at some time (on the
        field string: :func:`experiments.field.prone`)."""
        if self.field is not None:
            return field_prone(self.field)
        wob = self.scenario.wob
        wob_max = max(wob.initial_n, wob.final_n or 0.0)
        return self.reference_speed_rad_s <= PRONE_SPEED_RAD_S or wob_max >= PRONE_WOB_N

    def env_kwargs(self) -> dict[str, Any]:
        """The env keywords of the run (``DrillString-v0``'s, or ``DrillStringField-v0``'s)."""
        episode_s = EPISODE_S if self.field is None else HELD_OUT_EPISODE_S
        return {**self.scenario.keywords(), "episode_s": episode_s}

    def row(self) -> dict[str, Any]:
        """The scenario's columns of a result row."""
        if self.field is not None:
            return {
                "scenario": self.id,
                **self.field.columns(),
                "in_range": self.field.in_range(),
                "seed": self.seed,
                "prone": self.prone,
            }
        wob = self.scenario.wob
        return {
            "scenario": self.id,
            "reference_speed_rad_s": self.reference_speed_rad_s,
            "wob_n": wob.initial_n,
            "wob_step_time_s": wob.step_time_s,
            "wob_final_n": wob.final_n,
            "uncertainty": self.condition,
            "seed": self.seed,
            "prone": self.prone,
        }


def held_out_scenario(
    id: str,
    seed: int,
    reference_rad_s: float,
    wob_kn: float,
    uncertainty: str | tuple[float, float, float] = "nominal",
    step: tuple[float, float] | None = None,
) -> HeldOutScenario:
    """A held-out run of ``DrillString-v0``.

    Args:
        id: Its id.
        seed: Its reset seed.
        reference_rad_s: Constant reference bit speed, rad/s.
        wob_kn: WOB, kN.
        uncertainty: A condition name or ``(Delta1, Delta2, Delta3)``.
        step: ``(time_s, final_kn)``: one WOB step change.
    """
    if isinstance(uncertainty, str):
        condition, deltas = uncertainty, UNCERTAINTY_CONDITIONS[uncertainty]
    else:
        deltas = (float(uncertainty[0]), float(uncertainty[1]), float(uncertainty[2]))
        condition = "d=(" + ",".join(f"{d:g}" for d in deltas) + ")"
    wob = WobProfile(wob_kn * 1e3)
    if step is not None:
        wob = WobProfile(wob_kn * 1e3, step[0], step[1] * 1e3)
    scenario = Scenario(
        wob=wob,
        reference=SpeedProfile.constant(reference_rad_s),
        uncertainty=deltas,
        noise_std_rad_s=NOISE_STD_RAD_S,
    )
    return HeldOutScenario(id, seed, condition, scenario)


def _h(k: int, *args: Any) -> HeldOutScenario:
    return held_out_scenario(f"h{k:02d}", 9_000 + k, *args)


HELD_OUT: Final[tuple[HeldOutScenario, ...]] = (
    _h(1, 4.0, 60.0, "nominal"),
    _h(2, 4.0, 120.0, "condition1", (50.0, 180.0)),
    _h(3, 5.0, 90.0, "condition2"),
    _h(4, 5.0, 160.0, "condition3", (60.0, 100.0)),
    _h(5, 6.0, 200.0, "nominal"),
    _h(6, 6.0, 70.0, "condition2", (40.0, 150.0)),
    _h(7, 7.0, 130.0, "condition1"),
    _h(8, 8.0, 100.0, "nominal", (50.0, 190.0)),
    _h(9, 8.0, 175.0, "condition3"),
    _h(10, 9.0, 65.0, "condition1"),
    _h(11, 10.0, 110.0, "condition2", (60.0, 70.0)),
    _h(12, 10.0, 185.0, "nominal"),
    _h(13, 11.0, 140.0, "condition3", (40.0, 200.0)),
    _h(14, 12.0, 97.347, "nominal"),
    _h(15, 12.0, 155.0, "condition2"),
    _h(16, 13.0, 80.0, "condition1", (50.0, 130.0)),
    _h(17, 14.0, 195.0, "condition1"),
    _h(18, 14.0, 60.0, "condition3"),
    _h(19, 15.0, 125.0, "nominal", (50.0, 165.0)),
    _h(20, 16.0, 170.0, "condition2"),
)
"""The main held-out set of ``DrillString-v0`` (module docstring)."""

_WORST: Final = (0.75, 0.75, 0.75)
_BEYOND: Final = (1.0, 1.0, 1.0)


def _c(k: int, *args: Any) -> HeldOutScenario:
    return held_out_scenario(f"c{k:02d}", 9_100 + k, *args)


CORNERS: Final[tuple[HeldOutScenario, ...]] = (
    _c(1, 3.0, 60.0, _WORST),
    _c(2, 3.0, 200.0),
    _c(3, 4.0, 220.0, _WORST),
    _c(4, 4.0, 200.0, "nominal", (10.0, 120.0)),
    _c(5, 5.0, 80.0, (0.75, 0.0, 0.75), (20.0, 210.0)),
    _c(6, 16.0, 220.0, _WORST),
    _c(7, 18.0, 200.0),
    _c(8, 6.0, 150.0, "condition2", (85.0, 230.0)),
    _c(9, 8.0, 230.0),
    _c(10, 10.0, 210.0, _BEYOND),
    _c(11, 12.0, 100.0, (0.75, 0.75, 0.0), (5.0, 220.0)),
    _c(12, 3.5, 180.0, "condition1", (30.0, 60.0)),
    _c(13, 14.0, 60.0, "nominal", (95.0, 230.0)),
    _c(14, 4.5, 140.0, (0.0, 0.75, 0.75)),
    _c(15, 5.0, 200.0, _BEYOND),
    _c(16, 7.0, 230.0, _WORST, (75.0, 150.0)),
)
"""The corner set of ``DrillString-v0``: the edges of the training randomisation and beyond
(module docstring)."""

FIELD_NOISE_STD_RAD_S: Final = 0.05
"""Noise of the measured speeds in the field's held-out runs, rad/s (the env's; the surface
torque and the telemetry carry the env's noise too)."""

FIELD_HELD_OUT: Final[tuple[HeldOutScenario, ...]] = tuple(
    HeldOutScenario(c.id, c.seed, c.condition.name, c.scenario(FIELD_NOISE_STD_RAD_S), c)
    for c in HELD_OUT_CASES
)
"""The held-out scenarios of ``DrillStringField-v0`` (:data:`experiments.field.HELD_OUT_CASES`:
16 fixed scenarios, 8 within the env's randomisation ranges, 8 outside them), the controllers
knowing the nominal string."""

SCENARIO_SETS: Final[dict[str, dict[str, tuple[HeldOutScenario, ...]]]] = {
    PAPER_ENV: {"heldout": HELD_OUT, "corners": CORNERS},
    FIELD_ENV: {"heldout": FIELD_HELD_OUT},
}
"""The held-out sets of each env, by name (the first is the default)."""


def held_out_set(env_id: str, name: str = "heldout") -> tuple[HeldOutScenario, ...]:
    """The held-out set ``name`` of ``env_id``.

    Raises:
        ValueError: for a set the env does not have.
    """
    sets = SCENARIO_SETS[FIELD_ENV if is_field(env_id) else PAPER_ENV]
    if name not in sets:
        raise ValueError(
            f"scenario set = {shown(name)} is not a held-out set of {env_id}: allowed {list(sets)}"
        )
    return sets[name]
