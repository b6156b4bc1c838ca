"""Hostile input to every loader and command: numbers beyond float range, wrong types, huge
sizes, names that try to become paths, text that tries to move the terminal.

Each class of input is generated for every place it can enter: env keywords, reset options,
actions, randomisation ranges, reward weights, plant and controller parameters, the tuned-gains
file, output names and the numeric options of every command. The expectation is the same
everywhere: a ``ValueError`` or ``TypeError`` (one line and exit code 2 on the command line)
that names the field, raised before anything large is allocated. Property tests (hypothesis)
run at a small budget by default and at a large one behind ``slow``.
(``tests/test_bad_input.py`` pins single messages; ``tests/test_fuzz.py`` fuzzes valid use.)
"""

from __future__ import annotations

import dataclasses
import fractions
import importlib
import json
import math
import os
import re
import tracemalloc
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import drill_env
from baselines.tuned import load_tuned_gains
from drill_env.distributed import (
    DISTRIBUTED_PRESETS,
    DistributedStringParameters,
    StringDamping,
    StringSection,
    with_measured_depth,
)
from drill_env.limits import (
    MAX_ELEMENTS,
    MAX_MEASURED_DEPTH_M,
    MAX_NUM_ENVS,
    MAX_SECTIONS,
)
from drill_env.options import PER_EPISODE_KEYWORDS, EnvConfig, FieldEnvConfig
from drill_env.parameters import DrillStringParameters
from drill_env.rewards import RewardWeights
from drill_env.scenarios import FieldRandomization, Randomization
from drill_env.validation import (
    MAX_SHOWN_CHARS,
    check_int,
    check_interval,
    check_range,
    check_real,
    printable,
    shown,
)
from experiments.arguments import number_type
from experiments.cli import SUBCOMMANDS
from experiments.cli import main as cli_main
from experiments.paths import MAX_NAME_CHARS, output_file, output_path, safe_file_name
from experiments.tables import Column, markdown_table

ENV_ID = "DrillString-v0"
FIELD_ID = "DrillStringField-v0"

