"""Portable model files: a trained policy as JSON and safetensors, read without running code.

A model folder holds three files (``docs/model-files.md`` describes them and the schema):

* ``config.json``: the architecture (:class:`~agents.inference.PolicySpec`), the env keywords
  the policy needs, its name and the training record, validated by :func:`validate_config`:
  the schema is a set of pydantic models (strict types, known fields only, bounded, finite)
  and the env keywords are checked by the env's own :class:`drill_env.options.EnvConfig`;
* ``policy.safetensors``: the actor network's weights, biases and log standard deviation
  (:meth:`PolicySpec.weight_shapes`);
* ``obs_norm.safetensors``: the observation normalisation: ``mean`` and ``var`` of shape
  ``(input_size,)``, ``clip_obs`` and ``epsilon`` (0-d).

Every safetensors file is read by :func:`read_safetensors`: its size is bounded before it is
read (the arrays' float64 size plus a bounded header), the header is parsed by the
``safetensors`` library, then every array must be float32 or float64, of the shape the config
implies, and finite. Folders of the previous format (2, ``.npz`` arrays) are read by
:mod:`agents.legacy_format`. Nothing here imports torch, calls pickle or evaluates text.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Final, Literal, NoReturn, TypeVar

import numpy as np
import numpy.typing as npt
import safetensors
import safetensors.numpy
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

from agents.inference import (
    ACTIVATIONS,
    NOISE_TYPES,
    Activation,
    GaussianMlp,
    Noise,
    ObsNorm,
    PolicySpec,
    stack_frames,
)
from agents.legacy_format import LEGACY_NORM_FILE, LEGACY_WEIGHTS_FILE, PREVIOUS_FORMAT, read_npz
from drill_env import COUPLED_ENV_ID, ENV_ID, FIELD_ENV_ID
from drill_env.coupled_env import CoupledEnvConfig
from drill_env.files import write_bytes, write_text
from drill_env.layout import OBSERVATION_MODES
from drill_env.options import EnvConfig, FieldEnvConfig
from drill_env.validation import shown

__all__ = [
    "ACTIVATIONS",
    "CONFIG_FILE",
    "DEFAULT_ENV_ID",
    "ENV_IDS",
    "FORMAT_VERSION",
    "MAX_FRAME_STACK",
    "MAX_INPUT_SIZE",
    "NOISE_TYPES",
    "NORM_FILE",
    "PREVIOUS_FORMAT",
    "RECORD_FIELDS",
    "STRICT",
    "WEIGHTS_FILE",
    "Count",
    "GaussianMlp",
    "ModelConfig",
    "ObsNorm",
    "PolicySpec",
    "array_files",
    "check_obs_norm",
    "read_arrays",
    "read_config",
    "read_json",
    "read_safetensors",
    "split_env_id",
    "stack_frames",
    "validate_config",
    "validate_json",
    "write_model_files",
    "write_safetensors",
]

FORMAT_VERSION: Final = 3
"""Version of the model folder format (1: a Stable-Baselines3 ``model.zip``; 2: ``.npz``
arrays; 3: safetensors arrays)."""
CONFIG_FILE: Final = "config.json"
WEIGHTS_FILE: Final = "policy.safetensors"
NORM_FILE: Final = "obs_norm.safetensors"

ENV_IDS: Final = (ENV_ID, FIELD_ENV_ID)
"""The envs a model of the torque-residual keywords can be for (``env_kwargs.env_id`` in
config.json); a model for ``DrillStringCoupled-v0`` has the coupled env's keywords
(``_CoupledEnvKwargsSchema``)."""
DEFAULT_ENV_ID: Final = ENV_ID
"""The env of a model whose ``env_kwargs`` name none."""

MAX_JSON_BYTES: Final = 1_000_000
MAX_OBSERVATION_SIZE: Final = 1024
MAX_FRAME_STACK: Final = 256
"""Most observations a policy may stack (``policy.frame_stack``)."""
MAX_INPUT_SIZE: Final = 4096
"""Largest network input, ``observation_size * frame_stack``."""
MAX_ACTION_SIZE: Final = 16
MAX_HIDDEN_LAYERS: Final = 8
MAX_HIDDEN_SIZE: Final = 1024
MAX_BOUND: Final = 1e9
"""Largest action bound and ``clip_obs``."""
MAX_JSON_INT: Final = 2**53
MAX_STRING: Final = 10_000
MAX_RECORD_DEPTH: Final = 4
MAX_RECORD_ITEMS: Final = 1000
MAX_HEADER_BYTES_PER_ARRAY: Final = 512
"""Bytes a safetensors header may spend per array (its name, dtype, shape and offsets); the
header may have 4096 bytes more (its ``__metadata__``, padding)."""
_SAFETENSORS_DTYPES: Final[dict[str, np.dtype[Any]]] = {
    "F32": np.dtype("<f4"),
    "F64": np.dtype("<f8"),
}


# ----------------------------------------------------------------------------- JSON reading
class _Rejected(ValueError):
    """A JSON construct refused while parsing (NaN, Infinity, duplicate keys)."""


def _reject_constant(name: str) -> NoReturn:
    raise _Rejected(f"the non-finite number {name} is not allowed")


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise _Rejected(f"the key {_show(key)} appears twice")
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
    with path.open("rb") as f:
        raw = f.read(max_bytes + 1)
    if len(raw) > max_bytes:
        size = max(path.stat().st_size, len(raw))
        raise ValueError(f"{where!r}: {size} bytes is too large: allowed at most {max_bytes}")
    try:
        text = raw.decode("utf-8")
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
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**40:
        return f"an integer of {len(str(abs(value)))} digits"
    return _one_line(repr(value), 60)


# ---------------------------------------------------------------------------------- schema
def _printable(value: str) -> str:
    if not value.isprintable():
        raise ValueError(f" = {_show(value)}: allowed printable characters only")
    return value


def _record_value(value: Any, depth: int = 0, path: str = "") -> Any:
    """Free JSON of the training record: bounded depth, sizes and integers, plain keys.

    Raises:
        ValueError: ``"{path} ..."``, the entry (below the validated field) and the problem.
    """
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, float) and not math.isfinite(value):  # 1e400 (NaN: the JSON reader)
        raise ValueError(f"{path} = {shown(value)}: allowed a finite number")
    if isinstance(value, int) and abs(value) > MAX_JSON_INT:
        raise ValueError(f"{path} = {_show(value)}: allowed an integer in [-2**53, 2**53]")
    if isinstance(value, str) and len(value) > MAX_STRING:
        raise ValueError(f"{path} is a string of {len(value)} characters: allowed {MAX_STRING}")
    if not isinstance(value, (list, dict)):
        return value
    if depth >= MAX_RECORD_DEPTH:
        raise ValueError(f"{path} is nested too deeply: allowed {MAX_RECORD_DEPTH} levels")
    if len(value) > MAX_RECORD_ITEMS:
        raise ValueError(f"{path} has {len(value)} items: allowed at most {MAX_RECORD_ITEMS}")
    if isinstance(value, list):
        return [_record_value(v, depth + 1, f"{path}[{i}]") for i, v in enumerate(value)]
    for key in value:
        if not _KEY.fullmatch(key):
            raise ValueError(
                f"{path}.{_field_name([key])} is not a valid field name: allowed letters, "
                "digits, '_', '.', '-', starting with a letter or '_' (entries such as "
                "':serialized:' are refused)"
            )
    return {k: _record_value(v, depth + 1, f"{path}.{k}") for k, v in value.items()}


_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]{0,99}")
STRICT: Final = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False, frozen=True)
Name = Annotated[str, Field(min_length=1, max_length=100), AfterValidator(_printable)]
Text = Annotated[str, Field(min_length=1, max_length=1000), AfterValidator(_printable)]
Bound = Annotated[float, Field(ge=-MAX_BOUND, le=MAX_BOUND)]
Count = Annotated[int, Field(ge=0, le=MAX_JSON_INT)]
Threads = Annotated[int, Field(ge=1, le=1_000_000)]
Record = Annotated[dict[str, Any], AfterValidator(_record_value)]
Model = TypeVar("Model", bound=BaseModel)


class _PolicySchema(BaseModel):
    """The ``policy`` field of config.json (:class:`PolicySpec`)."""

    model_config = STRICT
    type: Annotated[str, Field(pattern="^gaussian_mlp$")]
    hidden_sizes: Annotated[
        list[Annotated[int, Field(ge=1, le=MAX_HIDDEN_SIZE)]], Field(max_length=MAX_HIDDEN_LAYERS)
    ]
    activation: Activation
    action_size: Annotated[int, Field(ge=1, le=MAX_ACTION_SIZE)]
    action_low: list[Bound]
    action_high: list[Bound]
    noise: Noise = "diagonal"
    frame_stack: Annotated[int, Field(ge=1, le=MAX_FRAME_STACK)] = 1


class _EnvKwargsSchema(BaseModel):
    """The ``env_kwargs`` field: their types here, their ranges in the env's ``EnvConfig``."""

    model_config = STRICT
    base_controller: Name | None
    control_dt_s: float
    residual_scale_nm: float
    min_torque_nm: float
    max_torque_nm: float
    env_id: Literal[ENV_IDS] = DEFAULT_ENV_ID  # type: ignore[valid-type]
    observation: Literal[OBSERVATION_MODES] | None = None  # type: ignore[valid-type]


