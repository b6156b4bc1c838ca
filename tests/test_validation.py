"""The one validation module (:mod:`drill_env.validation`): every message names the field, the
value and what is allowed."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np
import pytest

from drill_env.validation import (
    check_bool,
    check_choice,
    check_finite_fields,
    check_int,
    check_interval,
    check_range,
    check_real,
    check_unknown,
    require,
)


@pytest.mark.parametrize("value", [3, 3.5, np.float32(2.0), np.int64(4)], ids=str)
def test_real_numbers_pass(value: object) -> None:
    assert check_real("x", value) == float(value)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", [True, "1", None, [1.0]], ids=repr)
def test_non_numbers_are_type_errors(value: object) -> None:
    message = f"x must be a real number, got {value!r} ({type(value).__name__})"
    with pytest.raises(TypeError, match=re.escape(message)):
        check_real("x", value)


def test_range() -> None:
    assert check_range("wob_n", 5, 0.0, 10.0) == 5.0
    for bad in (-1.0, 11.0, math.nan, math.inf):
        with pytest.raises(ValueError, match=r"wob_n = .* is out of range: allowed \[0, 10\]"):
            check_range("wob_n", bad, 0.0, 10.0)


def test_interval() -> None:
    assert check_interval("r", (1, 2), 0.0, 5.0) == (1.0, 2.0)
    with pytest.raises(ValueError, match=r"r = \(3, 1\) is inverted"):
        check_interval("r", (3, 1), 0.0, 5.0)
    with pytest.raises(ValueError, match=r"r\[1\] = 9 is out of range"):
        check_interval("r", (1, 9), 0.0, 5.0)
    with pytest.raises(ValueError, match="must be a \\(low, high\\) pair"):
        check_interval("r", (1,), 0.0, 5.0)


def test_int_bool_require_choice() -> None:
    assert check_int("n", 3) == 3
    for bad in (0, True, 2.0):
        with pytest.raises(ValueError, match=r"n = .* allowed an integer >= 1"):
            check_int("n", bad)
    with pytest.raises(TypeError, match="flag must be True or False, got 1"):
        check_bool("flag", 1)
    with pytest.raises(ValueError, match=r"k = -1 is out of range: allowed > 0"):
        require("k", -1, "> 0", False)
    require("k", 1, "> 0", True)
    with pytest.raises(ValueError, match=r"mode = 'x' is not a known mode: allowed \['a', 'b'\]"):
        check_choice("mode", "x", ("b", "a"), "mode")


def test_unknown_names_list_the_valid_ones() -> None:
    check_unknown(["a"], ["a", "b"])
    with pytest.raises(TypeError, match=r"unrecognized keyword\(s\): c, d; valid keywords: a, b"):
        check_unknown(["d", "c", "a"], ["a", "b"])
    with pytest.raises(TypeError, match=r"unrecognized gain\(s\) for pid: q; valid gains: kp"):
        check_unknown(["q"], ["kp"], "gain", "pid")


@dataclass(frozen=True)
class _Gains:
    kp: float = 1.0
    name: str = "x"

    def __post_init__(self) -> None:
        check_finite_fields(self, "_Gains.")


def test_finite_fields_coerce_and_name_the_field() -> None:
    assert type(_Gains(kp=np.float32(2.0)).kp) is float  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"_Gains\.kp must be finite, got nan"):
        _Gains(kp=math.nan)
    with pytest.raises(TypeError, match=r"_Gains\.kp must be a real number, got '2' \(str\)"):
        _Gains(kp="2")  # type: ignore[arg-type]
