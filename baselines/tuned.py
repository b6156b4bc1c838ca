"""The speed loops with tuned factors: ``stiff_pi_tuned``, ``soft_speed_tuned``,
``z_torque_tuned``.

Each is its loop (:mod:`baselines.stiff_pi`, :mod:`baselines.soft_speed`,
:mod:`baselines.z_torque`) with the relative factors that ``drill-gym tune``
(:mod:`experiments.tune_baselines`) selected, read from the data file
:data:`TUNED_GAINS_FILE` (``baselines/tuned_gains.json``, shipped with the package). The file
holds one entry per controller and plant kind: the factors tuned on ``DrillString-v0`` apply
when the controller's model of the string is a :class:`~drill_env.parameters.DrillStringParameters`,
those tuned on ``DrillStringField-v0`` when it is a
:class:`~drill_env.distributed.DistributedStringParameters`. The controller picks the entry in
:meth:`tuning` from the model the env hands it, so one name serves both envs; the gains
(``kp``, ``ki``, ``z``, ``tau_mean``) then follow from that model exactly as for the untuned
loop.

The file is plain JSON, read with :func:`json.loads` and checked field by field
(:func:`parse_tuned_gains`): nothing in it is executed, unknown or malformed fields are a
``ValueError`` naming the field, and every factor passes the range checks of its gains
dataclass. Its layout::

    {"format": 1,
     "about": "free text",
     "controllers": {
       "soft_speed": {
         "DrillStringParameters": {
           "env": "DrillString-v0",
           "gains": {"impedance_factor": 1.2, "frequency_factor": 0.9,
                     "inertia_compensation": true},
           "validation_score": 0.41, "default_validation_score": 0.47,
           "command": "drill-gym tune --env DrillString-v0 --write"},
         "DistributedStringParameters": {...}},
       "z_torque": {...}}}

``gains`` may give any field of the loop's gains dataclass except ``limits`` (the drive's
torque limits come from the env); a field left out keeps its default.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Final

from baselines.base import Gains, Model, resolve_model
from baselines.soft_speed import SoftSpeed, SoftSpeedGains
from baselines.speed_loop import SpeedLoopController
from baselines.stiff_pi import StiffPI, StiffPIGains
from baselines.z_torque import ZTorque, ZTorqueGains
from drill_env.distributed import DistributedStringParameters
from drill_env.ids import ENV_ID, FIELD_ENV_ID
from drill_env.parameters import DrillStringParameters
from drill_env.validation import check_unknown, printable, shown

__all__ = [
    "KIND_ENVS",
    "TUNABLE",
    "TUNED_FORMAT",
    "TUNED_GAINS_FILE",
    "SoftSpeedTuned",
    "StiffPITuned",
    "TunedEntry",
    "ZTorqueTuned",
    "load_tuned_gains",
    "parse_tuned_gains",
    "plant_kind",
    "tuned_gains_document",
]

TUNED_GAINS_FILE: Final = Path(__file__).with_name("tuned_gains.json")
"""The shipped file of tuned factors."""
TUNED_FORMAT: Final = 1
"""Version of the file's layout."""
TUNABLE: Final[dict[str, type[Any]]] = {
    "stiff_pi": StiffPIGains,
    "soft_speed": SoftSpeedGains,
    "z_torque": ZTorqueGains,
}
"""The loops whose factors can be tuned, with their gains dataclasses."""
KIND_ENVS: Final = {
    "DrillStringParameters": ENV_ID,
    "DistributedStringParameters": FIELD_ENV_ID,
}
"""Plant kind (the type of the controller's model) -> the env its factors are tuned on."""
_MAX_BYTES: Final = 1_000_000
_ENTRY_KEYS: Final = ("env", "gains", "validation_score", "default_validation_score", "command")
_TOP_KEYS: Final = ("format", "about", "controllers")


@dataclass(frozen=True)
class TunedEntry:
    """The tuned factors of one loop on one plant kind, with where they come from.

    Attributes:
        gains: The factors (an instance of the loop's gains dataclass).
        env_id: The env they were tuned on.
        validation_score: Their score on the validation scenarios (``None``: not recorded).
        default_validation_score: The default factors' score on the same scenarios.
        command: The command that selected them.
    """

    gains: Gains
    env_id: str
    validation_score: float | None = None
    default_validation_score: float | None = None
    command: str = ""


def plant_kind(model: Model) -> str:
    """The plant kind of a controller's model: ``"DrillStringParameters"`` (the 4-DOF string)
    or ``"DistributedStringParameters"`` (a distributed field string)."""
    if isinstance(model, DistributedStringParameters):
        return "DistributedStringParameters"
    if isinstance(model, DrillStringParameters):
        return "DrillStringParameters"
    raise TypeError(
        "model must be a DrillStringParameters or a DistributedStringParameters, got "
        f"{type(model).__name__}"
    )