SMALL = settings(
    deadline=None,
    max_examples=40,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
LARGE = settings(
    deadline=None,
    max_examples=2_000,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

# ------------------------------------------------------------------------ the input classes
HUGE_NUMBERS = [10**400, -(10**400), 10**5000, 2**1024, fractions.Fraction(10**400, 3)]
"""Real numbers beyond the float range (``float()`` of them raises OverflowError)."""
NOT_FINITE = [math.nan, math.inf, -math.inf, np.float64(np.nan), np.float32(np.inf)]
NOT_REAL = [1 + 2j, np.complex128(1j), "3", b"3", None, [1.0], (1.0,), {"x": 1}, object()]
BOOLS = [True, False, np.bool_(True)]
HOSTILE_NUMBERS = HUGE_NUMBERS + NOT_FINITE + NOT_REAL + BOOLS
HOSTILE_NAMES = [
    "../x",
    "../../etc/passwd",
    "/abs",
    "a/b",
    "a\\b",
    "\x1b[2J",
    "x\ny|z",
    "CON",
    "nul.txt",
    "com1",
    "x" * 300,
    "",
    ".",
    "..",
    ".hidden",
    "-rf",
    "\u202eevil",
    "é\x00",
]
"""Names that try to leave a folder, clear the terminal, break a table or hit a device."""


def _id(value: Any) -> str:
    """A test id for ``value`` that every pytest process computes alike: an object with the
    default ``repr`` (which holds its memory address) by its type's name."""
    if type(value).__repr__ is object.__repr__:
        return f"<{type(value).__name__}>"
    return shown(value, 24)


_ids = [_id(v) for v in HOSTILE_NUMBERS]


@pytest.fixture(scope="module", autouse=True)
def _compiled() -> None:
    """Load (or compile) the engine once, outside the allocation tracing of :func:`_refused`
    (tracing slows compilation down a hundredfold)."""
    for env_id in (ENV_ID, FIELD_ID):
        env = gym.make(env_id, episode_s=1.0)
        env.reset(seed=0)
        env.step(np.zeros(1, np.float32))
        env.close()
        venv = gym.make_vec(env_id, num_envs=2, episode_s=1.0)
        venv.reset(seed=0)
        venv.step(np.zeros((2, 1), np.float32))
        venv.close()


def _one_line(message: str) -> bool:
    return "\n" not in message and "\x1b" not in message and len(message) < 600


def _refused(call: Callable[[], Any], field: str) -> BaseException:
    """``call()`` raises ValueError or TypeError naming ``field`` on one line, allocating
    little (refused before the work: under 64 MB of Python and numpy allocations)."""
    tracemalloc.start()
    try:
        with pytest.raises((ValueError, TypeError)) as err:
            call()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    message = str(err.value)
    assert field in message, message
    assert _one_line(message), message
    assert peak < 64 * 2**20, f"{peak / 2**20:.0f} MB allocated before refusing"
    return err.value


# --------------------------------------------------------------- the validation functions
anything = st.one_of(
    st.integers(min_value=-(10**500), max_value=10**500),
    st.floats(allow_nan=True, allow_infinity=True),
    st.complex_numbers(),
    st.text(max_size=20),
    st.binary(max_size=8),
    st.booleans(),
    st.none(),
    st.fractions(),
    st.decimals(allow_nan=True),
    st.lists(st.integers(), max_size=3),
    st.sampled_from([np.float32(1.5), np.int64(3), np.float64("nan"), np.bool_(True)]),
)


def _check_validators(value: Any) -> None:
    for call in (
        lambda: check_real("x", value),
        lambda: check_range("x", value, -1.0, 1.0),
        lambda: check_int("x", value, 0, 10),
        lambda: check_interval("x", (value, value), -1.0, 1.0),
    ):
        try:
            result = call()
        except (ValueError, TypeError) as err:
            message = str(err)
            assert message.startswith("x"), message
            assert _one_line(message), message
        else:
            assert result is not None
    text = shown(value)
    assert len(text) <= MAX_SHOWN_CHARS and text.isprintable()


@SMALL
@given(anything)
def test_validators_raise_only_value_or_type_errors(value: Any) -> None:
    """Any value: a number in range, or ValueError/TypeError naming the field on one line."""
    _check_validators(value)


@pytest.mark.slow
@LARGE
@given(anything)
def test_validators_raise_only_value_or_type_errors_long(value: Any) -> None:
    _check_validators(value)


@SMALL
@given(st.floats(-2.0, 2.0), st.integers(-(10**400), 10**400))
def test_range_agrees_with_the_mathematical_check(value: float, big: int) -> None:
    """In-range values pass unchanged; huge integers are out of range, never OverflowError."""
    if -1.0 <= value <= 1.0:
        assert check_range("x", value, -1.0, 1.0) == value
    else:
        with pytest.raises(ValueError, match=r"x = .* is out of range: allowed \[-1, 1\]"):
            check_range("x", value, -1.0, 1.0)
    if abs(big) > 1:
        with pytest.raises(ValueError, match=r"out of range"):
            check_range("x", big, -1.0, 1.0)


@SMALL
@given(st.text())
def test_printable_leaves_no_control_characters(text: str) -> None:
    """Any text: one printable line, bounded, and no bare ``|`` in a table cell."""
    line = printable(text)
    assert line.isprintable() or set(line) <= {" "} or line == ""
    assert len(line) <= MAX_SHOWN_CHARS
    cell = printable(text, 1000, cell=True)
    assert re.search(r"(?<!\\)\|", cell) is None


def test_a_long_path_keeps_its_file_name_and_its_start() -> None:
    path = "/data/" + "deep/" * 40 + "gains.json"
    line = printable(path)
    assert len(line) == MAX_SHOWN_CHARS and "..." in line
    assert line.startswith("/data/deep/") and line.endswith("/gains.json")
    assert printable("short path/gains.json") == "short path/gains.json"
    cut = printable("\n" * 200 + "end")  # escapes count against the limit too
    assert len(cut) <= MAX_SHOWN_CHARS and cut.endswith("end") and cut.isprintable()


def test_shown_bounds_huge_integers_and_hostile_reprs() -> None:
    class Evil:
        def __repr__(self) -> str:
            raise RuntimeError("no")

    class Loud:
        def __repr__(self) -> str:
            return "\x1b[2J\n" * 100

    assert shown(10**5000) == f"<an integer of {len(format(10**5000, 'x')) * 4} bits>"
    assert shown(-(10**400)).startswith("-<an integer")
    assert shown(Evil()) == "<Evil object>"
    assert "\x1b" not in shown(Loud()) and len(shown(Loud())) <= MAX_SHOWN_CHARS


# ------------------------------------------------------------------------- env keywords
def _numeric_keywords(config: type[EnvConfig]) -> list[str]:
    return [
        f.name
        for f in dataclasses.fields(config)
        if "float" in str(f.type) and f.name in config.keywords()
    ]


LUMPED_NUMERIC = _numeric_keywords(EnvConfig)
FIELD_NUMERIC = _numeric_keywords(FieldEnvConfig)


def _with_partner(name: str, value: Any) -> dict[str, Any]:
    """The keywords that test ``name = value`` (its partner keyword too, where one needs the
    other)."""
    partners = {"wob_step_time_s": ("wob_final_n", 1e5), "wob_final_n": ("wob_step_time_s", 1.0)}
    kwargs = {name: value}
    if name in partners:
        kwargs[partners[name][0]] = partners[name][1]
    return kwargs


@pytest.mark.parametrize("value", HOSTILE_NUMBERS, ids=_ids)
@pytest.mark.parametrize("name", LUMPED_NUMERIC)
def test_every_numeric_keyword_refuses_hostile_numbers(name: str, value: Any) -> None:
    """Huge, non-finite, complex, string, bool or container values of a numeric keyword."""
    if value is None and name in ("wob_step_time_s", "wob_final_n", "telemetry_period_s",
                                  "torque_rate_limit_nm_per_s"):  # fmt: skip
        pytest.skip("None means 'not set' for this keyword")
    if value is False and name == "randomize":
        pytest.skip("a bool keyword")
    _refused(lambda: EnvConfig(**_with_partner(name, value)), name)


@pytest.mark.parametrize("value", HUGE_NUMBERS + NOT_FINITE + NOT_REAL[:4] + BOOLS, ids=_id)
@pytest.mark.parametrize("name", [n for n in FIELD_NUMERIC if n not in LUMPED_NUMERIC])
def test_every_field_keyword_refuses_hostile_numbers(name: str, value: Any) -> None:
    if name == "hook_stiffness_n_m" and isinstance(value, float | np.floating) and value > 0:
        assert math.isinf(value)  # +inf is this keyword's default: a rigid hook
        pytest.skip("an infinite hook stiffness means a rigid hook")
    _refused(lambda: FieldEnvConfig(**{name: value}), name)


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + NOT_REAL[:3], ids=_id)
@pytest.mark.parametrize("name", [k for k in PER_EPISODE_KEYWORDS if k in LUMPED_NUMERIC])
def test_reset_options_refuse_hostile_numbers(name: str, value: Any) -> None:
    """The same values as reset options: refused, and the env still resets afterwards."""
    env = gym.make(ENV_ID, episode_s=1.0).unwrapped
    env.reset(seed=0)
    _refused(lambda: env.reset(seed=0, options=_with_partner(name, value)), name)
    obs, _ = env.reset(seed=0)
    assert np.all(np.isfinite(obs))


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + NOT_REAL[:3], ids=_id)
def test_field_reset_options_refuse_hostile_depths(value: Any) -> None:
    env = gym.make(FIELD_ID, episode_s=1.0).unwrapped
    env.reset(seed=0)
    _refused(lambda: env.reset(seed=0, options={"measured_depth_m": value}), "measured_depth_m")


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + ["3", 1j, True], ids=_id)
@pytest.mark.parametrize(
    ("owner", "field"),
    [(Randomization, f.name) for f in dataclasses.fields(Randomization)]
    + [(FieldRandomization, f.name) for f in dataclasses.fields(FieldRandomization)],
)
def test_randomisation_ranges_refuse_hostile_numbers(owner: type, field: str, value: Any) -> None:
    """Either end of a range, or a single probability, beyond float range or not a number."""
    default = getattr(owner(), field)
    bad = (default[0], value) if isinstance(default, tuple) else value
    _refused(lambda: owner(**{field: bad}), field)
    config = EnvConfig if owner is Randomization else FieldEnvConfig
    _refused(lambda: config(randomization={field: bad}), field)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + ["3", 1j, True], ids=_id)
