"""The held-out scenario sets of ``DrillString-v0``: explicit lists of runs, none of them a
training draw, fixed before any agent was trained on them.

* :data:`CORNERS` (``corners``): 16 runs at and beyond the edges of the training
  randomisation (``drill_env.scenarios.Randomization``: V_ref 4-16 rad/s, WOB 60-200 kN, each
  Delta 0-0.75, a WOB step at 50 s in half the episodes): the lowest speeds (3-5 rad/s),
  the highest WOB (up to 230 kN), the largest uncertainty (every Delta 0.75, and 1.0 beyond
  the range), and WOB steps up or down at any time from 5 s to 95 s.

Every run is 100 s from rest with 0.1 rad/s measurement noise and its own reset seed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

from drill_env.scenarios import UNCERTAINTY_CONDITIONS, Scenario, SpeedProfile, WobProfile

__all__ = [
    "CORNERS",
    "EPISODE_S",
    "NOISE_STD_RAD_S",
    "HeldOutScenario",
    "held_out_scenario",
]

EPISODE_S: Final = 100.0
"""Length of every held-out run, s."""
NOISE_STD_RAD_S: Final = 0.1
"""Measurement noise on the speeds, rad/s."""
PRONE_SPEED_RAD_S: Final = 6.0
"""A run is stick-slip prone at or below this reference bit speed, rad/s ..."""
PRONE_WOB_N: Final = 150e3
"""... or when its WOB reaches this value at some time, N."""


@dataclass(frozen=True)
class HeldOutScenario:
    """One held-out run: its id, its reset seed (which drives the noise), the label of its
    parametric uncertainty and the scenario.

    Attributes:
        id: ``h01``, ``c01``, ...
        seed: Reset seed of the run.
        condition: The paper's uncertainty condition (``nominal``, ``condition1`` ..
            ``condition3``) or ``d=(D1,D2,D3)`` for other Deltas.
        scenario: The scenario (``NOISE_STD_RAD_S`` noise, from rest).
    """

    id: str
    seed: int
    condition: str
    scenario: Scenario

    @property
    def reference_speed_rad_s(self) -> float:
        """The (constant) reference bit speed, rad/s."""
        return self.scenario.reference.value(0.0)

    @property
    def prone(self) -> bool:
        """Stick-slip prone: V_ref <= 6 rad/s, or a WOB of at least 150 kN at some time."""
        wob = self.scenario.wob
        wob_max = max(wob.initial_n, wob.final_n or 0.0)
        return self.reference_speed_rad_s <= PRONE_SPEED_RAD_S or wob_max >= PRONE_WOB_N

    def env_kwargs(self) -> dict[str, Any]:
        """The ``DrillString-v0`` keywords of the run."""
        return {**self.scenario.keywords(), "episode_s": EPISODE_S}

    def row(self) -> dict[str, Any]:
        """The scenario's columns of a result row."""
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
    """A held-out run.

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
        deltas = tuple(float(d) for d in uncertainty)  # type: ignore[assignment]
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


_WORST: Final = (0.75, 0.75, 0.75)
_BEYOND: Final = (1.0, 1.0, 1.0)

CORNERS: Final[tuple[HeldOutScenario, ...]] = (
    held_out_scenario("c01", 9_101, 3.0, 60.0, _WORST),
    held_out_scenario("c02", 9_102, 3.0, 200.0),
    held_out_scenario("c03", 9_103, 4.0, 220.0, _WORST),
    held_out_scenario("c04", 9_104, 4.0, 200.0, "nominal", (10.0, 120.0)),
    held_out_scenario("c05", 9_105, 5.0, 80.0, (0.75, 0.0, 0.75), (20.0, 210.0)),
    held_out_scenario("c06", 9_106, 16.0, 220.0, _WORST),
    held_out_scenario("c07", 9_107, 18.0, 200.0),
    held_out_scenario("c08", 9_108, 6.0, 150.0, "condition2", (85.0, 230.0)),
    held_out_scenario("c09", 9_109, 8.0, 230.0),
    held_out_scenario("c10", 9_110, 10.0, 210.0, _BEYOND),
    held_out_scenario("c11", 9_111, 12.0, 100.0, (0.75, 0.75, 0.0), (5.0, 220.0)),
    held_out_scenario("c12", 9_112, 3.5, 180.0, "condition1", (30.0, 60.0)),
    held_out_scenario("c13", 9_113, 14.0, 60.0, "nominal", (95.0, 230.0)),
    held_out_scenario("c14", 9_114, 4.5, 140.0, (0.0, 0.75, 0.75)),
    held_out_scenario("c15", 9_115, 5.0, 200.0, _BEYOND),
    held_out_scenario("c16", 9_116, 7.0, 230.0, _WORST, (75.0, 150.0)),
)
"""The corner set: the edges of the training randomisation and beyond (module docstring)."""
