"""The results database: every file that is not one is refused before any work and left
byte for byte as it was; every row is read back through its study's schema, and a row that
does not fit is a one-line error naming the file, the row and the item."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sqlite3
import stat
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from experiments.cli import main as cli_main
from experiments.results_db import (
    APPLICATION_ID,
    Exactly,
    Fields,
    Flag,
    Name,
    Near,
    Number,
    SchemaError,
    Text,
    Values,
    check_results_file,
)
from experiments.stick_slip_map import MapStudy
from experiments.sweep import read_results, run_sweep

WOBS = (60e3, 110e3, 160e3)
SPEEDS = (3.0, 7.0)
SHORT: dict[str, Any] = {"duration_s": 4.0, "window_s": 2.0, "noise_std_rad_s": 0.1, "seed": 5}
MAP_ARGV = ["map", "--wob-n", "2", "--speed-n", "1", "--duration", "1", "--window", "1"]


def small_map() -> MapStudy:
    return MapStudy(("stiff_pi",), WOBS, SPEEDS, task_cells=2, **SHORT)


@contextlib.contextmanager
def time_limit(seconds: int) -> Iterator[None]:
    """Fail instead of hanging (a FIFO opened for reading waits for a writer)."""

    def expired(*_: Any) -> None:
        raise TimeoutError(f"no answer within {seconds} s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


# --------------------------------------------------------------------- files that are refused
def _text(path: Path) -> Path:
    path.write_text("my notes: do not lose them\n")
    return path


def _old_results(path: Path) -> Path:
    path.write_text(
        '{"sweep": "map", "spec": {}, "spec_hash": "ab", "format": 1}\n'
        '{"task": "stiff_pi/rows0-0", "items": {"stiff_pi/row0": {}}}\n'
    )
    return path


def _link_to_notes(path: Path) -> Path:
    path.symlink_to(_text(path.with_name("notes.txt")))
    return path


def _dangling_link(path: Path) -> Path:
    path.symlink_to(path.with_name("nowhere.sqlite"))
    return path


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _folder(path: Path) -> Path:
    path.mkdir()
    (path / "inside.txt").write_text("x")
    return path


def _device(path: Path) -> Path:
    return Path("/dev/null")


def _other_program(path: Path) -> Path:
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        db.execute("CREATE TABLE accounts (name TEXT, balance REAL)")
        db.execute("INSERT INTO accounts VALUES ('me', 10.0)")
    return path


def _other_application(path: Path) -> Path:
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        db.execute("PRAGMA application_id = 1234")
        db.execute("CREATE TABLE t (x)")
    return path


def _our_id_other_tables(path: Path) -> Path:
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        db.execute("PRAGMA user_version = 1")
        db.execute("CREATE TABLE results (item TEXT, record TEXT)")
        db.execute("CREATE TABLE studies (x)")
    return path


def _our_columns_no_constraints(path: Path) -> Path:
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        db.execute("PRAGMA user_version = 1")
        db.execute("CREATE TABLE studies (settings_hash, version, sweep, settings, created_utc)")
        db.execute(
            "CREATE TABLE results (settings_hash, version, item, task, record, finished_utc)"
        )
    return path


def _link_loop(path: Path) -> Path:
    path.symlink_to(path)
    return path


def _newer_layout(path: Path) -> Path:
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        db.execute("PRAGMA user_version = 7")
        db.execute("CREATE TABLE results (x)")
    return path


def _short_binary(path: Path) -> Path:
    path.write_bytes(b"SQLite format 3\x00" + bytes(20))
    return path


REFUSED: dict[str, tuple[Callable[[Path], Path], str]] = {
    "text": (_text, r"is not a results database \(not an SQLite file\)"),
    "old-json-lines": (_old_results, r"is a JSON-lines results file of an earlier version"),
    "link-to-notes": (_link_to_notes, r"is not a results database \(not an SQLite file\)"),
    "dangling-link": (_dangling_link, r"is a symbolic link to a file that does not exist"),
    "fifo": (_fifo, r"is a FIFO \(named pipe\), not a results database"),
    "folder": (_folder, r"is a folder, not a results database"),
    "device": (_device, r"is a character device, not a results database"),
    "other-program": (_other_program, r"is an SQLite database of another program"),
    "other-application": (_other_application, r"another program \(application id 0x4d2\)"),
    "other-tables": (_our_id_other_tables, r"has table 'studies' with columns \['x'\]: a "),
    "no-constraints": (_our_columns_no_constraints, r"has a table 'studies' other than a "),
    "newer-layout": (_newer_layout, r"is a results database of layout 7: this version reads"),
    "short": (_short_binary, r"is not a results database \(not an SQLite file\)"),
}


def _snapshot(path: Path) -> Any:
    """What must not change: the bytes and times of a file (of a link's target), a folder's
    listing, the kind of anything else."""
    status = os.stat(path)
    if stat.S_ISREG(status.st_mode):
        return path.read_bytes(), status.st_mtime_ns, status.st_size
    if stat.S_ISDIR(status.st_mode):
        return sorted(p.name for p in path.iterdir()), status.st_mtime_ns
    return stat.S_IFMT(status.st_mode), status.st_mtime_ns


@pytest.mark.parametrize("kind", list(REFUSED))
def test_a_file_that_is_not_a_results_database_is_refused_untouched(
    kind: str, tmp_path: Path
) -> None:
    make, message = REFUSED[kind]
    path = make(tmp_path / "results.sqlite")
    before = _snapshot(path) if os.path.exists(path) else None
    listing = sorted(p.name for p in tmp_path.iterdir())
    for resume in (False, True):
        with time_limit(30), pytest.raises(ValueError, match=message) as err:
            run_sweep(small_map(), results_path=path, resume=resume, progress=False)
        assert "\n" not in str(err.value) and "it is left as it is" in str(err.value)
    with time_limit(30), pytest.raises(ValueError, match=message):
        read_results(path, small_map())
    assert (_snapshot(path) if os.path.exists(path) else None) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == listing  # no -wal, no -shm, nothing


@pytest.mark.parametrize("kind", ["text", "old-json-lines", "fifo", "device", "other-program"])
def test_the_command_refuses_it_on_one_line_before_any_work(
    kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    make, message = REFUSED[kind]
    path = make(tmp_path / "results.sqlite")
    before = _snapshot(path)
    out = tmp_path / "out"
    with time_limit(60):
        code = cli_main([*MAP_ARGV, "--no-progress", "--results", str(path), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("drill-gym map: error: "), err
    assert f"--results {str(path)!r}" in err
    assert _snapshot(path) == before
    assert not out.exists()  # nothing computed, nothing written


def test_a_side_file_of_sqlite_that_is_a_link_is_refused(tmp_path: Path) -> None:
    notes = _text(tmp_path / "notes.txt")
    (tmp_path / "r.sqlite-wal").symlink_to(notes)
    before = _snapshot(notes)
    with pytest.raises(ValueError, match=r"has a -wal file beside it that is not SQLite's"):
        run_sweep(small_map(), results_path=tmp_path / "r.sqlite", progress=False)
    assert _snapshot(notes) == before and not (tmp_path / "r.sqlite").exists()


def test_new_empty_and_linked_databases_are_accepted(tmp_path: Path) -> None:
    """A missing file (in a missing folder) and an empty one become results databases; a
    link to a results database is followed to it."""
    assert check_results_file(tmp_path / "a" / "new.sqlite") == tmp_path / "a" / "new.sqlite"
    empty = tmp_path / "empty.sqlite"
    empty.touch()
    outcome = run_sweep(small_map(), results_path=empty, progress=False)
    link = tmp_path / "link.sqlite"
    link.symlink_to(empty)
    assert read_results(link, small_map()) == outcome.records
    resumed = run_sweep(small_map(), results_path=link, resume=True, progress=False)
    assert resumed.loaded == 3 and resumed.ran == [] and link.is_symlink()
    with pytest.raises(FileNotFoundError, match=r"results database '.*missing.sqlite' does not"):
        read_results(tmp_path / "missing.sqlite", small_map())
    assert not (tmp_path / "missing.sqlite").exists()


def test_a_loop_of_links_is_one_error(tmp_path: Path) -> None:
    path = _link_loop(tmp_path / "loop.sqlite")
    with pytest.raises(OSError, match=r"'.*loop.sqlite' cannot be examined: Too many levels"):
        run_sweep(small_map(), results_path=path, progress=False)
    assert path.is_symlink()


def test_results_inside_a_file_are_refused(tmp_path: Path) -> None:
    notes = _text(tmp_path / "notes.txt")
    with pytest.raises(ValueError, match=r"is inside a file, not a folder"):
        run_sweep(small_map(), results_path=notes / "r.sqlite", progress=False)


# ---------------------------------------------------------------------- rows and schemas
@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A results database with the three rows of :func:`small_map`."""
    path = tmp_path_factory.mktemp("db") / "map.sqlite"
    run_sweep(small_map(), results_path=path, progress=False)
    return path


ROW1 = "item = 'stiff_pi/row1'"
EDITS: dict[str, tuple[str, str]] = {
    "string-for-number": (
        f"UPDATE results SET record = json_set(record, '$.severity[1]', 'x') WHERE {ROW1}",
        r"severity\[1\] = 'x' is not a finite number",
    ),
    "infinite": (
        f'UPDATE results SET record = replace(record, \'"severity": [\', \'"severity": '
        f"[1e999, ') WHERE {ROW1}",
        r"severity has 3 values: expected 2",
    ),
    "infinite-in-place": (
        f"UPDATE results SET record = json_set(record, '$.stuck_fraction', json('[1e999, 0.5]'))"
        f" WHERE {ROW1}",
        r"stuck_fraction\[0\] = inf is not a finite number",
    ),
    "nan-literal": (
        f'UPDATE results SET record = replace(record, \'"severity": [\', \'"severity": '
        f"[NaN, ') WHERE {ROW1}",
        r"the record is not valid JSON \(NaN is not a finite number\)",
    ),
    "huge-integer": (
        f"UPDATE results SET record = '{{\"severity\": [{10**400}, 1.0], ' || "
        f"substr(record, instr(record, '\"stuck_fraction\"')) WHERE {ROW1}",
        r"severity\[0\] = 1000000.* is not a finite number",
    ),
    "out-of-range": (
        f"UPDATE results SET record = json_set(record, '$.stuck_fraction[0]', 2.5) WHERE {ROW1}",
        r"stuck_fraction\[0\] = 2.5 is out of range: allowed \[0, 1\]",
    ),
    "negative-severity": (
        f"UPDATE results SET record = json_set(record, '$.severity[0]', -1.0) WHERE {ROW1}",
        r"severity\[0\] = -1.0 is out of range",
    ),
    "bool-for-number": (
        f"UPDATE results SET record = json_set(record, '$.severity[0]', json('true')) WHERE {ROW1}",
        r"severity\[0\] = True is not a finite number",
    ),
    "controller-with-escape": (
        f"UPDATE results SET record = json_set(record, '$.map.controller', "
        f"'stiff_pi' || char(27) || '[31m') WHERE {ROW1}",
        r"map.controller = 'stiff_pi\\x1b\[31m' is not this study's 'stiff_pi'",
    ),
    "controller-as-path": (
        f"UPDATE results SET record = json_set(record, '$.map.controller', '../../evil') "
        f"WHERE {ROW1}",
        r"map.controller = '../../evil' is not this study's 'stiff_pi'",
    ),
    "another-duration": (
        f"UPDATE results SET record = json_set(record, '$.map.duration_s', 50.0) WHERE {ROW1}",
        r"map.duration_s = 50.0 is not this study's 4.0",
    ),
    "missing-field": (
        f"UPDATE results SET record = json_remove(record, '$.stuck_fraction') WHERE {ROW1}",
        r"stuck_fraction is missing",
    ),
    "extra-field": (
        f"UPDATE results SET record = json_set(record, '$.evil', 1) WHERE {ROW1}",
        r"'evil' is not a field of this record",
    ),
    "not-json": (
        f"UPDATE results SET record = 'not json' WHERE {ROW1}",
        r"the record is not valid JSON",
    ),
    "deeply-nested": (
        f"UPDATE results SET record = '{'[' * 100000}' WHERE {ROW1}",
        r"the record is not valid JSON",
    ),
    "not-an-object": (
        f"UPDATE results SET record = '[1, 2]' WHERE {ROW1}",
        r"record = \[1, 2\] is not an object",
    ),
    "integer-column": (
        f"UPDATE results SET record = 42 WHERE {ROW1}",
        r"record = 42 is not an object",  # TEXT affinity: stored as the text '42'
    ),
    "blob-column": (
        f"UPDATE results SET record = CAST(record AS BLOB) WHERE {ROW1}",
        r"the record is blob, not JSON text",
    ),
    "unknown-item": (
        f"UPDATE results SET item = 'stiff_pi/row9' WHERE {ROW1}",
        r"\(item 'stiff_pi/row9'\): not an item of this study 'map'",
    ),
    "item-with-newline": (
        f"UPDATE results SET item = 'stiff_pi/row1' || char(10) || 'x' WHERE {ROW1}",
        r"\(item 'stiff_pi/row1\\nx'\): not an item of this study",
    ),
}


@pytest.mark.parametrize("edit", list(EDITS))
def test_a_row_that_does_not_fit_the_schema_is_a_one_line_error(
    edit: str, written: Path, tmp_path: Path
) -> None:
    statement, message = EDITS[edit]
    path = tmp_path / "map.sqlite"
    shutil.copy(written, path)
    with contextlib.closing(sqlite3.connect(path)) as db, db:
        (rowid,) = db.execute(f"SELECT rowid FROM results WHERE {ROW1}").fetchone()
        assert db.execute(statement).rowcount == 1
    for read in (
        lambda: read_results(path, small_map()),
        lambda: run_sweep(small_map(), results_path=path, resume=True, progress=False),
    ):
        with pytest.raises(ValueError, match=message) as err:
            read()
        text = str(err.value)
        assert text.startswith(f"results database {str(path)!r}: row {rowid} (item '")
        assert "\n" not in text


def test_a_too_long_record_is_refused_unread(
    written: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import experiments.results_db as results_db

    monkeypatch.setattr(results_db, "MAX_RECORD_CHARS", 50)
    with pytest.raises(ValueError, match=r"row 1 \(item 'stiff_pi/row0'\): the record has \d+ "):
        read_results(written, small_map())


def test_a_bad_row_on_the_command_line_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [*MAP_ARGV, "--no-plots", "--no-progress", "--out", str(tmp_path)]
    assert cli_main([*argv, "--resume"]) == 0
    capsys.readouterr()
    with contextlib.closing(sqlite3.connect(tmp_path / "stick_slip_map.sqlite")) as db, db:
        db.execute(
            "UPDATE results SET record = json_set(record, '$.map.parameters', '../x') "
            "WHERE item = 'stiff_pi/row1'"
        )
    assert cli_main([*argv, "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "row 2 (item 'stiff_pi/row1'): map.parameters = '../x'" in err


# ---------------------------------------------------------------------------- the schemas
@pytest.mark.parametrize(
    ("schema", "value", "message"),
    [
        (Number(), float("nan"), r"x = nan is not a finite number"),
        (Number(nullable=False), None, r"x = None is not a finite number"),
        (Number(integer=True), 1.5, r"x = 1.5 is not an integer"),
        (Number(high=1.0), 10**400, r"is out of range|is not a finite number"),
        (Flag(), 0, r"x = 0 is not true or false"),
        (Name(), 3, r"x = 3 is not a name \(a string\)"),
        (Name(), "  ", r"is not a name \(it is blank\)"),
        (Name(), "a\u202eb", r"has control characters"),
        (Name(), "x" * 201, r"a name of 201 characters: allowed at most 200"),
        (Text(), "line\nbreak", r"has control characters"),
        (Values(Number(), 2), [1.0], r"x has 1 values: expected 2"),
        (Exactly(1.0), True, r"x = True is not this study's 1.0"),
        (Exactly([1, "a"]), [1, "b"], r"is not this study's \[1, 'a'\]"),
        (Near(2.3), 2.31, r"x = 2.31 is not this study's 2.3"),
        (Near(2.3), "2.3", r"x = '2.3' is not a finite number"),
        (Fields({}, rest=Number()), {"a\x00": 1.0}, r"x: field name = 'a\\x00' has control"),
    ],
)
def test_schema_errors_name_the_field(schema: Any, value: Any, message: str) -> None:
    with pytest.raises(SchemaError, match=message):
        schema.check(value, "x")


def test_schemas_accept_what_they_describe() -> None:
    Fields(
        {"a": Number(), "b": Values(Flag(), 2), "c": Exactly({"k": [1.0, None]})},
        optional={"n": Text()},
        rest=Name(),
    ).check({"a": None, "b": [True, False], "c": {"k": [1.0, None]}, "n": "", "z": "stiff_pi"}, "")
