"""The studies on ``DrillStringField-v0`` (``drill-gym compare``, ``map``, ``evaluate``,
``waves`` with ``--env DrillStringField-v0``) at a tiny budget, the default env's outputs
unchanged, the node-state accessor of the field env and the space-time figure."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import drill_env  # noqa: F401  (registers the envs)
from drill_env.distributed import discretize, with_measured_depth
from drill_env.evaluation import ZeroAction, episode_metrics, rollout
from drill_env.metrics import METRIC_KEYS
from drill_env.modes import natural_frequencies_hz
from experiments import compare, evaluate, field, stick_slip_map, waves
from experiments.plots import text_problems
from experiments.spec_cli import spec_from_args
from experiments.sweep import Backend, run_sweep, spec_hash
from experiments.waves import space_time_figure, string_response_figure

FIELD = field.FIELD_ENV


# ------------------------------------------------------------------ the node-state accessor
def test_string_state_reads_every_node() -> None:
    env = gym.make(
        FIELD,
        randomize=False,
        base_controller="stiff_pi",
        measured_depth_m=1_500.0,
        sensor_period_s=0.001,
        noise_std_rad_s=0.0,
        torque_noise_std_nm=0.0,
        telemetry_noise_std_rad_s=0.0,
        control_dt_s=0.1,
    )
    with pytest.raises(RuntimeError, match="call reset"):
        env.unwrapped.string_state()  # type: ignore[attr-defined]
    env.reset(seed=0)
    chain = discretize(with_measured_depth("field_2500m", 1_500.0))
    for _ in range(30):
        _, _, _, _, info = env.step(np.zeros(1, dtype=np.float32))
    state = env.unwrapped.string_state()  # type: ignore[attr-defined]
    n = chain.n_nodes
    assert state.node_depth_m.shape == (n,) and state.speed_rad_s.shape == (n,)
    assert state.twist_rad.shape == (n - 1,) and state.torque_nm.shape == (n - 1,)
    np.testing.assert_array_equal(state.node_depth_m, chain.node_depth_m)
    assert state.node_depth_m[-1] == pytest.approx(1_500.0)
    # The compiled loop's own readings of the same instant (exact sensors, 1 ms sampling).
    assert state.speed_rad_s[0] == info["top_drive_speed_rad_s"]
    assert state.speed_rad_s[-1] == info["bit_speed_rad_s"]
    assert state.torque_nm[0] == pytest.approx(info["surface_torque_nm"], rel=1e-12, abs=1e-9)
    state.speed_rad_s[0] = 1e9  # a copy: the env is untouched
    assert env.unwrapped.string_state().speed_rad_s[0] == info["top_drive_speed_rad_s"]  # type: ignore[attr-defined]


# ---------------------------------------------------------------------------- data
def test_observations_of_each_controller() -> None:
    assert field.observations_of("proposed") == ("state",)
    assert field.observations_of("stiff_pi") == ("state", "surface")
    assert field.observations_of("csmc", ["surface"]) == ("state",)
    assert field.observations_of("z_torque", ["surface"]) == ("surface",)
    assert field.run_label({"controller": "z_torque", "observation": "surface"}) == (
        "z_torque (surface)"
    )
    assert field.run_label({"controller": "csmc"}) == "csmc"
    assert field.file_label("z_torque (surface)") == "z_torque_surface"
    with pytest.raises(ValueError, match="env = 'Nope-v0' is not a known env"):
        field.is_field("Nope-v0")


def test_field_cases_are_the_documented_grid() -> None:
    cases = field.compare_cases()
    assert len(cases) == 12 and cases[0].id == "1.5km-150kN-60rpm-nominal"
    chosen, focus = field.figure_cases(cases)
    assert chosen == [f"{d}km-150kN-60rpm-nominal" for d in ("1.5", "2.5", "4")]
    assert focus == "2.5km-150kN-60rpm-nominal"
    severe = next(c for c in cases if c.condition.name == "severe")
    plant, nominal = severe.string(), severe.nominal_string()
    assert (plant.mu_a, plant.mu_0, plant.xi) == (1.0, 0.5, 1.0)
    assert plant.damping.mud_rate_per_s == pytest.approx(0.5 * nominal.damping.mud_rate_per_s)
    assert severe.scenario(0.0).controller_model == nominal
    assert severe.scenario(0.0, "exact").controller_model == plant
    with pytest.raises(ValueError, match="condition = 'rough' is not a field condition"):
        field.compare_cases(conditions=["rough"])


def test_held_out_set_inside_and_outside_the_ranges() -> None:
    ids = [s.id for s in evaluate.FIELD_HELD_OUT]
    assert ids == [f"f{k:02d}" for k in range(1, 17)]
    inside = [s.id for s in evaluate.FIELD_HELD_OUT if s.field and s.field.in_range()]
    assert inside == [f"f{k:02d}" for k in range(1, 9)]
    deep = [s for s in evaluate.FIELD_HELD_OUT if s.field and s.field.parameters == "deep_5000m"]
    assert [s.field.measured_depth_m for s in deep if s.field] == [3800.0, 5000.0, 5500.0, 6000.0]


# --------------------------------------------------------------- the default env unchanged
def test_default_compare_row_is_the_plain_rollout() -> None:
    rows, _ = compare.run_comparison(
        ["csmc"], ["condition2"], [0.1], duration_s=2.0, keep_traces=False, progress=False
    )
    assert tuple(rows[0]) == compare.ROW_KEYS
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller="csmc",
        uncertainty="condition2",
        noise_std_rad_s=0.1,
        episode_s=2.0,
        control_dt_s=1.0,
        max_episode_steps=-1,
    )
    expected = episode_metrics(rollout(env, ZeroAction(), seed=0))
    for key in METRIC_KEYS:
        assert rows[0][key] == expected[key], key


def test_default_map_cell_is_the_plain_rollout() -> None:
    result = stick_slip_map.compute_map(
        "stiff_pi", [80e3], [4.0], duration_s=20.0, window_s=10.0, progress=False
    )
    assert result.file_stem() == "stick_slip_map_stiff_pi" and result.label == "stiff_pi"
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller="stiff_pi",
        wob_n=80e3,
        reference_speed_rad_s=4.0,
        noise_std_rad_s=0.0,
        episode_s=20.0,
        control_dt_s=1.0,
        max_episode_steps=-1,
    )
    trace = rollout(env, ZeroAction(), seed=0)
    w = trace.bit_speed_rad_s[-10_000:]
    assert w.mean() > 1.0 and trace.bit_stuck[-10_000:].any()  # a cell in stick-slip
    assert result.severity[0, 0] == pytest.approx((w.max() - w.min()) / (2 * w.mean()), rel=1e-12)
    assert result.stuck_fraction[0, 0] == pytest.approx(trace.bit_stuck[-10_000:].mean(), rel=1e-12)


# ------------------------------------------------------------------------- compare
def test_field_compare_rows_and_files(tmp_path: Path) -> None:
    argv = [
        "--env", FIELD, "--controllers", "stiff_pi", "proposed", "--depths", "1500",
        "--conditions", "nominal", "--noise", "0", "--duration", "2", "--no-agent",
        "--no-progress", "--out", str(tmp_path),
    ]  # fmt: skip
    assert compare.main(argv) == 0
    rows = json.loads((tmp_path / "compare.json").read_text())
    assert [(r["controller"], r["observation"], r["scenario"]) for r in rows] == [
        ("stiff_pi", "state", "1.5km-150kN-60rpm-nominal"),
        ("stiff_pi", "state", "1.5km-100kN-120rpm-nominal"),
        ("stiff_pi", "surface", "1.5km-150kN-60rpm-nominal"),
        ("stiff_pi", "surface", "1.5km-100kN-120rpm-nominal"),
        ("proposed", "state", "1.5km-150kN-60rpm-nominal"),
        ("proposed", "state", "1.5km-100kN-120rpm-nominal"),
    ]
    assert all(tuple(r) == compare.FIELD_ROW_KEYS for r in rows)
    assert rows[0]["measured_depth_m"] == 1500.0 and rows[0]["controller_model"] == "nominal"
    names = {p.name for p in (tmp_path / "figures").iterdir()}
    assert {"speed_torque_stiff_pi_surface.png", "noise_speed_torque.png"} <= names
    # the same numbers as one plain run of the field env
    case = field.compare_cases([1500.0], ["nominal"])[0]
    env = gym.make(
        FIELD,
        **case.scenario(0.0).keywords(),
        torque_noise_std_nm=0.0,
        telemetry_noise_std_rad_s=0.0,
        base_controller="proposed",
        observation="state",
        episode_s=2.0,
        control_dt_s=1.0,
    )
    expected = episode_metrics(rollout(env, ZeroAction(), seed=0))
    for key in METRIC_KEYS:
        assert rows[4][key] == expected[key], key


def test_field_compare_figures_have_no_text_problems() -> None:
    cases = compare.comparison_cases(FIELD, ["nominal"], depths_m=[1500.0, 2500.0])
    rows, traces = compare.run_comparison(
        ["z_torque", "csmc"], [], [0.0, 0.05], duration_s=2.0, env_id=FIELD, cases=cases,
        progress=False,
    )  # fmt: skip
    chosen, focus = field.figure_cases([c.field for c in cases if c.field is not None])
    figures = dict(compare.comparison_figures(rows, traces, chosen, focus))
    assert "speed_torque_z_torque_surface.png" in figures
    assert {name: text_problems(fig) for name, fig in figures.items() if text_problems(fig)} == {}


def test_field_compare_bad_condition() -> None:
    with pytest.raises(SystemExit) as exc:
        compare.main(["--env", FIELD, "--conditions", "condition1", "--no-agent"])
    assert exc.value.code == 2


# ----------------------------------------------------------------------------- map
def test_field_map_tiny_grid(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = [
        "--env", FIELD, "--controllers", "soft_speed", "csmc", "--observations", "surface",
        "--depths", "1500", "--wob-n", "2", "--speed-n", "1", "--duration", "2", "--window", "1",
        "--no-progress", "--out", str(tmp_path),
    ]  # fmt: skip
    assert stick_slip_map.main(argv) == 0
    assert "csmc (state) at 1500 m: 2 cells" in capsys.readouterr().out
    assert (tmp_path / "stick_slip_map_csmc_state_1500m.csv").is_file()
    assert (tmp_path / "stick_slip_maps_1500m.png").is_file()
    csv = tmp_path / "stick_slip_map_soft_speed_surface_1500m.csv"
    lines = csv.read_text().splitlines()
    assert lines[0] == ",".join(stick_slip_map.CSV_COLUMNS) and len(lines) == 3
    assert (tmp_path / "stick_slip_map_soft_speed_surface_1500m.png").is_file()


def test_field_map_defaults_and_errors() -> None:
    result = stick_slip_map.compute_map(
        "stiff_pi", [1e5], [6.0], duration_s=1.0, window_s=1.0, progress=False, env_id=FIELD
    )
    assert (result.observation, result.measured_depth_m) == ("state", 2500.0)
    assert result.file_stem() == "stick_slip_map_stiff_pi_state_2500m"
    with pytest.raises(ValueError, match="parameters = 'zribi2024' is not a known preset of"):
        stick_slip_map.compute_map("stiff_pi", [1e5], [6.0], duration_s=1.0, env_id=FIELD,
                                   parameters="zribi2024", window_s=1.0)  # fmt: skip
    with pytest.raises(ValueError, match="keywords of the field string"):
        stick_slip_map.compute_map("stiff_pi", [1e5], [6.0], duration_s=1.0, window_s=1.0,
                                   observation="surface")  # fmt: skip
    with pytest.raises(SystemExit):
        stick_slip_map.main(["--depths", "1500"])  # a field option on the paper's env


# ------------------------------------------------------------------------ evaluate
def test_field_evaluate_tiny() -> None:
    scenarios = [s for s in evaluate.FIELD_HELD_OUT if s.id in ("f01", "f09")]
    rows, traces = evaluate.evaluate(
        [], ["soft_speed", "proposed"], scenarios, keep_traces=["proposed (state)"], env_id=FIELD,
        observations=["surface"],
    )  # fmt: skip
    labels = [(r["scenario"], field.run_label(r)) for r in rows]
    assert labels == [
        ("f01", "soft_speed (surface)"),
        ("f01", "proposed (state)"),
        ("f09", "soft_speed (surface)"),
        ("f09", "proposed (state)"),
    ]
    # deep_5000m's pipe impedance (296 N m s/rad) is below the drive's own damping (425):
    # soft_speed runs there with kp = 0, its closest match.
    assert all(r["note"] == "" and r["iae"] > 0 for r in rows)
    assert set(traces) == {("f01", "proposed (state)"), ("f09", "proposed (state)")}
    summary = evaluate.summarize(rows, "proposed (state)")
    assert "runs" not in summary["means"]["soft_speed (surface)"]  # every scenario ran
    table = evaluate.per_scenario_table(rows, list(summary["means"]))
    assert "deep_5000m at 3,800 m" in table and "n/a" not in table


def test_field_evaluate_keeps_a_row_for_a_controller_that_cannot_be_made(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A controller whose tuning has no solution on a string gets a row without metrics that
    says why, and the tables show n/a for it."""
    run = evaluate.run_scenario

    def refuse_on_f09(scenario, policy, kwargs, env_id=evaluate.PAPER_ENV):  # type: ignore[no-untyped-def]
        if scenario.id == "f09" and kwargs.get("base_controller") == "soft_speed":
            raise ValueError("impedance_factor = 1.0 is out of range for this model")
        return run(scenario, policy, kwargs, env_id)

    monkeypatch.setattr(evaluate, "run_scenario", refuse_on_f09)
    scenarios = [s for s in evaluate.FIELD_HELD_OUT if s.id in ("f01", "f09")]
    rows, _ = evaluate.evaluate(
        [], ["soft_speed"], scenarios, env_id=FIELD, observations=["surface"]
    )
    mine = {r["scenario"]: r for r in rows if r["controller"] == "soft_speed"}
    assert mine["f09"]["iae"] is None and "impedance_factor" in mine["f09"]["note"]
    assert mine["f01"]["note"] == "" and mine["f01"]["iae"] > 0
    summary = evaluate.summarize(rows, "proposed (state)")
    assert summary["means"]["soft_speed (surface)"]["runs"] == 1.0
    assert summary["means"]["soft_speed (surface)"]["iae"] == mine["f01"]["iae"]
    assert "| n/a | n/a |" in evaluate.per_scenario_table(rows, list(summary["means"]))


