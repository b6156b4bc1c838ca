"""Portable model files: a trained policy as JSON and ``.npz`` arrays, read without running code.

A model folder holds three files (``docs/model-files.md`` describes them and the schema):

* ``config.json``: the architecture (:class:`PolicySpec`), the ``DrillString-v0`` keywords the
  policy needs, its name and the training record, validated by :func:`validate_config`
  against an explicit schema (known keys only, typed, bounded, finite);
* ``policy.npz``: the actor network's weights, biases and log standard deviation
  (:meth:`PolicySpec.weight_shapes`);
* ``obs_norm.npz``: the observation normalisation: ``mean`` and ``var`` of shape
  ``(observation_size,)``, ``clip_obs`` and ``epsilon`` (0-d).

Every ``.npz`` is read by :func:`read_npz`: the zip directory is checked first (entry names,
count, declared uncompressed sizes, the ``.npy`` header of each entry: dtype float32 or
float64, the expected shape), then the arrays are read with ``np.load(allow_pickle=False)``
and checked to be finite. Nothing here imports torch, calls pickle or evaluates text; this
module needs only NumPy and the standard library.
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, NoReturn

import numpy as np
import numpy.typing as npt

__all__ = [
    "ACTIVATIONS",
    "CONFIG_FILE",
    "FORMAT_VERSION",
    "DEFAULT_ENV_ID",
    "ENV_IDS",
    "FIELD_ENV_KEYWORDS",
    "MAX_FRAME_STACK",
    "MAX_INPUT_SIZE",
    "NOISE_TYPES",
    "NORM_FILE",
    "POLICY_ENV_KEYWORDS",
    "RECORD_FIELDS",
    "WEIGHTS_FILE",
    "GaussianMlp",
    "ObsNorm",
    "PolicySpec",
    "read_json",
    "read_npz",
    "read_model_files",
    "split_env_id",
    "stack_frames",
    "validate_config",
    "write_model_files",
]

FORMAT_VERSION: Final = 2
"""Version of the model folder format (1 was a Stable-Baselines3 ``model.zip``)."""
CONFIG_FILE: Final = "config.json"
WEIGHTS_FILE: Final = "policy.npz"
NORM_FILE: Final = "obs_norm.npz"

ACTIVATIONS: Final = ("tanh", "relu")
"""Activation functions of the hidden layers."""
NOISE_TYPES: Final = ("diagonal", "state_dependent")
"""Exploration noise of the Gaussian: a log-std per action (``log_std`` of shape
``(action_size,)``), or gSDE (``log_std`` of shape ``(last hidden size, action_size)``)."""

POLICY_ENV_KEYWORDS: Final = (
    "base_controller",
    "control_dt_s",
    "residual_scale_nm",
    "min_torque_nm",
    "max_torque_nm",
)
"""The ``DrillString-v0`` keywords a model folder records (``env_kwargs`` in config.json)."""

ENV_IDS: Final = ("DrillString-v0", "DrillStringField-v0")
"""The envs a model can be for (``env_kwargs.env_id`` in config.json)."""
DEFAULT_ENV_ID: Final = "DrillString-v0"
"""The env of a model whose ``env_kwargs`` name none (every model of format 2 before the field
string)."""
FIELD_ENV_KEYWORDS: Final = ("observation",)
"""Optional ``env_kwargs`` of a model for ``DrillStringField-v0``: the keywords that shape its
observation besides the base controller (default: the env's)."""

MAX_JSON_BYTES: Final = 1_000_000
MAX_OBSERVATION_SIZE: Final = 1024
MAX_FRAME_STACK: Final = 256
"""Most observations a policy may stack (``policy.frame_stack``)."""
MAX_INPUT_SIZE: Final = 4096
"""Largest network input, ``observation_size * frame_stack``."""
MAX_ACTION_SIZE: Final = 16
MAX_HIDDEN_LAYERS: Final = 8
MAX_HIDDEN_SIZE: Final = 1024
MAX_TORQUE_NM: Final = 1e6
MAX_CLIP_OBS: Final = 1e9
MAX_JSON_INT: Final = 2**53
MAX_STRING: Final = 10_000
MAX_NPY_HEADER: Final = 16_384
"""Bytes allowed per ``.npy`` entry on top of its float64 data (header and padding)."""


# ----------------------------------------------------------------------------- JSON reading
class _Rejected(ValueError):
    """A JSON construct refused while parsing (NaN, Infinity, duplicate keys)."""


def _reject_constant(name: str) -> NoReturn:
    raise _Rejected(f"the non-finite number {name} is not allowed")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Rejected(f"the key {key!r} appears twice")
        out[key] = value
    return out


def read_json(path: Path, max_bytes: int = MAX_JSON_BYTES) -> dict[str, Any]:
    """A JSON object from ``path``, refusing NaN/Infinity literals and duplicate keys.

    Raises:
        FileNotFoundError: No such file.
        ValueError: Too large, not UTF-8, not JSON, or not an object; the message names the
            file and the problem.
    """
    where = str(path)
    if not path.is_file():
        raise FileNotFoundError(f"{where!r}: no such file")
    size = path.stat().st_size
    if size > max_bytes:
        raise ValueError(f"{where!r}: {size} bytes is too large: allowed at most {max_bytes}")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as err:
        raise ValueError(f"{where!r} is not UTF-8 text: {err.reason} at byte {err.start}") from None
    try:
        data = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_no_duplicates)
    except json.JSONDecodeError as err:
        raise ValueError(
            f"{where!r} is not valid JSON: {err.msg} at line {err.lineno} column {err.colno}"
        ) from None
    except RecursionError:
        raise ValueError(f"{where!r} is not valid JSON: nested too deeply") from None
    except ValueError as err:  # our hooks, or an integer with too many digits
        raise ValueError(f"{where!r} is not valid JSON: {_one_line(str(err))}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{where!r}: expected a JSON object, found {type(data).__name__}")
    return data