@pytest.mark.parametrize("field", [f.name for f in dataclasses.fields(RewardWeights)])
def test_reward_weights_refuse_hostile_numbers(field: str, value: Any) -> None:
    _refused(lambda: EnvConfig(reward_weights={field: value}), field)  # type: ignore[arg-type]


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + ["3", 1j, True], ids=_id)
@pytest.mark.parametrize("field", [f.name for f in dataclasses.fields(DrillStringParameters)])
def test_plant_parameters_refuse_hostile_numbers(field: str, value: Any) -> None:
    _refused(lambda: DrillStringParameters(**{field: value}), field)


_SECTION = {
    "length_m": 100.0,
    "outer_diameter_m": 0.2,
    "inner_diameter_m": 0.1,
    "shear_modulus_pa": 80e9,
    "density_kg_m3": 8000.0,
}


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + ["3", 1j, True], ids=_id)
@pytest.mark.parametrize("field", list(_SECTION))
def test_string_sections_refuse_hostile_numbers(field: str, value: Any) -> None:
    _refused(lambda: StringSection(**{**_SECTION, field: value}), field)


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + ["3", 1j, True], ids=_id)
@pytest.mark.parametrize(
    "field",
    ["top_drive_inertia_kg_m2", "bit_inertia_kg_m2", "bit_radius_m", "mu_a", "mu_0", "xi", "Dw",
     "element_length_m"],
)  # fmt: skip
def test_distributed_parameters_refuse_hostile_numbers(field: str, value: Any) -> None:
    base = DISTRIBUTED_PRESETS["field_2500m"]
    _refused(lambda: dataclasses.replace(base, **{field: value}), field)