def test_field_evaluate_command_leaves_out_models_of_the_other_env(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [
        "--env", FIELD, "--controllers", "stiff_pi", "--observations", "surface",
        "--scenarios", "f14", "--no-plots", "--no-progress", "--out", str(tmp_path),
    ]  # fmt: skip
    assert evaluate.main(argv) == 0
    out = capsys.readouterr()
    assert "is for DrillString-v0, left out" in out.err
    assert "| stiff_pi (surface) |" in out.out
    rows = json.loads((tmp_path / "heldout.json").read_text())
    shipped = [evaluate.load_policy(p) for p in evaluate.shipped_models()]
    # the shipped models made for the field string run there, beside their base controllers
    # (with no agent, the base is the proposed SMC)
    mine = [a for a in shipped if a.env_id == FIELD]
    observation = {a.name: a.env_kwargs.get("observation", "surface") for a in mine}
    expected = {"stiff_pi (surface)"} | {
        f"{name} ({observation[a.name]})"
        for a in mine
        for name in (a.name, a.env_kwargs["base_controller"])
    }
    if not mine:
        expected.add("proposed (state)")
    assert {field.run_label(r) for r in rows} == expected
    with pytest.raises(SystemExit):
        evaluate.main(["--env", FIELD, "--scenarios", "h01", "--out", str(tmp_path)])


# --------------------------------------------------------------------- waves, figures
@pytest.fixture(scope="module")
def recorded() -> Any:
    case = field.compare_cases([1500.0], ["nominal"])[0]
    return waves.record_run(case, "stiff_pi", "surface", duration_s=6.0, window_s=3.0)


def test_recorded_run(recorded: Any) -> None:
    history = recorded.history
    n = discretize(with_measured_depth("field_2500m", 1_500.0)).n_nodes
    assert history.time_s.shape == (300,) and history.speed_rad_s.shape == (300, n)
    assert history.time_s[0] == pytest.approx(waves.RECORD_DT_S)
    assert history.wave_speed_m_s == pytest.approx(np.sqrt(61e9 / 7850.0))
    assert recorded.label == "stiff_pi (surface)"
    assert 0.0 <= recorded.metrics["stuck_fraction"] <= 1.0


def test_space_time_figure(recorded: Any) -> None:
    history = recorded.history.window(3.0)
    fig = space_time_figure(history, "stiff_pi (surface), 1,500 m")
    assert text_problems(fig) == []
    speed, torque = (ax.collections[0] for ax in fig.axes[:2])
    assert speed.get_array().shape == history.speed_rad_s.T.shape
    assert torque.get_array().shape == history.torque_nm.T.shape
    # the release guides climb at the wave speed, from the bit to the surface
    for line in fig.axes[0].lines[1:]:
        (t0, t1), (d0, d1) = line.get_xdata(), line.get_ydata()
        assert (d0, d1) == (pytest.approx(1500.0), 0.0)
        assert (d0 - d1) / (t1 - t0) == pytest.approx(history.wave_speed_m_s)
    with pytest.raises(ValueError, match="fewer than two samples"):
        space_time_figure(history.window(1e9))


def test_string_response_figure(recorded: Any) -> None:
    fig = string_response_figure(
        {"stiff_pi (surface)": recorded.history, "again": recorded.history}, "two runs"
    )
    assert text_problems(fig) == []
    with pytest.raises(ValueError, match="histories is empty"):
        string_response_figure({})


def test_cycle_period_of_a_known_signal() -> None:
    t = np.arange(0, 60, 0.02)
    # a period-two cycle (slips of two sizes every 4 s) reads as the time between slips
    x = np.where(np.sin(2 * np.pi * t / 4.0) > 0, 1.0 + 0.3 * (np.sin(np.pi * t / 4.0) > 0), 0.0)
    assert waves.cycle_period_s(x, 0.02) == pytest.approx(4.0, abs=0.03)
    assert waves.cycle_period_s(np.ones(100), 0.02) is None


def test_string_table_has_the_modes_of_the_chain() -> None:
    rows = waves.string_table([2500.0])
    string = with_measured_depth("field_2500m", 2500.0)
    f1, f2 = natural_frequencies_hz(string, 2, top="clamped", bit="free")
    assert rows[0]["stick_slip_period_s"] == pytest.approx(1 / f1)
    assert rows[0]["second_mode_period_s"] == pytest.approx(1 / f2)
    assert rows[0]["round_trip_s"] == pytest.approx(2 * 2240.92 / np.sqrt(61e9 / 7850.0))
    assert rows[-1]["string"].startswith("zribi2024")


# ------------------------------------------------------------------- waves, command line
def test_waves_options_make_the_spec() -> None:
    spec = spec_from_args(
        waves.WavesSpec,
        waves._parser().parse_args(
            ["--controllers", "stiff_pi", "--depth", "3000", "--duration", "10", "--window", "5"]
        ),
    )
    assert spec == waves.WavesSpec(
        controllers=("stiff_pi",), depth_m=3000.0, duration_s=10.0, window_s=5.0
    )
    assert "--duration " not in waves._parser().format_help()  # the old name is hidden


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"duration_s": 10.0, "window_s": 20.0}, "--window: 20 is out of range"),
        ({"duration_s": 10.01, "window_s": 5.0}, "--duration-s: 10.01 is not a multiple of 0.02 s"),
        ({"depth_m": 100.0}, "--depth: 100 is out of range: allowed > BHA length"),
    ],
)
def test_waves_spec_refuses_what_cannot_run(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        waves.WavesSpec(**kwargs)  # type: ignore[arg-type]


# ------------------------------------------------------------------- waves, on the runner
def small_waves(**changes: Any) -> waves.WavesStudy:
    settings = {
        "controllers": ("stiff_pi", "proposed"),
        "observations": ("surface",),
        "depth_m": 1500.0,
        "depths_m": (1500.0,),
        "duration_s": 2.0,
        "window_s": 1.0,
        **changes,
    }
    return waves.WavesStudy(waves.WavesSpec(**settings))


def test_waves_items_are_the_recorded_runs() -> None:
    study = small_waves()
    assert study.items() == [
        "string/0",
        "string/1",
        "run/0/stiff_pi/surface",
        "run/1/proposed/state",
        "equivalent/0/proposed",
        "equivalent/1/proposed",
    ]
    assert small_waves(no_equivalent=True).items() == study.items()[:4]
    outcome = run_sweep(study, progress=False)
    case = waves._case(1500.0, 150e3, 60.0, "nominal")
    alone = waves.record_run(case, "proposed", "state", duration_s=2.0, window_s=1.0)
    assert outcome.records["run/1/proposed/state"] == {"label": alone.label, **alone.metrics}
    history = outcome.extras["waves/run/1/proposed/state"]["run/1/proposed/state"]
    np.testing.assert_array_equal(history.speed_rad_s, alone.history.speed_rad_s)


def test_waves_database_and_resume_write_the_serial_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--controllers", "stiff_pi", "proposed", "--observations", "surface"]
    argv += ["--depth", "1500", "--depths", "1500", "--duration-s", "2", "--window-s", "1"]
    argv += ["--no-progress"]
    results = str(tmp_path / "results.sqlite")
    assert waves.main([*argv, "--no-plots", "--out", str(tmp_path / "serial")]) == 0
    assert (
        waves.main([*argv, "--no-plots", "--out", str(tmp_path / "db"), "--results", results]) == 0
    )
    capsys.readouterr()
    assert (
        waves.main([*argv, "--out", str(tmp_path / "again"), "--results", results, "--resume"]) == 0
    )
    out = capsys.readouterr().out
    assert "0 tasks run" in out and "6 items read from the results database" in out
    assert "no figures: runs read from the results file" in out
    texts = {n: (tmp_path / n / "waves.json").read_text() for n in ("serial", "db", "again")}
    assert texts["serial"] == texts["db"] == texts["again"]


def test_waves_settings_hash_changes_with_every_setting_of_the_numbers() -> None:
    base = small_waves()
    changes: dict[str, Any] = {
        "controllers": ("stiff_pi",),
        "observations": ("state",),
        "depth_m": 1600.0,
        "depths_m": (1600.0,),
        "wob_n": 140e3,
        "rpm": 70.0,
        "condition": next(c for c in field.FIELD_CONDITIONS if c != "nominal"),
        "duration_s": 4.0,
        "window_s": 2.0,
        "seed": 1,
        "no_equivalent": True,
    }
    hashes = {spec_hash(base.name, base.spec())}
    for key, value in changes.items():
        study = small_waves(**{key: value})
        hashes.add(spec_hash(study.name, study.spec()))
    assert len(hashes) == 1 + len(changes)
    same = small_waves(out=Path("elsewhere"), no_plots=True, no_progress=True)
    assert spec_hash(same.name, same.spec()) == spec_hash(base.name, base.spec())


def test_waves_on_ray_equals_the_serial_run() -> None:
    pytest.importorskip("ray")
    study = small_waves(no_equivalent=True)
    serial = run_sweep(study, progress=False)
    swept = run_sweep(study, Backend(workers=2), progress=False, results_path=None)
    assert swept.records == serial.records
