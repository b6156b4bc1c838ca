"""The held-out evaluation (:mod:`experiments.evaluate`): its scenario set and its summary."""

from __future__ import annotations

from typing import Any

import pytest

from experiments.evaluate import HELD_OUT, goal_report, summarize


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


def _row(label: str, scenario: str, iae: float, rmsd: float, sev: float, prone: bool,
         chattering: float = 1.0) -> dict[str, Any]:  # fmt: skip
    metrics = {k: 1.0 for k in ("ise", "rmse", "overshoot_pct", "stuck_fraction")}
    return {
        "scenario": scenario, "controller": label, "prone": prone, "iae": iae, "rmsd_nm": rmsd,
        "stick_slip_severity": sev, "settling_time_s": None, "diverged": False,
        "chattering_nm_per_s": chattering, **metrics,
    }  # fmt: skip


def test_summary_goal_check() -> None:
    """The goal: the lowest mean IAE and prone severity of all, RMSD within 1 % and chattering
    no higher than the base's, and no scenario more than 5 % worse than the base."""
    rows = [_row("proposed", "a", 100, 10, 1.0, True), _row("agent", "a", 60, 10.1, 0.5, True)]
    rows += [_row("proposed", "b", 100, 10, 0.0, False), _row("agent", "b", 80, 10.1, 0.9, False)]
    rows += [_row("loop", "a", 75, 12, 0.6, True), _row("loop", "b", 75, 12, 0.1, False)]
    goal = summarize(rows, agents=["agent"])["goal"]["agent"]
    assert goal["iae_ratio"] == pytest.approx(0.7) and goal["rmsd_ratio"] == pytest.approx(1.01)
    assert goal["worst_iae_ratio"] == pytest.approx(0.8) and goal["best_engineered_iae"] == 75
    assert goal["met"] and goal["missed"] == []
    # a better engineered loop, more chattering, one scenario 10 % worse than the base
    rows += [_row("better", "a", 60, 9, 0.2, True), _row("better", "b", 60, 9, 0.1, False)]
    rows[1] = _row("agent", "a", 110, 10.1, 0.5, True, chattering=1.5)
    goal = summarize(rows, agents=["agent"])["goal"]["agent"]
    assert goal["worst_iae_ratio"] == pytest.approx(1.1) and not goal["met"]
    assert goal["missed"] == [
        "IAE below every engineered controller's",
        "prone severity below every engineered controller's",
        "chattering no higher than the base's",
        "IAE at most 1.05 x the base's in every scenario",
    ]


def test_goal_report_names_each_criterion_and_its_numbers() -> None:
    rows = [_row("proposed", "a", 100, 10, 1.0, True), _row("agent", "a", 60, 10.1, 0.5, True)]
    rows += [_row("proposed", "b", 100, 10, 0.0, False), _row("agent", "b", 80, 10.1, 0.9, False)]
    rows += [_row("loop", "a", 75, 12, 0.6, True), _row("loop", "b", 75, 12, 0.1, False)]
    rows += [_row("better", "a", 90, 9, 0.2, True), _row("better", "b", 90, 9, 0.1, False)]
    rows[1] = _row("agent", "a", 60, 10.1, 0.5, True, chattering=1.5)
    summary = summarize(rows, agents=["agent"])
    text = goal_report(summary, ["agent"], {"agent": "residual torque on proposed"})
    lines = text.splitlines()
    assert lines[0].startswith("Goal check. A learned agent's goal is to be the best controller")
    assert lines[1:] == [
        "agent, residual torque on proposed: 3 of 5 criteria hold, goal not met",
        "  holds   mean IAE 70.0 rad against 75.0 of the best engineered controller (loop)",
        "  misses  prone severity 0.500 against 0.200 (better)",
        "  holds   RMSD +1.0 % of proposed's (allowed up to +1 %)",
        "  misses  chattering +25.0 % of proposed's (allowed up to +0 %)",
        "  holds   worst scenario IAE 0.80 x proposed's (allowed up to 1.05 x)",
    ]
    assert len(summary["goal"]["agent"]["missed"]) == 2


def test_corner_set_lies_at_or_beyond_the_edges_of_the_training_randomisation() -> None:
    """Every corner run sits at an edge of the training distribution (or beyond it) in at least
    one dimension, and no seed is shared with the main set or the validation scenarios."""
    from drill_env.scenarios import Randomization
    from experiments.heldout import CORNERS, held_out_set

    train = Randomization()
    lo_v, hi_v = train.reference_range_rad_s
    _, hi_w = train.wob_range_n
    _, hi_d = train.delta_range
    step_s = train.wob_step_time_fraction[0] * 100.0
    assert len({s.id for s in CORNERS}) == len(CORNERS) == 16
    seeds = {s.seed for s in CORNERS}
    assert not seeds & {s.seed for s in HELD_OUT} and all(s < 20_000 for s in seeds)
    for s in CORNERS:
        wob = s.scenario.wob
        edges = [
            s.reference_speed_rad_s < lo_v or s.reference_speed_rad_s > hi_v,
            max(wob.initial_n, wob.final_n or 0.0) > hi_w,
            max(s.scenario.uncertainty) >= hi_d,
            wob.step_time_s is not None and wob.step_time_s != step_s,
        ]
        assert any(edges), s.id
    assert held_out_set("DrillString-v0", "corners") is CORNERS
    with pytest.raises(ValueError, match="'corners' is not a held-out set of DrillStringField-v0"):
        held_out_set("DrillStringField-v0", "corners")


def test_evaluate_command_on_the_corner_set(
    tmp_path: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    from experiments.evaluate import main

    argv = ["--scenario-set", "corners", "--scenarios", "c01", "c12", "--controllers",
            "proposed", "--no-plots", "--no-progress", "--out", str(tmp_path)]  # fmt: skip
    assert main(argv) == 0
    rows = json.loads((tmp_path / "heldout.json").read_text())
    assert {r["scenario"] for r in rows} == {"c01", "c12"}
    assert {r["uncertainty"] for r in rows} == {"d=(0.75,0.75,0.75)", "condition1"}
    with pytest.raises(SystemExit) as err:
        main(["--scenario-set", "corners", "--scenarios", "h01", "--out", str(tmp_path)])
    assert err.value.code == 2
    assert (
        "argument --scenarios: h01 is not a scenario of the corners set" in capsys.readouterr().err
    )
    with pytest.raises(SystemExit) as err:
        main(["--env", "DrillStringField-v0", "--scenario-set", "corners"])
    assert err.value.code == 2
    assert "--scenario-set: corners is not a held-out set of DrillStringField-v0" in (
        capsys.readouterr().err
    )


def test_models_as_arguments_or_as_an_option() -> None:
    from experiments.evaluate import EvaluateSpec, _parser

    parser = _parser()
    for argv in (["a", "b"], ["--models", "a", "b"], ["a", "--models", "b"]):
        args = parser.parse_args(argv)
        assert sorted([*args.model_folders, *args.models]) == ["a", "b"]
    assert EvaluateSpec().output.parts[-2:] == ("results", "evaluate")
    assert EvaluateSpec(scenario_set="corners").output.name == "evaluate_corners"
