"""Validation of user input, in one place: every check names the field, the bad value and
the allowed range, so that a message alone tells the user what to change.

Conventions: a value of the wrong type is a ``TypeError``; a value of the right type outside
its range is a ``ValueError``; unknown names are a ``TypeError`` (keywords) or a ``ValueError``
(choices) that lists the valid ones. A real number too large for a float (``10**400``) is out of
range, never an ``OverflowError``; a value is shown in a message by :func:`shown` (bounded, one
line, no control characters), and any text from outside that reaches a terminal goes through
:func:`printable`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import numbers
import unicodedata
from collections.abc import Collection, Iterable, Iterator, Sequence
from typing import Any, Final

import numpy as np

__all__ = [
    "MAX_MESSAGE_CHARS",
    "MAX_SHOWN_CHARS",
    "InputTypeError",
    "check_bool",
    "check_choice",
    "check_finite_fields",
    "check_int",
    "check_interval",
    "check_range",
    "check_real",
    "check_seeds",
    "check_unknown",
    "input_type_errors",
    "printable",
    "require",
    "shown",
]

MAX_SHOWN_CHARS: Final = 80
"""Longest text :func:`shown` and :func:`printable` put in a message (longer is cut with ...)."""


def _escaped(text: str, cell: bool) -> str:
    """``text`` with control and format characters as ``\\xNN`` or ``\\uNNNN`` (and, in a
    Markdown ``cell``, ``|`` as ``\\|``)."""
    out: list[str] = []
    for char in text:
        if cell and char == "|":
            out.append("\\|")
        elif char == "\\" or char.isprintable() or char == " ":
            out.append(char)
        elif unicodedata.category(char) == "Zs":  # exotic spaces: show as a space
            out.append(" ")
        else:
            code = ord(char)
            out.append(f"\\x{code:02x}" if code < 0x100 else f"\\u{code:04x}")
    return "".join(out)


def printable(text: object, limit: int = MAX_SHOWN_CHARS, cell: bool = False) -> str:
    """``text`` made safe for one line of a terminal, a log or (``cell``) a Markdown table
    cell: control and format characters (newlines, escape sequences, bidirectional overrides)
    become ``\\xNN`` or ``\\uNNNN``, in a cell ``|`` (its border) becomes ``\\|``, and more
    than ``limit`` characters are cut in the middle with ``...``, keeping a third of them from
    the end (the file's name at the end of a long path)."""
    full = str(text)
    # Every character gives at least one, so the first limit + 1 decide whether it fits.
    line = _escaped(full[: limit + 1], cell)
    if len(line) <= limit:
        return line
    keep = max(0, limit - 3)
    tail_chars = keep // 3
    tail = _escaped(full[-tail_chars:], cell)[-tail_chars:] if tail_chars else ""
    return line[: keep - tail_chars] + "..." + tail


MAX_MESSAGE_CHARS: Final = 1000
"""Longest message of an :class:`InputTypeError` (longer is cut with ...)."""


class InputTypeError(TypeError):
    """A ``TypeError`` about a value from outside whose message is always printable and
    bounded: it is passed through :func:`printable` whenever the exception is built, also when
    a caller builds it again with more text. (Gymnasium's ``make`` re-raises a ``TypeError`` of
    an env's constructor as ``type(err)(f"{err} ... with kwargs ({kwargs})")``, which would
    otherwise print the raw keywords: escape sequences, or a 10 MB string.)"""

    def __init__(self, *args: object) -> None:
        super().__init__(*(printable(arg, MAX_MESSAGE_CHARS) for arg in args))


@contextlib.contextmanager
def input_type_errors() -> Iterator[None]:
    """Turn a ``TypeError`` raised inside into an :class:`InputTypeError` (same message, made
    printable and bounded): wrap the construction of an env's configuration from the keywords
    a user gave, so that no caller can add them to the message raw."""
    try:
        yield
    except InputTypeError:
        raise
    except TypeError as err:
        raise InputTypeError(str(err)) from None


def shown(value: object, limit: int = MAX_SHOWN_CHARS) -> str:
    """A bounded one-line ``repr`` of ``value`` for an error message: an integer too long to
    print is shown by its sign and digit count, any object whose ``repr`` fails or is long is
    cut, and nothing in it can move the terminal's cursor."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**30:
        sign = "-" if value < 0 else ""
        return f"{sign}<an integer of {len(format(abs(value), 'x')) * 4} bits>"
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a hostile __repr__ must not hide the real error
        text = f"<{type(value).__name__} object>"
    return printable(text, limit)


def _is_real(value: object) -> bool:
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Real)


def check_real(name: str, value: object, allowed: str = "a finite real number") -> float:
    """``value`` as a float; ``TypeError`` naming ``name`` unless it is a real number (bools,
    complex numbers, strings and arrays are not), ``ValueError`` naming ``allowed`` when it is
    beyond the float range (an ``int`` such as ``10**400``). NaN and infinities pass: the range
    checks refuse them."""
    if not _is_real(value):
        raise InputTypeError(
            f"{name} must be a real number, got {shown(value)} ({printable(type(value).__name__)})"
        )
    try:
        return float(value)  # type: ignore[arg-type]
    except (OverflowError, ValueError, TypeError, ArithmeticError):
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed {allowed}") from None


def check_range(name: str, value: object, low: float, high: float) -> float:
    """``value`` as a float if it is a finite real number in ``[low, high]`` (an infinite end
    is open: infinities are refused)."""
    allowed = (
        f"{'(' if math.isinf(low) else '['}{low:g}, {high:g}{')' if math.isinf(high) else ']'}"
    )
    v = check_real(name, value, allowed)
    if not (math.isfinite(v) and low <= v <= high):
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed {allowed}")
    return v


def check_interval(
    name: str, bounds: Sequence[float], low: float, high: float
) -> tuple[float, float]:
    """A ``(lo, hi)`` pair with both ends in ``[low, high]`` and ``lo <= hi``."""
    if isinstance(bounds, (str, bytes)) or not isinstance(bounds, Sequence) or len(bounds) != 2:
        raise ValueError(f"{name} must be a (low, high) pair, got {shown(bounds)}")
    lo = check_range(f"{name}[0]", bounds[0], low, high)
    hi = check_range(f"{name}[1]", bounds[1], low, high)
    if lo > hi:
        raise ValueError(f"{name} = {shown(tuple(bounds))} is inverted: low must be <= high")
    return lo, hi


def check_int(name: str, value: object, low: int = 1, high: int | None = None) -> int:
    """``value`` if it is an integer (not a bool) in ``[low, high]`` (no upper bound when
    ``high`` is None)."""
    allowed = f"an integer >= {low}" if high is None else f"an integer in [{low}, {high}]"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed {allowed}")
    if value < low or (high is not None and value > high):
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed {allowed}")
    return int(value)


def check_seeds(seed: object, count: int) -> list[int | None]:
    """The reset seeds of ``count`` strings from a vector env's ``seed``: ``None`` (none),
    an integer ``s >= 0`` (string ``i`` gets ``s + i``) or a list of ``count`` of them (each
    ``None`` or an integer >= 0).

    Raises:
        TypeError: ``seed`` is none of these (a bool, a float, a string).
        ValueError: a negative seed, or a list of another length.
    """
    if seed is None:
        return [None] * count
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
        first = check_int("seed", seed, 0)
        return [first + i for i in range(count)]
    if not isinstance(seed, (list, tuple)):
        raise InputTypeError(
            f"seed must be None, an integer >= 0 or a list of {count} of them, got {shown(seed)}"
        )
    if len(seed) != count:
        raise ValueError(f"seed list must have {count} entries, got {len(seed)}")
    return [None if s is None else check_int(f"seed[{i}]", s, 0) for i, s in enumerate(seed)]


def check_bool(name: str, value: object) -> bool:
    """``value`` if it is ``True`` or ``False``."""
    if not isinstance(value, bool):
        raise InputTypeError(f"{name} must be True or False, got {shown(value)}")
    return value


def require(name: str, value: object, allowed: str, ok: bool) -> None:
    """``ValueError`` ``"{name} = {shown(value)} is out of range: allowed {allowed}"`` unless ``ok``."""
    if not ok:
        raise ValueError(f"{name} = {shown(value)} is out of range: allowed {allowed}")


def check_choice(name: str, value: object, choices: Collection[str], what: str = "") -> str:
    """``value`` if it is one of ``choices``; else a ``ValueError`` listing them."""
    if not isinstance(value, str) or value not in choices:
        kind = f" {what}" if what else ""
        raise ValueError(
            f"{name} = {shown(value)} is not a known{kind or ' value'}: allowed {sorted(choices)}"
        )
    return value


def check_unknown(
    given: Iterable[str], valid: Sequence[str], what: str = "keyword", owner: str = ""
) -> None:
    """``TypeError`` ``"unrecognized {what}(s)[ for {owner}]: ...; valid {what}s: ..."`` for
    names not in ``valid`` (python-control's convention for keyword arguments)."""
    unknown = sorted((printable(name) for name in set(given) - set(valid)), key=str)
    if unknown:
        scope = f" for {owner}" if owner else ""
        raise InputTypeError(
            f"unrecognized {what}(s){scope}: {', '.join(unknown)}; valid {what}s: "
            f"{', '.join(valid)}"
        )


def check_finite_fields(owner: Any, prefix: str = "", coerce: bool = True) -> None:
    """Check that every ``float`` field of the frozen dataclass ``owner`` holds a finite real
    number and (with ``coerce``) store it as a Python ``float``. Run it in ``__post_init__``
    before the range checks, which compare the values.

    Raises:
        TypeError: naming ``{prefix}{field}``, the value and its type when it is not a number.
        ValueError: naming ``{prefix}{field}`` and the value when it is not finite.
    """
    for field in dataclasses.fields(owner):
        if field.type not in ("float", float):
            continue
        name = f"{prefix}{field.name}"
        value = check_real(name, getattr(owner, field.name))
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {shown(value)}")
        if coerce:
            object.__setattr__(owner, field.name, value)