class _CoupledEnvKwargsSchema(BaseModel):
    """The ``env_kwargs`` of a ``DrillStringCoupled-v0`` model: their types here, their ranges
    in the env's ``CoupledEnvConfig``."""

    model_config = STRICT
    env_id: Literal[COUPLED_ENV_ID]  # type: ignore[valid-type]
    torque_loop: Name
    control_dt_s: float
    residual_torque_nm: float
    max_torque_nm: float


class _ConfigSchema(BaseModel):
    """config.json: the model and its training record (never interpreted)."""

    model_config = STRICT
    format: Annotated[int, Field(ge=PREVIOUS_FORMAT, le=FORMAT_VERSION)]
    name: Name
    env_kwargs: _EnvKwargsSchema
    observation_size: Annotated[int, Field(ge=1, le=MAX_OBSERVATION_SIZE)]
    policy: _PolicySchema
    train_config: Record | None = None
    timesteps: Count | None = None
    run_timesteps: Count | None = None
    resumed_from: Count | None = None
    selected: Text | None = None
    validation_score: Annotated[float, Field(ge=-1e9, le=1e9)] | None = None
    wall_time_s: Annotated[float, Field(ge=0.0, le=1e9)] | None = None
    cpu_count: Threads | None = None
    torch_threads: Threads | None = None
    source: Text | None = None


