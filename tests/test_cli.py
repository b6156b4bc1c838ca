"""The ``drill-gym`` command line (:mod:`experiments.cli`, :mod:`experiments.arguments`): one
way of failing, the same options in every subcommand, help in plain words.

These run in-process (fast); ``tests/test_commands.py`` runs the commands as a user types them.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import re
import shutil
from pathlib import Path
from typing import Any

import pytest

from agents.config import TrainConfig
from agents.policy import DEFAULT_MODEL_DIR
from experiments.cli import DEBUG_VARIABLE, SUBCOMMANDS, main

SHIPPED = DEFAULT_MODEL_DIR / "residual_ppo"


def parser_of(name: str) -> argparse.ArgumentParser:
    """The argument parser of a subcommand."""
    module: Any = importlib.import_module(SUBCOMMANDS[name][0])
    parser: argparse.ArgumentParser = module._parser()
    return parser


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# ---------------------------------------------------------------------------- dispatcher
def test_help_lists_every_subcommand_and_the_debug_switch(
    capsys: pytest.CaptureFixture[str],
) -> None:
    code, out, _ = run(["--help"], capsys)
    assert code == 0
    for name in SUBCOMMANDS:
        assert f"  {name} " in out
    assert f"{DEBUG_VARIABLE}=1" in out


@pytest.mark.parametrize("name", list(SUBCOMMANDS))
def test_every_subcommand_module_has_a_main_and_a_parser(name: str) -> None:
    module = importlib.import_module(SUBCOMMANDS[name][0])
    assert callable(module.main)
    assert parser_of(name).prog == f"drill-gym {name}"


# ------------------------------------------------------------------------- user errors
def _corrupt_model(tmp_path: Path) -> Path:
    folder = tmp_path / "corrupt"
    shutil.copytree(SHIPPED, folder)
    (folder / "policy.safetensors").write_bytes(b"\x10\x00\x00\x00\x00\x00\x00\x00not a header....")
    return folder


USER_ERRORS = [
    (["evaluate", "--controllers", "foo"], "argument --controllers: unknown controller 'foo': allowed csmc, msmc"),
    (["evaluate", "/nonexistent"], "no model at '/nonexistent'"),
    (["evaluate", "CORRUPT"], "policy.safetensors' is not valid policy network weights"),
    (["evaluate", "--scenarios", "h99"], "unknown scenario 'h99': allowed h01, h02"),
    (["train", "--total-timesteps", "-5"], "--total-timesteps = -5 is out of range: allowed an integer >= 1"),
    (["train", "--resume", "--run-dir", "RUN"], "--resume: no checkpoint in"),
    (["train", "--seed", "x"], "argument --seed: invalid int value: 'x'"),
    (["compare", "--duration", "-1"], "argument --duration: -1 is out of range: allowed (0, 100000] s"),
    (["compare", "--duration-s", "0.0005"], "argument --duration-s: 0.0005 is not a multiple of the 0.001 s plant step"),
    (["compare", "--controllers", "foo"], "argument --controllers: unknown controller 'foo': allowed csmc, msmc, asmc, proposed"),
    (["compare", "--conditions", "condition4"], "argument --conditions: unknown condition 'condition4'"),
    (["compare", "--noise", "-0.1"], "argument --noise: -0.1 is out of range: allowed [0, 10] rad/s"),
    (["map", "--wob-min", "-3"], "argument --wob-min: -3 is out of range: allowed (0, 1e+06] N"),
    (["map", "--controller", "foo"], "unknown controller 'foo': allowed csmc"),
    (["map", "--controllers", "foo"], "unknown controller 'foo': allowed csmc"),
    (["convert", "OLD.zip", "NEW"], "argument --trust-pickle: is required to read OLD = 'OLD.zip'"),
    (["convert", "/nonexistent", "NEW"], "OLD = '/nonexistent' does not exist"),
    (["convert", "/nonexistent.zip", "NEW", "--trust-pickle"], "OLD = '/nonexistent.zip' does not"),
    (["convert"], "the following arguments are required: OLD, NEW"),
    (["convert", "OLD"], "the following arguments are required: NEW"),
    *[([name, "--bogus"], "unrecognized arguments: --bogus") for name in SUBCOMMANDS if name != "convert"],
    (["convert", "OLD", "NEW", "--bogus"], "unrecognized arguments: --bogus"),
]  # fmt: skip


@pytest.mark.parametrize(("argv", "message"), USER_ERRORS)
def test_a_user_error_is_one_line_with_exit_code_2(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    if "CORRUPT" in argv:
        argv = [str(_corrupt_model(tmp_path)) if a == "CORRUPT" else a for a in argv]
    argv = [str(tmp_path / "run") if a == "RUN" else a for a in argv]
    argv = [str(tmp_path / "new") if a == "NEW" else a for a in argv]
    code, out, err = run(argv, capsys)
    prog = f"drill-gym {argv[0]}"
    assert code == 2
    assert err.count("\n") == 1, err
    assert err.startswith(f"{prog}: error: ") and err.endswith(f" (see {prog} --help)\n"), err
    assert message in err, err
    assert "Traceback" not in err and "usage:" not in err
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("argv", [["nosuch"], ["--bogus"]])
def test_an_unknown_command_is_one_line(
    argv: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run(argv, capsys)
    assert code == 2 and err.count("\n") == 1
    assert re.match(
        r"drill-gym: error: unknown (command|option) '.*': allowed commands compare, map, "
        r"probability-map, train, sweep-train, evaluate, convert, waves, realism, tune, coupled, "
        r"benchmark, calibrate, replay, coupled-controllers \(see drill-gym --help\)\n$",
        err,
    )


def test_debug_variable_shows_the_traceback(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv(DEBUG_VARIABLE, "1")
    with pytest.raises(FileNotFoundError, match="no model at '/nonexistent'"):
        main(["evaluate", "/nonexistent"])
    monkeypatch.setenv(DEBUG_VARIABLE, "0")
    assert main(["evaluate", "/nonexistent"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_a_missing_optional_package_is_one_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import experiments.train

    def no_sb3(argv: object) -> int:
        raise ModuleNotFoundError("No module named 'stable_baselines3'", name="stable_baselines3")

    monkeypatch.setattr(experiments.train, "main", no_sb3)
    code, _, err = run(["train"], capsys)
    assert code == 2 and err.count("\n") == 1
    assert "needs the package 'stable_baselines3'" in err and "pip install -e '.[rl]'" in err


# --------------------------------------------------------------------- the same options
@pytest.mark.parametrize(
    ("name", "options"),
    [
        ("compare", ["--out", "--seed", "--no-progress", "--no-plots", "--controllers"]),
        ("map", ["--out", "--seed", "--no-progress", "--no-plots", "--controllers"]),
        ("evaluate", ["--out", "--no-progress", "--no-plots", "--controllers"]),
        ("train", ["--out", "--run-dir", "--seed", "--no-progress"]),
    ],
)
def test_shared_options_are_in_every_subcommand(name: str, options: list[str]) -> None:
    known = {s for action in parser_of(name)._actions for s in action.option_strings}
    assert set(options) <= known


def test_aliases_mean_the_same() -> None:
    evaluate = parser_of("evaluate")
    assert evaluate.parse_args(["--no-figures"]).no_plots is True
    assert "--no-figures" not in evaluate.format_help()  # hidden, still accepted
    stick_slip = parser_of("map")
    assert stick_slip.parse_args(["--controller", "csmc"]).controllers == ["csmc"]
    assert "--controller " not in stick_slip.format_help()  # hidden: --controllers is documented
    assert stick_slip.parse_args(["--controllers", "csmc", "asmc"]).controllers == ["csmc", "asmc"]
    train = parser_of("train")
    assert train.parse_args(["--out", "somewhere"]).run_dir == "somewhere"
    assert train.parse_args(["--run-dir", "elsewhere"]).run_dir == "elsewhere"
    # an option not given leaves no value (the env's default applies later): runs/EXP_NAME__SEED
    assert "run_dir" not in vars(train.parse_args([]))
    assert train.parse_args(["--no-progress"]).no_progress is True


# --------------------------------------------------------------------------------- help
MARKUP = ("`", ":class:", ":func:", ":data:", ":meth:", ":mod:")


@pytest.mark.parametrize("name", list(SUBCOMMANDS))
def test_help_is_plain_words_with_every_default(
    name: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, _ = run([name, "--help"], capsys)
    assert code == 0
    for mark in MARKUP:
        assert mark not in out, (name, mark)
    assert not re.search(r"\bissues?\b", out, re.IGNORECASE)
    assert "Table 3" not in out  # explained in words instead
    parser = parser_of(name)
    formatter: Any = parser.formatter_class(prog=parser.prog)
    for action in parser._actions:
        if not action.option_strings or action.help == argparse.SUPPRESS:
            continue
        if action.default in (None, False, argparse.SUPPRESS) or action.nargs == 0:
            continue
        assert "(default" in (formatter._get_help_string(action) or ""), (name, action.dest)


def test_conditions_are_explained(capsys: pytest.CaptureFixture[str]) -> None:
    """The help names the conditions and points to the page that explains them."""
    _, out, _ = run(["compare", "--help"], capsys)
    flat = " ".join(out.split())
    assert "uncertainty conditions" in flat and "(default: nominal condition1-3;" in flat
    assert "docs/specification.md section 2.2" in flat
    page = (Path(__file__).parents[1] / "docs" / "specification.md").read_text()
    section = page[page.index("### 2.1 Parametric uncertainty") : page.index("## 3. Controllers")]
    assert "| `condition1` | 0.40 | 0.30 | 0.30 |" in section and "`severe`: mu_a 1.0" in section


def test_convert_an_old_model(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``drill-gym convert OLD/model.zip NEW --trust-pickle`` writes the portable files, which
    load without the opt-in and act as the old model did."""
    pytest.importorskip("stable_baselines3")
    import numpy as np

    from agents.policy import load_policy
    from test_agents import _old_sb3_model_folder, tiny_config

    _, venv = _old_sb3_model_folder(tiny_config(tmp_path), tmp_path / "old")
    venv.close()
    zip_file = tmp_path / "old" / "model.zip"
    code, out, err = run(
        ["convert", str(zip_file), str(tmp_path / "new"), "--trust-pickle"], capsys
    )
    assert code == 0, err
    assert out == f"converted old from {zip_file} to {tmp_path / 'new'}\n"
    assert {p.name for p in (tmp_path / "new").iterdir()} == {
        "config.json",
        "policy.safetensors",
        "obs_norm.safetensors",
    }
    obs = np.random.default_rng(5).normal(size=(16, 11)).astype(np.float32)
    old = load_policy(zip_file, trust_pickle=True)
    np.testing.assert_array_equal(
        load_policy(tmp_path / "new").predict(obs)[0], old.predict(obs)[0]
    )