def _one_line(text: str, limit: int = 200) -> str:
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


def _show(value: Any) -> str:
    return _one_line(repr(value), 60)


# ------------------------------------------------------------------------- schema checking
class _Fields:
    """Typed access to the fields of one JSON object; every error names the file and field."""

    def __init__(self, where: str, data: Any, prefix: str = "") -> None:
        self.where = where
        self.prefix = prefix
        if not isinstance(data, dict):
            self.fail(prefix.rstrip(".") or "(top level)", f"is {_show(data)}: expected an object")
        self.data: dict[str, Any] = data

    def fail(self, name: str, message: str) -> NoReturn:
        raise ValueError(f"{self.where!r}: field {name} {message}")

    def name(self, key: Any) -> str:
        if self.prefix.endswith("["):
            return f"{self.prefix}{key}]"
        return f"{self.prefix}{key}"

    def known(self, required: Sequence[str], optional: Sequence[str] = ()) -> None:
        allowed = [*required, *optional]
        for key in self.data:
            if key not in allowed:
                self.fail(
                    self.name(str(key)), f"is not known: allowed fields are {', '.join(allowed)}"
                )
        for key in required:
            if key not in self.data:
                self.fail(self.name(key), "is missing")

    def integer(self, key: Any, low: int, high: int) -> int:
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            self.fail(
                self.name(key),
                f"= {_show(value)} is out of range: allowed an integer in [{low}, {high}]",
            )
        return value

    def number(self, key: Any, low: float, high: float, *, open_low: bool = False) -> float:
        value = self.data[key]
        ok = (
            not isinstance(value, bool)
            and isinstance(value, (int, float))
            and math.isfinite(value)
            and (low < value if open_low else low <= value)
            and value <= high
        )
        if not ok:
            bracket = "(" if open_low else "["
            self.fail(
                self.name(key),
                f"= {_show(value)} is out of range: allowed a finite number in "
                f"{bracket}{low:g}, {high:g}]",
            )
        return float(value)

    def choice(self, key: Any, allowed: Sequence[Any]) -> Any:
        value = self.data[key]
        if not any(value == a and type(value) is type(a) for a in allowed):
            self.fail(self.name(key), f"= {_show(value)} is not valid: allowed {list(allowed)}")
        return value

    def text(self, key: Any, max_len: int = 200) -> str:
        value = self.data[key]
        if not isinstance(value, str) or not 0 < len(value) <= max_len or not value.isprintable():
            self.fail(
                self.name(key),
                f"= {_show(value)} is not valid: allowed a printable string of 1 to {max_len} "
                "characters",
            )
        return value

    def numbers(self, key: Any, length: int, bound: float) -> tuple[float, ...]:
        value = self.data[key]
        if not isinstance(value, list) or len(value) != length:
            self.fail(self.name(key), f"= {_show(value)} is not valid: allowed a list of {length}")
        inner = _Fields(self.where, dict(enumerate(value)), f"{self.name(key)}[")
        return tuple(inner.number(i, -bound, bound) for i in range(length))


