"""Trust covers the named file only, messages of hostile keywords stay safe through Gymnasium,
and paths no command can use are refused before the study is imported.

``tests/test_hostile_inputs.py`` generates hostile inputs for every loader and command; this
file pins the three rules that live at the edges: ``train --resume --trust-pickle FILE``,
Gymnasium's re-raise of an env's ``TypeError`` with the raw keywords, and
:mod:`experiments.preflight`.
"""

from __future__ import annotations

import json
import os
import pickle
import re
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import drill_env  # noqa: F401  (registers the envs)
from agents.checkpoints import find_last_checkpoint
from agents.config import TrainConfig
from agents.train import _prepare_run_dir
from drill_env.validation import (
    MAX_MESSAGE_CHARS,
    InputTypeError,
    input_type_errors,
    printable,
)
from experiments.cli import SUBCOMMANDS
from experiments.cli import main as cli_main
from experiments.preflight import refused_path
from experiments.train import parse_config

ROOT = Path(__file__).resolve().parents[1]
SMALL = settings(
    deadline=None,
    max_examples=60,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow],
)


class _Payload:
    """Unpickled, creates the file ``path`` (proof that code ran)."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __reduce__(self) -> Any:
        return (Path.touch, (self.path,))


@pytest.fixture
def marker(tmp_path: Path) -> Iterator[Path]:
    path = tmp_path / "MARKER"
    yield path
    assert not path.exists(), "a pickle was opened"


def _old_run(tmp_path: Path, marker: Path, norm: bool = True) -> Path:
    """A run folder of an older version: a pickled checkpoint (and its VecNormalize file)
    holding a payload, plus a decoy pickle with more decisions under another name."""
    run_dir = tmp_path / "run"
    folder = run_dir / "checkpoints"
    folder.mkdir(parents=True)
    (run_dir / "config.json").write_text(
        json.dumps({"exp_name": "x", "total_timesteps": 1, "n_steps": 1})
    )
    evil = pickle.dumps(_Payload(marker))
    (folder / "rl_model_1024_steps.zip").write_bytes(evil)
    if norm:
        (folder / "rl_model_vecnormalize_1024_steps.pkl").write_bytes(evil)
    (folder / "trusted.zip").write_bytes(evil)  # named like nothing resume reads
    return run_dir


def _resume(run_dir: Path, *trusted: Path | str) -> Any:
    config = TrainConfig(
        run_dir=str(run_dir), resume=True, trust_pickle=tuple(str(t) for t in trusted)
    )
    return _prepare_run_dir(config, run_dir)


# ------------------------------------------------------------------ trust: the named files
def test_resume_refuses_an_old_checkpoint_without_its_files_named(
    tmp_path: Path, marker: Path
) -> None:
    run_dir = _old_run(tmp_path, marker)
    folder = run_dir / "checkpoints"
    zip_file, norm = (
        folder / "rl_model_1024_steps.zip",
        folder / "rl_model_vecnormalize_1024_steps.pkl",
    )
    with pytest.raises(
        ValueError, match=r"naming its files: --trust-pickle .*1024_steps.zip .*pkl"
    ):
        _resume(run_dir)
    with pytest.raises(ValueError, match=r"naming its files"):
        _resume(run_dir, zip_file)  # the VecNormalize file is a second pickle
    with pytest.raises(ValueError, match=r"naming its files"):
        _resume(run_dir, folder / "trusted.zip", norm)  # another file of the folder
    lone = _old_run(tmp_path / "lone", marker, norm=False) / "checkpoints"
    with pytest.raises(ValueError, match=r"names '.*trusted.zip', which --resume does not read"):
        _resume(lone.parent, lone / "rl_model_1024_steps.zip", lone / "trusted.zip")
    with pytest.raises(ValueError, match=r"no such file"):
        _resume(run_dir, zip_file, tmp_path / "missing.pkl")
    with pytest.raises(ValueError, match=r"no such file"):
        _resume(run_dir, folder)  # a folder never stands for the files in it


def test_resume_reads_the_old_checkpoint_through_the_names_given(
    tmp_path: Path, marker: Path
) -> None:
    run_dir = _old_run(tmp_path, marker)
    folder = run_dir / "checkpoints"
    link = tmp_path / "mine.zip"
    link.symlink_to(folder / "rl_model_1024_steps.zip")
    last = _resume(run_dir, folder / "rl_model_vecnormalize_1024_steps.pkl", link)
    assert last.legacy and last.steps == 1024
    assert last.path == link  # the name the user gave, not one found in the folder
    assert last.legacy_norm == folder / "rl_model_vecnormalize_1024_steps.pkl"
    without_norm = _old_run(tmp_path / "b", marker, norm=False)
    only = without_norm / "checkpoints" / "rl_model_1024_steps.zip"
    assert _resume(without_norm, only).pickles == (only,)


def test_trust_on_a_checkpoint_folder_is_refused(tmp_path: Path, marker: Path) -> None:
    run_dir = tmp_path / "run"
    ck = run_dir / "checkpoints" / "steps_64"
    ck.mkdir(parents=True)
    (ck / "training.json").write_text("{}")
    last = find_last_checkpoint(run_dir)
    assert last is not None and not last.legacy and last.pickles == ()
    decoy = tmp_path / "x.zip"
    decoy.write_bytes(pickle.dumps(_Payload(marker)))
    with pytest.raises(ValueError, match=r"is a checkpoint folder, read without pickle"):
        _resume(run_dir, decoy)
    assert _resume(run_dir).path == ck


@pytest.mark.parametrize(
    ("value", "match"),
    [
        (True, r"--trust-pickle = True is not valid: name the pickled checkpoint files"),
        ("a.zip", r"expected a list of file names"),
        (("a", "b", "c"), r"names 3 files: allowed at most 2"),
        (("",), r"expected a file name"),
        (("a\x00b",), r"expected a file name"),
        ((5,), r"expected a file name"),
    ],
    ids=repr,
)
def test_trust_pickle_names_files(value: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        TrainConfig(resume=True, trust_pickle=value)


def test_trust_needs_resume_and_is_never_read_from_a_record() -> None:
    with pytest.raises(ValueError, match=r"--trust-pickle .* it needs --resume"):
        TrainConfig(trust_pickle=("a.zip",))
    assert parse_config(["--resume", "--trust-pickle", "a.zip", "b.pkl"]).trust_pickle == (
        "a.zip",
        "b.pkl",
    )
    shipped = json.loads((ROOT / "agents/models/residual_ppo/config.json").read_text())
    assert shipped["train_config"]["trust_pickle"] is False  # what earlier versions wrote
    assert TrainConfig.from_dict(shipped["train_config"]).trust_pickle == ()
    record = {**shipped["train_config"], "resume": True, "trust_pickle": ["x.zip"]}
    assert TrainConfig.from_dict(record).trust_pickle == ()  # a file never grants trust


def test_train_command_refuses_an_unnamed_pickle_on_one_line(
    tmp_path: Path, marker: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_dir = _old_run(tmp_path, marker)
    decoy = run_dir / "checkpoints" / "trusted.zip"
    code = cli_main(["train", "--run-dir", str(run_dir), "--resume", "--trust-pickle", str(decoy)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "naming its files: --trust-pickle" in err


# ------------------------------------------------- Gymnasium's re-raise keeps messages safe
class _Loud:
    """An object whose repr moves the terminal (and is long)."""

    def __repr__(self) -> str:
        return "\x1b[2J\x1b[31m" * 500


HOSTILE_VALUES: dict[str, Any] = {
    "escape": "\x1b[31mred\x1b[0m",
    "huge": "x" * 10_000_000,
    "repr": _Loud(),
    "newlines": "a\nb\r\nc\u202e",
}
ENV_KEYWORDS = {
    "DrillString-v0": ["foo", "wob_n", "parameters", "randomization", "reward_weights"],
    "DrillStringField-v0": ["foo", "measured_depth_m", "randomization", "observation"],
    "DrillStringCoupled-v0": ["foo", "string", "bit", "applied_force_n", "torque_loop"],
}


def _safe(message: str) -> bool:
    return len(message) <= MAX_MESSAGE_CHARS and printable(message, 10**6) == message


@pytest.mark.parametrize("value", list(HOSTILE_VALUES), ids=str)
@pytest.mark.parametrize(
    ("env_id", "keyword"), [(e, k) for e, ks in ENV_KEYWORDS.items() for k in ks]
)
def test_make_errors_show_keywords_escaped_and_bounded(
    env_id: str, keyword: str, value: str
) -> None:
    start = time.perf_counter()
    with pytest.raises((TypeError, ValueError)) as caught:
        gym.make(env_id, **{keyword: HOSTILE_VALUES[value]})
    assert time.perf_counter() - start < 1.0
    error = caught.value
    assert _safe(str(error)), str(error)[:300]
    for note in getattr(error, "__notes__", []):
        assert _safe(note), note[:300]
    if isinstance(error, TypeError):
        assert isinstance(error, InputTypeError)


def test_a_hostile_keyword_name_is_escaped() -> None:
    with pytest.raises(InputTypeError) as caught:
        hostile: dict[str, Any] = {"\x1b[2J" * 100_000: 1}
        gym.make("DrillString-v0", **hostile)
    assert _safe(str(caught.value)) and "\\x1b[2J" in str(caught.value)


@pytest.mark.parametrize(
    ("keywords", "match"),
    [
        ({"num_envs": 10**12}, r"num_envs = 1000000000000 is out of range: allowed an integer"),
        ({"num_envs": _Loud()}, r"num_envs = (\\x1b\[2J\\x1b\[31m)+.*is out of range"),
        ({"max_episode_steps": 10**400}, r"max_episode_steps = <an integer of \d+ bits>"),
        ({"render_mode": "\x1b[2J" * 10**5}, r"render_mode = '(\\x1b\[2J)+.*not supported"),
    ],
    ids=["num_envs", "repr", "steps", "render_mode"],
)
def test_coupled_vector_env_bounds_and_escapes(keywords: dict[str, Any], match: str) -> None:
    start = time.perf_counter()
    with pytest.raises(ValueError, match=match) as caught:
        gym.make_vec("DrillStringCoupled-v0", **keywords)
    assert time.perf_counter() - start < 1.0 and _safe(str(caught.value))


@SMALL
@given(st.text(max_size=3000), st.text(max_size=200))
def test_input_type_errors_are_always_safe(first: str, more: str) -> None:
    """Whatever text an error is built from, also when a caller rebuilds it with more."""
    with pytest.raises(InputTypeError) as caught, input_type_errors():
        raise TypeError(first)
    rebuilt = type(caught.value)(f"{caught.value} with kwargs ({more!s})")
    for error in (caught.value, rebuilt):
        assert _safe(str(error))


@SMALL
@given(st.text(max_size=2000), st.integers(0, 300))
def test_printable_is_bounded_and_has_no_control_characters(text: str, limit: int) -> None:
    line = printable(text, limit)
    assert len(line) <= max(limit, 3) and line.isprintable()
    if len(text) <= limit and text.isprintable() and "\\" not in text:
        assert line == text


# ----------------------------------------------- paths refused before the study is imported
@pytest.fixture
def specials(tmp_path: Path) -> Iterator[dict[str, Path]]:
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    folder = tmp_path / "folder"
    folder.mkdir()
    regular = tmp_path / "notes.txt"
    regular.write_text("mine")
    sock_path = tmp_path / "sock"
    server = socket.socket(socket.AF_UNIX)
    server.bind(str(sock_path))
    try:
        yield {
            "fifo": fifo,
            "socket": sock_path,
            "device": Path("/dev/zero"),
            "folder": folder,
            "file": regular,
        }
    finally:
        server.close()


PREFLIGHT_CASES = [
    (["map", "--results", "{fifo}"], r"--results '.*fifo' is a FIFO \(named pipe\)"),
    (["compare", "--results={device}"], r"'/dev/zero' is a character device"),
    (["tune", "--results", "{socket}"], r"'.*sock' is a socket"),
    (["probability-map", "--results", "{folder}"], r"'.*folder' is a folder: expected a file"),
    (["tune", "--gains-file", "{folder}"], r"--gains-file .* is a folder"),
    (["tune", "--gains-file", "{fifo}"], r"is a FIFO"),
    (["calibrate", "{fifo}", "--window", "0", "1"], r"'.*fifo' is a FIFO"),
    (["calibrate", "{device}", "--window", "0", "1"], r"is a character device"),
    (["replay", "{folder}/../fifo", "{file}"], r"is a FIFO"),
    (["map", "--models", "{file}", "{fifo}"], r"is a FIFO"),
    (["evaluate", "{socket}"], r"is a socket"),
    (["benchmark", "mod:Cls", "--out", "{file}"], r"argument --out: .* is a file, not a folder"),
    (["coupled", "--out", "{fifo}"], r"is a FIFO"),
    (["train", "--run-dir", "{file}"], r"argument --run-dir: .* is a file, not a folder"),
    (["convert", "{fifo}", "{folder}/new"], r"is a FIFO"),
    (
        ["coupled", "--out", "{file}/sub/dir"],
        r"--out: '.*sub/dir' lies inside '.*notes.txt', which",
    ),
    (["map", "--results", "{file}/r.db"], r"--results '.*r.db' lies inside '.*notes.txt', which"),
]


@pytest.mark.parametrize(("argv", "match"), PREFLIGHT_CASES, ids=lambda v: " ".join(v)[:40])
def test_unusable_paths_are_refused_before_importing_the_study(
    argv: list[str], match: str, specials: dict[str, Path]
) -> None:
    filled = [a.format(**{k: str(v) for k, v in specials.items()}) for a in argv]
    problem = refused_path(filled[1:])
    assert problem is not None and re.search(match, problem), problem


def test_preflight_passes_what_commands_can_use(specials: dict[str, Path]) -> None:
    for argv in (
        ["--results", str(specials["file"].with_name("new.db")), "--out", str(specials["folder"])],
        ["--models", str(specials["folder"]), "--seed", "0", "--controllers", "proposed"],
        ["--gains-file", str(specials["file"]), "--write"],
        [str(specials["file"]), "--window", "0", "1"],
        ["--out", str(specials["folder"] / "new")],
    ):
        assert refused_path(argv) is None, argv


def test_a_fifo_as_results_is_refused_within_a_second(
    specials: dict[str, Path], tmp_path: Path
) -> None:
    """The whole command, in a fresh interpreter: no study, NumPy or Numba is imported."""
    code = (
        "import sys, time; t = time.perf_counter(); from experiments.cli import main; "
        "c = main(sys.argv[1:]); "
        "heavy = [m for m in ('numpy', 'numba', 'experiments.stick_slip_map') if m in sys.modules]; "
        "print(c, time.perf_counter() - t, heavy)"
    )
    argv = ["map", "--results", str(specials["fifo"]), "--out", str(tmp_path / "out")]
    done = subprocess.run(
        [sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    code_text, seconds, heavy = done.stdout.split(" ", 2)
    assert code_text == "2" and heavy.strip() == "[]", done.stdout
    assert float(seconds) < 1.0
    assert done.stderr.count("\n") == 1 and "is a FIFO" in done.stderr
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------ measured logs and plant files
def _log(tmp_path: Path, text: str | bytes, name: str = "log.csv") -> Path:
    path = tmp_path / name
    if isinstance(text, str):
        text = text.encode("utf-8", "surrogatepass")
    path.write_bytes(text)
    return path


GOOD_ROWS = "0,1\n0.001,1\n0.002,1\n"
HOSTILE_LOGS: dict[str, tuple[str | bytes, str]] = {
    "beyond-float": ("time_s,top_speed_rad_s\n0,1\n0.001,1e400\n0.002,1\n", r"row 2: inf"),
    "nan": ("time_s,top_speed_rad_s\n0,1\n0.001,nan\n0.002,1\n", r"row 2: nan is not finite"),
    "nul-bytes": ("time_s,top_speed_rad_s\n0,1\n0.001,1\x00\n", r"row 2: '1\\x00' is not"),
    "escape-cell": ("time_s,top_speed_rad_s\n0,\x1b[2J\n", r"row 1: '\\x1b\[2J' is not a number"),
    "huge-cell": ("time_s,top_speed_rad_s\n0," + "9" * 60_000 + "x\n", r"row 1: '9{20,}\.\.\."),
    "long-line": ("time_s,top_speed_rad_s\n0," + "1" * 100_000 + "\n", r"line 2: longer than"),
    "long-header": ("#" + "x" * 100_000 + "\n" + GOOD_ROWS, r"line 1: longer than 65536"),
    "escape-column": ("time_s,top_speed_rad_s,\x1b[31m\n" + GOOD_ROWS, r"unknown column.*\\x1b"),
    "many-columns": ("time_s,top_speed_rad_s," + ",".join(f"c{i}" for i in range(5000)) + "\n",
                     r"'c7' and 4992 more"),
    "duplicate": ("time_s,top_speed_rad_s,time_s\n0,1,0\n", r"'time_s' appear twice"),
    "not-utf8": (b"time_s,top_speed_rad_s\n0,\xff\n", r"is not UTF-8 text"),
    "infinity": ("time_s,top_speed_rad_s\n0,1\n0.001,-Infinity\n0.002,1\n",
                 r"row 2: -inf is not finite"),
}  # fmt: skip


@pytest.mark.parametrize("case", list(HOSTILE_LOGS))
def test_hostile_logs_are_refused_on_one_safe_line(tmp_path: Path, case: str) -> None:
    from drill_env.measured_log import read_log

    text, match = HOSTILE_LOGS[case]
    start = time.perf_counter()
    with pytest.raises(ValueError, match=match) as caught:
        read_log(_log(tmp_path, text))
    assert time.perf_counter() - start < 1.0
    assert _safe(str(caught.value)), str(caught.value)[:300]


def test_a_log_with_a_byte_order_mark_is_read(tmp_path: Path) -> None:
    from drill_env.measured_log import read_log

    log = read_log(_log(tmp_path, "\ufefftime_s,top_speed_rad_s\n" + GOOD_ROWS))
    assert list(log.time_s) == [0.0, 0.001, 0.002]


@pytest.mark.parametrize("kind", ["fifo", "device", "folder", "socket"])
def test_logs_and_plants_that_are_not_regular_files_are_never_opened(
    kind: str, specials: dict[str, Path]
) -> None:
    from drill_env.calibrated_plant import load_plant
    from drill_env.measured_log import read_log

    for reader in (read_log, load_plant):
        start = time.perf_counter()
        with pytest.raises(ValueError, match=r"is (a folder|not a regular file)"):
            reader(specials[kind])
        assert time.perf_counter() - start < 1.0


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{"format": NaN}', r"NaN is not allowed"),
        ('{"format": 1e400}', r"the number '1e400' is beyond the float range"),
        ('{"format": ' + "9" * 400 + "}", r"the integer '9+\.\.\.9+' is beyond the float range"),
        ('{"format": 1, "format": 2}', r"field 'format' appears twice"),
        ("[" * 100_000 + "]" * 100_000, r"nested too deeply"),
        ('{"\x1b[2J": 1', r"is not JSON"),
    ],
    ids=["nan", "float", "int", "repeated", "deep", "broken"],
)
def test_hostile_plant_files_are_refused_on_one_line(tmp_path: Path, text: str, match: str) -> None:
    from drill_env.calibrated_plant import load_plant

    with pytest.raises(ValueError, match=match) as caught:
        load_plant(_log(tmp_path, text, "plant.json"))
    assert _safe(str(caught.value))


# ------------------------------------------------------------------ property tests
LARGE = settings(deadline=None, max_examples=2_000, suppress_health_check=[HealthCheck.too_slow])
_ARGV = st.lists(
    st.one_of(
        st.text(max_size=40),
        st.sampled_from(["--results", "--out", "--gains-file", "--run-dir", "--", "/dev/null"]),
        st.builds(lambda o, v: f"{o}={v}", st.sampled_from(["--results", "--out"]), st.text()),
    ),
    max_size=8,
)


def _check_preflight(argv: list[str]) -> None:
    problem = refused_path(argv)
    assert problem is None or (_safe(problem) and "\n" not in problem)
    if problem is None:
        assert not any(a in ("/dev/null", "--results=/dev/null") for a in argv)


@SMALL
@given(_ARGV)
def test_preflight_never_fails_and_reports_safely(argv: list[str]) -> None:
    _check_preflight(argv)


@pytest.mark.slow
@LARGE
@given(_ARGV)
def test_preflight_never_fails_and_reports_safely_long(argv: list[str]) -> None:
    _check_preflight(argv)


_LOG_TEXT = st.one_of(
    st.binary(max_size=300),
    st.builds(
        lambda rows: "time_s,top_speed_rad_s\n" + "\n".join(",".join(r) for r in rows),
        st.lists(
            st.lists(
                st.one_of(
                    st.floats(allow_nan=True, allow_infinity=True).map(repr),
                    st.integers(-(10**400), 10**400).map(str),
                    st.text(max_size=6),
                ),
                min_size=1,
                max_size=3,
            ),
            max_size=8,
        ),
    ),
)


def _check_log(tmp_path: Path, data: str | bytes) -> None:
    from drill_env.measured_log import read_log

    path = _log(tmp_path, data)
    try:
        log = read_log(path)
    except ValueError as err:
        assert _safe(str(err)), str(err)[:200]
        return
    assert np.all(np.isfinite(log.time_s)) and np.all(np.diff(log.time_s) > 0)
    assert all(np.all(np.isfinite(v)) for v in log.columns.values())


@SMALL
@given(_LOG_TEXT)
def test_any_log_is_read_finite_or_refused_safely(tmp_path_factory: Any, data: Any) -> None:
    _check_log(tmp_path_factory.mktemp("log"), data)


@pytest.mark.slow
@LARGE
@given(_LOG_TEXT)
def test_any_log_is_read_finite_or_refused_safely_long(tmp_path_factory: Any, data: Any) -> None:
    _check_log(tmp_path_factory.mktemp("log"), data)


_JSON_TEXT = st.one_of(
    st.text(max_size=200),
    st.recursive(
        st.one_of(
            st.none(),
            st.booleans(),
            st.floats(),
            st.integers(-(10**400), 10**400),
            st.text(max_size=10),
        ),
        lambda inner: st.one_of(
            st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)
        ),
        max_leaves=20,
    ).map(lambda v: json.dumps(v)),
)


@SMALL
@given(_JSON_TEXT)
def test_any_plant_file_is_refused_on_one_safe_line(tmp_path_factory: Any, text: str) -> None:
    from drill_env.calibrated_plant import load_plant

    path = _log(tmp_path_factory.mktemp("plant"), text, "plant.json")
    with pytest.raises(ValueError) as caught:  # none of these is a plant
        load_plant(path)
    assert _safe(str(caught.value)), str(caught.value)[:300]


# ------------------------------------------------- a run folder's links are not followed
@pytest.mark.parametrize("where", ["config.json", "progress-resumed-at-64.csv", "checkpoints/x"])
def test_resume_refuses_a_run_folder_holding_links(tmp_path: Path, where: str) -> None:
    run_dir = tmp_path / "run"
    (run_dir / "checkpoints" / "steps_64").mkdir(parents=True)
    (run_dir / "checkpoints" / "steps_64" / "training.json").write_text("{}")
    notes = tmp_path / "notes.txt"
    notes.write_text("mine")
    (run_dir / where).symlink_to(notes)
    with pytest.raises(ValueError, match=r"is a symbolic link: drill-gym train writes only"):
        _resume(run_dir)
    assert notes.read_text() == "mine"


def test_overwrite_does_not_read_a_fifo_as_the_run_record(tmp_path: Path) -> None:
    from agents.train import _is_run_folder

    run_dir = tmp_path / "run"
    run_dir.mkdir()
    os.mkfifo(run_dir / "config.json")
    start = time.perf_counter()
    assert not _is_run_folder(run_dir)
    assert time.perf_counter() - start < 1.0
    (run_dir / "config.json").unlink()
    (run_dir / "config.json").write_text('{"exp_name": 1, "total_timesteps": 1, "n_steps": NaN}')
    assert not _is_run_folder(run_dir)


def test_train_refuses_a_save_dir_holding_other_files(tmp_path: Path) -> None:
    from agents.train import _check_save_dir

    mine = tmp_path / "project"
    mine.mkdir()
    (mine / "config.json").write_text("my settings")
    with pytest.raises(ValueError, match=r"--save-dir .* holds other files"):
        _check_save_dir(TrainConfig(save_dir=str(mine)))
    (tmp_path / "link").symlink_to(mine)
    with pytest.raises(ValueError, match=r"exists and is not a folder"):
        _check_save_dir(TrainConfig(save_dir=str(tmp_path / "link")))
    _check_save_dir(TrainConfig(save_dir=str(tmp_path / "new")))
    _check_save_dir(TrainConfig(save_dir=str(ROOT / "agents/models/residual_ppo")))
    assert (mine / "config.json").read_text() == "my settings"


def test_the_command_line_prints_an_errors_notes_safely(capsys: pytest.CaptureFixture[str]) -> None:
    from experiments.arguments import run_command

    def fail() -> int:
        err = ValueError("wob_n = 'x' is out of range")
        note = "raised with kwargs {'wob_n': '\x1b[2J" + "x" * 10_000 + "'}"
        err.__notes__ = [note]  # type: ignore[attr-defined]  # add_note (Python 3.11)
        raise err

    assert run_command("drill-gym x", fail, debug=False) == 2
    line = capsys.readouterr().err
    assert line.count("\n") == 1 and "\x1b" not in line and len(line) < 1200
    assert "out of range; raised with kwargs {'wob_n': '\\x1b[2J" in line


@pytest.mark.parametrize("kind", ["bool", "timestamp", "text", "duplicate", "escape"])
def test_parquet_logs_hold_numbers_in_known_columns(tmp_path: Path, kind: str) -> None:
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")

    from drill_env.measured_log import read_log

    t = pa.array(np.arange(5) * 1e-3)
    second, names, match = {
        "bool": (pa.array([True] * 5), None, r"'top_speed_rad_s' is not numeric \(bool\)"),
        "timestamp": (pa.array(np.arange(5).astype("datetime64[ns]")), None, r"not numeric"),
        "text": (pa.array(["1"] * 5), None, r"not numeric \(string\)"),
        "duplicate": (t, ["time_s", "time_s"], r"'time_s' appear twice"),
        "escape": (t, ["time_s", "\x1b[2J"], r"unknown column\(s\) '\\x1b\[2J'"),
    }[kind]
    table = pa.Table.from_arrays([t, second], names=names or ["time_s", "top_speed_rad_s"])
    pq.write_table(table, tmp_path / "log.parquet")
    with pytest.raises(ValueError, match=match) as caught:
        read_log(tmp_path / "log.parquet")
    assert _safe(str(caught.value))


@pytest.mark.parametrize("command", sorted(SUBCOMMANDS))
@pytest.mark.parametrize("kind", ["fifo", "device", "socket"])
def test_every_command_refuses_a_special_file_at_once(
    command: str, kind: str, specials: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    for argv in (
        [command, str(specials[kind])],
        [command, "--out", str(specials[kind])],
        [command, f"--results={specials[kind]}"],
    ):
        start = time.perf_counter()
        assert cli_main(argv) == 2
        assert time.perf_counter() - start < 1.0
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith(f"drill-gym {command}: error: "), err


@pytest.mark.parametrize("env_id", ["DrillString-v0", "DrillStringCoupled-v0"])
@pytest.mark.parametrize(
    ("seed", "error", "match"),
    [
        ("x", TypeError, r"seed must be None, an integer >= 0 or a list of 2 of them, got 'x'"),
        (1.5, TypeError, r"got 1.5"),
        (True, TypeError, r"got True"),
        (-1, ValueError, r"seed = -1 is out of range: allowed an integer >= 0"),
        ([1], ValueError, r"seed list must have 2 entries, got 1"),
        ([1, -(10**400)], ValueError, r"seed\[1\] = -<an integer of \d+ bits> is out of range"),
        ([1, "\x1b[2J"], ValueError, r"seed\[1\] = '\\x1b\[2J' is out of range"),
    ],
    ids=["text", "float", "bool", "negative", "short", "huge", "escape"],
)
def test_vector_env_seeds_are_checked_alike(
    env_id: str, seed: Any, error: type, match: str
) -> None:
    env = gym.make_vec(env_id, num_envs=2)
    try:
        with pytest.raises(error, match=match):
            env.reset(seed=seed)
        env.reset(seed=[3, None])
        env.reset(seed=np.int64(4))
    finally:
        env.close()


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"n_steps": 10**9}, r"--n-steps 1000000000 x --num-envs 16 = 16000000000 decisions"),
        ({"num_envs": 10**6, "n_steps": 11}, r"= 11000000 decisions per rollout is out of range"),
        ({"total_timesteps": 10**20}, r"--total-timesteps = 1\d{20} is out of range"),
    ],
    ids=["n_steps", "num_envs", "total"],
)
def test_train_sizes_are_refused_before_anything_is_built(
    changes: dict[str, Any], match: str, tmp_path: Path
) -> None:
    from agents.train import train

    config = TrainConfig(run_dir=str(tmp_path / "run"), batch_size=11, **changes)
    start = time.perf_counter()
    with pytest.raises(ValueError, match=match):
        train(config)
    assert time.perf_counter() - start < 1.0 and not (tmp_path / "run").exists()


def test_a_memory_error_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    from experiments.arguments import run_command

    def fail() -> int:
        raise MemoryError("Unable to allocate 656. GiB for an array")

    assert run_command("drill-gym x", fail, debug=False) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not enough memory: Unable to allocate 656. GiB" in err


_SEEDS = st.one_of(
    st.none(),
    st.integers(-(10**400), 10**400),
    st.floats(),
    st.booleans(),
    st.text(max_size=5),
    st.lists(st.one_of(st.none(), st.integers(-5, 10**30), st.text(max_size=3)), max_size=4),
)


@SMALL
@given(_SEEDS, st.integers(1, 3))
def test_check_seeds_returns_one_seed_per_string_or_refuses(seed: Any, count: int) -> None:
    from drill_env.validation import check_seeds

    try:
        seeds = check_seeds(seed, count)
    except (TypeError, ValueError) as err:
        assert _safe(str(err)) and ("seed" in str(err))
        return
    assert len(seeds) == count
    assert all(s is None or (type(s) is int and s >= 0) for s in seeds)


# ------------------------------------------------------------- writing: whole, never via a link
def _writers(tmp_path: Path) -> dict[str, Any]:
    """Every kind of file writer of the package, each writing one small file to ``path``."""
    from agents.model_format import write_safetensors
    from drill_env.files import write_text
    from experiments.plots import save_figure
    from experiments.tables import write_csv, write_json

    def figure(path: Path) -> Path:
        from matplotlib.figure import Figure

        return save_figure(Figure(figsize=(1, 1)), path)

    def safetensors(path: Path) -> Path:
        write_safetensors(path, {"w": np.ones(3)})
        return path

    def log(path: Path) -> Path:
        from drill_env.measured_log import MeasuredLog, write_log_csv

        t = np.arange(3, dtype=np.float64) * 1e-3
        return write_log_csv(MeasuredLog(t, {"top_speed_rad_s": np.ones(3)}), path)

    return {
        "log": log,
        "json": lambda p: write_json({"a": 1}, p),
        "csv": lambda p: write_csv([{"a": 1}], p, ["a"]),
        "text": lambda p: write_text(p, "report\n"),
        "figure": figure,
        "safetensors": safetensors,
    }


WRITERS = ["json", "csv", "text", "figure", "safetensors", "log"]


@pytest.mark.parametrize("kind", WRITERS)
def test_a_writer_refuses_a_link_at_its_target(tmp_path: Path, kind: str) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    out = tmp_path / "out"
    out.mkdir()
    link = out / f"result.{kind}"
    link.symlink_to(notes)
    with pytest.raises(ValueError, match="is a symbolic link") as caught:
        _writers(tmp_path)[kind](link)
    assert notes.read_text() == "my notes" and link.is_symlink()
    assert sorted(p.name for p in out.iterdir()) == [link.name]  # no temporary file left
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("kind", WRITERS)
def test_a_writer_replaces_its_own_file_and_follows_no_stray_temporary(
    tmp_path: Path, kind: str
) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("my notes")
    target = tmp_path / "out" / f"result.{kind}"
    target.parent.mkdir()
    for stray in (target.with_name(target.name + ".tmp"), target.parent / f".{target.name}.tmp"):
        stray.symlink_to(notes)  # the old writers' fixed temporary names
    writer = _writers(tmp_path)[kind]
    writer(target)
    first = target.read_bytes()
    writer(target)  # its own earlier output: replaced
    assert target.read_bytes() == first and not target.is_symlink()
    assert notes.read_text() == "my notes"
    mask = os.umask(0)
    os.umask(mask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~mask  # as open(path, "w") would give


@pytest.mark.parametrize("kind", ["folder", "fifo"])
def test_a_writer_refuses_a_target_that_is_not_a_regular_file(tmp_path: Path, kind: str) -> None:
    from experiments.tables import write_json

    target = tmp_path / "result.json"
    if kind == "folder":
        target.mkdir()
    else:
        os.mkfifo(target)
    with pytest.raises(ValueError, match="exists and is not a regular file"):
        write_json({"a": 1}, target)


def test_a_failed_write_leaves_the_old_file_whole(tmp_path: Path) -> None:
    """A crash while writing (here an object JSON cannot hold, or an exception inside the
    block) leaves the previous file as it was and no temporary file beside it."""
    from drill_env.files import replacing
    from experiments.tables import write_json

    target = tmp_path / "tuned_gains.json"
    write_json({"old": 1.0}, target)
    before = target.read_bytes()
    with pytest.raises(TypeError):
        write_json({"new": object()}, target)
    with pytest.raises(KeyboardInterrupt), replacing(target) as f:
        f.write('{"half": ')
        raise KeyboardInterrupt
    assert target.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [target.name]


def test_tune_write_refuses_a_linked_gains_file_before_the_search(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    gains = ROOT / "baselines" / "tuned_gains.json"
    link = tmp_path / "gains.json"
    link.symlink_to(gains)
    before = gains.read_bytes()
    start = time.perf_counter()
    code = cli_main(["tune", "--write", "--gains-file", str(link), "--out", str(tmp_path / "o")])
    assert code == 2 and time.perf_counter() - start < 5.0
    assert "is a symbolic link" in capsys.readouterr().err
    assert gains.read_bytes() == before and not (tmp_path / "o").exists()


# ------------------------------------------------ every input is checked before --out is made
def _bad_inputs(folder: Path) -> dict[str, list[str]]:
    """One bad input per command that passes the parser and is refused by the command."""
    (folder / "model").mkdir()
    (folder / "model" / "config.json").write_text('{"name": "x"}')
    (folder / "bad.json").write_text("not json")
    (folder / "log.csv").write_text("time_s,x\n0,1\n")
    (folder / "notes.txt").write_text("notes")
    model, out = str(folder / "model"), str(folder / "out")
    return {
        "benchmark": [model, "--out", out],
        "calibrate": [str(folder / "log.csv"), "--window", "0:1", "--out", out],
        "compare": ["--controllers", f"{folder}/missing.py:X", "--no-agent", "--out", out],
        "convert": [str(folder / "notes.txt"), out],
        "coupled": ["--forces", "-1", "--out", out],
        "coupled-controllers": ["--agent", model, "--no-grid", "--out", out],
        "evaluate": [model, "--out", out],
        "map": ["--models", model, "--out", out],
        "probability-map": ["--results", str(folder / "notes.txt"), "--out", out],
        "realism": ["--results", str(folder / "notes.txt"), "--out", out],
        "replay": [
            str(folder / "bad.json"),
            str(folder / "log.csv"),
            "--window",
            "0:1",
            "--out",
            out,
        ],  # fmt: skip
        "sweep-train": ["--set", "nonsense=1", "--out", out],
        "train": ["--total-timesteps", "0", "--out", out],
        "tune": ["--write", "--gains-file", str(folder / "bad.json"), "--out", out],
        "waves": ["--depth", "-5", "--out", out],
    }


def test_every_command_has_a_bad_input_case(tmp_path: Path) -> None:
    assert sorted(_bad_inputs(tmp_path)) == sorted(SUBCOMMANDS)


@pytest.mark.parametrize("command", sorted(SUBCOMMANDS))
def test_a_refused_input_creates_no_output_folder(
    tmp_path: Path, command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = _bad_inputs(tmp_path)[command]
    assert cli_main([command, *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"drill-gym {command}: error: "), err
    assert not (tmp_path / "out").exists(), err


# ----------------------------------------------------- raw values never reach a message unbounded
class _Hostile:
    def __repr__(self) -> str:
        return "\x1b[2J" + "x" * 100_000


@pytest.mark.parametrize(
    "value",
    [_Hostile(), "\x1b[2J" * 10_000, 10**400, [1.0] * 10_000, "1"],
    ids=["object", "escapes", "huge-int", "long-list", "text"],
)
@pytest.mark.parametrize("argument", ["wob_n", "torque_nm", "duration_s", "step_s", "record_every"])
def test_the_chain_helpers_show_hostile_values_bounded(argument: str, value: Any) -> None:
    from drill_env.chain import chain_integrate_constant_torque, steady_drilling_torque_nm

    args: dict[str, Any] = dict(torque_nm=1e4, wob_n=1e5, duration_s=1.0)
    with pytest.raises((ValueError, TypeError)) as caught:
        chain_integrate_constant_torque("field_2500m", **{**args, argument: value})
    assert argument in str(caught.value) and _safe(str(caught.value)), str(caught.value)[:200]
    assert len(str(caught.value)) < 300
    if argument == "wob_n":
        with pytest.raises((ValueError, TypeError)) as caught:
            steady_drilling_torque_nm("field_2500m", value, 10.0)
        assert "wob_n" in str(caught.value) and len(str(caught.value)) < 300


def test_no_message_formats_a_raw_repr_of_a_value() -> None:
    """Messages show values through ``shown`` (bounded, escaped); ``!r`` is left only for
    ``str(...)`` (a string's ``repr`` is escaped, a path is bounded by the system) and
    ``where``, a file's name the code formats itself."""
    pattern = re.compile(r"\{([^{}!:]+?)!r\}")
    allowed = re.compile(r"^(str\(|where\b|self\.(name|env_kwargs|gains)$|float\()")
    found = []
    for package in ("drill_env", "baselines", "agents", "experiments"):
        for source in sorted((ROOT / package).rglob("*.py")):
            for number, line in enumerate(source.read_text().splitlines(), 1):
                for match in pattern.finditer(line):
                    expression = match.group(1).strip()
                    if not allowed.match(expression) and "__qualname__" not in expression:
                        found.append(f"{source.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not found, "\n".join(found)


# ----------------------------------------------- render_mode: our message, never Gymnasium's
@pytest.mark.parametrize(
    "env_id", ["DrillString-v0", "DrillStringField-v0", "DrillStringCoupled-v0"]
)
@pytest.mark.parametrize(
    "mode",
    ["x" * 1_000_000, "\x1b[2J", 5, ["human"], _Hostile()],
    ids=["long", "escapes", "int", "list", "object"],
)
def test_a_bad_render_mode_is_refused_by_the_env_before_gymnasium_prints_it(
    env_id: str, mode: Any, recwarn: pytest.WarningsRecorder
) -> None:
    with pytest.raises(ValueError, match=r"^render_mode = .* is not valid: allowed None") as caught:
        gym.make(env_id, render_mode=mode)
    assert _safe(str(caught.value)) and len(str(caught.value)) < 300
    assert not [w for w in recwarn if "render_mode" in str(w.message)]