def test_train_help_is_short_and_help_all_lists_every_setting(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``train --help`` lists the everyday settings and points to ``--help-all``, which lists
    every field of the run's settings; every field stays an option either way."""
    code, short, _ = run(["train", "--help"], capsys)
    assert code == 0 and short.rstrip().endswith("drill-gym train --help-all")
    assert "--learning-rate" not in short and "--duration-s" in short and "--env " in short
    code, full, _ = run(["train", "--help-all"], capsys)
    assert code == 0 and "--learning-rate" in full and "PPO's sampling" in " ".join(full.split())
    train = parser_of("train")
    for f in dataclasses.fields(TrainConfig):
        flag = "--" + f.name.replace("_", "-")
        assert flag in train._option_string_actions, flag  # the field's own name works
        if flag not in ("--env-id", "--run-dir", "--episode-s"):
            assert flag in full, flag
    args = train.parse_args(["--env-id", "DrillStringField-v0", "--episode-s", "50"])
    assert (args.env_id, args.episode_s) == ("DrillStringField-v0", 50.0)
    assert train.parse_args(["--duration-s", "40", "--anneal-lr", "false"]).episode_s == 40.0
    assert train.parse_args(["--no-anneal-lr"]).anneal_lr is False


@pytest.mark.parametrize("name", list(SUBCOMMANDS))
def test_help_fits_on_a_screen(
    name: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    code, out, _ = run([name, "--help"], capsys)
    assert code == 0 and len(out.splitlines()) < 60, (name, len(out.splitlines()))


OLD_NAMES = ("--duration", "--episode", "--episode-s", "--env-id", "--run-dir")
"""Option names replaced by one name per meaning (--duration-s, --env, --out)."""
WINDOW_INTERVAL = ("coupled", "calibrate", "replay")
"""Commands whose --window is a time interval (START END, A:B); elsewhere the analysis window
at the end of a run is its length, --window-s."""


@pytest.mark.parametrize("name", list(SUBCOMMANDS))
def test_one_name_per_meaning(name: str) -> None:
    shown = {
        s
        for action in parser_of(name)._actions
        if action.help != argparse.SUPPRESS
        for s in action.option_strings
    }
    assert not shown & set(OLD_NAMES), (name, shown & set(OLD_NAMES))
    if name not in WINDOW_INTERVAL:
        assert "--window" not in shown, name
