"""The bit-side model against independent references, the calibration on synthetic logs with
known parameters, the plant file, the twin env, and the commands as a user types them."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import drill_env  # noqa: F401  (registers the envs)
from drill_env.bit_model import P_A0, P_AA, P_CV, P_J, P_K, P_TAU, P_XI, simulate_bit
from drill_env.calibrated_plant import (
    PLANT_FORMAT,
    CalibratedPlant,
    FittedParameter,
    env_keywords,
    load_plant,
    parameter_unit,
    plant_from_json,
)
from drill_env.measured_log import MeasuredLog, write_log_csv
from experiments.calibration_fit import MomentumBalance, calibrate, features
from experiments.synthetic_log import LAB_TRUTH, _lab_run, lab_log

ROOT = Path(__file__).resolve().parents[1]
TRUTH = np.array(
    [LAB_TRUTH.J_bit, LAB_TRUTH.k, LAB_TRUTH.c, LAB_TRUTH.a_static, LAB_TRUTH.a_sliding,
     LAB_TRUTH.xi, LAB_TRUTH.c_v, LAB_TRUTH.tau]
)  # fmt: skip


def _truth_nm() -> np.ndarray:
    """The rig's parameters with the friction in N m at its mean WOB (for runs without WOB)."""
    p = TRUTH.copy()
    p[P_AA] *= LAB_TRUTH.wob_n
    p[P_A0] *= LAB_TRUTH.wob_n
    return p


def _memory_rhs(t: float, y: np.ndarray, p: np.ndarray, top) -> list[float]:
    twist, w, v = y
    t_e = p[P_K] * twist + p[2] * (top(t) - w)
    friction = p[P_A0] + (p[P_AA] - p[P_A0]) * math.exp(-p[P_XI] * v) + p[P_CV] * w
    return [top(t) - w, (t_e - friction) / p[0], (abs(w) - v) / p[P_TAU]]


def test_slipping_bit_matches_a_tight_scipy_integration() -> None:
    """While the bit slips (it never stops here) the model is a smooth ODE."""
    p = _truth_nm()
    t = np.arange(0.0, 2.0, 1e-3)

    def top(time: float) -> float:
        return 6.0 + 1.0 * math.sin(2 * math.pi * 0.5 * time)

    twist0, speed0 = 1.3, 6.0  # 0.2 rad above the balance: a free oscillation on top
    ref = solve_ivp(
        _memory_rhs, (0, t[-1]), [twist0, speed0, speed0], t_eval=t, args=(p, top),
        rtol=1e-10, atol=1e-12, method="DOP853",
    )  # fmt: skip
    speed, torque, stuck = simulate_bit(
        t, np.array([top(x) for x in t]), p, "memory", twist0, speed0, substeps=100
    )
    assert not stuck.any()
    assert np.max(np.abs(speed - ref.y[1])) < 2e-3 * np.ptp(ref.y[1]) + 1e-3
    friction = p[P_A0] + (p[P_AA] - p[P_A0]) * np.exp(-p[P_XI] * ref.y[2]) + p[P_CV] * ref.y[1]
    assert np.max(np.abs(torque - friction)) < 2e-3


def test_break_away_time_is_closed_form() -> None:
    """From rest with no twist, a top drive at constant speed ``W`` winds the string until
    ``k W t = T_a`` (no damping): the bit breaks away at ``t = T_a / (k W)``."""
    p = _truth_nm()
    p[2] = 0.0
    t = np.arange(0.0, 2.0, 1e-3)
    speed, torque, stuck = simulate_bit(t, np.full(t.size, 2.0), p, "karnopp", 0.0, 0.0)
    expected = p[P_AA] / (p[P_K] * 2.0)
    first_slip = t[np.argmin(stuck)]
    assert first_slip == pytest.approx(expected, abs=1.5e-3)
    stuck_part = t < expected - 2e-3
    assert np.allclose(torque[stuck_part], p[P_K] * 2.0 * t[stuck_part], atol=1e-9)


def test_steady_sliding_torque_is_closed_form() -> None:
    """At a constant top speed ``V`` with damping the bit settles at ``V`` and the torque on
    bit at ``T_0 + (T_a - T_0) exp(-xi V) + c_v V``."""
    p = _truth_nm()
    p[2] = 0.5  # damped enough to settle within the run
    p[P_XI] = 0.05
    t = np.arange(0.0, 20.0, 1e-2)
    v = 8.0
    speed, torque, _ = simulate_bit(t, np.full(t.size, v), p, "memory", 0.0, v)
    expected = p[P_A0] + (p[P_AA] - p[P_A0]) * math.exp(-p[P_XI] * v) + p[P_CV] * v
    assert speed[-1] == pytest.approx(v, rel=1e-6)
    assert torque[-1] == pytest.approx(expected, rel=1e-6)


