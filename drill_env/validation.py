"""Validation of user input, in one place: every check names the field, the bad value and
the allowed range, so that a message alone tells the user what to change.

Conventions: a value of the wrong type is a ``TypeError``; a value of the right type outside
its range is a ``ValueError``; unknown names are a ``TypeError`` (keywords) or a ``ValueError``
(choices) that lists the valid ones.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Collection, Iterable, Sequence
from typing import Any

import numpy as np

__all__ = [
    "check_bool",
    "check_choice",
    "check_finite_fields",
    "check_int",
    "check_interval",
    "check_range",
    "check_real",
    "check_unknown",
    "require",
]


def _is_real(value: object) -> bool:
    return not isinstance(value, (bool, np.bool_)) and isinstance(value, numbers.Real)


def check_real(name: str, value: object) -> float:
    """``value`` as a float; ``TypeError`` naming ``name`` unless it is a real number."""
    if not _is_real(value):
        raise TypeError(f"{name} must be a real number, got {value!r} ({type(value).__name__})")
    return float(value)  # type: ignore[arg-type]


def check_range(name: str, value: object, low: float, high: float) -> float:
    """``value`` as a float if it is a finite real number in ``[low, high]``."""
    v = check_real(name, value)
    if not (math.isfinite(v) and low <= v <= high):
        raise ValueError(f"{name} = {value!r} is out of range: allowed [{low:g}, {high:g}]")
    return v


def check_interval(
    name: str, bounds: Sequence[float], low: float, high: float
) -> tuple[float, float]:
    """A ``(lo, hi)`` pair with both ends in ``[low, high]`` and ``lo <= hi``."""
    if len(bounds) != 2:
        raise ValueError(f"{name} must be a (low, high) pair, got {bounds!r}")
    lo = check_range(f"{name}[0]", bounds[0], low, high)
    hi = check_range(f"{name}[1]", bounds[1], low, high)
    if lo > hi:
        raise ValueError(f"{name} = {tuple(bounds)!r} is inverted: low must be <= high")
    return lo, hi


def check_int(name: str, value: object, low: int = 1) -> int:
    """``value`` if it is an integer (not a bool) of at least ``low``."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"{name} = {value!r} is out of range: allowed an integer >= {low}")
    if value < low:
        raise ValueError(f"{name} = {value!r} is out of range: allowed an integer >= {low}")
    return int(value)


def check_bool(name: str, value: object) -> bool:
    """``value`` if it is ``True`` or ``False``."""
    if not isinstance(value, bool):
        raise TypeError(f"{name} must be True or False, got {value!r}")
    return value


def require(name: str, value: object, allowed: str, ok: bool) -> None:
    """``ValueError`` ``"{name} = {value!r} is out of range: allowed {allowed}"`` unless ``ok``."""
    if not ok:
        raise ValueError(f"{name} = {value!r} is out of range: allowed {allowed}")


def check_choice(name: str, value: object, choices: Collection[str], what: str = "") -> str:
    """``value`` if it is one of ``choices``; else a ``ValueError`` listing them."""
    if not isinstance(value, str) or value not in choices:
        kind = f" {what}" if what else ""
        raise ValueError(
            f"{name} = {value!r} is not a known{kind or ' value'}: allowed {sorted(choices)}"
        )
    return value


def check_unknown(
    given: Iterable[str], valid: Sequence[str], what: str = "keyword", owner: str = ""
) -> None:
    """``TypeError`` ``"unrecognized {what}(s)[ for {owner}]: ...; valid {what}s: ..."`` for
    names not in ``valid`` (python-control's convention for keyword arguments)."""
    unknown = sorted(set(given) - set(valid))
    if unknown:
        scope = f" for {owner}" if owner else ""
        raise TypeError(
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
            raise ValueError(f"{name} must be finite, got {value!r}")
        if coerce:
            object.__setattr__(owner, field.name, value)
