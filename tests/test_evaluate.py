"""The held-out evaluation (:mod:`experiments.evaluate`): its scenario set and its summary."""

from __future__ import annotations

from typing import Any

import pytest

from experiments.evaluate import HELD_OUT, summarize


def test_held_out_set_covers_the_training_ranges() -> None:
    """20 distinct scenarios over V_ref 4-16 rad/s, WOB 60-200 kN, all four uncertainty
    conditions, eight WOB steps, 14 stick-slip prone."""
    ids = [s.id for s in HELD_OUT]
    assert len(ids) == len(set(ids)) == 20
    refs = [s.reference_speed_rad_s for s in HELD_OUT]
    wobs = [w for s in HELD_OUT for w in (s.scenario.wob.initial_n, s.scenario.wob.final_n) if w]
    assert min(refs) == 4.0 and max(refs) == 16.0
    assert min(wobs) == 60e3 and max(wobs) == 200e3
    assert {s.condition for s in HELD_OUT} == {
        "nominal",
        "condition1",
        "condition2",
        "condition3",
    }
    assert sum(s.scenario.wob.final_n is not None for s in HELD_OUT) == 8
    assert sum(s.prone for s in HELD_OUT) == 14


def test_summary_goal_check() -> None:
    def row(label: str, iae: float, rmsd: float, sev: float, prone: bool) -> dict[str, Any]:
        metrics = {
            k: 1.0
            for k in ("ise", "rmse", "overshoot_pct", "chattering_nm_per_s", "stuck_fraction")
        }
        return {
            "controller": label, "prone": prone, "iae": iae, "rmsd_nm": rmsd,
            "stick_slip_severity": sev, "settling_time_s": None, "diverged": False, **metrics,
        }  # fmt: skip

    rows = [row("proposed", 100, 10, 1.0, True), row("agent", 60, 10, 0.5, True)]
    rows += [row("proposed", 100, 10, 0.0, False), row("agent", 80, 10, 0.9, False)]
    goal = summarize(rows)["goal"]["agent"]
    assert goal["iae_ratio"] == pytest.approx(0.7) and goal["met"]