def test_stick_slip_matches_the_independent_rig_integration() -> None:
    """The lab rig's own fine-step integrator (top drive included) and the calibration's
    simulator driven by the rig's top-drive speed agree through stick-slip cycles."""
    rig = LAB_TRUTH
    values = (
        rig.J_top, rig.J_bit, rig.k, rig.c, rig.a_static, rig.a_sliding, rig.xi, rig.c_v,
        rig.tau, rig.kp, rig.ki, rig.reference_rad_s, rig.wob_n,
    )  # fmt: skip
    out = _lab_run(values, 5.0, 1e-3, 1e-6, 0.05, -1.0, -1.0)
    t = np.arange(out.shape[0]) * 1e-3
    speed, torque, stuck = simulate_bit(t, out[:, 0], TRUTH, "memory", 0.0, 0.0, out[:, 3])
    assert stuck.mean() > 0.2  # it does stick-slip
    assert np.sqrt(np.mean((speed - out[:, 1]) ** 2)) / np.std(out[:, 1]) < 0.03
    assert np.sqrt(np.mean((torque - out[:, 2]) ** 2)) / np.std(out[:, 2]) < 0.03


def test_the_momentum_balance_holds_for_the_rig_and_pins_inertia_and_stiffness() -> None:
    """The integrated momentum balance the fit adds to its residuals is the rig's physics:
    on the rig's noise-free stick-slip log it vanishes (to the sampling's trapezoid error) at
    the true inertia, stiffness and damping, whatever the friction, and grows when the
    inertia or the stiffness is 5 % off."""
    rig = LAB_TRUTH
    values = (
        rig.J_top, rig.J_bit, rig.k, rig.c, rig.a_static, rig.a_sliding, rig.xi, rig.c_v,
        rig.tau, rig.kp, rig.ki, rig.reference_rad_s, rig.wob_n,
    )  # fmt: skip
    out = _lab_run(values, 5.0, 1e-3, 1e-6, 0.05, -1.0, -1.0)
    t = np.arange(out.shape[0]) * 1e-3
    log = MeasuredLog(
        t,
        {"top_speed_rad_s": out[:, 0], "bit_speed_rad_s": out[:, 1], "bit_torque_nm": out[:, 2]},
        "rig",
    ).window(1.0, 5.0)
    balance = MomentumBalance.of(log)
    at_truth = float(np.sqrt(np.mean(balance.residuals(TRUTH) ** 2)))
    assert at_truth < 0.01
    for index in (0, P_K):
        off = TRUTH.copy()
        off[index] *= 1.05
        assert np.sqrt(np.mean(balance.residuals(off) ** 2)) > 5 * at_truth


def test_features_of_a_known_periodic_signal() -> None:
    t = np.arange(0.0, 8.0, 1e-3)
    phase = t % 0.8
    speed = np.where(phase < 0.3, 0.0, 6.0 * np.sin(np.pi * (phase - 0.3) / 0.5))
    torque = 2.0 + 0.5 * np.cos(2 * np.pi * t / 0.8)
    f = features(t, speed, torque, threshold=0.3)
    assert f["period_fft_s"] == pytest.approx(0.8, rel=0.01)
    assert f["period_cycles_s"] == pytest.approx(0.8, rel=0.01)
    assert f["bit_speed_p2p_rad_s"] == pytest.approx(6.0, rel=0.01)
    assert f["bit_torque_p2p_nm"] == pytest.approx(1.0, rel=0.01)
    assert f["bit_torque_mean_nm"] == pytest.approx(2.0, rel=0.01)
    stuck_expected = 0.3 / 0.8 + 2 * (0.5 / math.pi) * math.asin(0.05) / 0.8
    assert f["stuck_fraction"] == pytest.approx(stuck_expected, abs=0.01)


@pytest.fixture(scope="module")
def lab() -> MeasuredLog:
    return lab_log(seed=3, duration_s=12.0, defects=False)