def _check_json_value(f: _Fields, key: Any, value: Any, depth: int) -> None:
    """Free JSON (the training record): finite numbers, bounded sizes, no ``:``-keys."""
    name = f.name(str(key))
    if value is None or isinstance(value, bool):
        return
    if isinstance(value, int):
        if abs(value) > MAX_JSON_INT:
            f.fail(name, f"= {_show(value)} is out of range: allowed |x| <= 2**53")
        return
    if isinstance(value, float):
        if not math.isfinite(value):
            f.fail(name, f"= {value!r} is out of range: allowed a finite number")
        return
    if isinstance(value, str):
        if len(value) > MAX_STRING:
            f.fail(name, f"is a string of {len(value)} characters: allowed at most {MAX_STRING}")
        return
    if depth >= 4:
        f.fail(name, "is nested too deeply: allowed at most 4 levels")
    if isinstance(value, list):
        if len(value) > 1000:
            f.fail(name, f"is a list of {len(value)} items: allowed at most 1000")
        for i, item in enumerate(value):
            _check_json_value(_Fields(f.where, {}, f"{name}["), i, item, depth + 1)
        return
    if isinstance(value, dict):
        inner = _Fields(f.where, value, name + ".")
        if len(value) > 1000:
            f.fail(name, f"is an object of {len(value)} fields: allowed at most 1000")
        for k, v in value.items():
            _check_key(inner, k)
            _check_json_value(inner, k, v, depth + 1)
        return
    f.fail(name, f"= {_show(value)} is not a JSON value")  # pragma: no cover - from json.loads


_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]{0,99}")


def _check_key(f: _Fields, key: str) -> None:
    if not _KEY.fullmatch(key):
        f.fail(
            f.name(_one_line(key, 40)),
            "is not a valid field name: allowed letters, digits, '_', '.', '-', starting with "
            "a letter or '_' (entries such as ':serialized:' or ':type:' are refused)",
        )


# ---------------------------------------------------------------------------- architecture
@dataclass(frozen=True)
class PolicySpec:
    """The architecture of a Gaussian MLP policy (``config.json``, field ``policy``).

    The action mean is ``W_k act(... act(W_0 z + b_0) ...) + b_k``, clipped to
    ``[action_low, action_high]``; ``z`` is the normalised network input: the observation, or
    with ``frame_stack = k > 1`` the last ``k`` observations concatenated, oldest first
    (:func:`stack_frames`), ``observation_size * k`` numbers.

    Attributes:
        observation_size: Length of the observation.
        hidden_sizes: Sizes of the hidden layers (0 to 8 layers of 1 to 1024 units).
        activation: ``"tanh"`` or ``"relu"``, after every hidden layer.
        action_size: Length of the action.
        action_low: Lower clipping bound per action entry.
        action_high: Upper clipping bound per action entry.
        noise: ``"diagonal"`` or ``"state_dependent"`` (:data:`NOISE_TYPES`).
        frame_stack: Observations in the network input (1 to :data:`MAX_FRAME_STACK`).
    """

    observation_size: int
    hidden_sizes: tuple[int, ...]
    activation: str = "tanh"
    action_size: int = 1
    action_low: tuple[float, ...] = (-1.0,)
    action_high: tuple[float, ...] = (1.0,)
    noise: str = "diagonal"
    frame_stack: int = 1

    def __post_init__(self) -> None:
        # The same checks as a config.json (programming errors surface the same way).
        validate_policy_spec(self.to_json(), "PolicySpec", self.observation_size)

    @property
    def input_size(self) -> int:
        """Length of the network input: ``observation_size * frame_stack`` (also the length
        of the normalisation statistics)."""
        return self.observation_size * self.frame_stack

    def layer_sizes(self) -> list[int]:
        """Input, hidden and output sizes."""
        return [self.input_size, *self.hidden_sizes, self.action_size]

    def weight_shapes(self) -> dict[str, tuple[int, ...]]:
        """The arrays of ``policy.npz`` and their shapes.

        ``hidden.{i}.weight`` ``(out, in)`` and ``hidden.{i}.bias`` ``(out,)`` per hidden
        layer, ``action.weight``, ``action.bias``, and ``log_std``: ``(action_size,)``, or
        ``(last hidden size, action_size)`` for state-dependent noise.
        """
        sizes = self.layer_sizes()
        shapes: dict[str, tuple[int, ...]] = {}
        for i in range(len(self.hidden_sizes)):
            shapes[f"hidden.{i}.weight"] = (sizes[i + 1], sizes[i])
            shapes[f"hidden.{i}.bias"] = (sizes[i + 1],)
        shapes["action.weight"] = (self.action_size, sizes[-2])
        shapes["action.bias"] = (self.action_size,)
        if self.noise == "diagonal":
            shapes["log_std"] = (self.action_size,)
        else:
            shapes["log_std"] = (sizes[-2], self.action_size)
        return shapes

    def to_json(self) -> dict[str, Any]:
        """The ``policy`` field of config.json (``frame_stack`` only when above 1, so a
        memoryless policy's file is as before)."""
        out: dict[str, Any] = {
            "type": "gaussian_mlp",
            "hidden_sizes": list(self.hidden_sizes),
            "activation": self.activation,
            "action_size": self.action_size,
            "action_low": [float(x) for x in self.action_low],
            "action_high": [float(x) for x in self.action_high],
            "noise": self.noise,
        }
        if self.frame_stack != 1:
            out["frame_stack"] = self.frame_stack
        return out