def _fail(where: str, message: str) -> ValueError:
    return ValueError(f"{printable(where, 200)}: {message}")


def _finite(value: Any) -> float | None:
    """``value`` as a finite float when it is a JSON number (not a bool) in the float range."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    try:
        number = float(value)
    except OverflowError:
        return None
    return number if math.isfinite(number) else None


def _object(value: Any, where: str, allowed: tuple[str, ...], required: tuple[str, ...]) -> None:
    if not isinstance(value, dict):
        raise _fail(where, f"expected a JSON object, got {type(value).__name__}")
    unknown = sorted(set(value) - set(allowed))
    if unknown:
        raise _fail(
            f"{where}.{printable(unknown[0])}", f"unknown field: allowed {', '.join(allowed)}"
        )
    missing = [k for k in required if k not in value]
    if missing:
        raise _fail(f"{where}.{missing[0]}", "missing")


def _number_or_none(value: Any, where: str) -> float | None:
    if value is None:
        return None
    number = _finite(value)
    if number is None:
        raise _fail(where, f"= {shown(value)}: expected a finite number or null")
    return number


def _gains(name: str, value: Any, where: str) -> Gains:
    gains_type = TUNABLE[name]
    fields = {f.name: f for f in dataclasses.fields(gains_type) if f.name != "limits"}
    _object(value, where, tuple(fields), ())
    kwargs: dict[str, Any] = {}
    for key, item in value.items():
        default = getattr(gains_type(), key)
        if isinstance(default, bool):
            if not isinstance(item, bool):
                raise _fail(f"{where}.{key}", f"= {shown(item)}: expected true or false")
            kwargs[key] = item
            continue
        number = _finite(item)
        if number is None:
            raise _fail(f"{where}.{key}", f"= {shown(item)}: expected a finite number")
        kwargs[key] = number
    try:
        return gains_type(**kwargs)
    except (TypeError, ValueError) as exc:
        raise _fail(where, str(exc)) from None


def parse_tuned_gains(data: Any, source: str = "tuned gains") -> dict[str, dict[str, TunedEntry]]:
    """The entries of a decoded tuned-gains document (the layout of the module docstring).

    Args:
        data: The decoded JSON.
        source: Where it comes from, for the messages (a file name).

    Returns:
        Loop name -> plant kind -> :class:`TunedEntry`.

    Raises:
        ValueError: naming the field (``controllers.soft_speed.DrillStringParameters.gains.x``)
            that is unknown, missing, of the wrong type or out of range.
    """
    _object(data, source, _TOP_KEYS, ("format", "controllers"))
    version = data["format"]
    if isinstance(version, bool) or version != TUNED_FORMAT:
        raise _fail(f"{source}.format", f"= {shown(version)}: expected {TUNED_FORMAT}")
    if not isinstance(data.get("about", ""), str):
        raise _fail(f"{source}.about", "expected a string")
    controllers = data["controllers"]
    _object(controllers, f"{source}.controllers", tuple(TUNABLE), ())
    out: dict[str, dict[str, TunedEntry]] = {}
    for name, kinds in controllers.items():
        where = f"{source}.controllers.{name}"
        _object(kinds, where, tuple(KIND_ENVS), ())
        out[name] = {}
        for kind, entry in kinds.items():
            at = f"{where}.{kind}"
            _object(entry, at, _ENTRY_KEYS, ("env", "gains"))
            if entry["env"] != KIND_ENVS[kind]:
                raise _fail(
                    f"{at}.env", f"= {shown(entry['env'])}: expected {shown(KIND_ENVS[kind])}"
                )
            command = entry.get("command", "")
            if not isinstance(command, str):
                raise _fail(f"{at}.command", f"= {shown(command)}: expected a string")
            out[name][kind] = TunedEntry(
                gains=_gains(name, entry["gains"], f"{at}.gains"),
                env_id=KIND_ENVS[kind],
                validation_score=_number_or_none(
                    entry.get("validation_score"), f"{at}.validation_score"
                ),
                default_validation_score=_number_or_none(
                    entry.get("default_validation_score"), f"{at}.default_validation_score"
                ),
                command=command,
            )
    return out


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if key in out:
            raise ValueError(f"field {shown(key)} appears twice")
        out[key] = value
    return out


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def load_tuned_gains(path: Path | str | None = None) -> dict[str, dict[str, TunedEntry]]:
    """The tuned factors in ``path`` (default :data:`TUNED_GAINS_FILE`), checked by
    :func:`parse_tuned_gains`.

    Raises:
        FileNotFoundError: no such file.
        ValueError: not JSON (or ``NaN``, ``Infinity``, a repeated field, over 1 MB), or a
            field that breaks the layout; the message names the file and the field.
    """
    file = Path(TUNED_GAINS_FILE if path is None else path)
    name = printable(str(file), 200)
    if not file.is_file():
        raise FileNotFoundError(f"no tuned gains file at {shown(name)}")
    with file.open("rb") as stream:
        raw = stream.read(_MAX_BYTES + 1)
    if len(raw) > _MAX_BYTES:
        raise ValueError(
            f"{shown(name)} is larger than {_MAX_BYTES:,} bytes: not a tuned gains file"
        )
    try:
        data = json.loads(
            raw.decode("utf-8"), object_pairs_hook=_no_duplicates, parse_constant=_no_constant
        )
    except RecursionError:
        raise ValueError(
            f"{shown(name)} is not a tuned gains file: JSON nested too deeply"
        ) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"{shown(name)} is not valid JSON: {printable(exc, 200)}") from None
    return parse_tuned_gains(data, printable(file.name, 200))


def tuned_gains_document(
    entries: Mapping[str, Mapping[str, TunedEntry]], about: str = ""
) -> dict[str, Any]:
    """The JSON document (a dict) of ``entries``, the inverse of :func:`parse_tuned_gains`
    (only the fields of the gains that :func:`parse_tuned_gains` reads, never ``limits``)."""
    controllers: dict[str, Any] = {}
    for name in TUNABLE:
        if name not in entries:
            continue
        controllers[name] = {}
        for kind in KIND_ENVS:
            entry = entries[name].get(kind)
            if entry is None:
                continue
            gains = {
                f.name: getattr(entry.gains, f.name)
                for f in dataclasses.fields(entry.gains)  # type: ignore[arg-type]
                if f.name != "limits"
            }
            controllers[name][kind] = {
                "env": entry.env_id,
                "gains": gains,
                "validation_score": entry.validation_score,
                "default_validation_score": entry.default_validation_score,
                "command": entry.command,
            }
    return {"format": TUNED_FORMAT, "about": about, "controllers": controllers}


class _TunedSpeedLoop(SpeedLoopController):
    """A speed loop whose factors are read from :data:`TUNED_GAINS_FILE`, one set per plant
    kind, picked in :meth:`gains_for` from the model the controller tunes for.

    Args:
        gains: Not accepted (the factors come from the file; use the untuned loop to give
            your own).
        model: The controller's own model of the string (preset name or parameters).
        **overrides: Fields replacing the tuned ones for every plant kind (``limits``, say).

    Raises:
        TypeError: ``gains`` given, or an override the loop does not have.
        ValueError: the file is malformed, or has no factors for the model's plant kind.
    """

    base_name: ClassVar[str]

    def __init__(self, gains: Any = None, model: str | Model = "zribi2024", **overrides: Any):
        if gains is not None:
            raise TypeError(
                f"{self.name} reads its factors from {TUNED_GAINS_FILE.name}: give single "
                f"factors as keywords, or use {self.base_name} with gains={shown(gains)}"
            )
        valid = [f.name for f in dataclasses.fields(self.gains_type)]
        check_unknown(overrides, valid, "gain", self.name)
        tuned = load_tuned_gains().get(self.base_name, {})
        self._tuned: dict[str, Any] = {
            kind: dataclasses.replace(entry.gains, **overrides)  # type: ignore[type-var]
            for kind, entry in tuned.items()
        }
        resolved = resolve_model(model)
        super().__init__(self.gains_for(resolved), model=resolved)

    def gains_for(self, model: DrillStringParameters | DistributedStringParameters) -> Any:
        """The tuned factors for the plant kind of ``model``."""
        kind = plant_kind(model)
        if kind not in self._tuned:
            raise ValueError(
                f"{self.name}: {TUNED_GAINS_FILE.name} has no factors of {self.base_name} for a "
                f"{kind} model (tuned on {KIND_ENVS[kind]}): run drill-gym tune --env "
                f"{KIND_ENVS[kind]} --write"
            )
        return self._tuned[kind]


class StiffPITuned(_TunedSpeedLoop, StiffPI):
    """``stiff_pi`` with the factors tuned by ``drill-gym tune``."""

    name = "stiff_pi_tuned"
    base_name = "stiff_pi"


class SoftSpeedTuned(_TunedSpeedLoop, SoftSpeed):
    """``soft_speed`` with the factors tuned by ``drill-gym tune``."""

    name = "soft_speed_tuned"
    base_name = "soft_speed"


class ZTorqueTuned(_TunedSpeedLoop, ZTorque):
    """``z_torque`` with the factors tuned by ``drill-gym tune``."""

    name = "z_torque_tuned"
    base_name = "z_torque"
