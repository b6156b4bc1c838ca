"""Checks of the command line that run before a subcommand's module is imported.

Importing a study loads NumPy, Numba and the compiled plants (seconds on a loaded machine), so
a path that can only hang or fail is refused here first, from its ``stat`` alone (nothing is
opened): any argument naming a FIFO, a socket or a device (``/dev/zero``), a folder given where
a file is read or written (``--results``, ``--gains-file``), a file given where a folder
is (``--out``, ``--run-dir``, ``--save-dir``), and either kind lying inside a file. Every other
check stays with the command. This
module uses the standard library only, and the error line has its one home here.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from typing import Final

__all__ = ["FILE_OPTIONS", "FOLDER_OPTIONS", "USAGE_ERROR", "error_line_format", "refused_path"]

USAGE_ERROR: Final = 2
"""Exit code of a user error (the argparse convention)."""

FILE_OPTIONS: Final = ("--results", "--gains-file")
"""Options whose value is a file that a command reads or writes."""
FOLDER_OPTIONS: Final = ("--out", "--run-dir", "--save-dir")
"""Options whose value is a folder that a command writes into."""
MAX_SHOWN_PATH: Final = 200
"""Longest path shown in a message (longer is cut with ...)."""
_SPECIAL: Final = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
)

error_line_format: Final = "{prog}: error: {message} (see {prog} --help)"
"""The one line that reports a user error of the command ``prog`` (``message`` one line)."""


def _shown(path: str) -> str:
    text = repr(path)  # control characters and lone surrogates escaped
    return text if len(text) <= MAX_SHOWN_PATH else text[: MAX_SHOWN_PATH - 3] + "..."


def _mode(path: str) -> int | None:
    """The mode of the file ``path`` names (links followed), or None if there is none."""
    if not path or "\x00" in path or len(path) > 4096:
        return None
    try:
        return os.stat(path).st_mode
    except (OSError, ValueError):
        return None


def _file_above(path: str) -> str | None:
    """The nearest existing folder above ``path`` when it is in fact a file (``path`` then
    cannot be made), or None."""
    if not path or "\x00" in path or len(path) > 4096:
        return None
    parent = os.path.dirname(os.path.normpath(path))
    for _ in range(256):
        if not parent or os.path.lexists(parent):
            break
        parent = os.path.dirname(parent)
    mode = _mode(parent) if parent else None
    return parent if mode is not None and not stat.S_ISDIR(mode) else None


def _problem(option: str | None, value: str) -> str | None:
    mode = _mode(value)
    if mode is None:
        above = _file_above(value) if option in FILE_OPTIONS + FOLDER_OPTIONS else None
        if above is not None:
            where = f"argument {option}: " if option in FOLDER_OPTIONS else f"{option} "
            return f"{where}{_shown(value)} lies inside {_shown(above)}, which is a file"
        return None
    # The wording of the checks these stand in for: argparse's for an output folder
    # (experiments.arguments.output_folder), the results database's for a file.
    if option in FOLDER_OPTIONS:
        what = f"argument {option}: {_shown(value)}"
    else:
        what = f"{option} {_shown(value)}" if option else _shown(value)
    for test, kind in _SPECIAL:
        if test(mode):
            return (
                f"{what} is {kind}: drill-gym reads and writes regular files "
                "and folders only; it is left as it is"
            )
    if option in FILE_OPTIONS and stat.S_ISDIR(mode):
        return f"{what} is a folder: expected a file (it is left as it is)"
    if option in FOLDER_OPTIONS and not stat.S_ISDIR(mode):
        return f"{what} is a file, not a folder: choose a folder"
    return None


def refused_path(argv: Sequence[str]) -> str | None:
    """The message refusing the first path of ``argv`` (a subcommand's arguments) that no
    command can use (see the module docstring), or None. Only ``stat`` is called."""
    option: str | None = None
    for token in argv:
        if token == "--":
            option = None
            continue
        if token.startswith("--"):
            name, equals, value = token.partition("=")
            if equals:
                problem = _problem(name, value)
                if problem:
                    return problem
                option = None
            else:
                option = name
            continue
        problem = _problem(option, token)
        if problem:
            return problem
        option = None
    return None