def validate_policy_spec(data: Any, where: str, observation_size: int) -> PolicySpec:
    """The ``policy`` field of a config.json as a :class:`PolicySpec` (every error is a
    one-line ``ValueError`` naming ``where`` and the field)."""
    f = _Fields(where, data, "policy.")
    f.known(
        ("type", "hidden_sizes", "activation", "action_size", "action_low", "action_high"),
        ("noise", "frame_stack"),
    )
    f.choice("type", ("gaussian_mlp",))
    hidden = f.data["hidden_sizes"]
    if not isinstance(hidden, list) or len(hidden) > MAX_HIDDEN_LAYERS:
        f.fail(
            "policy.hidden_sizes",
            f"= {_show(hidden)} is not valid: allowed a list of at most {MAX_HIDDEN_LAYERS} sizes",
        )
    sizes = _Fields(where, dict(enumerate(hidden)), "policy.hidden_sizes[")
    hidden_sizes = tuple(sizes.integer(i, 1, MAX_HIDDEN_SIZE) for i in range(len(hidden)))
    activation = f.choice("activation", ACTIVATIONS)
    action_size = f.integer("action_size", 1, MAX_ACTION_SIZE)
    low = f.numbers("action_low", action_size, MAX_CLIP_OBS)
    high = f.numbers("action_high", action_size, MAX_CLIP_OBS)
    if not all(a < b for a, b in zip(low, high, strict=True)):
        f.fail("policy.action_low", f"= {list(low)} must be below action_high = {list(high)}")
    noise = f.choice("noise", NOISE_TYPES) if "noise" in f.data else "diagonal"
    if noise == "state_dependent" and not hidden_sizes:
        f.fail("policy.noise", "= 'state_dependent' needs at least one hidden layer")
    frame_stack = f.integer("frame_stack", 1, MAX_FRAME_STACK) if "frame_stack" in f.data else 1
    if observation_size * frame_stack > MAX_INPUT_SIZE:
        f.fail(
            "policy.frame_stack",
            f"= {frame_stack} is out of range: observation_size {observation_size} x "
            f"frame_stack {frame_stack} = {observation_size * frame_stack} network inputs, "
            f"allowed at most {MAX_INPUT_SIZE}",
        )
    spec = object.__new__(PolicySpec)  # skip __post_init__: these values are checked
    for name, value in (
        ("observation_size", observation_size),
        ("hidden_sizes", hidden_sizes),
        ("activation", activation),
        ("action_size", action_size),
        ("action_low", low),
        ("action_high", high),
        ("noise", noise),
        ("frame_stack", frame_stack),
    ):
        object.__setattr__(spec, name, value)
    return spec


# -------------------------------------------------------------------------------- config.json
RECORD_FIELDS: Final = (
    "train_config",
    "timesteps",
    "run_timesteps",
    "resumed_from",
    "selected",
    "validation_score",
    "wall_time_s",
    "cpu_count",
    "torch_threads",
    "source",
)
"""Optional top-level fields of config.json: the training record (never interpreted)."""
_REQUIRED_FIELDS: Final = ("format", "name", "env_kwargs", "observation_size", "policy")


@dataclass(frozen=True)
class ModelConfig:
    """A validated ``config.json``.

    Attributes:
        name: The agent's name.
        env_kwargs: The env keywords (:data:`POLICY_ENV_KEYWORDS`, and for
            ``DrillStringField-v0`` those of :data:`FIELD_ENV_KEYWORDS` it gives), without
            ``env_id``.
        spec: The architecture.
        record: The rest of the file (``format``, ``observation_size``, ``policy`` and the
            training record: ``train_config``, ``timesteps``, ...).
        env_id: The env the model is for (``env_kwargs.env_id`` in the file; absent:
            :data:`DEFAULT_ENV_ID`).
    """

    name: str
    env_kwargs: dict[str, Any]
    spec: PolicySpec
    record: dict[str, Any] = field(default_factory=dict)
    env_id: str = DEFAULT_ENV_ID