@pytest.mark.parametrize("value", HUGE_NUMBERS[:2] + NOT_FINITE[:2] + ["3", 1j, True], ids=_id)
@pytest.mark.parametrize("field", [f.name for f in dataclasses.fields(StringDamping)])
def test_string_damping_refuses_hostile_numbers(field: str, value: Any) -> None:
    _refused(lambda: StringDamping(**{field: value}), field)


@pytest.mark.parametrize("value", ["nope", 3, "../x", "\x1b[2J"], ids=repr)
def test_controller_parameters_errors_name_the_keyword(value: Any) -> None:
    """A bad ``controller_parameters`` is named as such, not as ``parameters``."""
    err = _refused(lambda: FieldEnvConfig(controller_parameters=value), "controller_parameters")
    assert "\x1b" not in str(err)


# ------------------------------------------------------------------------------- sizes
SIZE_CASES = {
    "depth-100000km": (lambda: gym.make(FIELD_ID, measured_depth_m=1e8), "measured_depth_m"),
    "depth-above-limit": (
        lambda: gym.make(FIELD_ID, measured_depth_m=MAX_MEASURED_DEPTH_M + 1.0),
        "measured_depth_m",
    ),
    "depth-helper": (
        lambda: with_measured_depth("field_2500m", 1e12),
        "measured_depth_m",
    ),
    "section-length": (
        lambda: StringSection(**{**_SECTION, "length_m": 1e9}),
        "length_m",
    ),
    "sections-sum": (
        lambda: DistributedStringParameters(
            sections=[StringSection(**{**_SECTION, "length_m": 15_000.0})] * 2,  # type: ignore[arg-type]
            top_drive_inertia_kg_m2=1000.0,
            bit_inertia_kg_m2=0.0,
            bit_radius_m=0.1,
        ),
        "measured_depth_m",
    ),
    "sections-count": (
        lambda: DistributedStringParameters(
            sections=[StringSection(**{**_SECTION, "length_m": 1.0})] * (MAX_SECTIONS + 1),  # type: ignore[arg-type]
            top_drive_inertia_kg_m2=1000.0,
            bit_inertia_kg_m2=0.0,
            bit_radius_m=0.1,
        ),
        "sections",
    ),
    "element-0.25m": (
        lambda: dataclasses.replace(DISTRIBUTED_PRESETS["field_2500m"], element_length_m=0.25),
        "element_length_m",
    ),
    "element-1mm": (
        lambda: dataclasses.replace(DISTRIBUTED_PRESETS["deep_5000m"], element_length_m=1e-3),
        "element_length_m",
    ),
    "elements-too-many": (
        lambda: dataclasses.replace(
            with_measured_depth("deep_5000m", MAX_MEASURED_DEPTH_M), element_length_m=3.0
        ),
        "element_length_m",
    ),
    "elements-too-short-for-the-step": (
        lambda: gym.make(
            FIELD_ID,
            parameters=dataclasses.replace(
                with_measured_depth("deep_5000m", 10_000.0), element_length_m=2.5
            ),
        ),
        "element_length_m",
    ),
    "num_envs-1e12": (lambda: gym.make_vec(ENV_ID, num_envs=10**12), "num_envs"),
    "num_envs-limit": (lambda: gym.make_vec(ENV_ID, num_envs=MAX_NUM_ENVS + 1), "num_envs"),
    "num_envs-bytes": (
        lambda: gym.make_vec(ENV_ID, num_envs=MAX_NUM_ENVS, control_dt_s=10.0, episode_s=10.0),
        "num_envs",
    ),
    "num_envs-huge-int": (lambda: gym.make_vec(ENV_ID, num_envs=10**400), "num_envs"),
    "num_envs-float": (lambda: gym.make_vec(ENV_ID, num_envs=1e6), "num_envs"),  # type: ignore[arg-type]
    "episode_s": (lambda: gym.make(ENV_ID, episode_s=1e9), "episode_s"),
    "max_episode_steps": (
        lambda: gym.make_vec(ENV_ID, num_envs=1, max_episode_steps=10**400),
        "max_episode_steps",
    ),
}