@pytest.mark.parametrize(
    "family",
    ["karnopp", pytest.param("memory", marks=pytest.mark.slow)],
)
def test_identifiable_parameters_are_recovered(lab: MeasuredLog, family: str) -> None:
    """On a 4 s window of the rig's log with measurement noise the parameters that set the
    stick-slip cycle are within a few per cent of the truth, each with its uncertainty (the
    simpler Karnopp family too: its friction law differs from the rig's only while slipping)."""
    result = calibrate(lab, (2.0, 6.0), families=(family,))
    plant = result.plant
    string = 0.03 if family == "memory" else 0.05  # the rig's own law: tighter
    checks = [
        ("bit_inertia", LAB_TRUTH.J_bit, string),
        ("stiffness", LAB_TRUTH.k, string),
        ("static_friction", LAB_TRUTH.a_static, 0.05),
    ]
    if family == "memory":
        checks.append(("sliding_friction", LAB_TRUTH.a_sliding, 0.12))
    for name, truth, tolerance in checks:
        p = plant.parameters[name]
        assert p.identified, name
        assert p.value == pytest.approx(truth, rel=tolerance), name
        assert p.relative_std is not None and p.relative_std < 0.25
    assert plant.uses_wob
    assert plant.parameters["static_friction"].unit == "m"


def test_what_the_data_cannot_tell_apart_is_reported_not_fitted() -> None:
    """A bit that slides steadily (no stick-slip) tells the friction at one speed and little
    else: the calibration holds the rest, marks them not identified and says why."""
    rig = LAB_TRUTH
    values = (
        rig.J_top, rig.J_bit, rig.k, 0.3, rig.a_static, rig.a_sliding, 0.05, rig.c_v,
        rig.tau, rig.kp, rig.ki, 8.0, rig.wob_n,
    )  # fmt: skip
    out = _lab_run(values, 6.0, 1e-3, 1e-5, 0.0, -1.0, -1.0)
    rng = np.random.default_rng(0)
    t = np.arange(out.shape[0], dtype=np.float64) * 1e-3
    columns = {
        name: out[:, j] + rng.normal(0, sd, t.size)
        for j, (name, sd) in enumerate(
            (("top_speed_rad_s", 0.03), ("bit_speed_rad_s", 0.05), ("bit_torque_nm", 0.03))
        )
    }
    log = MeasuredLog(t, columns)
    try:
        result = calibrate(log, (5.0, 6.0), families=("stribeck_viscous",), use_wob=False)
    except ValueError as exc:  # nothing at all identified is also an honest answer
        assert "identifies no parameter" in str(exc)
        return
    held = [n for n, p in result.plant.parameters.items() if not p.identified]
    assert held, "a steady slide cannot identify every parameter"
    for name in held:
        p = result.plant.parameters[name]
        assert p.relative_std is None
        assert "not identifiable" in p.note


@pytest.fixture(scope="module")
def karnopp_plant(lab: MeasuredLog) -> CalibratedPlant:
    return calibrate(lab, (2.0, 5.0), families=("karnopp",)).plant


def test_plant_file_round_trip_and_schema(tmp_path: Path, karnopp_plant: CalibratedPlant) -> None:
    plant = karnopp_plant
    path = plant.save(tmp_path / "plant.json")
    back = load_plant(path)
    assert back.family == plant.family
    assert np.allclose(back.model_vector(), plant.model_vector())
    data = json.loads(path.read_text())
    assert data["format"] == PLANT_FORMAT
    assert data["parameters"]["stiffness"]["unit"] == "N m/rad"
    bad = dict(data, extra=1)
    with pytest.raises(ValueError, match=r"unknown field\(s\) \['extra'\]"):
        plant_from_json(bad)
    bad = json.loads(path.read_text())
    bad["parameters"]["stiffness"]["value"] = -1.0
    with pytest.raises(ValueError, match=r"parameters.stiffness.value = -1.0 is out of range"):
        plant_from_json(bad)
    bad = json.loads(path.read_text())
    del bad["parameters"]["bit_inertia"]
    with pytest.raises(ValueError, match=r"missing \['bit_inertia'\]"):
        plant_from_json(bad)
    bad = json.loads(path.read_text())
    bad["format"] = "pickle"
    with pytest.raises(ValueError, match=r"format = 'pickle'"):
        plant_from_json(bad)


def test_the_calibrated_plant_runs_in_the_env(karnopp_plant: CalibratedPlant) -> None:
    plant = karnopp_plant
    keywords = env_keywords(plant)
    assert keywords["max_torque_nm"] < 20  # a lab rig: a few N m
    assert keywords["reference_speed_rad_s"] == pytest.approx(3.0, rel=0.05)
    env = gym.make("DrillString-v0", episode_s=1.0, **keywords)
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        obs, _, terminated, _, info = env.step(np.zeros(env.action_space.shape, np.float32))
        assert np.all(np.isfinite(obs))
        assert not terminated
    env.close()


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-m", "experiments.cli", *args],
        capture_output=True, text=True, cwd=cwd, env=env, timeout=600,
    )  # fmt: skip