def split_env_id(env_kwargs: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """``(env id, the env keywords without it)`` of validated ``env_kwargs``."""
    keywords = dict(env_kwargs)
    return str(keywords.pop("env_id", DEFAULT_ENV_ID)), keywords


def validate_env_kwargs(data: Any, where: str) -> dict[str, Any]:
    """The ``env_kwargs`` field: exactly the keywords of :data:`POLICY_ENV_KEYWORDS`, typed
    and in range (whether the base controller is registered is checked by the loader)."""
    f = _Fields(where, data, "env_kwargs.")
    f.known(POLICY_ENV_KEYWORDS, ("env_id", *FIELD_ENV_KEYWORDS))
    base = f.data["base_controller"]
    if base is not None:
        f.text("base_controller", 100)
    out: dict[str, Any] = {"base_controller": base}
    out["control_dt_s"] = f.number("control_dt_s", 0.0, 10.0, open_low=True)
    out["residual_scale_nm"] = f.number("residual_scale_nm", 0.0, MAX_TORQUE_NM)
    out["min_torque_nm"] = f.number("min_torque_nm", -MAX_TORQUE_NM, MAX_TORQUE_NM)
    out["max_torque_nm"] = f.number("max_torque_nm", -MAX_TORQUE_NM, MAX_TORQUE_NM)
    if not out["min_torque_nm"] < out["max_torque_nm"]:
        f.fail(
            "env_kwargs.min_torque_nm",
            f"= {out['min_torque_nm']!r} must be below max_torque_nm = {out['max_torque_nm']!r}",
        )
    if "env_id" in f.data:
        out["env_id"] = f.choice("env_id", ENV_IDS)
    field_only = [k for k in FIELD_ENV_KEYWORDS if k in f.data]
    if field_only and out.get("env_id") != "DrillStringField-v0":
        f.fail(
            f"env_kwargs.{field_only[0]}",
            "is a keyword of DrillStringField-v0: set env_kwargs.env_id to it",
        )
    if "observation" in f.data:
        out["observation"] = f.choice("observation", ("state", "surface"))
    return out


def validate_config(data: Any, where: str) -> ModelConfig:
    """Check a parsed config.json against the schema (``docs/model-files.md``).

    Args:
        data: The parsed JSON.
        where: The file (for the messages).

    Raises:
        ValueError: One line naming ``where``, the field and what is wrong: an unknown or
            missing field, a wrong type, a number out of range or not finite, a key such as
            ``:serialized:``.
    """
    f = _Fields(where, data)
    if isinstance(f.data.get("format"), int) and f.data["format"] == 1:
        f.fail(
            "format",
            "= 1: this is a Stable-Baselines3 model (model.zip, a pickle); load it with "
            "trust_pickle=True or convert it with 'python -m agents.convert'",
        )
    for key in f.data:
        _check_key(f, str(key))
    f.known(_REQUIRED_FIELDS, RECORD_FIELDS)
    f.choice("format", (FORMAT_VERSION,))
    name = f.text("name", 100)
    env_id, env_kwargs = split_env_id(validate_env_kwargs(f.data["env_kwargs"], where))
    observation_size = f.integer("observation_size", 1, MAX_OBSERVATION_SIZE)
    spec = validate_policy_spec(f.data["policy"], where, observation_size)
    for key in ("timesteps", "run_timesteps", "resumed_from"):
        if key in f.data:
            f.integer(key, 0, MAX_JSON_INT)
    for key in ("cpu_count", "torch_threads"):
        if key in f.data and f.data[key] is not None:
            f.integer(key, 1, 1_000_000)
    if "wall_time_s" in f.data:
        f.number("wall_time_s", 0.0, 1e9)
    if "validation_score" in f.data:
        f.number("validation_score", -1e9, 1e9)
    for key in ("selected", "source"):
        if key in f.data:
            f.text(key, 1000)
    if "train_config" in f.data:
        inner = _Fields(where, f.data["train_config"], "train_config.")
        for k, v in inner.data.items():
            _check_key(inner, k)
            _check_json_value(inner, k, v, 1)
    record = {k: v for k, v in f.data.items() if k not in ("name", "env_kwargs")}
    return ModelConfig(name=name, env_kwargs=env_kwargs, spec=spec, record=record, env_id=env_id)


# ------------------------------------------------------------------------------ .npz reading
_FLOAT_DTYPES: Final = (np.dtype("<f4"), np.dtype("<f8"), np.dtype(">f4"), np.dtype(">f8"))


def read_npz(
    path: Path, expected: Mapping[str, tuple[int, ...]], what: str
) -> dict[str, npt.NDArray[np.float64]]:
    """Arrays of an ``.npz`` file, each float32 or float64 of the expected shape, all finite.

    The zip directory is checked before anything is decompressed: only ``NAME.npy`` entries
    for the expected names, at most their float64 size plus a header each (a zip bomb
    declares far more), stored or deflated, not encrypted; each entry's ``.npy`` header must
    declare a float dtype and the expected shape. Then ``np.load(allow_pickle=False)``.

    Args:
        path: The file.
        expected: Array name -> shape.
        what: What the file holds (for the messages).

    Returns:
        The arrays as float64, by name.

    Raises:
        FileNotFoundError: No such file.
        ValueError: One line naming the file and what is wrong.
    """
    where = str(path)
    if not path.is_file():
        raise FileNotFoundError(f"{where!r}: no such file (expected {what})")
    allowed = sum(8 * math.prod(s) + MAX_NPY_HEADER for s in expected.values())
    max_file = allowed + 1024 * (len(expected) + 1)
    with path.open("rb") as f:  # read once: the checks and np.load see the same bytes
        data = f.read(max_file + 1)
    if len(data) > max_file:
        size = max(path.stat().st_size, len(data))
        raise ValueError(
            f"{where!r}: {size} bytes is too large for {what}: allowed at most {max_file}"
        )
    bad = f"{where!r} is not valid {what} (an .npz archive of float arrays)"
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            infos = archive.infolist()
            if len(infos) > len(expected):
                raise ValueError(
                    f"{where!r}: {len(infos)} entries: expected {len(expected)} "
                    f"({', '.join(expected)})"
                )
            declared = sum(i.file_size for i in infos)
            if declared > allowed:
                raise ValueError(
                    f"{where!r}: its entries declare {declared} bytes uncompressed: allowed at "
                    f"most {allowed} for {what} (a zip bomb?)"
                )
            names: list[str] = []
            for info in infos:
                name = info.filename[:-4] if info.filename.endswith(".npy") else ""
                if name not in expected or name in names:
                    raise ValueError(
                        f"{where!r}: unexpected entry {info.filename!r}: expected one each of "
                        f"{', '.join(k + '.npy' for k in expected)}"
                    )
                names.append(name)
                if info.flag_bits & 0x1 or info.compress_type not in (
                    zipfile.ZIP_STORED,
                    zipfile.ZIP_DEFLATED,
                ):
                    raise ValueError(
                        f"{where!r}: entry {info.filename!r} is encrypted or uses an unsupported "
                        "compression: allowed stored or deflated"
                    )
                with archive.open(info) as entry:
                    _check_npy_header(entry, where, name, expected[name])
            missing = [k for k in expected if k not in names]
            if missing:
                raise ValueError(f"{where!r}: missing array(s) {', '.join(missing)} ({what})")
    except ValueError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, RuntimeError) as err:
        raise ValueError(f"{bad}: {_one_line(str(err))}") from None
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            arrays = {k: np.asarray(archive[k]) for k in expected}
    except (ValueError, zipfile.BadZipFile, OSError, EOFError, KeyError) as err:
        raise ValueError(f"{bad}: {_one_line(str(err))}") from None
    out: dict[str, npt.NDArray[np.float64]] = {}
    for name, array in arrays.items():
        if array.dtype not in _FLOAT_DTYPES or array.shape != tuple(expected[name]):
            raise ValueError(  # pragma: no cover - the headers were checked
                f"{where!r}: array {name} has dtype {array.dtype} and shape {array.shape}: "
                f"expected float32/float64 of shape {tuple(expected[name])}"
            )
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{where!r}: array {name} has non-finite values (NaN or inf)")
        out[name] = array.astype(np.float64)
    return out


