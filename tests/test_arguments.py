"""The shared option checks of :mod:`experiments.arguments`: an output folder (``--out``) that
is a file, lies inside one or cannot be written is refused by every command when it parses its
options, before any work, on one line, and the file is left as it was."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from experiments.arguments import check_output_folder, run_command
from experiments.cli import main as cli_main
from experiments.train import main as train_main

COMMANDS = {
    "compare": ["compare", "--no-agent"],
    "map": ["map"],
    "evaluate": ["evaluate"],
    "probability-map": ["probability-map"],
    "realism": ["realism"],
    "waves": ["waves"],
    "tune": ["tune"],
    "sweep-train": ["sweep-train"],
}
"""Every command with an output folder, as typed (its other options at their defaults)."""
DEFAULT_OUT_IS_NONE = ("evaluate", "tune")
"""Commands whose default folder depends on other options (checked once it is known)."""


def _notes(path: Path) -> tuple[bytes, int]:
    return path.read_bytes(), path.stat().st_mtime_ns


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    code = cli_main(argv)
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert err.startswith(f"drill-gym {argv[0]}: error: argument --out: "), err
    return err


@pytest.mark.parametrize("command", list(COMMANDS))
def test_out_naming_a_file_is_refused_before_any_work(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    notes = tmp_path / "notes.txt"
    notes.write_text("mine\n")
    before = _notes(notes)
    err = _refused([*COMMANDS[command], "--out", str(notes)], capsys)
    assert f"{str(notes)!r} is a file, not a folder" in err
    err = _refused([*COMMANDS[command], "--out", str(notes / "sub")], capsys)
    assert f"lies inside {str(notes)!r}, which is a file" in err
    assert _notes(notes) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]  # nothing else made


@pytest.mark.parametrize("command", ["map", "compare", *DEFAULT_OUT_IS_NONE])
def test_a_default_output_folder_inside_a_file_is_refused(
    command: str,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``results`` is a user's file: the default folders (results/, results/evaluate,
    results/tune/ENV) are refused, the file kept."""
    monkeypatch.chdir(tmp_path)
    Path("results").write_text("mine\n")
    before = _notes(Path("results"))
    err = _refused(COMMANDS[command], capsys)
    assert "'results'" in err and ("which is a file" in err or "is a file, not a folder" in err)
    assert _notes(Path("results")) == before


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root may write anywhere"
)
def test_an_unwritable_output_folder_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        err = _refused(["map", "--out", str(locked / "new")], capsys)
        assert f"the folder {str(locked)!r} is not writable" in err
    finally:
        locked.chmod(0o700)


def test_check_output_folder_accepts_new_and_existing_folders(tmp_path: Path) -> None:
    assert check_output_folder(tmp_path) == tmp_path
    assert check_output_folder(tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert not (tmp_path / "a").exists()  # checked, not made
    assert sorted(tmp_path.iterdir()) == []  # the write check leaves nothing behind
    (tmp_path / "link").symlink_to(tmp_path / "missing")
    with pytest.raises(ValueError, match=r"'.*link' is a FIFO, a device or a broken link, not"):
        check_output_folder(tmp_path / "link")  # a dangling link is not a folder
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(
        ValueError, match=r"'.*fifo' is a FIFO, a device or a broken link, not a folder"
    ):
        check_output_folder(tmp_path / "fifo")


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_folder_that_takes_no_entries_is_refused_before_any_work(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``/proc`` passes the permission bits for root but takes no new folder: refused at
    once, whoever runs the tests."""
    err = _refused(["compare", "--out", "/proc/drill-gym-results"], capsys)
    assert "'/proc/drill-gym-results'" in err
    assert "takes no new entries" in err or "is not writable" in err
    assert "compare (serial)" not in err  # no run started


def test_train_refuses_a_run_folder_that_is_a_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``train --out`` (its ``--run-dir``) is refused before the command is imported, and
    by the training itself, before it starts."""
    notes = tmp_path / "notes.txt"
    notes.write_text("mine\n")
    before = _notes(notes)
    assert cli_main(["train", "--out", str(notes), "--total-timesteps", "100"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--out: {str(notes)!r} is a file" in err, err
    argv = ["--run-dir=" + str(notes), "--total-timesteps", "100"]
    assert run_command("drill-gym train", lambda: train_main(argv), debug=False) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--run-dir {str(notes)!r} is a file" in err, err
    assert _notes(notes) == before
