"""The results database of the sweep runner (SQLite, the standard library's ``sqlite3``), and
the schemas every row is read back through.

One database file holds the results of any number of studies. Table ``studies`` has a row per
(settings hash, package version): the sweep's name and its settings as JSON; table
``results`` a row per finished item, keyed by (settings hash, package version, item), with the
task that made it and its record as JSON. A finished task is written in one transaction, so an
interrupted sweep (Ctrl-C, ``kill -9``, a power cut) leaves every finished task whole and
nothing of the others. The file runs in WAL mode with a busy timeout: several processes (two
sweeps, or Ray's driver and a second sweep) write to one file safely, each its own rows.

A file is opened only when it is a results database of drill-gym or a new one (a missing or
empty file): anything else (a text file, the JSON-lines results of earlier versions, an SQLite
database of another program, a folder, a FIFO, a device, a dangling link) is refused before any
work starts and left exactly as it was. A FIFO or device is never opened (``stat`` first).

A record is read back through its study's :data:`Schema` (:class:`Fields`, :class:`Values`,
:class:`Number`, :class:`Flag`, :class:`Name`, :class:`Text`, :class:`Exactly`,
:class:`Near`): a wrong type,
a non-finite number, a name with control characters or a setting that is not the study's is a
one-line error naming the file, the row and the field.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import stat
import time
import unicodedata
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Protocol

from drill_env import __version__
from drill_env.validation import printable, shown
from experiments.tables import json_clean

__all__ = [
    "APPLICATION_ID",
    "MAX_RECORD_CHARS",
    "SCHEMA_VERSION",
    "Exactly",
    "Fields",
    "Flag",
    "Name",
    "Near",
    "Number",
    "ResultsDatabase",
    "Schema",
    "SchemaError",
    "Text",
    "Values",
    "check_results_file",
    "exactly",
    "package_version",
]

APPLICATION_ID: Final = 0x44475352
"""SQLite ``application_id`` of a results database of drill-gym (``DGSR`` in ASCII)."""
SCHEMA_VERSION: Final = 1
"""SQLite ``user_version``: the layout of the tables below."""
SQLITE_MAGIC: Final = b"SQLite format 3\x00"
"""The first 16 bytes of every SQLite database file."""
BUSY_TIMEOUT_S: Final = 60.0
"""How long a writer waits for another one to finish its transaction, s."""
MAX_RECORD_CHARS: Final = 16 * 2**20
"""Longest record read back (characters of its JSON); a longer one is refused unread."""
NAME_MAX_CHARS: Final = 200
"""Longest name (controller, scenario, condition) in a record."""
TEXT_MAX_CHARS: Final = 4000
"""Longest free text (a note) in a record."""

_TABLES: Final = {
    "studies": ("settings_hash", "version", "sweep", "settings", "created_utc"),
    "results": ("settings_hash", "version", "item", "task", "record", "finished_utc"),
}
"""The columns of each table, in order (the schema a file must have)."""
_CREATE: Final = (
    "CREATE TABLE studies ("
    " settings_hash TEXT NOT NULL, version TEXT NOT NULL, sweep TEXT NOT NULL,"
    " settings TEXT NOT NULL, created_utc TEXT NOT NULL,"
    " PRIMARY KEY (settings_hash, version))",
    "CREATE TABLE results ("
    " settings_hash TEXT NOT NULL, version TEXT NOT NULL, item TEXT NOT NULL,"
    " task TEXT NOT NULL, record TEXT NOT NULL, finished_utc TEXT NOT NULL,"
    " UNIQUE (settings_hash, version, item),"
    " FOREIGN KEY (settings_hash, version) REFERENCES studies (settings_hash, version))",
)
_SIDE_FILES: Final = ("-wal", "-shm", "-journal")
"""Files SQLite keeps beside a database."""


def package_version() -> str:
    """The version of drill-string-gym that writes and reads the results."""

    return str(__version__)


# -------------------------------------------------------------------------------- schemas
class SchemaError(ValueError):
    """A record does not fit its schema; ``str()`` names the field (``severity[3]``)."""


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _at(where: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{where}[{key}]"
    return f"{where}.{key}" if where else key


class Schema(Protocol):
    """What a value read back from the database must be."""

    def check(self, value: Any, where: str) -> None:
        """Raise :class:`SchemaError` naming ``where`` (the field's path) if ``value`` does not
        fit."""
        ...


@dataclass(frozen=True)
class Number:
    """A finite number (not a boolean) in ``[low, high]``; ``None`` (a non-finite result, as
    JSON writes it) only when ``nullable``; a whole number when ``integer``."""

    nullable: bool = True
    integer: bool = False
    low: float = -math.inf
    high: float = math.inf

    def check(self, value: Any, where: str) -> None:
        if value is None and self.nullable:
            return
        kind = "an integer" if self.integer else "a finite number"
        ok = isinstance(value, int) if self.integer else isinstance(value, (int, float))
        if isinstance(value, bool) or not ok:
            raise SchemaError(f"{where} = {_shown(value)} is not {kind}")
        try:
            number = float(value)
        except OverflowError:
            number = math.inf
        if not math.isfinite(number):
            raise SchemaError(f"{where} = {_shown(value)} is not {kind}")
        if not self.low <= number <= self.high:
            raise SchemaError(
                f"{where} = {_shown(value)} is out of range: allowed [{self.low:g}, {self.high:g}]"
            )


@dataclass(frozen=True)
class Flag:
    """``true`` or ``false``."""

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, bool):
            raise SchemaError(f"{where} = {_shown(value)} is not true or false")


def _printable(value: Any, where: str, what: str, longest: int) -> None:
    if not isinstance(value, str):
        raise SchemaError(f"{where} = {_shown(value)} is not {what} (a string)")
    if len(value) > longest:
        raise SchemaError(f"{where}: {what} of {len(value)} characters: allowed at most {longest}")
    if any(unicodedata.category(c)[0] == "C" for c in value):
        raise SchemaError(f"{where} = {_shown(value)} has control characters")


@dataclass(frozen=True)
class Name:
    """A name (a controller, a scenario, a condition): a non-empty string of printable
    characters, at most :data:`NAME_MAX_CHARS`."""

    def check(self, value: Any, where: str) -> None:
        _printable(value, where, "a name", NAME_MAX_CHARS)
        if not value.strip():
            raise SchemaError(f"{where} = {_shown(value)} is not a name (it is blank)")


@dataclass(frozen=True)
class Text:
    """Free text of printable characters (may be empty), at most :data:`TEXT_MAX_CHARS`."""

    def check(self, value: Any, where: str) -> None:
        _printable(value, where, "a text", TEXT_MAX_CHARS)


def _same(a: Any, b: Any) -> bool:
    """Whether two JSON values are equal, a boolean never equal to a number."""
    if isinstance(a, bool) or isinstance(b, bool):
        return isinstance(a, bool) and isinstance(b, bool) and a == b
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return a == b
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    return type(a) is type(b) and bool(a == b)


def as_json(value: Any) -> Any:
    """``value`` as it reads back from its JSON text (non-finite floats as ``None``)."""
    return json.loads(json.dumps(json_clean(value), allow_nan=False))


@dataclass(frozen=True)
class Exactly:
    """Exactly ``value`` (as JSON: a setting of the study the record must carry unchanged)."""

    value: Any

    def check(self, value: Any, where: str) -> None:
        expected = as_json(self.value)
        if not _same(value, expected):
            raise SchemaError(f"{where} = {_shown(value)} is not this study's {_shown(expected)}")


@dataclass(frozen=True)
class Near:
    """A finite number within ``tolerance`` (relative, at least absolute) of ``value``: a
    setting the work reports after its own rounding (a duration as a whole number of steps
    times the step)."""

    value: float
    tolerance: float = 1e-9

    def check(self, value: Any, where: str) -> None:
        Number(nullable=False).check(value, where)
        if abs(float(value) - self.value) > self.tolerance * max(1.0, abs(self.value)):
            raise SchemaError(f"{where} = {_shown(value)} is not this study's {shown(self.value)}")


def exactly(values: Mapping[str, Any]) -> dict[str, Exactly]:
    """``{key: Exactly(value)}`` for each entry of ``values``."""
    return {key: Exactly(value) for key, value in values.items()}


@dataclass(frozen=True)
class Values:
    """A list of ``item`` values, of ``length`` of them when it is given."""

    item: Schema
    length: int | None = None

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, list):
            raise SchemaError(f"{where} = {_shown(value)} is not a list")
        if self.length is not None and len(value) != self.length:
            raise SchemaError(f"{where} has {len(value)} values: expected {self.length}")
        for k, entry in enumerate(value):
            self.item.check(entry, _at(where, k))


@dataclass(frozen=True)
class Fields:
    """An object with the fields ``required`` (each present), ``optional`` (each may be) and,
    when ``rest`` is given, any other field (named by a :class:`Name`) that fits ``rest``."""

    required: Mapping[str, Schema]
    optional: Mapping[str, Schema] = field(default_factory=dict)
    rest: Schema | None = None

    def check(self, value: Any, where: str) -> None:
        if not isinstance(value, dict):
            raise SchemaError(f"{where or 'record'} = {_shown(value)} is not an object")
        for key, schema in self.required.items():
            if key not in value:
                raise SchemaError(f"{_at(where, key)} is missing")
            schema.check(value[key], _at(where, key))
        for key, entry in value.items():
            if key in self.required:
                continue
            chosen = self.optional.get(key, self.rest)
            if chosen is None:
                raise SchemaError(f"{_at(where, _shown(key))} is not a field of this record")
            if key not in self.optional:
                Name().check(key, f"{where or 'record'}: field name")
            chosen.check(entry, _at(where, key))


# ------------------------------------------------------------------------------- the file
_KINDS: Final = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _refuse(path: Path, why: str) -> ValueError:
    return ValueError(
        f"--results {str(path)!r} {why}: it is left as it is; choose another file (a new file "
        "becomes a results database)"
    )


def _kind(mode: int) -> str | None:
    """What a file of ``mode`` is, when it is not a regular file."""
    for test, name in _KINDS:
        if test(mode):
            return name
    return None if stat.S_ISREG(mode) else "not a regular file"


def check_results_file(path: Path) -> Path:
    """The file a results database at ``path`` lives in, after checking that it is one, or
    that it does not exist yet (or is empty); reads at most its first 100 bytes.

    A symbolic link is followed to its target, which is checked the same way (a dangling link
    is refused). Nothing is created, written or truncated.

    Raises:
        ValueError: The file is anything but a results database of drill-gym or a new file.
        OSError: It cannot be read.
    """
    path = Path(path)
    target = path
    if path.is_symlink():
        target = Path(os.path.realpath(path))
        if not os.path.lexists(target):
            raise _refuse(path, "is a symbolic link to a file that does not exist")
    try:
        status = os.stat(target)
    except FileNotFoundError:
        status = None
    except NotADirectoryError:
        raise _refuse(path, "is inside a file, not a folder") from None
    except OSError as err:  # a loop of links, a name too long, no permission
        raise OSError(f"--results {str(path)!r} cannot be examined: {err.strerror}") from None
    if status is not None:
        kind = _kind(status.st_mode)
        if kind is not None:
            raise _refuse(path, f"is {kind}, not a results database")
        if status.st_size:
            _check_header(path, target)
    for suffix in _SIDE_FILES:
        side = Path(f"{target}{suffix}")
        if os.path.lexists(side) and (side.is_symlink() or not side.is_file()):
            raise _refuse(path, f"has a {suffix} file beside it that is not SQLite's ({side})")
    return target


def _check_header(path: Path, target: Path) -> None:
    """Refuse ``target`` unless its first bytes are those of a results database (or of an
    SQLite file without an application id, checked further once it is open)."""
    descriptor = os.open(target, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0))
    try:
        kind = _kind(os.fstat(descriptor).st_mode)
        if kind is not None:  # replaced since the stat above
            raise _refuse(path, f"is {kind}, not a results database")
        head = os.read(descriptor, 100)
    finally:
        os.close(descriptor)
    if not head.startswith(SQLITE_MAGIC) or len(head) < 100:
        if head.lstrip()[:1] == b"{" and b'"sweep"' in head:
            raise _refuse(
                path,
                "is a JSON-lines results file of an earlier version (results are now kept in "
                "an SQLite database)",
            )
        raise _refuse(path, "is not a results database (not an SQLite file)")
    application_id = int.from_bytes(head[68:72], "big")
    user_version = int.from_bytes(head[60:64], "big")
    if application_id not in (0, APPLICATION_ID):
        raise _refuse(
            path, f"is an SQLite database of another program (application id {application_id:#x})"
        )
    if application_id == APPLICATION_ID and user_version != SCHEMA_VERSION:
        raise _refuse(
            path,
            f"is a results database of layout {user_version}: this version reads layout "
            f"{SCHEMA_VERSION}",
        )


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a finite number")


@dataclass
class ResultsDatabase:
    """An open results database, tied to one study (its sweep name, settings and the package
    version); made by :meth:`open`.

    Attributes:
        path: The file as the user named it.
        sweep: The sweep's name.
        settings_hash: SHA-256 of the sweep's name and settings
            (:func:`experiments.sweep.spec_hash`).
        version: The package version (:func:`package_version`).
        other_rows: Rows of other settings or versions in the file when it was opened (left
            as they are).
    """

    path: Path
    sweep: str
    settings_hash: str
    version: str
    connection: sqlite3.Connection
    other_rows: int = 0

    @classmethod
    def open(
        cls,
        path: Path,
        sweep: str,
        settings: Mapping[str, Any],
        settings_hash: str,
        *,
        resume: bool = False,
        overwrite: bool = False,
        version: str | None = None,
        read_only: bool = False,
    ) -> ResultsDatabase:
        """Open (or create) the results database ``path`` for the study ``sweep`` with
        ``settings``, before any of its work runs.

        Without ``resume`` a file that already holds rows of these settings and version is
        refused, unless ``overwrite``, which deletes exactly those rows. With ``read_only``
        the file must exist and nothing is written (to :meth:`load` its rows).

        Raises:
            ValueError: The file is not a results database (it is left as it was), or it
                holds rows of these settings and neither ``resume`` nor ``overwrite`` is set.
            OSError: The file or its folder cannot be made or written (or, ``read_only``,
                the file does not exist).
        """
        if resume and overwrite:
            raise ValueError("--resume and --overwrite exclude each other: choose one")
        path = Path(path)
        target = check_results_file(path)
        version = package_version() if version is None else version
        if read_only and not target.is_file():
            raise FileNotFoundError(f"results database {str(path)!r} does not exist")
        if not read_only:
            target.parent.mkdir(parents=True, exist_ok=True)
        try:
            connection = sqlite3.connect(
                f"{target.absolute().as_uri()}?mode={'ro' if read_only else 'rwc'}",
                timeout=BUSY_TIMEOUT_S,
                isolation_level=None,
                uri=True,
            )
        except sqlite3.Error as err:
            raise OSError(f"--results {str(path)!r}: cannot open it ({err})") from None
        # The file's schema runs no function with side effects (SQLite's trusted_schema).
        connection.execute("PRAGMA trusted_schema = OFF")
        database = cls(path, sweep, settings_hash, version, connection)
        try:
            database._prepare(writable=not read_only)
            if not read_only:
                database._claim(settings, resume=resume, overwrite=overwrite)
        except sqlite3.Error as err:
            connection.close()
            raise database._failure(err) from None
        except BaseException:
            connection.close()
            raise
        return database

    def _failure(self, err: sqlite3.Error) -> Exception:
        text = str(err)
        if isinstance(err, sqlite3.DatabaseError) and "not a database" in text:
            return _refuse(self.path, "is not a results database (not an SQLite file)")
        return OSError(f"--results {str(self.path)!r}: {text}")

    def _prepare(self, writable: bool = True) -> None:
        """Make a new file a results database (``writable``), or check that the file is
        one."""
        db = self.connection
        db.execute("BEGIN IMMEDIATE" if writable else "BEGIN")
        try:
            application_id = db.execute("PRAGMA application_id").fetchone()[0]
            user_version = db.execute("PRAGMA user_version").fetchone()[0]
            objects = db.execute("SELECT type, name FROM sqlite_master").fetchall()
            if application_id == 0 and user_version == 0 and not objects and not writable:
                raise _refuse(self.path, "is empty: not a results database yet")
            if application_id == 0 and user_version == 0 and not objects:
                db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                for statement in _CREATE:
                    db.execute(statement)
            elif application_id != APPLICATION_ID:
                raise _refuse(self.path, "is an SQLite database of another program")
            elif user_version != SCHEMA_VERSION:
                raise _refuse(
                    self.path,
                    f"is a results database of layout {user_version}: this version reads "
                    f"layout {SCHEMA_VERSION}",
                )
            else:
                extra = [
                    f"{printable(kind, 20)} {_shown(name)}"
                    for kind, name in objects
                    if not (kind == "table" and name in _TABLES)
                    and not (kind == "index" and str(name).startswith("sqlite_autoindex_"))
                ]
                if extra:
                    more = f" and {len(extra) - 5} more" if len(extra) > 5 else ""
                    raise _refuse(
                        self.path,
                        f"has {', '.join(extra[:5])}{more}, which a results database has not",
                    )
                for (table, columns), statement in zip(_TABLES.items(), _CREATE, strict=True):
                    found = tuple(
                        row[1] for row in db.execute(f"PRAGMA table_info({table})").fetchall()
                    )
                    if found != columns:
                        raise _refuse(
                            self.path,
                            f"has table {shown(table)} with columns {list(found)}: a results "
                            f"database has {list(columns)}",
                        )
                    (sql,) = db.execute(
                        "SELECT sql FROM sqlite_master WHERE type = 'table' AND name = ?",
                        (table,),
                    ).fetchone()
                    if sql != statement:  # the same columns, other types or constraints
                        raise _refuse(
                            self.path, f"has a table {shown(table)} other than a results database's"
                        )
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise
        if writable:
            db.execute("PRAGMA journal_mode = WAL")
            db.execute("PRAGMA synchronous = NORMAL")

    def _claim(self, settings: Mapping[str, Any], *, resume: bool, overwrite: bool) -> None:
        """Refuse, or delete (``overwrite``), rows of this study when not resuming; register
        the study."""
        db = self.connection
        key = (self.settings_hash, self.version)
        db.execute("BEGIN IMMEDIATE")
        try:
            (mine,) = db.execute(
                "SELECT count(*) FROM results WHERE settings_hash = ? AND version = ?", key
            ).fetchone()
            (total,) = db.execute("SELECT count(*) FROM results").fetchone()
            self.other_rows = int(total) - int(mine)
            if mine and not resume:
                if not overwrite:
                    raise ValueError(
                        f"--results {str(self.path)!r} already holds {mine} results of these "
                        f"settings (sweep {shown(self.sweep)}, version {self.version}): add --resume "
                        "to keep them and run only the missing items, or --overwrite to delete "
                        "them and run again"
                    )
                db.execute("DELETE FROM results WHERE settings_hash = ? AND version = ?", key)
            text = json.dumps(json_clean(dict(settings)), sort_keys=True, allow_nan=False)
            db.execute(
                "INSERT INTO studies VALUES (?, ?, ?, ?, ?) ON CONFLICT DO NOTHING",
                (*key, self.sweep, text, _now()),
            )
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise

    def load(
        self, items: Iterable[str], schema_of: Callable[[str], Schema]
    ) -> dict[str, dict[str, Any]]:
        """The records of this study (same settings and version) by item, each read back
        through ``schema_of(item)``.

        Raises:
            ValueError: A row that is not an item of the study or whose record does not fit
                its schema; the message names the file, the row id and the item.
        """
        wanted = set(items)
        records: dict[str, dict[str, Any]] = {}
        try:
            rows = self.connection.execute(
                "SELECT rowid, item, typeof(record), length(record),"
                " CASE WHEN length(record) <= ? THEN record END"
                " FROM results WHERE settings_hash = ? AND version = ? ORDER BY rowid",
                (MAX_RECORD_CHARS, self.settings_hash, self.version),
            ).fetchall()
        except sqlite3.Error as err:
            raise self._failure(err) from None
        for rowid, item, kind, length, text in rows:
            where = f"results database {str(self.path)!r}: row {rowid} (item {_shown(item)})"
            if not isinstance(item, str) or item not in wanted:
                raise ValueError(f"{where}: not an item of this study {shown(self.sweep)}")
            if item in records:
                raise ValueError(f"{where}: a second row of this item")
            if kind != "text":
                raise ValueError(f"{where}: the record is {kind}, not JSON text")
            if text is None:
                raise ValueError(
                    f"{where}: the record has {length} characters: allowed at most "
                    f"{MAX_RECORD_CHARS}"
                )
            try:
                record = json.loads(text, parse_constant=_reject_constant)
            except (ValueError, RecursionError) as err:
                raise ValueError(f"{where}: the record is not valid JSON ({err})") from None
            try:
                schema_of(item).check(record, "")
            except SchemaError as err:
                raise ValueError(f"{where}: {err}") from None
            records[item] = record
        return records

    def add(self, task: str, records: Mapping[str, Mapping[str, Any]]) -> None:
        """Write the records of one finished task in one transaction (an item already there,
        written by a concurrent run of the same study, is kept)."""
        finished = _now()
        rows = [
            (
                self.settings_hash,
                self.version,
                item,
                task,
                json.dumps(record, allow_nan=False),
                finished,
            )
            for item, record in records.items()
        ]
        db = self.connection
        try:
            db.execute("BEGIN IMMEDIATE")
            try:
                db.executemany(
                    "INSERT INTO results VALUES (?, ?, ?, ?, ?, ?) ON CONFLICT DO NOTHING", rows
                )
                db.execute("COMMIT")
            except BaseException:
                if db.in_transaction:
                    db.execute("ROLLBACK")
                raise
        except sqlite3.Error as err:
            raise self._failure(err) from None

    def close(self) -> None:
        """Close the connection (the file stays a valid database at every moment)."""
        self.connection.close()