def _check_npy_header(entry: Any, where: str, name: str, shape: tuple[int, ...]) -> None:
    fmt = np.lib.format
    try:
        version = fmt.read_magic(entry)
        if version == (1, 0):
            found, _, dtype = fmt.read_array_header_1_0(entry)
        elif version == (2, 0):
            found, _, dtype = fmt.read_array_header_2_0(entry)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except (ValueError, OSError, EOFError, SyntaxError, TypeError):
        raise ValueError(
            f"{where!r}: entry {name}.npy is not a valid .npy array: its header cannot be read "
            "(expected the .npy magic, a version and a dict of descr, fortran_order, shape)"
        ) from None
    if dtype not in _FLOAT_DTYPES:
        raise ValueError(
            f"{where!r}: array {name} has dtype {dtype}: allowed float32 or float64 "
            "(object and other dtypes are refused)"
        )
    if tuple(found) != tuple(shape):
        raise ValueError(f"{where!r}: array {name} has shape {tuple(found)}: expected {shape}")


def write_npz(path: Path, arrays: Mapping[str, npt.ArrayLike]) -> None:
    """Write float arrays uncompressed to ``path`` (via a temporary file, then renamed)."""
    tmp = path.with_name(path.name + ".tmp.npz")
    clean = {}
    for k, v in arrays.items():
        a = np.asarray(v)
        if a.dtype not in _FLOAT_DTYPES:
            a = a.astype(np.float64)
        clean[k] = a
    np.savez(tmp, **clean)  # type: ignore[arg-type]
    os.replace(tmp, path)