@pytest.mark.parametrize("case", list(SIZE_CASES))
def test_sizes_are_bounded_before_allocating(case: str) -> None:
    """Every size from outside is refused with its documented limit, before allocating."""
    call, field = SIZE_CASES[case]
    _refused(call, field)


def test_the_largest_accepted_string_builds_quickly() -> None:
    """At the limits (20 km, elements the plant step allows) the field env still builds."""
    string = dataclasses.replace(
        with_measured_depth("deep_5000m", MAX_MEASURED_DEPTH_M), element_length_m=6.0
    )
    assert sum(drill_env.distributed.section_element_counts(string)) <= MAX_ELEMENTS
    env = gym.make(FIELD_ID, parameters=string, episode_s=0.2)
    obs, _ = env.reset(seed=0)
    assert np.all(np.isfinite(obs))


# ------------------------------------------------------------------------------ actions
HOSTILE_ACTIONS = {
    "huge-int": 10**400,
    "huge-int-list": [10**400],
    "complex": np.array([0.5 + 1j]),
    "complex-scalar": 0.5j,
    "string": "0.5",
    "string-array": np.array(["0.5"]),
    "bytes": b"1",
    "object": object(),
    "object-array": np.array([0.5], dtype=object),
    "masked": np.ma.masked_array([0.5], mask=[True]),
    "masked-unmasked": np.ma.masked_array([0.5], mask=[False]),
    "bool": True,
    "bool-array": np.array([True]),
    "none": None,
    "dict": {"a": 1},
    "nan": np.array([np.nan]),
    "inf-float32": np.array([np.inf], np.float32),
    "longdouble-huge": np.array([np.longdouble("1e4000")]),
    "wrong-shape": np.zeros((2,)),
    "wrong-ndim": np.zeros((1, 1, 1)),
    "empty": np.zeros(0),
}


@pytest.fixture(scope="module")
def single_env() -> Iterator[Any]:
    env = gym.make(ENV_ID, episode_s=1.0).unwrapped
    yield env
    env.close()


@pytest.mark.parametrize("case", list(HOSTILE_ACTIONS))
def test_hostile_actions_are_refused_naming_action(case: str, single_env: Any) -> None:
    single_env.reset(seed=0)
    with np.errstate(all="ignore"):
        _refused(lambda: single_env.step(HOSTILE_ACTIONS[case]), "action")
    _, _, _, _, info = single_env.step(np.zeros(1, np.float32))  # the episode goes on
    assert info["time_s"] == pytest.approx(single_env.config.control_dt_s)


@pytest.mark.parametrize(
    "case", ["huge-int-list", "complex", "string-array", "masked", "bool-array", "object-array"]
)
def test_hostile_actions_are_refused_by_the_vector_env(case: str) -> None:
    venv = gym.make_vec(ENV_ID, num_envs=1, episode_s=1.0)
    venv.reset(seed=0)
    action = HOSTILE_ACTIONS[case]
    if isinstance(action, np.ndarray):
        action = action.reshape(1, 1)
    _refused(lambda: venv.step(action), "action")


@pytest.mark.parametrize(
    "action", [0.5, 1, np.float32(0.5), np.int64(0), [0.25], np.array([0.5], np.float16)], ids=repr
)
def test_real_actions_of_any_numeric_type_are_accepted(action: Any, single_env: Any) -> None:
    single_env.reset(seed=0)
    obs, _, _, _, _ = single_env.step(action)
    assert np.all(np.isfinite(obs))


# ----------------------------------------------------------------- a base controller's output
class _Returns:
    """A Python base controller returning a fixed value."""

    def __init__(self, value: Any) -> None:
        self.value = value

    def reset(self) -> None:
        pass

    def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> Any:
        return self.value


@pytest.mark.parametrize(
    "value", ["10000", None, 1j, [1.0, 2.0], np.zeros(3), True, object(), np.array(["1"])],
    ids=_id,
)  # fmt: skip
def test_a_base_controller_returning_garbage_is_named(value: Any) -> None:
    """Not a real number: a TypeError naming the controller and what it returned."""
    env = gym.make(ENV_ID, base_controller=_Returns(value), episode_s=1.0)
    env.reset(seed=0)
    with pytest.raises(TypeError, match=r"base_controller _Returns\.torque\(\) returned") as err:
        env.step(np.zeros(1, np.float32))
    assert _one_line(str(err.value))