def test_calibrate_and_replay_as_a_user_types_them(tmp_path: Path) -> None:
    measured = lab_log(seed=1, duration_s=9.0, defects=False)
    measured.column("bit_speed_rad_s")[3500] += 30.0  # a spike at 3.5 s, in the fitted window
    log = write_log_csv(measured, tmp_path / "rig.csv")
    done = _cli("calibrate", str(log), "--window", "2:5", "--family", "karnopp", "--out",
                "cal", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    for name in ("plant.json", "report.md", "fit.png", "loop.png", "uncertainty.png"):
        assert (tmp_path / "cal" / name).is_file()
    report = (tmp_path / "cal" / "report.md").read_text()
    assert "| spike | bit_speed_rad_s | 3.5 to 3.5 |" in report
    assert "| gap |" not in report
    load_plant(tmp_path / "cal" / "plant.json")
    done = _cli("replay", "cal/plant.json", str(log), "--window", "5:9", "--out", "rep",
                cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    header = (tmp_path / "rep" / "replay.csv").read_text().splitlines()[0]
    assert header.startswith("time_s,bit_speed_rad_s,bit_torque_nm,")
    table = (tmp_path / "rep" / "features.csv").read_text()
    for key in ("period_fft_s", "period_cycles_s", "bit_speed_p2p_rad_s", "bit_torque_p2p_nm",
                "bit_torque_mean_nm", "stuck_fraction", "normalised_rms_speed_error"):  # fmt: skip
        assert key in table
    assert load_plant(tmp_path / "cal" / "plant.json").top_drive is not None
    done = _cli("replay", "cal/plant.json", str(log), "--window", "5:9", "--out", "free",
                "--free-running", cwd=tmp_path)  # fmt: skip
    assert done.returncode == 0, done.stderr
    header = (tmp_path / "free" / "replay.csv").read_text().splitlines()[0]
    assert header.startswith("time_s,bit_speed_rad_s,bit_torque_nm,top_speed_rad_s,")
    assert "Free running" in (tmp_path / "free" / "replay.md").read_text()
    free_table = (tmp_path / "free" / "features.csv").read_text()
    for key in ("top_speed_std_rad_s", "surface_torque_mean_nm"):
        assert key in free_table


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("calibrate", "rig.csv", "--window", "5:2", "--out", "o"), "argument --window"),
        (("calibrate", "rig.csv", "--window", "2:x", "--out", "o"), "argument --window"),
        (("calibrate", "missing.csv", "--window", "0:1", "--out", "o"), "No such file"),
        (("calibrate", "rig.csv", "--window", "0:1", "--out", "afile"), "is a file, not a folder"),
        (("calibrate", "rig.csv", "--window", "0:99", "--out", "o"), "out of range"),
        (
            ("calibrate", "rig.csv", "--window", "0:1", "--out", "o", "--fix", "mass=1"),
            "unknown parameter 'mass'",
        ),
        (
            ("calibrate", "bad.csv", "--window", "0:1", "--out", "o"),
            "column 'bit_speed_rad_s', row 2",
        ),
        (("replay", "afile", "rig.csv", "--window", "0:1", "--out", "o"), "not JSON"),
        (
            (
                "replay",
                "plant.json",
                "rig.csv",
                "--window",
                "0:0.05",
                "--out",
                "o",
                "--free-running",
            ),
            "no identified top drive",
        ),
        (
            ("calibrate", "rig.csv", "--window", "0:0.05", "--out", "mine"),
            "is not from a previous run of this command",
        ),
    ],  # fmt: skip
    ids=[
        "inverted-window",
        "bad-window",
        "missing-log",
        "out-is-a-file",
        "window-outside",
        "unknown-fix",
        "bad-value",
        "bad-plant",
        "free-without-top-drive",
        "not-ours",
    ],  # fmt: skip
)
def test_user_errors_are_one_line_and_exit_2(
    tmp_path: Path, args: tuple[str, ...], match: str
) -> None:
    t = np.arange(100, dtype=np.float64) * 1e-3
    write_log_csv(
        MeasuredLog(t, {"top_speed_rad_s": np.ones(100), "bit_speed_rad_s": np.ones(100),
                        "bit_torque_nm": np.ones(100)}),
        tmp_path / "rig.csv",
    )  # fmt: skip
    (tmp_path / "bad.csv").write_text(
        "time_s,top_speed_rad_s,bit_speed_rad_s,bit_torque_nm\n0,1,1,1\n0.001,1,?,1\n"
    )
    (tmp_path / "afile").write_text("mine")
    values = {"bit_inertia": 0.02, "stiffness": 1.5, "damping": 0.01, "static_friction": 2.5,
              "sliding_friction": 1.5, "stribeck_rate": 0.5}  # fmt: skip
    CalibratedPlant(
        "karnopp",
        False,
        {n: FittedParameter(v, parameter_unit(n, False)) for n, v in values.items()},
    ).save(tmp_path / "plant.json")  # a plant without an identified top drive
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "report.md").write_text("my notes")
    done = _cli(*args, cwd=tmp_path)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert match in lines[0]
    assert (tmp_path / "afile").read_text() == "mine"
    assert (tmp_path / "mine" / "report.md").read_text() == "my notes"