# --------------------------------------------------------------------------- normalisation
@dataclass(frozen=True)
class ObsNorm:
    """Observation normalisation ``clip((obs - mean) / sqrt(var + epsilon), +-clip_obs)``.

    Attributes:
        mean: Running mean, shape ``(observation_size,)``.
        var: Running variance (>= 0), same shape.
        clip_obs: Clipping bound of the normalised observation (> 0).
        epsilon: Added to the variance (>= 0; ``var + epsilon > 0``).
    """

    mean: npt.NDArray[np.float64]
    var: npt.NDArray[np.float64]
    clip_obs: float = 10.0
    epsilon: float = 1e-8

    @classmethod
    def identity(cls, size: int) -> ObsNorm:
        """No normalisation (mean 0, variance 1, no clipping in practice)."""
        return cls(np.zeros(size), np.ones(size), 1e6, 0.0)

    @staticmethod
    def shapes(size: int) -> dict[str, tuple[int, ...]]:
        """The arrays of ``obs_norm.npz``."""
        return {"mean": (size,), "var": (size,), "clip_obs": (), "epsilon": ()}

    def check(self, where: str) -> None:
        """Ranges (the arrays are already finite)."""
        if np.any(self.var < 0):
            raise ValueError(f"{where!r}: array var has negative entries: allowed >= 0")
        if not 0 < self.clip_obs <= MAX_CLIP_OBS:
            raise ValueError(
                f"{where!r}: clip_obs = {self.clip_obs!r} is out of range: allowed (0, 1e9]"
            )
        if not 0 <= self.epsilon <= 1.0:
            raise ValueError(f"{where!r}: epsilon = {self.epsilon!r} is out of range: [0, 1]")
        if np.any(self.var + self.epsilon <= 0):
            raise ValueError(f"{where!r}: var + epsilon must be > 0 in every entry")

    def arrays(self) -> dict[str, npt.NDArray[np.float64]]:
        """The arrays of ``obs_norm.npz``."""
        return {
            "mean": np.asarray(self.mean, np.float64),
            "var": np.asarray(self.var, np.float64),
            "clip_obs": np.asarray(self.clip_obs, np.float64),
            "epsilon": np.asarray(self.epsilon, np.float64),
        }


# --------------------------------------------------------------------------- frame stacking
def stack_frames(
    history: npt.ArrayLike | None,
    observation: npt.ArrayLike,
    episode_start: npt.ArrayLike | None,
    frame_stack: int,
) -> npt.NDArray[np.float32]:
    """The network input after one more observation: the last ``frame_stack`` observations
    concatenated, oldest first, zeros for the instants before the episode's start.

    This is Stable-Baselines3's ``VecFrameStack`` on a vector of observations (the history
    shifted left by one observation, the rows that start an episode cleared, the new
    observation written at the end), so a policy trained behind that wrapper sees at inference
    exactly what it saw in training.

    Args:
        history: The previous input, shape ``(n, m * frame_stack)``; ``None`` at the start.
        observation: The new observations, shape ``(n, m)``.
        episode_start: Per row, whether the observation is the first of an episode (its
            history is then cleared), shape ``(n,)``; ``None``: no row starts.
        frame_stack: Observations kept, ``k >= 1``.

    Returns:
        The new input, float32, shape ``(n, m * frame_stack)``.

    Raises:
        ValueError: ``history`` or ``episode_start`` of another shape.
    """
    obs = np.asarray(observation, dtype=np.float32)
    n, m = obs.shape
    width = m * frame_stack
    if history is None:
        stacked = np.zeros((n, width), dtype=np.float32)
    else:
        stacked = np.array(history, dtype=np.float32)
        if stacked.shape != (n, width):
            raise ValueError(
                f"state has shape {stacked.shape}: expected ({n}, {width}), the history of "
                f"{frame_stack} observations of {m} (pass None at the start of an episode)"
            )
    stacked = np.roll(stacked, -m, axis=1)
    if episode_start is not None:
        start = np.asarray(episode_start, dtype=bool).reshape(-1)
        if start.shape != (n,):
            raise ValueError(f"episode_start has {start.size} entries: expected {n}")
        stacked[start] = 0.0
    stacked[:, width - m :] = obs
    return stacked


