"""The realism study (:mod:`experiments.realism`, ``drill-gym realism``) and the maps' level
of realism (``experiments.stick_slip_map.compute_map(..., realism=...)``, ``--realism``)."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

from drill_env.control import controller_names
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.metrics import METRIC_KEYS
from drill_env.options import REALISM_KEYWORDS, EnvConfig, FieldEnvConfig, realism_keywords
from experiments import realism, stick_slip_map
from experiments.cli import main as cli_main
from experiments.evaluate import FIELD_HELD_OUT, HELD_OUT
from experiments.field import FIELD_ENV, PAPER_ENV, run_on
from experiments.plots import text_problems
from experiments.realism import (
    FACTORS,
    FIELD,
    IDEAL,
    SURFACE,
    break_points,
    broken,
    factor_settings,
    study_settings,
)


def changed(a: dict[str, Any], b: dict[str, Any]) -> set[str]:
    """The realism keywords whose values differ between ``a`` and ``b``."""
    return {k for k in REALISM_KEYWORDS if a[k] != b[k]}


# ---------------------------------------------------------------------------- settings
def test_the_levels_are_those_of_the_envs() -> None:
    assert realism_keywords("ideal") == IDEAL and realism_keywords("field") == FIELD
    # The surface setting is the field's channel without telemetry, the actuator ideal (and
    # no delay: the delay of telemetry that never comes is idle).
    surface_only = realism_keywords("surface_only")
    assert changed(SURFACE, IDEAL) == {
        "observation", "sensor_period_s", "torque_noise_std_nm", "telemetry_noise_std_rad_s",
    }  # fmt: skip
    assert changed(SURFACE, surface_only) == {
        "actuator_dead_time_s", "actuator_lag_s", "torque_rate_limit_nm_per_s",
        "telemetry_delay_s",
    }  # fmt: skip
    settings = study_settings()
    assert settings[0].factor == "ideal" and dict(settings[0].keywords) == IDEAL
    assert settings[-1].factor == "field" and dict(settings[-1].keywords) == FIELD


@pytest.mark.parametrize("factor", FACTORS, ids=lambda f: f.name)
def test_each_setting_moves_one_factor_from_its_base(factor: realism.Factor) -> None:
    settings = factor_settings(factor)
    assert [s.label for s in settings] == [step.label for step in factor.steps]
    assert dict(settings[0].keywords) == dict(factor.base)  # the first value is the base
    for setting in settings[1:]:
        moved = changed(dict(setting.keywords), dict(factor.base))
        assert moved and moved <= set(factor.keywords), (factor.name, setting.label, moved)
        if factor.name != "observation":
            assert len(factor.keywords) == 1 and len(moved) == 1
        EnvConfig(**setting.keywords)  # valid keywords of both envs
        FieldEnvConfig(**setting.keywords)
    if dict(factor.base) == IDEAL and factor.name != "observation":
        # The actuator factors: each value differs from the ideal level in exactly one keyword.
        assert all(len(changed(dict(s.keywords), IDEAL)) == 1 for s in settings[1:])
    if factor.name == "observation":
        # Surface signals alone, then the field's sampling and noise on top.
        assert changed(dict(settings[1].keywords), IDEAL) == {"observation"}
        assert dict(settings[-1].keywords) == SURFACE
    if factor.name.startswith("telemetry"):
        assert changed(dict(factor.base), SURFACE) <= {"telemetry_period_s"}


def test_equal_settings_share_their_runs() -> None:
    study = realism.RealismStudy(
        envs=(PAPER_ENV,),
        controllers=("stiff_pi",),
        settings=tuple(study_settings()),
        scenarios={PAPER_ENV: ("h14",)},
    )
    keys = [s.key for s in study.settings]
    # ideal = observation state = dead time 0 = lag 0 = no rate limit; surface = no telemetry;
    # a 5 s period without delay = delay 0 at 5 s; likewise at 0.05 s.
    assert len(study.keywords()) == len(keys) - 7
    assert keys.count("ideal") == 5 and len(study.items()) == len(study.keywords())
    with pytest.raises(ValueError, match="factor 'wind' is not known: allowed observation"):
        study_settings(["wind"])


# ------------------------------------------------------------------------- break points
def _row(
    factor: str, index: int, iae: float, sev: float, div: int = 0, c: str = "a"
) -> dict[str, Any]:
    return {
        "env": PAPER_ENV, "controller": c, "factor": factor, "index": index,
        "value": float(index), "label": f"v{index}", "iae": iae, "stick_slip_severity": sev,
        "stuck_fraction": 0.0, "diverged": div,
    }  # fmt: skip


def test_broken_is_the_documented_criterion() -> None:
    ideal = _row("ideal", 0, 100.0, 0.2)
    assert broken(_row("x", 1, 150.0, 0.5), ideal) == ""  # at the limits: holds
    assert broken(_row("x", 1, 151.0, 0.2), ideal) == "IAE x1.5"
    assert broken(_row("x", 1, 100.0, 0.51), ideal) == "severity 0.51"
    assert broken(_row("x", 1, 90.0, 0.1, div=1), ideal) == "diverged"
    # Severity counts only where the ideal run was not in stick-slip already.
    assert broken(_row("x", 1, 120.0, 1.4), _row("ideal", 0, 100.0, 0.9)) == ""
    assert broken(_row("x", 1, 90.0, 0.1, div=1), _row("ideal", 0, 100.0, 0.1, div=1)) == ""
    assert broken(_row("x", 1, math.nan, math.nan), ideal) == ""
    # The drive at a torque limit: more than 0.1 of the run above the ideal share.
    held = {**ideal, "torque_at_limit": 0.2}
    assert broken({**_row("x", 1, 100.0, 0.2), "torque_at_limit": 0.3}, held) == ""
    assert broken({**_row("x", 1, 100.0, 0.2), "torque_at_limit": 0.35}, held) == "at limit 0.35"


def test_break_points_on_a_synthetic_table() -> None:
    rows = [
        _row("ideal", 0, 100.0, 0.2),
        _row("ideal", 0, 50.0, 0.8, c="b"),
        # Factor "dead": a breaks on severity at v2 (and again at v3), b on IAE at v3.
        *[
            _row("dead", k, i, s)
            for k, (i, s) in enumerate([(100, 0.2), (120, 0.3), (140, 0.6), (300, 1.0)])
        ],
        *[
            _row("dead", k, i, s, c="b")
            for k, (i, s) in enumerate([(50, 0.8), (60, 1.5), (70, 2.0), (80, 0.8)])
        ],
        # Factor "rate": a holds everywhere, b diverges at v1.
        *[_row("rate", k, 110.0, 0.3) for k in range(3)],
        _row("rate", 1, 40.0, 0.8, div=1, c="b"),
        _row("rate", 0, 50.0, 0.8, c="b"),
        _row("field", 0, 160.0, 0.3),
        _row("field", 0, 60.0, 0.9, c="b"),
    ]
    got = {(r["controller"], r["factor"]): r for r in break_points(rows)}
    assert set(got) == {(c, f) for c in "ab" for f in ("dead", "rate", "field")}
    assert got[("a", "dead")]["label"] == "v2" and got[("a", "dead")]["reason"] == "severity 0.60"
    assert got[("a", "dead")]["iae_ideal"] == 100.0 and got[("a", "dead")]["severity"] == 0.6
    assert got[("b", "dead")]["label"] == "v3" and got[("b", "dead")]["reason"] == "IAE x1.6"
    assert got[("a", "rate")]["label"] == "-" and got[("a", "rate")]["value"] is None
    assert got[("b", "rate")]["label"] == "v1" and got[("b", "rate")]["reason"] == "diverged"
    assert got[("a", "field")]["reason"] == "IAE x1.6" and got[("b", "field")]["reason"] == ""
    with pytest.raises(ValueError, match="no ideal row of c on DrillString-v0"):
        break_points([_row("dead", 0, 1.0, 0.1, c="c")])


# ----------------------------------------------------------------------- loop margins
def test_loop_margins_of_a_pi_loop_on_an_inertia_are_the_closed_forms() -> None:
    inertia, kp = 930.0, 69_681.0
    ki = kp**2 / (4.0 * inertia)  # critically damped, as stiff_pi
    m = realism.loop_margins(kp, ki, lambda w: 1j * w * inertia)
    # |kp + ki / (j w)| = J w: J^2 w^4 - kp^2 w^2 - ki^2 = 0.
    w_c = math.sqrt((kp**2 + math.sqrt(kp**4 + 4.0 * inertia**2 * ki**2)) / (2.0 * inertia**2))
    pm = math.atan(kp * w_c / ki)
    assert m.crossover_rad_s == pytest.approx(w_c, rel=1e-3)
    assert m.phase_margin_deg == pytest.approx(math.degrees(pm), abs=0.05)
    assert m.dead_time_margin_s == pytest.approx(pm / w_c, rel=2e-3)
    # A lag adds -atan(w tau) to the phase -90 - atan(ki / (kp w)): zero margin at tau = kp / ki.
    assert m.lag_margin_s == pytest.approx(kp / ki, rel=1e-3)
    p = realism.loop_margins(kp, 0.0, lambda w: 1j * w * inertia)  # a P loop: 90 degrees
    assert p.phase_margin_deg == pytest.approx(90.0, abs=0.01) and math.isinf(p.lag_margin_s)
    assert p.dead_time_margin_s == pytest.approx(math.pi / 2 / (kp / inertia), rel=2e-3)


@pytest.mark.parametrize("parameters", ["zribi2024", "field_2500m"])
def test_chain_impedance_is_the_solved_chain(parameters: str) -> None:
    """The recursion against the chain's equations solved at each frequency: the nodes'
    speeds under a unit torque on the top drive, ``(j w M + D + (K / (j w) + C) L) v = e0``."""
    from drill_env.distributed import chain_from_parameters

    chain = chain_from_parameters(parameters)
    n = chain.node_inertia_kg_m2.size
    for w in (0.3, 2.0, 40.0):
        a = np.diag(1j * w * chain.node_inertia_kg_m2 + chain.node_damping_nm_s_rad)
        for e in range(n - 1):
            k = chain.element_stiffness_nm_rad[e] / (1j * w) + chain.element_damping_nm_s_rad[e]
            a[e, e] += k
            a[e + 1, e + 1] += k
            a[e, e + 1] -= k
            a[e + 1, e] -= k
        v = np.linalg.solve(a, np.eye(n)[0])
        assert realism.chain_impedance(chain, np.array(w)) == pytest.approx(1.0 / v[0], rel=1e-9)


def _torque_swing(env_id: str, **actuator: float) -> float:
    """Std of the applied torque of ``stiff_pi`` over the last 10 s of a noise-free 40 s run
    at a constant operating point (bit sliding), N m."""
    point = (1e5, 10.0) if env_id == FIELD_ENV else (97_347.0, 12.0)
    env = gym.make(
        env_id, randomize=False, base_controller="stiff_pi", episode_s=40.0, control_dt_s=1.0,
        noise_std_rad_s=0.0, wob_n=point[0], reference_speed_rad_s=point[1],
        **{**IDEAL, **actuator},
    )  # fmt: skip
    env.reset(seed=0)
    torques = []
    for _ in range(40):
        env.step(np.zeros(1, dtype=np.float32))
        torques.append(env.unwrapped.plant_samples().torque_nm)  # type: ignore[attr-defined]
    env.close()
    return float(np.std(np.concatenate(torques)[-10_000:]))


@pytest.mark.parametrize(
    ("env_id", "keyword", "margin", "wider"),
    [
        (PAPER_ENV, "actuator_dead_time_s", "dead_time_margin_s", 10.0),
        (PAPER_ENV, "actuator_lag_s", "lag_margin_s", 5.0),
        (FIELD_ENV, "actuator_dead_time_s", "dead_time_margin_s", 3.0),
    ],
)
def test_the_stiff_loop_oscillates_past_its_margin(
    env_id: str, keyword: str, margin: str, wider: float
) -> None:
    """The closed loop, simulated with the friction and the torque limits, against the linear
    margins of :func:`realism.loop_margins`: at 0.8 times the margin the torque holds as still
    as with an ideal drive, at 1.25 times it swings ``wider`` times wider. (The field string's
    lag margin marks no such onset: it is left out.)"""
    (row,) = realism.loop_numbers([env_id], ["stiff_pi"])
    quiet = _torque_swing(env_id)
    below = _torque_swing(env_id, **{keyword: round(0.8 * row[margin], 3)})  # whole plant steps
    above = _torque_swing(env_id, **{keyword: round(1.25 * row[margin], 3)})
    assert below < 1.2 * quiet, (below, quiet)
    assert above > wider * below, (above, below)


# ------------------------------------------------------------------------------- runs
@pytest.mark.parametrize(("env_id", "scenario"), [(PAPER_ENV, "h03"), (FIELD_ENV, "f01")])
def test_a_run_is_the_held_out_run_at_any_decision_period(env_id: str, scenario: str) -> None:
    """The study's runs (1 s decisions) score exactly like the held-out evaluation's runs
    (0.05 s decisions) with the same keywords: the field level with its sensor noise."""
    held_out = next(s for s in (*HELD_OUT, *FIELD_HELD_OUT) if s.id == scenario)
    got = realism.run_one(env_id, scenario, "proposed", FIELD, episode_s=4.0)
    kwargs = {**held_out.env_kwargs(), **FIELD, "episode_s": 4.0, "base_controller": "proposed"}
    trace = run_on(env_id, kwargs, ZeroAction(), held_out.seed)
    at_limit = got.pop("torque_at_limit")
    assert got == episode_metrics(trace)
    assert set(METRIC_KEYS) <= set(got)
    top = 50_800.0 if env_id == FIELD_ENV else 50_000.0  # the envs' torque limits: 0 to top
    u = trace.torque_nm
    assert at_limit == np.mean((u <= 0.001 * top) | (u >= 0.999 * top))


def test_the_tiny_study_runs_and_writes_its_files(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "realism"
    argv = [
        "realism", "--controllers", "stiff_pi", "z_torque", "--scenarios", "h14", "h01",
        "f03", "f07", "--duration-s", "3", "--factors", "rate_limit", "--out", str(out), "--no-progress",
    ]  # fmt: skip
    assert cli_main(argv) == 0
    printed = capsys.readouterr().out
    assert "## DrillStringField-v0: break points" in printed and "| rate_limit (N m/s) |" in printed
    names = {p.name for p in out.rglob("*") if p.is_file()}
    assert names == {
        "realism.csv", "realism.json", "runs.csv", "breakpoints.csv", "breakpoints.json",
        "summary.json", "realism_rate_limit.png",
    }  # fmt: skip
    means = json.loads((out / "realism.json").read_text())
    # 2 envs x (ideal + 6 rate limits + field) x 2 controllers, two scenarios each.
    assert len(means) == 2 * 8 * 2 and {r["runs"] for r in means} == {2}
    assert len((out / "runs.csv").read_text().splitlines()) == 1 + 2 * 8 * 2 * 2
    # The prone severity is that of the one prone scenario (h01, f07), the mean of both not.
    per_run = {
        (r["env"], r["factor"], r["index"], r["controller"], r["scenario"]): r
        for r in csv.DictReader((out / "runs.csv").open())
    }
    for r in means:
        key = (r["env"], r["factor"], str(r["index"]), r["controller"])
        prone, other = ("h01", "h14") if r["env"] == PAPER_ENV else ("f07", "f03")
        severities = [float(per_run[(*key, sc)]["stick_slip_severity"]) for sc in (prone, other)]
        assert r["prone_severity"] == pytest.approx(severities[0], rel=1e-12)
        assert r["stick_slip_severity"] == pytest.approx(np.mean(severities), rel=1e-12)
    breaks = json.loads((out / "breakpoints.json").read_text())
    assert {(b["env"], b["factor"]) for b in breaks} == {
        (e, f) for e in (PAPER_ENV, FIELD_ENV) for f in ("rate_limit", "field")
    }
    # The ideal row and "no rate limit" are the same run; a row is the plain rollout.
    by = {(r["env"], r["factor"], r["index"], r["controller"]): r for r in means}
    for env_id in (PAPER_ENV, FIELD_ENV):
        assert (
            by[(env_id, "ideal", 0, "z_torque")]["iae"]
            == by[(env_id, "rate_limit", 0, "z_torque")]["iae"]
        )
    held_out = next(s for s in FIELD_HELD_OUT if s.id == "f03")
    env = gym.make(
        FIELD_ENV,
        **{**held_out.env_kwargs(), **IDEAL, "torque_rate_limit_nm_per_s": 3e4, "episode_s": 3.0},
        base_controller="z_torque",
    )  # fmt: skip
    want = episode_metrics(rollout(env, ZeroAction(), held_out.seed))
    got = per_run[(FIELD_ENV, "rate_limit", "4", "z_torque", "f03")]["iae"]
    assert float(got) == pytest.approx(want["iae"], rel=1e-12)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["runs"] == 2 * 7 * 2 * 2 and summary["distinct_settings"] == 7
    assert summary["prone"] == {PAPER_ENV: ["h01"], FIELD_ENV: ["f07"]}


def test_every_figure_has_no_text_problems() -> None:
    rows = []
    for env_id in (PAPER_ENV, FIELD_ENV):
        for c, scale in (("csmc", 1.0), ("soft_speed", 0.5), ("z_torque", 2.0)):
            rows.append(
                {**_row("ideal", 0, 100.0 * scale, 0.2), "env": env_id, "controller": c, "runs": 6}
            )
            for factor in FACTORS:
                for k in range(len(factor.steps)):
                    rows.append({
                        **_row(factor.name, k, scale * (100.0 + 40 * k), 0.1 * k, div=int(k == 3)),
                        "env": env_id, "controller": c, "runs": 6,
                    })  # fmt: skip
    figures = dict(realism.realism_figures(rows, break_points(rows)))
    assert set(figures) == {f"realism_{f.name}.png" for f in FACTORS}
    for name, fig in figures.items():
        assert text_problems(fig) == [], name
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert labels[:3] == ["csmc", "soft_speed", "z_torque"], name
        assert "break point (ring, in the controller's colour)" in labels


def test_the_spec_is_the_study_the_options_ask_for() -> None:
    spec = realism.RealismSpec(
        envs=(PAPER_ENV, FIELD_ENV, PAPER_ENV), scenarios=("h14", "f03", "h14"), duration_s=3.0
    )
    study = spec.study(task_runs=2)
    assert study.envs == (PAPER_ENV, FIELD_ENV) and study.task_runs == 2
    assert dict(study.scenarios) == {PAPER_ENV: ("h14",), FIELD_ENV: ("f03",)}
    assert study.episode_s == 3.0 and study.controllers == tuple(controller_names())
    assert realism.RealismSpec().study().scenarios == realism.SCENARIOS
    with pytest.raises(ValueError, match="--duration-s: 2.5 is not a whole number"):
        realism.RealismSpec(duration_s=2.5)


BAD = [
    (["--env", "Mars-v0"], "argument --env: unknown env 'Mars-v0': allowed DrillString-v0"),
    (["--factors", "wind"], "argument --factors: unknown factor 'wind': allowed observation"),
    (["--controllers", "foo"], "argument --controllers: unknown controller 'foo': allowed csmc"),
    (["--scenarios", "h99"], "argument --scenarios: unknown scenario 'h99': allowed h01"),
    (
        ["--env", "DrillString-v0", "--scenarios", "f03"],
        "--scenarios: none of f03 is a held-out scenario of DrillString-v0",
    ),
    (["--duration-s", "2.5"], "--duration-s: 2.5 is not a whole number of seconds"),
    (["--episode", "2.5"], "--duration-s: 2.5 is not a whole number of seconds"),
    (["--duration-s", "-1"], "argument --duration-s: -1 is out of range: allowed (0, 10000] s"),
    (["--episode", "-1"], "argument --episode: -1 is out of range: allowed (0, 10000] s"),
    (["--seed", "x"], "argument --seed: 'x' is not an integer"),
]


@pytest.mark.parametrize(("argv", "message"), BAD)
def test_bad_options_are_one_line_and_exit_2(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = cli_main(["realism", *argv, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith("drill-gym realism: error: ") and message in err, err
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------ maps with a level
@pytest.fixture
def made_with(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """The keywords of every ``gym.make_vec`` a map calls (the env is still made)."""
    calls: list[dict[str, Any]] = []
    real = gym.make_vec

    def spy(env_id: str, **kwargs: Any) -> Any:
        calls.append({"env_id": env_id, **kwargs})
        return real(env_id, **kwargs)

    monkeypatch.setattr(stick_slip_map.gym, "make_vec", spy)
    return calls


def test_map_realism_names_the_level_only_when_it_is_not_the_default() -> None:
    assert stick_slip_map.map_realism(PAPER_ENV, None) is None
    assert stick_slip_map.map_realism(PAPER_ENV, "ideal") is None  # the env's own defaults
    assert stick_slip_map.map_realism(FIELD_ENV, "ideal") == "ideal"
    assert stick_slip_map.map_realism(PAPER_ENV, "field") == "field"
    with pytest.raises(ValueError, match="realism = 'lab' is not a known level: allowed ideal"):
        stick_slip_map.map_realism(PAPER_ENV, "lab")


def test_the_maps_level_sets_the_envs_keywords(made_with: list[dict[str, Any]]) -> None:
    cell = {"duration_s": 20.0, "window_s": 10.0, "progress": False}
    default = stick_slip_map.compute_map("proposed", [80e3], [4.0], **cell)
    ideal = stick_slip_map.compute_map("proposed", [80e3], [4.0], realism="ideal", **cell)
    field = stick_slip_map.compute_map("proposed", [80e3], [4.0], realism="field", **cell)
    # Today's map passes no keyword of the channel or the actuator: the env's defaults, which
    # are the ideal level, so realism="ideal" is the same env, map and file names.
    assert not set(REALISM_KEYWORDS) & set(made_with[0])
    assert made_with[1] == made_with[0]
    assert {f.name: f.default for f in dataclasses.fields(EnvConfig) if f.name in IDEAL} == IDEAL
    np.testing.assert_array_equal(default.severity, ideal.severity)
    np.testing.assert_array_equal(default.stuck_fraction, ideal.stuck_fraction)
    assert default.file_stem() == ideal.file_stem() == "stick_slip_map_proposed"
    assert default.realism is None and default.label == "proposed"
    assert {k: made_with[2][k] for k in REALISM_KEYWORDS} == FIELD
    assert field.file_stem() == "stick_slip_map_proposed_field"
    assert field.label == "proposed [field]"
    # The field level's cell is the env's plain run with those keywords.
    env = gym.make(
        PAPER_ENV, randomize=False, base_controller="proposed", wob_n=80e3,
        reference_speed_rad_s=4.0, noise_std_rad_s=0.0, episode_s=20.0, control_dt_s=1.0,
        **FIELD,
    )  # fmt: skip
    trace = rollout(env, ZeroAction(), seed=0)
    w = trace.bit_speed_rad_s[-10_000:]
    assert w.mean() > 1.0
    assert field.severity[0, 0] == pytest.approx((w.max() - w.min()) / (2 * w.mean()), rel=1e-12)
    assert field.stuck_fraction[0, 0] == pytest.approx(trace.bit_stuck[-10_000:].mean(), rel=1e-12)
    assert field.severity[0, 0] != default.severity[0, 0]
    with pytest.raises(ValueError, match="observation = 'state' is not that of realism = 'field'"):
        stick_slip_map.compute_map("proposed", [80e3], [4.0], realism="field",
                                   observation="state", env_id=FIELD_ENV, **cell)  # fmt: skip


def test_the_field_maps_level(made_with: list[dict[str, Any]]) -> None:
    cell = {"duration_s": 1.0, "window_s": 1.0, "progress": False, "env_id": FIELD_ENV}
    default = stick_slip_map.compute_map("stiff_pi", [100e3], [8.0], **cell)
    field = stick_slip_map.compute_map("stiff_pi", [100e3], [8.0], realism="field", **cell)
    # Today's field map: the env's own sensors and actuator, the state observed, no sensor
    # noise without speed noise.
    assert made_with[0]["observation"] == "state"
    assert made_with[0]["torque_noise_std_nm"] == made_with[0]["telemetry_noise_std_rad_s"] == 0
    assert not {"actuator_dead_time_s", "actuator_lag_s", "sensor_period_s"} & set(made_with[0])
    assert default.file_stem() == "stick_slip_map_stiff_pi_state_2500m"
    # The field level: every keyword of the level, its noise included.
    assert {k: made_with[1][k] for k in REALISM_KEYWORDS} == FIELD
    assert field.observation == "surface" and field.realism == "field"
    assert field.file_stem() == "stick_slip_map_stiff_pi_surface_2500m_field"


def test_map_command_with_a_level(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    grid = ["--wob-n", "1", "--wob-min", "1e5", "--wob-max", "1e5", "--speed-n", "1",
            "--speed-min", "8", "--speed-max", "8", "--duration", "1", "--window", "1",
            "--no-progress", "--no-plots"]  # fmt: skip
    argv = ["map", "--controllers", "stiff_pi", "csmc", "--realism", "surface_only", *grid]
    assert cli_main([*argv, "--out", str(tmp_path)]) == 0
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == [
        "stick_slip_map_csmc_surface_only.csv",
        "stick_slip_map_stiff_pi_surface_only.csv",
    ]
    capsys.readouterr()
    assert cli_main(["map", "--realism", "lab", *grid]) == 2
    assert "argument --realism: invalid choice: 'lab'" in capsys.readouterr().err


SWEEP_GRID = ["--controllers", "stiff_pi", "csmc", "--wob-n", "2", "--wob-min", "6e4",
              "--wob-max", "1e5", "--speed-n", "2", "--speed-min", "6", "--speed-max", "12",
              "--duration", "10", "--window", "5", "--no-progress", "--no-plots"]  # fmt: skip


def map_files(tmp_path: Path, name: str, env_id: str, *options: str) -> dict[str, str]:
    """The CSV files of ``drill-gym map`` with ``options`` on ``env_id`` (name: text)."""
    out = tmp_path / name
    assert cli_main(["map", "--env", env_id, *SWEEP_GRID, *options, "--out", str(out)]) == 0
    return {p.name: p.read_text() for p in sorted(out.glob("*.csv"))}


@pytest.mark.parametrize(("env_id", "level"), [(PAPER_ENV, "surface_only"), (FIELD_ENV, "ideal")])
def test_map_of_a_level_on_the_sweep_runner_is_the_serial_map(
    env_id: str, level: str, tmp_path: Path
) -> None:
    """The sweep runner (serially, a task per WOB row) makes the serial maps of a level, and
    they are not the default maps (the level reaches the cells)."""
    serial = map_files(tmp_path, "serial", env_id, "--realism", level)
    swept = map_files(tmp_path, "swept", env_id, "--realism", level, "--task-size", "1")
    assert len(serial) == 2 and all(name.endswith(f"_{level}.csv") for name in serial)
    assert swept == serial
    default = map_files(tmp_path, "default", env_id)
    observation = realism_keywords(level)["observation"]
    stem = "stick_slip_map_stiff_pi" + (f"_{observation}_2500m" if env_id == FIELD_ENV else "")
    assert default[f"{stem}.csv"] != serial[f"{stem}_{level}.csv"]


@pytest.mark.slow
def test_map_of_a_level_on_ray_is_the_serial_map(tmp_path: Path) -> None:
    serial = map_files(tmp_path, "serial", FIELD_ENV, "--realism", "field")
    assert map_files(tmp_path, "ray", FIELD_ENV, "--realism", "field", "--workers", "2") == serial
