"""``drill-gym tune`` (:mod:`experiments.tune_baselines`) and the tuned speed loops
(:mod:`baselines.tuned`): a tiny search end to end, the training and validation scenarios, the
selection rule, the tuned-gains file and its loader."""

from __future__ import annotations

import contextlib
import csv
import json
import math
import sqlite3
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import baselines.tuned as tuned
import experiments.tune_baselines as tune
from agents.config import TrainConfig
from agents.train import VALIDATION_SEED, validation_scenarios, validation_score
from baselines import SoftSpeed, StiffPI, ZTorque, make_controller
from baselines.base import resolve_model
from baselines.tuned import KIND_ENVS, load_tuned_gains, parse_tuned_gains
from drill_env.evaluation import ZeroAction, rollout
from experiments.cli import main as cli_main

LUMPED = resolve_model("zribi2024")
FIELD = resolve_model("field_2500m")
UNTUNED = {"stiff_pi": StiffPI, "soft_speed": SoftSpeed, "z_torque": ZTorque}


def short_episodes(monkeypatch: pytest.MonkeyPatch, episode_s: float = 2.0) -> None:
    """Every run of the search lasts ``episode_s`` instead of the agent's 100 s."""
    original = tune.tuning_env_kwargs

    def shorter(env_id: str, config: Any = None) -> dict[str, Any]:
        return {**original(env_id, config), "episode_s": episode_s}

    monkeypatch.setattr(tune, "tuning_env_kwargs", shorter)