# ------------------------------------------------------------------------------- the network
class GaussianMlp:
    """The actor of a Gaussian MLP policy in NumPy (float64 arithmetic).

    Args:
        spec: The architecture.
        weights: The arrays of :meth:`PolicySpec.weight_shapes` (any float dtype; stored as
            float64).

    Raises:
        ValueError: A missing, extra, misshapen or non-finite array.
    """

    def __init__(self, spec: PolicySpec, weights: Mapping[str, npt.ArrayLike]) -> None:
        shapes = spec.weight_shapes()
        extra = sorted(set(weights) - set(shapes))
        missing = [k for k in shapes if k not in weights]
        if extra or missing:
            raise ValueError(
                f"policy weights: missing {missing}, unexpected {extra}; expected {list(shapes)}"
            )
        self.spec = spec
        self.weights: dict[str, npt.NDArray[np.float64]] = {}
        for name, shape in shapes.items():
            array = np.asarray(weights[name], dtype=np.float64)
            if array.shape != shape or not np.all(np.isfinite(array)):
                raise ValueError(
                    f"policy weights: {name} has shape {array.shape}, expected {shape}, and must "
                    "be finite"
                )
            self.weights[name] = array
        n = len(spec.hidden_sizes)
        self._layers = [
            (self.weights[f"hidden.{i}.weight"], self.weights[f"hidden.{i}.bias"]) for i in range(n)
        ]
        self._low = np.asarray(spec.action_low, np.float64)
        self._high = np.asarray(spec.action_high, np.float64)

    def latent(self, z: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Output of the last hidden layer, shape ``(n, last hidden size)``."""
        h = z
        for weight, bias in self._layers:
            h = h @ weight.T + bias
            h = np.tanh(h) if self.spec.activation == "tanh" else np.maximum(h, 0.0)
        return h

    def mean_action(self, latent: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """The Gaussian's mean (unclipped), shape ``(n, action_size)``."""
        return latent @ self.weights["action.weight"].T + self.weights["action.bias"]

    def action_std(self, latent: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Standard deviation of the action noise, shape ``(n, action_size)``: ``exp(log_std)``,
        or for state-dependent noise ``sqrt(latent^2 @ exp(log_std)^2)`` (the marginal of
        gSDE with a fresh noise matrix at every call)."""
        std = np.exp(self.weights["log_std"])
        if self.spec.noise == "diagonal":
            return np.broadcast_to(std, (latent.shape[0], self.spec.action_size))
        return np.sqrt((latent * latent) @ (std * std))

    def clip(self, action: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Clip to the action bounds."""
        return np.clip(action, self._low, self._high)


# --------------------------------------------------------------------------- folder read/write
@dataclass(frozen=True)
class ModelFiles:
    """The validated contents of a model folder."""

    config: ModelConfig
    weights: dict[str, npt.NDArray[np.float64]]
    obs_norm: ObsNorm


def read_model_files(folder: Path) -> ModelFiles:
    """Read and check ``config.json``, ``obs_norm.npz`` and ``policy.npz`` of ``folder``.

    Raises:
        FileNotFoundError: A file is missing.
        ValueError: A file breaks the schema (one line naming the file and the field).
    """
    config = validate_config(read_json(folder / CONFIG_FILE), str(folder / CONFIG_FILE))
    size = config.spec.input_size
    norm_file = folder / NORM_FILE
    stats = read_npz(norm_file, ObsNorm.shapes(size), "observation normalisation statistics")
    obs_norm = ObsNorm(
        stats["mean"], stats["var"], float(stats["clip_obs"]), float(stats["epsilon"])
    )
    obs_norm.check(str(norm_file))
    weights = read_npz(folder / WEIGHTS_FILE, config.spec.weight_shapes(), "policy network weights")
    return ModelFiles(config, weights, obs_norm)


def write_model_files(
    folder: Path,
    *,
    name: str,
    env_kwargs: Mapping[str, Any],
    spec: PolicySpec,
    weights: Mapping[str, npt.ArrayLike],
    obs_norm: ObsNorm,
    record: Mapping[str, Any] | None = None,
) -> Path:
    """Write a model folder (the arrays first, ``config.json`` last).

    ``record`` holds the optional training-record fields (``train_config``, ``timesteps``,
    ...); the whole config is checked against the schema before anything is written.

    Returns:
        The folder.
    """
    config = {
        "format": FORMAT_VERSION,
        "name": name,
        "env_kwargs": dict(env_kwargs),
        "observation_size": spec.observation_size,
        "policy": spec.to_json(),
        **{
            k: v
            for k, v in (record or {}).items()
            if k not in ("format", "observation_size", "policy")
        },
    }
    text = json.dumps(config, indent=2, allow_nan=False) + "\n"
    validate_config(json.loads(text), str(folder / CONFIG_FILE))
    GaussianMlp(spec, weights)  # shapes and finiteness
    obs_norm.check(str(folder / NORM_FILE))
    folder.mkdir(parents=True, exist_ok=True)
    write_npz(folder / WEIGHTS_FILE, {k: np.asarray(v) for k, v in weights.items()})
    write_npz(folder / NORM_FILE, obs_norm.arrays())
    tmp = folder / (CONFIG_FILE + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, folder / CONFIG_FILE)
    return folder