@pytest.mark.parametrize(
    "value", [math.nan, math.inf, -math.inf, np.float64("nan"), 10**400], ids=_id
)
def test_a_base_controller_returning_no_finite_torque_ends_the_episode(value: Any) -> None:
    """NaN, infinite or beyond float range: the episode ends, the reason names the controller,
    and the observation stays finite."""
    env = gym.make(ENV_ID, base_controller=_Returns(value), episode_s=1.0)
    env.reset(seed=0)
    obs, reward, terminated, _, info = env.step(np.zeros(1, np.float32))
    assert terminated and reward == -1.0
    assert info["termination_reason"].startswith("base_controller _Returns returned")
    assert np.all(np.isfinite(obs))
    venv = gym.make_vec(ENV_ID, num_envs=2, base_controller=_Returns(value), episode_s=1.0)
    venv.reset(seed=0)
    _, _, terminated_v, _, infos = venv.step(np.zeros((2, 1), np.float32))
    assert terminated_v.all()
    assert all(r.startswith("base_controller _Returns") for r in infos["termination_reason"])


def test_a_base_controller_returning_numpy_scalars_works() -> None:
    for value in (np.float32(20_000.0), np.array([20_000.0]), np.int64(20_000)):
        env = gym.make(ENV_ID, base_controller=_Returns(value), episode_s=1.0)
        env.reset(seed=0)
        _, _, terminated, _, _ = env.step(np.zeros(1, np.float32))
        assert not terminated


# ------------------------------------------------------------------------- tuned gains
def _gains_file(tmp_path: Path, text: str | bytes) -> Path:
    path = tmp_path / "gains.json"
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def _document(gains: str) -> str:
    return (
        '{"format": 1, "controllers": {"stiff_pi": {"DrillStringParameters": '
        f'{{"env": "DrillString-v0", "gains": {gains}}}}}}}}}'
    )


GAINS_FILES: dict[str, tuple[str | bytes, str]] = {
    "deep-nesting": ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    "deep-objects": ('{"a":' * 50_000 + "1" + "}" * 50_000, "gains.json"),
    "huge-int": (_document('{"bandwidth_factor": ' + "9" * 400 + "}"), "bandwidth_factor"),
    "huge-exponent": (_document('{"bandwidth_factor": 1e400}'), "bandwidth_factor"),
    "too-many-digits": (_document('{"bandwidth_factor": ' + "9" * 5000 + "}"), "gains.json"),
    "nan": (_document('{"bandwidth_factor": NaN}'), "NaN"),
    "string": (_document('{"bandwidth_factor": "2"}'), "bandwidth_factor"),
    "bool": (_document('{"bandwidth_factor": true}'), "bandwidth_factor"),
    "escape-key": (_document('{"\\u001b[2J": 1}'), "unknown field"),
    "binary": (b"\xff\xfe\x00garbage", "gains.json"),
    "score-huge": (
        '{"format": 1, "controllers": {"stiff_pi": {"DrillStringParameters": {"env": '
        '"DrillString-v0", "gains": {}, "validation_score": ' + "9" * 400 + "}}}}",
        "validation_score",
    ),
    "format-huge": ('{"format": ' + "9" * 400 + ', "controllers": {}}', "format"),
    "too-large": (" " * 1_100_000 + "{}", "larger than"),
}


@pytest.mark.parametrize("case", list(GAINS_FILES))
def test_tuned_gains_loader_refuses_hostile_files(case: str, tmp_path: Path) -> None:
    """One-line ValueError naming the file (and the field), never Recursion/OverflowError."""
    text, field = GAINS_FILES[case]
    path = _gains_file(tmp_path, text)
    with pytest.raises(ValueError) as err:
        load_tuned_gains(path)
    message = str(err.value)
    assert "gains.json" in message and field in message, message
    assert _one_line(message), message


def test_tuned_gains_loader_refuses_a_fifo(tmp_path: Path) -> None:
    """A FIFO is not a file: refused at once (it would block a reader forever)."""
    fifo = tmp_path / "gains.json"
    os.mkfifo(fifo)
    with pytest.raises(FileNotFoundError, match="no tuned gains file"):
        load_tuned_gains(fifo)