class _CoupledConfigSchema(_ConfigSchema):
    """config.json of a ``DrillStringCoupled-v0`` model."""

    env_kwargs: _CoupledEnvKwargsSchema  # type: ignore[assignment]


def _is_coupled(data: Any) -> bool:
    kwargs = data.get("env_kwargs") if isinstance(data, dict) else None
    return isinstance(kwargs, dict) and kwargs.get("env_id") == COUPLED_ENV_ID


RECORD_FIELDS: Final = tuple(_ConfigSchema.model_fields)[5:]
"""Optional top-level fields of config.json: the training record (never interpreted)."""


def _field_name(loc: Sequence[int | str]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            text = part if _KEY.fullmatch(part) or part.isprintable() else repr(part)
            out += ("." if out else "") + _one_line(text, 40)
    return out or "(top level)"


def _schema_error(
    where: str, error: ValidationError, root: type[BaseModel], prefix: str = ""
) -> ValueError:
    """The first error of a pydantic validation as one line naming the file and field."""
    errors = error.errors(include_url=False)
    unknown = [e for e in errors if e["type"] == "extra_forbidden"]
    first = (unknown or errors)[0]  # an unknown field first: it names a hostile entry
    loc = list(first["loc"])
    name = prefix + _field_name(loc)
    kind, message = first["type"], first["msg"]
    if kind == "extra_forbidden":
        model = root
        for part in loc[:-1]:
            annotation = model.model_fields[str(part)].annotation
            if isinstance(annotation, type) and issubclass(annotation, BaseModel):
                model = annotation
        allowed = ", ".join(model.model_fields)
        return ValueError(f"{where!r}: field {name} is not known: allowed fields are {allowed}")
    if kind == "missing":
        return ValueError(f"{where!r}: field {name} is missing")
    if kind == "model_type":
        message = "expected an object"
    elif kind == "value_error":  # our validators: the entry below the field, and the problem
        return ValueError(f"{where!r}: field {name}{message.removeprefix('Value error, ')}")
    else:
        message = "allowed " + message.removeprefix("Input should be ")
    return ValueError(f"{where!r}: field {name} = {_show(first['input'])}: {message}")


def validate_json(schema: type[Model], data: Any, where: str) -> Model:
    """``data`` (parsed JSON) validated by the pydantic model ``schema``.

    Raises:
        ValueError: One line naming ``where`` and the first field in error.
    """
    try:
        return schema.model_validate(data)
    except ValidationError as err:
        raise _schema_error(where, err, schema) from None


# -------------------------------------------------------------------------------- config.json
@dataclass(frozen=True)
class ModelConfig:
    """A validated ``config.json``.

    Attributes:
        name: The agent's name.
        env_kwargs: The env keywords the model records, without ``env_id``.
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

    @property
    def format(self) -> int:
        """The format version of the file (2: ``.npz`` arrays, 3: safetensors)."""
        return int(self.record.get("format", FORMAT_VERSION))


def split_env_id(env_kwargs: Mapping[str, Any]) -> tuple[str, dict[str, Any]]:
    """``(env id, the env keywords without it)`` of validated ``env_kwargs``."""
    keywords = dict(env_kwargs)
    return str(keywords.pop("env_id", DEFAULT_ENV_ID)), keywords


def validate_env_kwargs(data: Any, where: str) -> dict[str, Any]:
    """The ``env_kwargs`` field: the keywords of ``_EnvKwargsSchema`` (``env_id`` and
    ``observation`` for ``DrillStringField-v0`` only), typed there and checked by the env's
    own ``EnvConfig`` (whether the base controller is registered is checked by the loader).

    Raises:
        ValueError: One line naming ``where`` and the field.
    """
    if isinstance(data, dict) and data.get("env_id") == COUPLED_ENV_ID:
        return _coupled_env_kwargs(data, where)
    try:
        schema = _EnvKwargsSchema.model_validate(data)
    except ValidationError as err:
        raise _schema_error(where, err, _EnvKwargsSchema, "env_kwargs.") from None
    keywords = schema.model_dump(exclude_unset=True)
    env_id, env_keywords = split_env_id(keywords)
    if "observation" in keywords and env_id != FIELD_ENV_ID:
        raise ValueError(
            f"{where!r}: field env_kwargs.observation is a keyword of {FIELD_ENV_ID}: set "
            "env_kwargs.env_id to it"
        )
    config = FieldEnvConfig if env_id == FIELD_ENV_ID else EnvConfig
    try:
        config.from_kwargs(env_keywords)
    except (ValueError, TypeError) as err:
        raise ValueError(f"{where!r}: field env_kwargs.{_one_line(str(err))}") from None
    return keywords


def _coupled_env_kwargs(data: dict[str, Any], where: str) -> dict[str, Any]:
    """:func:`validate_env_kwargs` of a ``DrillStringCoupled-v0`` model."""
    try:
        schema = _CoupledEnvKwargsSchema.model_validate(data)
    except ValidationError as err:
        raise _schema_error(where, err, _CoupledEnvKwargsSchema, "env_kwargs.") from None
    keywords = schema.model_dump()
    try:
        CoupledEnvConfig(**{k: v for k, v in keywords.items() if k != "env_id"})
    except (ValueError, TypeError) as err:
        raise ValueError(f"{where!r}: field env_kwargs.{_one_line(str(err))}") from None
    return keywords


def validate_config(data: Any, where: str) -> ModelConfig:
    """Check a parsed config.json against the schema (``docs/model-files.md``).

    Args:
        data: The parsed JSON.
        where: The file (for the messages).

    Raises:
        ValueError: One line naming ``where``, the field and what is wrong: an unknown or
            missing field, a wrong type, a number out of range or not finite, a key such as
            ``:serialized:`` in the training record.
    """
    if isinstance(data, dict) and data.get("format") == 1 and type(data["format"]) is int:
        raise ValueError(
            f"{where!r}: field format = 1: this is a Stable-Baselines3 model (model.zip, a "
            "pickle); load the model.zip itself with trust_pickle=True or convert it with "
            "'drill-gym convert' (agents.convert)"
        )
    schema = validate_json(
        _CoupledConfigSchema if _is_coupled(data) else _ConfigSchema, data, where
    )
    env_id, env_kwargs = split_env_id(validate_env_kwargs(data["env_kwargs"], where))
    policy = schema.policy
    for key in ("action_low", "action_high"):
        if len(getattr(policy, key)) != policy.action_size:
            raise ValueError(
                f"{where!r}: field policy.{key} = {getattr(policy, key)}: allowed a list of "
                f"{policy.action_size} (policy.action_size)"
            )
    if not all(a < b for a, b in zip(policy.action_low, policy.action_high, strict=True)):
        raise ValueError(
            f"{where!r}: field policy.action_low = {policy.action_low} must be below "
            f"action_high = {policy.action_high}"
        )
    if policy.noise == "state_dependent" and not policy.hidden_sizes:
        raise ValueError(f"{where!r}: field policy.noise = 'state_dependent' needs a hidden layer")
    inputs = schema.observation_size * policy.frame_stack
    if inputs > MAX_INPUT_SIZE:
        raise ValueError(
            f"{where!r}: field policy.frame_stack = {policy.frame_stack} is out of range: "
            f"observation_size {schema.observation_size} x frame_stack {policy.frame_stack} = "
            f"{inputs} network inputs, allowed at most {MAX_INPUT_SIZE}"
        )
    spec = PolicySpec(
        observation_size=schema.observation_size,
        hidden_sizes=tuple(policy.hidden_sizes),
        activation=policy.activation,
        action_size=policy.action_size,
        action_low=tuple(policy.action_low),
        action_high=tuple(policy.action_high),
        noise=policy.noise,
        frame_stack=policy.frame_stack,
    )
    record = {k: v for k, v in data.items() if k not in ("name", "env_kwargs")}
    return ModelConfig(schema.name, env_kwargs, spec, record, env_id)


# ------------------------------------------------------------------------- safetensors files
def read_safetensors(
    path: Path, expected: Mapping[str, tuple[int, ...]], what: str
) -> dict[str, npt.NDArray[np.float64]]:
    """Arrays of a safetensors file, each float32 or float64 of the expected shape, finite.

    The header length (the file's first 8 bytes) must be at most
    :data:`MAX_HEADER_BYTES_PER_ARRAY` per array plus 4096; the ``safetensors`` library then
    parses the header (names, dtypes, shapes, offsets that tile the data), which is checked
    against ``expected`` before the data is read. The file may hold at most the arrays'
    float64 size plus that header; it is read once and parsed again from those bytes.

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
    bad = f"{where!r} is not valid {what} (a safetensors file of float arrays)"
    max_header = MAX_HEADER_BYTES_PER_ARRAY * len(expected) + 4096
    with path.open("rb") as f:
        head = f.read(8)
    header = int.from_bytes(head, "little") if len(head) == 8 else -1
    if not 0 < header <= max_header:
        found = "no header length" if header < 0 else f"a header of {header} bytes"
        raise ValueError(f"{bad}: {found}: allowed 1 to {max_header} bytes")
    try:
        with safetensors.safe_open(where, framework="np") as file:
            layout = {
                name: (file.get_slice(name).get_dtype(), tuple(file.get_slice(name).get_shape()))
                for name in file.keys()  # noqa: SIM118 - a safetensors handle, not a dict
            }
    except (safetensors.SafetensorError, OSError, ValueError, OverflowError) as err:
        raise ValueError(f"{bad}: {_one_line(str(err))}") from None
    _check_layout(where, layout, expected, what)
    max_file = 8 + header + sum(8 * math.prod(s) for s in expected.values())
    with path.open("rb") as f:  # read once: the parser below sees exactly these bytes
        data = f.read(max_file + 1)
    if len(data) > max_file:
        size = max(path.stat().st_size, len(data))
        raise ValueError(f"{where!r}: {size} bytes is too large for {what}: allowed {max_file}")
    try:
        tensors = dict(safetensors.deserialize(data))
    except (safetensors.SafetensorError, ValueError, OverflowError) as err:
        raise ValueError(f"{bad}: {_one_line(str(err))}") from None
    _check_layout(
        where, {k: (t["dtype"], tuple(t["shape"])) for k, t in tensors.items()}, expected, what
    )
    out: dict[str, npt.NDArray[np.float64]] = {}
    for name, shape in expected.items():
        dtype = _SAFETENSORS_DTYPES[tensors[name]["dtype"]]
        array = np.frombuffer(tensors[name]["data"], dtype=dtype).reshape(shape)
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{where!r}: array {name} has non-finite values (NaN or inf)")
        out[name] = array.astype(np.float64)
    return out


def _check_layout(
    where: str,
    layout: Mapping[str, tuple[str, tuple[int, ...]]],
    expected: Mapping[str, tuple[int, ...]],
    what: str,
) -> None:
    """The arrays' names, dtypes and shapes as a safetensors header declares them."""
    unexpected = [name for name in layout if name not in expected]
    if unexpected:
        raise ValueError(
            f"{where!r}: unexpected array {_show(unexpected[0])}: expected one each of "
            f"{', '.join(expected)}"
        )
    missing = [name for name in expected if name not in layout]
    if missing:
        raise ValueError(f"{where!r}: missing array(s) {', '.join(missing)} ({what})")
    for name in expected:
        dtype, shape = layout[name]
        if dtype not in _SAFETENSORS_DTYPES:
            raise ValueError(
                f"{where!r}: array {name} has dtype {_show(dtype)}: allowed F32 or F64 "
                "(float32 or float64)"
            )
        if shape != expected[name]:
            raise ValueError(
                f"{where!r}: array {name} has shape {shape}: expected {expected[name]}"
            )


def write_safetensors(path: Path, arrays: Mapping[str, npt.ArrayLike]) -> None:
    """Write float arrays (float32 and float64 kept, other dtypes as float64) to ``path`` as
    safetensors (whole or not at all, never through a link: :func:`drill_env.files.replacing`)."""
    clean: dict[str, npt.NDArray[Any]] = {}
    for name, value in arrays.items():
        array = np.asarray(value)
        if array.dtype not in (np.float32, np.float64):
            array = array.astype(np.float64)
        clean[name] = np.array(array, dtype=array.dtype.newbyteorder("<"), order="C")
    write_bytes(path, safetensors.numpy.save(clean))


def check_obs_norm(norm: ObsNorm, where: str) -> None:
    """Ranges of the normalisation statistics (their arrays already finite)."""
    if np.any(norm.var < 0):
        raise ValueError(f"{where!r}: array var has negative entries: allowed >= 0")
    if not 0 < norm.clip_obs <= MAX_BOUND:
        raise ValueError(
            f"{where!r}: clip_obs = {shown(norm.clip_obs)} is out of range: allowed (0, 1e9]"
        )
    if not 0 <= norm.epsilon <= 1.0:
        raise ValueError(
            f"{where!r}: epsilon = {shown(norm.epsilon)} is out of range: allowed [0, 1]"
        )
    if np.any(norm.var + norm.epsilon <= 0):
        raise ValueError(f"{where!r}: var + epsilon must be > 0 in every entry")


# --------------------------------------------------------------------------- folder read/write
def array_files(format_version: int) -> tuple[str, str]:
    """``(weights file, normalisation file)`` of a model folder of ``format_version``."""
    if format_version == PREVIOUS_FORMAT:
        return LEGACY_WEIGHTS_FILE, LEGACY_NORM_FILE
    return WEIGHTS_FILE, NORM_FILE


def read_config(folder: Path) -> ModelConfig:
    """``config.json`` of ``folder``, checked against the schema."""
    path = folder / CONFIG_FILE
    return validate_config(read_json(path), str(path))


def read_arrays(
    folder: Path, config: ModelConfig
) -> tuple[ObsNorm, dict[str, npt.NDArray[np.float64]]]:
    """The normalisation statistics and the weights of ``folder`` (safetensors, or ``.npz``
    for format 2), checked against ``config``."""
    weights_name, norm_name = array_files(config.format)
    read = read_npz if config.format == PREVIOUS_FORMAT else read_safetensors
    norm_file = folder / norm_name
    shapes = ObsNorm.shapes(config.spec.input_size)
    norm = ObsNorm.from_arrays(read(norm_file, shapes, "observation normalisation statistics"))
    check_obs_norm(norm, str(norm_file))
    weights = read(folder / weights_name, config.spec.weight_shapes(), "policy network weights")
    return norm, weights


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
    """Write a model folder of the current format (the arrays first, ``config.json`` last).

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
        **{k: v for k, v in (record or {}).items() if k in RECORD_FIELDS},
    }
    text = json.dumps(config, indent=2, allow_nan=False) + "\n"
    validate_config(json.loads(text), str(folder / CONFIG_FILE))
    GaussianMlp(spec, weights)  # shapes and finiteness
    check_obs_norm(obs_norm, str(folder / NORM_FILE))
    folder.mkdir(parents=True, exist_ok=True)
    write_safetensors(folder / WEIGHTS_FILE, weights)
    write_safetensors(folder / NORM_FILE, obs_norm.arrays())
    write_text(folder / CONFIG_FILE, text)
    return folder