# ----------------------------------------------------------------------- a tiny search
def test_a_tiny_search_writes_its_files_and_a_gains_file_that_loads(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    short_episodes(monkeypatch)
    out, gains = tmp_path / "out", tmp_path / "gains.json"
    argv = ["--loops", "soft_speed", "z_torque", "--candidates", "3", "--refine", "2"]
    argv += ["--episodes", "2", "--top", "2", "--out", str(out), "--no-progress"]
    assert tune.main([*argv, "--write", "--gains-file", str(gains)]) == 0
    printed = capsys.readouterr().out
    with contextlib.closing(sqlite3.connect(out / "tune.sqlite")) as db:
        sweeps = [sweep for (sweep,) in db.execute("SELECT sweep FROM studies ORDER BY rowid")]
        (stored,) = db.execute("SELECT count(*) FROM results").fetchone()
    assert sweeps == ["tune-round0", "tune-round1", "tune-validation"]
    assert len((out / "candidates.csv").read_text().splitlines()) == 1 + 2 * (3 + 2)
    summary = json.loads((out / "tune.json").read_text())
    entries = load_tuned_gains(gains)
    for loop in ("soft_speed", "z_torque"):
        selected = summary["loops"][loop]["selected"]
        assert selected["key"].startswith(f"{loop}/r")
        entry = entries[loop]["DrillStringParameters"]
        assert entry.env_id == "DrillString-v0"
        for name, value in selected["factors"].items():
            assert getattr(entry.gains, name) == value
        assert entry.validation_score == selected["validation_score"]
        assert entry.command.startswith("drill-gym tune --loops soft_speed z_torque")
        assert f"{loop}: selected {selected['key']}" in printed
    assert "stiff_pi" not in entries  # only the loops tuned
    # training: 2 episodes of 2 s for the reference and for each of 5 candidates per loop;
    # validation: the agent's validation episodes for the reference and for the top 2 (and the
    # default) per loop
    with (out / "candidates.csv").open() as f:
        rows = list(csv.DictReader(f))
    for loop in ("soft_speed", "z_torque"):
        assert sum(r["validated"] == "True" for r in rows if r["loop"] == loop) == 2
    validated = sum(bool(r.get("validation_score")) for r in rows)
    assert validated in (4, 5, 6)
    assert stored == (1 + 2 * 3) + 2 * 2 + (1 + validated)  # one row per candidate run
    expected = 2 * 2.0 * (1 + 2 * 5) + len(tune.validation_episodes()) * 2.0 * (1 + validated)
    assert summary["budget"]["simulated_s"] == pytest.approx(expected)

    # --resume reads everything back: the same selection, no run made
    def fail(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("a candidate ran again")

    monkeypatch.setattr(tune, "candidates_task", fail)
    assert tune.main([*argv, "--resume"]) == 0
    again = json.loads((out / "tune.json").read_text())
    assert again["loops"] == summary["loops"]


def test_the_default_factors_are_candidate_zero_and_are_validated(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    short_episodes(monkeypatch)
    settings = tune.TuneSpec(loops=("stiff_pi",), candidates=3, refine=0, episodes=1, top=1)
    result = tune.run_tuning(settings, progress=False)
    (loop,) = result.loops
    default = loop.row(loop.default)
    assert loop.default == "stiff_pi/r0/c000"
    assert tune.factors_of(default) == {"bandwidth_factor": 50.0, "damping_ratio": 1.0}
    assert "validation_score" in default  # validated beside the top candidate
    assert sum(r["validated"] for r in loop.rows) == 1


# --------------------------------------------------------------------------- scenarios
def test_training_episodes_follow_the_agents_vector_env() -> None:
    """Episode n is episode n // 16 of string n % 16, string i seeded with 1 + i."""
    episodes = tune.training_episodes(18)
    assert episodes[:2] == [(1, 0), (2, 0)] and episodes[15] == (16, 0)
    assert episodes[16:] == [(1, 1), (2, 1)]


def test_the_second_training_episode_is_the_vector_envs_second_episode() -> None:
    """A string's unseeded reset after its seeded one replays what the agent's vector env
    runs after an autoreset (the same scenario and noise: the same bit speed)."""
    kwargs = {**tune.tuning_env_kwargs("DrillString-v0"), "episode_s": 0.5}
    venv = gym.make_vec(
        "DrillString-v0", num_envs=2, max_episode_steps=5, base_controller="soft_speed", **kwargs
    )
    venv.reset(seed=[1, 2])
    speeds = []
    for step in range(11):
        venv.step(np.zeros((2, 1), dtype=np.float32))
        if step > 5:  # step 5 is the autoreset
            speeds.append(venv.unwrapped.plant_samples().bit_speed_rad_s[1].copy())  # type: ignore[attr-defined]
    env = gym.make("DrillString-v0", max_episode_steps=-1, base_controller="soft_speed", **kwargs)
    rollout(env, ZeroAction(), 2)
    second = rollout(env, ZeroAction(), None)
    np.testing.assert_array_equal(np.concatenate(speeds), second.bit_speed_rad_s)
    venv.close()


def test_validation_episodes_are_the_agents_validation_scenarios() -> None:
    """The search validates on the agent's validation scenarios and the ones after them."""
    kwargs, seeds = validation_scenarios(TrainConfig())
    ours_seeds = [s for s, _ in tune.validation_episodes()]
    assert ours_seeds[: len(seeds)] == seeds
    assert ours_seeds == [VALIDATION_SEED + k for k in range(tune.VALIDATION_EPISODES)]
    ours = tune.tuning_env_kwargs("DrillString-v0")
    assert ours == {k: v for k, v in kwargs.items() if k != "base_controller"}
    assert tune.tuning_env_kwargs("DrillStringField-v0") == {"randomize": True, "episode_s": 100.0}


def test_latin_hypercube_fills_every_stratum_once() -> None:
    points = tune.latin_hypercube(7, 3, np.random.default_rng(0))
    for d in range(3):
        assert sorted(np.floor(points[:, d] * 7).astype(int)) == list(range(7))


# ---------------------------------------------------------------------- the selection
def _record(iae: list[float], rmsd: list[float], sev: list[float], diverged: Any = None) -> Any:
    return {
        "iae": iae,
        "rmsd_nm": rmsd,
        "stick_slip_severity": sev,
        "diverged": diverged or [False] * len(iae),
    }


def test_the_selection_score_is_the_agents_validation_score() -> None:
    reference = _record([100.0, 300.0], [10e3, 14e3], [0.5, 1.5])
    candidate = _record([50.0, 110.0], [11e3, 13.2e3], [0.2, 0.6])
    score = tune.score_of(candidate, reference)
    iae, rmsd, sev = 160.0 / 400.0, 24.2e3 / 24e3, 0.8 / 2.0
    assert score.iae_ratio == pytest.approx(iae)
    assert score.rmsd_ratio == pytest.approx(rmsd)
    assert score.severity_ratio == pytest.approx(sev)
    assert score.score == pytest.approx(iae + 10 * (rmsd - 0.99))  # RMSD above 0.99
    rows = [dict(zip(("iae", "rmsd_nm", "stick_slip_severity"), r, strict=True)) for r in
            zip(candidate["iae"], candidate["rmsd_nm"], candidate["stick_slip_severity"], strict=True)]  # fmt: skip
    base = [dict(zip(("iae", "rmsd_nm", "stick_slip_severity"), r, strict=True)) for r in
            zip(reference["iae"], reference["rmsd_nm"], reference["stick_slip_severity"], strict=True)]  # fmt: skip
    assert score.score == validation_score(rows, base).score
    assert score.feasible
    lean = _record([50.0, 110.0], [9e3, 12e3], [0.2, 0.6])  # RMSD ratio 0.875: no penalty
    assert tune.score_of(lean, reference).score == pytest.approx(0.4)


def test_a_diverged_or_broken_run_rules_a_candidate_out() -> None:
    reference = _record([100.0, 300.0], [10e3, 14e3], [0.5, 1.5])
    diverged = _record([1.0, 1.0], [1.0, 1.0], [0.0, 0.0], diverged=[False, True])
    assert tune.score_of(diverged, reference).score == math.inf
    assert not tune.score_of(diverged, reference).feasible
    broken = _record([1.0, None], [1.0, 1.0], [0.0, 0.0])  # type: ignore[list-item]
    assert not tune.score_of(broken, reference).feasible


# ------------------------------------------------------------------- tuned controllers
def _document(**changes: Any) -> dict[str, Any]:
    kinds = {
        "soft_speed": (
            {"impedance_factor": 1.5, "frequency_factor": 0.8},
            {"impedance_factor": 2.5, "frequency_factor": 0.5},
        ),
        "z_torque": (
            {"impedance_factor": 3.0, "mean_periods": 0.5, "bandwidth_factor": 2.0},
            {"impedance_factor": 2.0, "mean_periods": 0.2, "bandwidth_factor": 10.0},
        ),
        "stiff_pi": ({"bandwidth_factor": 1.2}, {"bandwidth_factor": 4.0, "damping_ratio": 0.7}),
    }
    controllers = {
        name: {
            kind: {"env": env, "gains": gains, "command": "drill-gym tune"}
            for (kind, env), gains in zip(KIND_ENVS.items(), pair, strict=True)
        }
        for name, pair in kinds.items()
    }
    return {"format": 1, "about": "test", "controllers": controllers, **changes}


@pytest.fixture
def gains_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path / "tuned_gains.json"
    path.write_text(json.dumps(_document()))
    monkeypatch.setattr(tuned, "TUNED_GAINS_FILE", path)
    return path


@pytest.mark.parametrize("loop", ["stiff_pi", "soft_speed", "z_torque"])
def test_a_tuned_loop_picks_its_factors_by_plant_kind(gains_file: Path, loop: str) -> None:
    lumped, field = (e["gains"] for e in _document()["controllers"][loop].values())
    controller = make_controller(f"{loop}_tuned")
    for model, factors in ((LUMPED, lumped), (FIELD, field)):
        expected = UNTUNED[loop](**factors)
        assert controller.tuning(model) == expected.tuning(model)  # type: ignore[attr-defined]
        law = controller.compiled_law(model)  # type: ignore[attr-defined]
        np.testing.assert_array_equal(law.params, expected.compiled_law(model).params)
    assert controller.gains == UNTUNED[loop](**lumped).gains  # its own model: zribi2024
    on_field = make_controller(f"{loop}_tuned", model="field_2500m")
    assert on_field.gains == UNTUNED[loop](**field).gains  # type: ignore[attr-defined]


def test_a_tuned_loop_runs_in_both_envs_with_its_factors(gains_file: Path) -> None:
    env = gym.make("DrillStringField-v0", base_controller="z_torque_tuned", episode_s=0.2)
    twin = gym.make(
        "DrillStringField-v0",
        base_controller=make_controller("z_torque", **_document()["controllers"]["z_torque"][
            "DistributedStringParameters"]["gains"]),
        episode_s=0.2,
    )  # fmt: skip
    a, b = rollout(env, ZeroAction(), 3), rollout(twin, ZeroAction(), 3)
    np.testing.assert_array_equal(a.torque_nm, b.torque_nm)


def test_overrides_apply_to_every_plant_kind_and_gains_are_refused(gains_file: Path) -> None:
    controller = make_controller("soft_speed_tuned", frequency_factor=2.0)
    assert controller.gains_for(FIELD).frequency_factor == 2.0  # type: ignore[attr-defined]
    assert controller.gains_for(FIELD).impedance_factor == 2.5  # type: ignore[attr-defined]
    with pytest.raises(TypeError, match=r"unrecognized gain\(s\) for soft_speed_tuned: k9"):
        make_controller("soft_speed_tuned", k9=1.0)
    with pytest.raises(TypeError, match="soft_speed_tuned reads its factors from tuned_gains"):
        make_controller("soft_speed_tuned", gains=tuned.SoftSpeedGains())


def test_a_plant_kind_missing_from_the_file_is_a_clear_error(
    gains_file: Path,
) -> None:
    document = _document()
    del document["controllers"]["soft_speed"]["DistributedStringParameters"]
    gains_file.write_text(json.dumps(document))
    controller = make_controller("soft_speed_tuned")  # the 4-DOF entry is there
    with pytest.raises(ValueError, match=r"no factors of soft_speed for a "
                       r"DistributedStringParameters model .*drill-gym tune --env "
                       r"DrillStringField-v0 --write"):  # fmt: skip
        controller.tuning(FIELD)  # type: ignore[attr-defined]


@pytest.mark.parametrize("loop", ["stiff_pi", "soft_speed", "z_torque"])
def test_the_shipped_file_has_both_plant_kinds_of_every_loop(loop: str) -> None:
    entries = load_tuned_gains()
    controller = make_controller(f"{loop}_tuned")
    for kind, model in (("DrillStringParameters", LUMPED), ("DistributedStringParameters", FIELD)):
        entry = entries[loop][kind]
        assert entry.env_id == KIND_ENVS[kind] and entry.command.startswith("drill-gym tune")
        assert controller.gains_for(model) == entry.gains  # type: ignore[attr-defined]


# ----------------------------------------------------------------- a hostile gains file
HOSTILE = [
    pytest.param("not json at all", r"is not valid JSON", id="not-json"),
    pytest.param('{"format": 1, "controllers": {}, "format": 1}', r"field 'format' appears twice", id="duplicate"),
    pytest.param('{"format": NaN, "controllers": {}}', r"NaN is not a number JSON allows", id="nan"),
    pytest.param('[1, 2]', r"tuned_gains.json: expected a JSON object, got list", id="list"),
]  # fmt: skip


@pytest.mark.parametrize(("text", "match"), HOSTILE)
def test_a_file_that_is_not_a_tuned_gains_document_is_refused(
    tmp_path: Path, text: str, match: str
) -> None:
    path = tmp_path / "tuned_gains.json"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_tuned_gains(path)


def _break(path: list[str], value: Any) -> dict[str, Any]:
    document = _document()
    target = document
    for key in path[:-1]:
        target = target[key]
    if value is KeyError:
        del target[path[-1]]
    else:
        target[path[-1]] = value
    return document


GAINS = ["controllers", "soft_speed", "DrillStringParameters", "gains"]
WHERE = r"tuned_gains\.json\.controllers\.soft_speed\.DrillStringParameters"
MALFORMED = [
    pytest.param(["format"], 2, r"tuned_gains\.json\.format: = 2: expected 1", id="format"),
    pytest.param(["format"], True, r"tuned_gains\.json\.format: = True: expected 1", id="format-bool"),
    pytest.param(["script"], "x", r"tuned_gains\.json\.script: unknown field: allowed format, about, controllers", id="top-field"),
    pytest.param(["controllers", "pid"], {}, r"tuned_gains\.json\.controllers\.pid: unknown field: allowed stiff_pi, soft_speed, z_torque", id="controller"),
    pytest.param(["controllers", "soft_speed", "Lumped"], {}, r"controllers\.soft_speed\.Lumped: unknown field: allowed DrillStringParameters, DistributedStringParameters", id="kind"),
    pytest.param([*GAINS[:3], "env"], "DrillStringField-v0", rf"{WHERE}\.env: = 'DrillStringField-v0': expected 'DrillString-v0'", id="env"),
    pytest.param([*GAINS[:3], "gains"], KeyError, rf"{WHERE}\.gains: missing", id="no-gains"),
    pytest.param([*GAINS, "kp"], 1000.0, rf"{WHERE}\.gains\.kp: unknown field: allowed impedance_factor, frequency_factor, inertia_compensation", id="gain-field"),
    pytest.param([*GAINS, "limits"], {"u_min_nm": 0}, rf"{WHERE}\.gains\.limits: unknown field", id="limits"),
    pytest.param([*GAINS, "impedance_factor"], "__import__('os').system('touch PWNED')", rf"{WHERE}\.gains\.impedance_factor: = .*: expected a finite number", id="code"),
    pytest.param([*GAINS, "impedance_factor"], True, rf"{WHERE}\.gains\.impedance_factor: = True: expected a finite number", id="bool"),
    pytest.param([*GAINS, "impedance_factor"], -1.0, rf"{WHERE}\.gains: SoftSpeedGains\.impedance_factor = -1\.0 is out of range: allowed \(0, 100\]", id="range"),
    pytest.param([*GAINS, "inertia_compensation"], 1, rf"{WHERE}\.gains\.inertia_compensation: = 1: expected true or false", id="flag"),
    pytest.param([*GAINS[:3], "validation_score"], "0.4", rf"{WHERE}\.validation_score: = '0\.4': expected a finite number or null", id="score"),
    pytest.param([*GAINS[:3], "command"], ["rm", "-rf"], rf"{WHERE}\.command: = \['rm', '-rf'\]: expected a string", id="command"),
    pytest.param(["controllers", "soft_speed", "DrillStringParameters"], [], rf"{WHERE}: expected a JSON object, got list", id="entry"),
]  # fmt: skip


@pytest.mark.parametrize(("path", "value", "match"), MALFORMED)
def test_a_malformed_gains_file_names_the_field(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, path: list[str], value: Any, match: str
) -> None:
    monkeypatch.chdir(tmp_path)
    file = tmp_path / "tuned_gains.json"
    file.write_text(json.dumps(_break(path, value)))
    with pytest.raises(ValueError, match=match):
        load_tuned_gains(file)
    monkeypatch.setattr(tuned, "TUNED_GAINS_FILE", file)
    with pytest.raises(ValueError, match=match):  # and no controller is made from it
        make_controller("soft_speed_tuned")
    assert not (tmp_path / "PWNED").exists()


def test_the_document_writer_and_the_parser_round_trip() -> None:
    entries = parse_tuned_gains(_document(), "x")
    again = parse_tuned_gains(tuned.tuned_gains_document(entries, about="test"), "x")
    assert again == entries


def test_the_spec_names_the_option_of_a_bad_setting() -> None:
    assert tune.TuneSpec(loops=("z_torque", "stiff_pi", "z_torque")).loops == (
        "z_torque",
        "stiff_pi",
    )
    assert tune.TuneSpec(env_id="DrillStringField-v0").folder == Path(
        "results/tune/DrillStringField-v0"
    )
    assert tune.TuneSettings is tune.TuneSpec  # the former name
    with pytest.raises(ValueError, match="--zoom: 0 is out of range"):
        tune.TuneSpec(zoom=0)
    with pytest.raises(ValueError, match="--loops: unknown loop 'pid'"):
        tune.TuneSpec(loops=("pid",))


# ------------------------------------------------------------------------ bad options
BAD_OPTIONS = [
    (["--candidates", "0"], "argument --candidates: 0 is out of range: allowed [1, 100000]"),
    (["--env", "CartPole-v1"], "argument --env: unknown env 'CartPole-v1': allowed DrillString-v0"),
    (["--loops", "pid"], "argument --loops: unknown loop 'pid': allowed stiff_pi, soft_speed"),
    (["--zoom", "0"], "argument --zoom: 0 is out of range: allowed (0, 1]"),
    (["--candidates", "2", "--refine", "0", "--top", "3"], "--top: 3 is out of range: allowed at most --candidates + --refine = 2"),
    (["--episodes", "x"], "argument --episodes: 'x' is not an integer"),
    (["--bogus"], "unrecognized arguments: --bogus"),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "message"), BAD_OPTIONS)
def test_a_bad_option_is_one_line_with_exit_code_2(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code = cli_main(["tune", *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("drill-gym tune: error: "), err
    assert message in err, err


def test_a_malformed_gains_file_fails_before_the_search(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    file = tmp_path / "g.json"
    file.write_text('{"format": 3, "controllers": {}}')
    code = cli_main(["tune", "--write", "--gains-file", str(file), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "g.json.format: = 3: expected 1" in err
    assert not (tmp_path / "tune.sqlite").exists()


def test_every_built_in_controller_is_declared_as_an_entry_point_in_pyproject() -> None:
    """The tuned loops are offered by name to an installed package too (after ``pip install``
    the entry points of pyproject.toml are the installed ones)."""
    tomllib = pytest.importorskip("tomllib")
    from baselines import BUILT_IN

    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    declared = project["project"]["entry-points"]["drill_string_gym.controllers"]
    assert declared == {n: f"{c.__module__}:{c.__name__}" for n, c in BUILT_IN.items()}
    assert "tuned_gains.json" in project["tool"]["setuptools"]["package-data"]["baselines"]
    assert list(BUILT_IN)[4:] == [
        "stiff_pi", "stiff_pi_tuned", "soft_speed", "soft_speed_tuned", "z_torque", "z_torque_tuned"
    ]  # fmt: skip
