"""The one argument parser of every ``drill-gym`` subcommand, and its value checks.

Every user error of the command line ends the same way: ONE line on standard error,
``drill-gym SUB: error: MESSAGE (see drill-gym SUB --help)``, and exit code 2, whether argparse
found it (an unknown option, a value that does not parse) or the subcommand did (a value out of
range, an unknown controller name). The help of every option shows its default.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Final, NoReturn

from drill_env.validation import printable, shown
from drill_env.validation import shown as shown_value
from experiments.preflight import USAGE_ERROR, error_line_format

__all__ = [
    "BASE_SEED_HIGH",
    "SEED_HIGH",
    "ArgumentParser",
    "HelpFormatter",
    "check_output_folder",
    "check_output_option",
    "error_line",
    "names_type",
    "number_type",
    "one_line",
    "output_folder",
    "run_command",
    "seed_option",
    "seed_type",
]

SEED_HIGH: Final = 2**32 - 1
"""Largest seed a command takes when it uses the seed as it is (a reset or training seed)."""
BASE_SEED_HIGH: Final = 2**31 - 1
"""Largest seed a command takes when it adds an item's index to it (cell ``i`` of a map is
reset with ``seed + i``), so that every derived seed stays within :data:`SEED_HIGH`."""


MAX_MESSAGE_CHARS: Final = 1000
"""Longest error message printed (longer is cut with ...)."""


def one_line(text: str) -> str:
    """``text`` with every run of white space (newlines included) replaced by one space, and
    every other control character (escape sequences) shown escaped
    (:func:`drill_env.validation.printable`)."""
    return printable(" ".join(str(text).split()), MAX_MESSAGE_CHARS)


def error_line(prog: str, message: str) -> str:
    """The one line that reports a user error of the command ``prog``."""
    return error_line_format.format(prog=prog, message=one_line(message))


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Keeps the description's paragraphs as written and appends ``(default: X)`` to every
    option whose help does not state its default (switches that are off by default and options
    without a default say nothing)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if (
            "(default" in text
            or default is None
            or default is argparse.SUPPRESS
            or isinstance(default, bool)
            or action.nargs == 0
            or not action.option_strings
        ):
            return text
        if isinstance(default, (list, tuple)):
            shown = " ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in default)
        elif isinstance(default, float):
            shown = f"{default:g}"
        else:
            shown = str(default)
        return f"{text} (default: {shown.replace('%', '%%')})"


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` that reports a user error on one line and exits with 2.

    ``prog`` is the command as the user types it (``drill-gym compare``); the formatter is
    :class:`HelpFormatter` unless another is given.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        """Print ``drill-gym SUB: error: MESSAGE (see drill-gym SUB --help)``; exit 2."""
        self.exit(USAGE_ERROR, error_line(self.prog, message) + "\n")

    def fail(self, option: str, message: str) -> NoReturn:
        """A user error of ``option`` (``--duration``): ``argument --duration: MESSAGE``."""
        self.error(f"argument {option}: {message}")


def number_type(
    low: float | None = None,
    high: float | None = None,
    *,
    open_low: bool = False,
    integer: bool = False,
    unit: str = "",
) -> Callable[[str], Any]:
    """An argparse ``type`` that parses a finite number and checks ``low <= value <= high``
    (``low < value`` with ``open_low``); its error names the value and the allowed range.

    Args:
        low, high: Range ends (``None``: unbounded).
        open_low: Exclude ``low`` itself.
        integer: Parse an integer instead of a float.
        unit: Unit shown in the message (``"s"``, ``"N"``, ``"rad/s"``).
    """
    unit_text = f" {unit}" if unit else ""

    def show(value: float) -> str:
        return str(int(value)) if integer else f"{value:g}"

    if low is not None and high is not None:
        allowed = f"{'(' if open_low else '['}{show(low)}, {show(high)}]{unit_text}"
    elif low is not None:
        allowed = f"{'>' if open_low else '>='} {show(low)}{unit_text}"
    elif high is not None:
        allowed = f"<= {show(high)}{unit_text}"
    else:
        allowed = "a finite number"
    kind = "an integer" if integer else "a number"

    def parse(text: str) -> Any:
        try:
            value: float = int(text) if integer else float(text)
        except ValueError:
            if integer and text.strip().lstrip("+-").isdigit():  # too many digits to convert
                raise argparse.ArgumentTypeError(
                    f"{shown(text)} is out of range: allowed {allowed}"
                ) from None
            raise argparse.ArgumentTypeError(f"{shown(text)} is not {kind}") from None
        ok = math.isfinite(value)
        if ok and low is not None:
            ok = value > low if open_low else value >= low
        if ok and high is not None:
            ok = value <= high
        if not ok:
            raise argparse.ArgumentTypeError(
                f"{printable(text)} is out of range: allowed {allowed}"
            )
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


def seed_type(base: bool = False) -> Callable[[str], Any]:
    """The argparse ``type`` of a seed: an integer in ``[0, SEED_HIGH]``, or in
    ``[0, BASE_SEED_HIGH]`` for a base seed (``base``) to which items add their index."""
    return number_type(0, BASE_SEED_HIGH if base else SEED_HIGH, integer=True)


def seed_option(parser: argparse.ArgumentParser, help: str, *, base: bool = False) -> None:
    """Add the ``--seed N`` option of a study (default 0; :func:`seed_type`), ``help`` saying
    what the seed drives."""
    parser.add_argument("--seed", type=seed_type(base), default=0, metavar="N", help=help)


def names_type(valid: Callable[[], Sequence[str]], what: str) -> Callable[[str], str]:
    """An argparse ``type`` that accepts one of the names ``valid()`` returns (read when the
    option is parsed, so plugins registered at import time count); the error lists them."""

    def parse(text: str) -> str:
        names = list(valid())
        if text not in names:
            raise argparse.ArgumentTypeError(
                f"unknown {what} {shown(text)}: allowed {', '.join(names)}"
            )
        return text

    parse.__name__ = what
    return parse


def check_output_folder(path: str | Path) -> Path:
    """``path`` as the output folder of a command, after checking that the command can write
    there: an existing folder that is writable, or a missing one whose nearest existing parent
    is a writable folder (it is not created here). Writable means that an empty folder can be
    made in it and removed again, so that a folder the permission bits call writable but that
    takes no entries (``/proc``, a full or read-only mount) is refused before any work.

    Raises:
        ValueError: ``path`` is an existing file (or lies inside one), or the folder it is or
            would be made in is not writable.
    """
    folder = Path(path)
    if os.path.lexists(folder) and not folder.is_dir():
        what = "is a file" if folder.is_file() else "is a FIFO, a device or a broken link"
        raise ValueError(f"{str(folder)!r} {what}, not a folder: choose a folder")
    existing = folder
    while not os.path.lexists(existing):
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{str(folder)!r} lies inside {str(existing)!r}, which is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"{str(folder)!r}: the folder {str(existing)!r} is not writable")
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".drill-gym-write-check-", dir=existing))
    except OSError as err:
        raise ValueError(
            f"{str(folder)!r}: the folder {str(existing)!r} takes no new entries "
            f"({err.strerror or err})"
        ) from None
    return folder


def check_output_option(path: str | Path, option: str = "--out") -> None:
    """:func:`check_output_folder` for a Spec's check of its output folder (a default is not
    parsed by argparse, so the Spec checks it): the message names ``option``."""
    try:
        check_output_folder(path)
    except ValueError as err:
        raise ValueError(f"argument {option}: {err}") from None


def output_folder(text: str) -> Path:
    """The argparse ``type`` of ``--out``: :func:`check_output_folder` (give the option's
    default as a string, so that the default is checked too)."""
    try:
        return check_output_folder(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


output_folder.__name__ = "folder"


def _with_notes(exc: BaseException) -> str:
    """The message of ``exc`` followed by its notes (``add_note``), which libraries use to add
    context; the line is made safe by :func:`error_line`."""
    notes = getattr(exc, "__notes__", None)
    texts = [str(n) for n in notes[:5]] if isinstance(notes, list) else []
    return "; ".join([str(exc), *texts])


def run_command(prog: str, main: Callable[[], int], debug: bool) -> int:
    """Run ``main()`` and turn a user error into one line on standard error and exit code 2.

    User errors are ``ValueError`` and ``OSError`` (a bad value, a missing or unreadable file)
    and a missing optional package (``ModuleNotFoundError``); with ``debug`` they are raised
    again with their traceback. ``SystemExit`` (from a parser:
    ``--help``, a usage error) becomes its exit code; Ctrl-C exits with 130.
    """
    try:
        return int(main() or 0)
    except SystemExit as exc:
        code = exc.code
        if code is None:
            return 0
        if isinstance(code, int):
            return code
        print(code, file=sys.stderr)
        return 1
    except ModuleNotFoundError as exc:
        if debug:
            raise
        extra = (
            "the scale extra has Ray and Optuna: pip install -e '.[scale]'"
            if str(exc.name).split(".")[0] in ("ray", "optuna")
            else "the rl extra has torch and stable-baselines3: pip install -e '.[rl]'"
        )
        print(
            f"{prog}: error: needs the package {shown_value(exc.name)}, which is not installed ({extra})",
            file=sys.stderr,
        )
        return USAGE_ERROR
    except (ValueError, OSError, OverflowError, RecursionError, MemoryError) as exc:
        # OverflowError, RecursionError and MemoryError: a number, a nesting or a size from
        # outside too large for a check that should have refused it first; still one line,
        # never a traceback.
        if debug:
            raise
        text = _with_notes(exc)
        if isinstance(exc, MemoryError):
            text = f"not enough memory: {text or 'MemoryError'} (reduce the sizes asked for)"
        print(error_line(prog, text), file=sys.stderr)
        return USAGE_ERROR
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