def test_tune_command_reports_a_hostile_gains_file_on_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _gains_file(tmp_path, "[" * 100_000)
    code = cli_main(["tune", "--write", "--gains-file", str(path), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "gains.json" in err, err


# ------------------------------------------------------------------------------- paths
@pytest.mark.parametrize("name", HOSTILE_NAMES, ids=repr)
def test_safe_file_name_is_one_harmless_component(name: str) -> None:
    safe = safe_file_name(name)
    assert safe and len(safe) <= MAX_NAME_CHARS
    assert re.fullmatch(r"[A-Za-z0-9_+=][A-Za-z0-9._+=-]*", safe), safe
    assert safe not in (".", "..") and "/" not in safe and "\\" not in safe
    assert safe.split(".")[0].lower() not in ("con", "nul", "com1", "prn", "aux")


@SMALL
@given(st.text(max_size=400), st.text(max_size=400))
def test_safe_file_names_never_collide(a: str, b: str) -> None:
    """Different names give different files; a clean name is kept as it is."""
    if a != b:
        assert safe_file_name(a) != safe_file_name(b)
    if re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_]{0,50}", a) and a.lower() not in ("con", "nul"):
        assert safe_file_name(a) == a


@pytest.mark.slow
@LARGE
@given(st.text(max_size=400), st.text(max_size=400))
def test_safe_file_names_never_collide_long(a: str, b: str) -> None:
    if a != b:
        assert safe_file_name(a) != safe_file_name(b)


@pytest.mark.parametrize("name", HOSTILE_NAMES, ids=repr)
def test_output_paths_stay_inside_the_output_folder(name: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    for path in (
        output_path(out, name, suffix=".csv"),
        output_path(out, "figures", name, suffix=".png"),
        output_file(out, f"{name}.png"),
        output_file(out, name),
    ):
        assert out.resolve() in path.resolve().parents
        assert len(path.name) <= MAX_NAME_CHARS


def test_output_path_refuses_a_link_out_of_the_folder(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "figures").symlink_to(tmp_path)
    with pytest.raises(ValueError, match="outside the output folder"):
        output_path(out, "figures", "x", suffix=".png")


class _Constant:
    """A plugin controller: a constant torque (its name is the attack)."""

    def reset(self) -> None:
        pass

    def torque(self, measurement: Any, reference_speed_rad_s: float, dt_s: float) -> float:
        return 20_000.0


def _files_under(folder: Path) -> set[Path]:
    return {p.resolve() for p in folder.rglob("*")}


@pytest.mark.parametrize(
    "name", ["../../escaped", "/tmp/abs_name", "a/b", "\x1b[2J|x\ny", "CON", "z" * 300], ids=repr
)
def test_map_writes_a_hostile_controller_name_inside_out(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A controller (a plugin, or a model) whose name is a path or an escape sequence: the map
    writes its CSV and figure inside ``--out`` and prints its name escaped."""
    monkeypatch.setitem(drill_env.control._FACTORIES, name, _Constant)  # registered for the test
    out = tmp_path / "deep" / "out"
    before = _files_under(tmp_path)
    code = cli_main([
        "map", "--controllers", name, "--wob-n", "2", "--speed-n", "2", "--duration", "0.2",
        "--window", "0.1", "--out", str(out), "--no-progress",
    ])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    written = _files_under(tmp_path) - before
    inside = out.resolve()
    assert written and all(inside in p.parents or p in (inside, *inside.parents) for p in written)
    assert {p.suffix for p in written if p.is_file()} == {".csv", ".png"}
    assert "\x1b" not in captured.out and "\x1b" not in captured.err
    assert not Path("/tmp/abs_name.csv").exists()


def test_markdown_cells_cannot_break_the_table() -> None:
    rows = [{"controller": "a|b\n| x |\x1b[2J"}]
    table = markdown_table(rows, [Column("controller", "controller", align="left")])
    lines = table.splitlines()
    assert len(lines) == 3 and "\x1b" not in table
    assert lines[2].count("|") - lines[2].count("\\|") == 2


# ----------------------------------------------------------------------- command line
HOSTILE_OPTION_VALUES = [
    "1e400", "-1e400", "nan", "inf", "-inf", "9" * 5000, "1j", "0x10", "\x1b[2J", "", "1e-400x",
]  # fmt: skip


def _numeric_options() -> list[tuple[str, str]]:
    found = []
    for command, (module_name, _) in SUBCOMMANDS.items():
        try:
            parser = importlib.import_module(module_name)._parser()
        except ModuleNotFoundError:  # pragma: no cover - an extra is not installed
            continue
        for action in parser._actions:
            kind = getattr(action.type, "__name__", "")
            if action.option_strings and kind in ("number", "integer", "int", "float"):
                found.append((command, action.option_strings[-1]))
    return found


NUMERIC_OPTIONS = _numeric_options()


def test_every_command_has_numeric_options_found() -> None:
    commands = {c for c, _ in NUMERIC_OPTIONS}
    assert {"compare", "map", "probability-map", "evaluate", "waves", "realism", "tune"} <= commands


@pytest.mark.parametrize(("command", "option"), NUMERIC_OPTIONS)
def test_every_numeric_option_refuses_hostile_values_on_one_line(
    command: str, option: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Each numeric option of each command: exit code 2, one line naming the option.

    The studies' options are checked while parsing (a trailing unknown option makes sure
    nothing runs if one were accepted); ``train`` checks its numbers when it builds its
    configuration, before training."""
    for value in HOSTILE_OPTION_VALUES:
        if command == "train":
            argv = [command, option, value, "--run-dir", str(tmp_path / "out")]
        else:
            argv = [command, option, value, "--out", str(tmp_path / "out"), "--zz-not-an-option"]
        code = cli_main(argv)
        err = capsys.readouterr().err
        assert option in err and "--zz-not-an-option" not in err, (command, option, value, err)
        if code == 0:  # pragma: no cover - a value that parses and is in range
            raise AssertionError(f"{command} {option} {value!r} was accepted")
        assert code == 2, (command, option, value, err)
        assert err.count("\n") == 1 and "Traceback" not in err, err
        assert "\x1b" not in err and len(err) < 1200, err
        assert not (tmp_path / "out").exists()


@SMALL
@given(st.text(max_size=50))
def test_number_type_refuses_or_returns_a_finite_number(text: str) -> None:
    import argparse

    parse = number_type(0.0, 10.0, unit="s")
    try:
        value = parse(text)
    except argparse.ArgumentTypeError as err:
        assert _one_line(str(err))
    else:
        assert math.isfinite(value) and 0.0 <= value <= 10.0


def test_an_unknown_command_name_is_shown_escaped(capsys: pytest.CaptureFixture[str]) -> None:
    code = cli_main(["\x1b[2J" + "x" * 5000])
    err = capsys.readouterr().err
    assert code == 2 and "\x1b" not in err and err.count("\n") == 1 and len(err) < 1200


def test_tuned_gains_document_round_trips() -> None:
    """The shipped file still loads (the loader's refusals do not refuse good files)."""
    entries = load_tuned_gains()
    assert entries and json.dumps(str(entries))


@pytest.mark.parametrize(
    "seed",
    [-1, 1.5, "x", True, [1, "a"], [1, -5], [1], 10**400 * -1, {"a": 1}],
    ids=_id,
)
def test_vector_env_seeds_are_checked(seed: Any) -> None:
    """A seed is None, an integer >= 0, or a list of one per string: anything else is named."""
    venv = gym.make_vec(ENV_ID, num_envs=2, episode_s=1.0)
    _refused(lambda: venv.reset(seed=seed), "seed")
    venv.reset(seed=np.int64(3))
    venv.reset(seed=[None, 10**400])


@pytest.mark.parametrize(
    "options",
    [{1: 2}, {None: 1}, {"\x1b[2J": 1}, {("a",): 1, "b": 2}, {"x" * 10_000: 1}],
    ids=["int-key", "none-key", "escape-key", "tuple-key", "long-key"],
)
def test_reset_options_with_hostile_names_are_refused(options: dict[Any, Any]) -> None:
    env = gym.make(ENV_ID, episode_s=1.0).unwrapped
    _refused(lambda: env.reset(seed=0, options=options), "unknown option")
    keywords = {str(k): v for k, v in options.items()}
    _refused(lambda: EnvConfig.from_kwargs(keywords), "unrecognized")


def test_speed_profiles_refuse_hostile_knots() -> None:
    """Profile helpers check their numbers and read no more knots than a profile holds."""
    import itertools

    from drill_env.scenarios import SpeedProfile

    endless = ((float(t), 1.0) for t in itertools.count())
    _refused(lambda: SpeedProfile.steps(5.0, endless), "knots")
    _refused(lambda: SpeedProfile.steps(5.0, [(10**400, 1.0)]), "reference time")
    _refused(lambda: SpeedProfile.ramp(1.0, 2.0, 0.0, 10**400), "ramp end time")
    _refused(lambda: SpeedProfile.constant(1j), "reference_speed_rad_s")  # type: ignore[arg-type]
    _refused(lambda: EnvConfig(reference_speed_rad_s=SpeedProfile.constant(10**400)), "reference")
    assert SpeedProfile.steps(5, [(1, 6)]).times_s == (0.0, 1.0, 1.0)