def test_synthetic_logs_are_seeded() -> None:
    a = lab_log(seed=5, duration_s=3.0, defects=False)
    b = lab_log(seed=5, duration_s=3.0, defects=False)
    c = lab_log(seed=6, duration_s=3.0, defects=False)
    for name in a.columns:
        assert np.array_equal(a.column(name), b.column(name))
    assert not np.array_equal(a.column("bit_speed_rad_s"), c.column("bit_speed_rad_s"))


def test_the_arguments_are_the_specs_fields(capsys: pytest.CaptureFixture[str]) -> None:
    """``calibrate`` and ``replay`` parse into their frozen Specs (the window a
    :class:`~experiments.calibrate.Window`, ``--fix`` repeatable); an unknown option is
    reported before a missing required argument."""
    from experiments import calibrate as cli
    from experiments.spec_cli import spec_from_args

    argv = ["rig.csv", "--window", "2:6", "--out", "o", "--fix", "stiffness=1.5"]
    argv += ["--fix", "damping=0", "--no-wob", "--family", "karnopp"]
    spec = spec_from_args(cli.CalibrateSpec, cli._parser().parse_args(argv))
    assert spec == cli.CalibrateSpec(
        log="rig.csv",
        window=cli.Window(2.0, 6.0),
        out=Path("o"),
        family="karnopp",
        no_wob=True,
        fix=(("stiffness", 1.5), ("damping", 0.0)),
    )
    argv = ["p.json", "rig.csv", "--window", "1:2", "--out", "o", "--free-running"]
    replay = spec_from_args(cli.ReplaySpec, cli.replay_parser().parse_args(argv))
    assert (replay.plant, replay.log, replay.window, replay.free_running) == (
        "p.json", "rig.csv", (1.0, 2.0), True,
    )  # fmt: skip
    for main, argv, message in (
        (cli.calibrate_main, ["--bogus"], "unrecognized arguments: --bogus"),
        (cli.calibrate_main, ["rig.csv"], "required: --window, --out"),
        (cli.replay_main, ["p.json", "--out", "o"], "required: LOG, --window"),
    ):
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        assert exit_info.value.code == 2
        assert message in capsys.readouterr().err


def test_a_one_sample_spike_of_the_bit_speed_does_not_move_the_fit() -> None:
    """A sensor's spike is left out where the bit speed is fitted and bridged where it is
    integrated (the momentum balances, the upper string): the fit with one spike is the fit
    without it, and the report counts the bridged sample."""
    clean = lab_log(seed=1, duration_s=6.0, defects=False)
    spiky = lab_log(seed=1, duration_s=6.0, defects=False)
    spiky.column("bit_speed_rad_s")[3500] += 30.0
    fits = [calibrate(log, (2.0, 5.0), families=("karnopp",)) for log in (clean, spiky)]
    (a, b) = (f.fits["karnopp"].p[P_J] for f in fits)
    assert b == pytest.approx(a, rel=0.05)
    assert fits[1].string is not None and fits[0].string is not None
    assert fits[1].string.chosen == fits[0].string.chosen
    assert (fits[0].string.bridged_spikes, fits[1].string.bridged_spikes) == (0, 1)
    top = [f.top_drive.values["inertia_kg_m2"] for f in fits if f.top_drive and f.top_drive.values]
    assert len(top) == 2 and top[1] == pytest.approx(top[0], rel=0.02)
