"""A calibrated plant file (``plant.json``, docs/calibration.md section 3): read with a schema
check, written without pickles, and turned into a plant the environments run.

The file is plain JSON: ``format`` (:data:`PLANT_FORMAT`), ``family`` (a friction family of
:mod:`drill_env.bit_model`), ``uses_wob``, ``parameters`` (name -> value, unit, whether the
data identified it, its relative standard deviation, a note), ``initial_twist_rad``, the
``window`` and ``log`` it was fitted on, the ``fit`` settings and numbers, and optional
``top_drive`` (the identified speed loop of the top drive). Nothing read becomes code or a
path.

:func:`drill_string_parameters` maps the plant onto the 4-DOF ``DrillString-v0`` plant and
:func:`env_keywords` gives the keywords of ``gym.make`` that follow from it (torque limits,
reference speed, WOB, noise), so that controllers run on a twin of the rig.
"""

from __future__ import annotations

import json
import math
import os
import stat
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from drill_env.bit_model import (
    FAMILIES,
    N_MODEL_PARAMS,
    P_A0,
    P_AA,
    P_C,
    P_CV,
    P_J,
    P_K,
    P_TAU,
    P_XI,
)
from drill_env.files import write_text
from drill_env.parameters import PLANT_DT_S, DrillStringParameters
from drill_env.validation import printable, shown

__all__ = [
    "MODEL_PARAMETERS",
    "PARAMETER_RANGES",
    "PLANT_FORMAT",
    "READ_FORMATS",
    "CalibratedPlant",
    "FittedParameter",
    "drill_string_parameters",
    "env_keywords",
    "check_parameter",
    "load_plant",
    "parameter_range_text",
    "parameter_unit",
]

PLANT_FORMAT: Final = "drill-string-gym/calibrated-plant/3"
"""The ``format`` of the plant files this version writes (2 adds each parameter's
``interval_95``; 3 the optional upper string of ``top_drive``,
:data:`drill_env.bit_model.STRING_KEYS`, which a reader of format 2 would ignore)."""
READ_FORMATS: Final = (
    "drill-string-gym/calibrated-plant/1",
    "drill-string-gym/calibrated-plant/2",
    PLANT_FORMAT,
)
"""The plant file formats this version reads."""
MAX_PLANT_BYTES: Final = 1 << 20
"""Largest plant file read, bytes."""

MODEL_PARAMETERS: Final = {
    "bit_inertia": (P_J, "kg m^2"),
    "stiffness": (P_K, "N m/rad"),
    "damping": (P_C, "N m s/rad"),
    "static_friction": (P_AA, "N m"),
    "sliding_friction": (P_A0, "N m"),
    "stribeck_rate": (P_XI, "s/rad"),
    "viscous_friction": (P_CV, "N m s/rad"),
    "memory_time": (P_TAU, "s"),
}
"""Name of each model parameter -> (index in the model vector, unit without WOB)."""
PARAMETER_RANGES: Final = {
    "bit_inertia": (1e-9, 1e9),
    "stiffness": (1e-9, 1e12),
    "damping": (0.0, 1e12),
    "static_friction": (1e-12, 1e9),
    "sliding_friction": (1e-12, 1e9),
    "stribeck_rate": (0.0, 1e6),
    "viscous_friction": (0.0, 1e12),
    "memory_time": (1e-9, 1e6),
}
"""Allowed ``[low, high]`` of each model parameter, in its unit (the friction torques in N m,
or m per N of WOB). The bit inertia, the stiffness and the memory time divide in the model
(the natural period ``2 pi sqrt(J/k)``, the lag ``h / tau``) and the friction torques must
be positive, so their ranges start above 0; the upper ends keep every product of the
simulation within the float range. A fitted value, a ``--fix`` value and a plant file's
value are all checked against these."""
FAMILY_PARAMETERS: Final = {
    "karnopp": tuple(list(MODEL_PARAMETERS)[:6]),
    "stribeck_viscous": tuple(list(MODEL_PARAMETERS)[:7]),
    "memory": tuple(MODEL_PARAMETERS),
}
"""The parameters each friction family has."""


def parameter_unit(name: str, uses_wob: bool) -> str:
    """Unit of the parameter ``name``: the friction torques are in m (per N of WOB) with WOB."""
    if uses_wob and name in ("static_friction", "sliding_friction"):
        return "m"
    return MODEL_PARAMETERS[name][1]


def parameter_range_text(name: str) -> str:
    """The allowed range of the parameter ``name`` as a message shows it, with its unit."""
    low, high = PARAMETER_RANGES[name]
    unit = MODEL_PARAMETERS[name][1]
    if name in ("static_friction", "sliding_friction"):
        unit = f"{unit} (m per N with WOB)"
    return f"[{low:g}, {high:g}] {unit}"


def check_parameter(name: str, value: object, where: str = "") -> float:
    """``value`` as a float if it is a finite number within the range of the model parameter
    ``name`` (:data:`PARAMETER_RANGES`); else ``ValueError`` naming ``where`` (the key path
    of the value, default ``name``) and the allowed range."""
    if name not in PARAMETER_RANGES:
        raise ValueError(f"unknown parameter {shown(name)}: allowed {', '.join(MODEL_PARAMETERS)}")
    label = where or name
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    number = float(value) if ok else math.nan  # type: ignore[arg-type]
    low, high = PARAMETER_RANGES[name]
    if not (math.isfinite(number) and low <= number <= high):
        raise ValueError(
            f"{label} = {shown(value)} is out of range: allowed {parameter_range_text(name)}"
        )
    return number


@dataclass(frozen=True)
class FittedParameter:
    """One parameter of a calibrated plant.

    Attributes:
        value: Its value, in ``unit``.
        unit: SI unit.
        identified: Whether the data determined it (False: fixed, ``note`` says at what).
        relative_std: Relative standard deviation of the fitted value, or None.
        note: How it was obtained.
        interval_95: ``(low, high)``: its 95 % interval (bootstrap), in ``unit``, or None.
    """

    value: float
    unit: str
    identified: bool = True
    relative_std: float | None = None
    note: str = ""
    interval_95: tuple[float, float] | None = None


@dataclass(frozen=True)
class CalibratedPlant:
    """A bit-side plant fitted to a log (see the module docstring for the file)."""

    family: str
    uses_wob: bool
    parameters: Mapping[str, FittedParameter]
    initial_twist_rad: float = 0.0
    window_s: tuple[float, float] = (0.0, 0.0)
    log: str = ""
    fit: Mapping[str, Any] = field(default_factory=dict)
    top_drive: Mapping[str, float] | None = None
    operating_point: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.family not in FAMILIES:
            raise ValueError(
                f"family = {shown(self.family)} is not known: allowed {', '.join(FAMILIES)}"
            )
        _check_family_parameters(self.family, self.parameters, "parameters")
        for name, p in self.parameters.items():
            check_parameter(name, p.value, f"parameters.{name}.value")
            if p.unit != parameter_unit(name, self.uses_wob):
                raise ValueError(
                    f"parameters.{name}.unit = {shown(p.unit)}: expected "
                    f"{shown(parameter_unit(name, self.uses_wob))}"
                )
        a_a = self.parameters["static_friction"].value
        a_0 = self.parameters["sliding_friction"].value
        if a_0 > a_a:
            raise ValueError(
                f"parameters.sliding_friction.value = {shown(a_0)} is out of range: allowed <= "
                f"static_friction = {shown(a_a)}"
            )

    def model_vector(self) -> npt.NDArray[np.float64]:
        """The model parameter vector of :func:`drill_env.bit_model.simulate_bit`."""
        p = np.zeros(N_MODEL_PARAMS)
        for name, fp in self.parameters.items():
            p[MODEL_PARAMETERS[name][0]] = fp.value
        return p

    def value(self, name: str) -> float:
        """The value of parameter ``name`` (0 for a term its family does not have)."""
        if name in self.parameters:
            return float(self.parameters[name].value)
        if name in MODEL_PARAMETERS:
            return 0.0
        raise ValueError(f"unknown parameter {shown(name)}: allowed {', '.join(MODEL_PARAMETERS)}")

    def to_json(self) -> dict[str, Any]:
        """The plant as the JSON object of the file."""
        return {
            "format": PLANT_FORMAT,
            "family": self.family,
            "uses_wob": self.uses_wob,
            "parameters": {
                n: {
                    "value": p.value,
                    "unit": p.unit,
                    "identified": p.identified,
                    "relative_std": p.relative_std,
                    "note": p.note,
                    "interval_95": None if p.interval_95 is None else list(p.interval_95),
                }
                for n, p in self.parameters.items()
            },
            "initial_twist_rad": self.initial_twist_rad,
            "window_s": list(self.window_s),
            "log": self.log,
            "fit": dict(self.fit),
            "top_drive": None if self.top_drive is None else dict(self.top_drive),
            "operating_point": dict(self.operating_point),
        }

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the plant file (JSON; NaN written as null)."""
        p = Path(path)
        return write_text(p, json.dumps(_clean(self.to_json()), indent=1) + "\n")


def _check_family_parameters(family: str, names: Mapping[str, Any], where: str) -> None:
    """``ValueError`` naming the key path (``where.NAME``) of the first parameter that the
    friction family ``family`` has and ``names`` lacks, or that ``names`` has and it does not."""
    expected = FAMILY_PARAMETERS[family]
    missing = [n for n in expected if n not in names]
    extra = [printable(n) for n in names if n not in expected]
    if missing or extra:
        path = f"{where}.{missing[0]}: missing" if missing else f"{where}.{extra[0]}: unknown"
        raise ValueError(
            f"{path} (family {shown(family)}: missing {missing}, unknown {extra}: expected "
            f"{', '.join(expected)})"
        )


def _clean(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def _field(data: Mapping[str, Any], name: str, kinds: tuple[type, ...], where: str) -> Any:
    if name not in data:
        raise ValueError(f"{where}.{name}: missing (a required field)")
    value = data[name]
    if not isinstance(value, kinds) or isinstance(value, bool) and bool not in kinds:
        names = "/".join(k.__name__ for k in kinds)
        raise ValueError(f"{where}.{name} = {shown(value)} is not {names}")
    return value


def plant_from_json(data: Any, where: str = "plant") -> CalibratedPlant:
    """Check the JSON object of a plant file against the schema and build the plant."""
    if not isinstance(data, Mapping):
        raise ValueError(f"{where}: expected a JSON object, got {type(data).__name__}")
    known = {
        "format", "family", "uses_wob", "parameters", "initial_twist_rad", "window_s", "log",
        "fit", "top_drive", "operating_point",
    }  # fmt: skip
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {unknown}: allowed {sorted(known)}")
    fmt = _field(data, "format", (str,), where)
    if fmt not in READ_FORMATS:
        raise ValueError(
            f"{where}.format = {shown(fmt)}: this version reads "
            f"{', '.join(map(repr, READ_FORMATS))}"
        )
    number = (int, float)
    parameters = {}
    raw = _field(data, "parameters", (dict,), where)
    for name, entry in raw.items():
        if name not in MODEL_PARAMETERS:
            raise ValueError(
                f"{where}.parameters: unknown parameter {shown(name)}: allowed "
                f"{', '.join(MODEL_PARAMETERS)}"
            )
        w = f"{where}.parameters.{name}"
        if not isinstance(entry, Mapping):
            raise ValueError(f"{w}: expected an object with value and unit")
        rel = entry.get("relative_std")
        if rel is not None and (not isinstance(rel, number) or isinstance(rel, bool)):
            raise ValueError(f"{w}.relative_std = {shown(rel)} is not a number or null")
        note = entry.get("note", "")
        if not isinstance(note, str):
            raise ValueError(f"{w}.note = {shown(note)} is not text")
        interval = entry.get("interval_95")
        if interval is not None and not (
            isinstance(interval, list)
            and len(interval) == 2
            and all(isinstance(v, number) and not isinstance(v, bool) for v in interval)
            and interval[0] <= interval[1]
        ):
            raise ValueError(f"{w}.interval_95 = {shown(interval)} is not [low, high] or null")
        parameters[name] = FittedParameter(
            check_parameter(name, _field(entry, "value", number, w), f"{w}.value"),
            _field(entry, "unit", (str,), w),
            bool(_field(entry, "identified", (bool,), w)),
            None if rel is None else float(rel),
            note,
            None if interval is None else (float(interval[0]), float(interval[1])),
        )
    window = _field(data, "window_s", (list,), where)
    if len(window) != 2 or not all(isinstance(v, number) for v in window):
        raise ValueError(f"{where}.window_s = {shown(window)} is not a pair of numbers")
    top = data.get("top_drive")
    if top is not None:
        if not isinstance(top, Mapping) or not all(
            isinstance(v, number) and math.isfinite(v) for v in top.values()
        ):
            raise ValueError(f"{where}.top_drive = {shown(top)} is not an object of numbers")
        top = {str(k): float(v) for k, v in top.items()}
    operating = data.get("operating_point", {})
    if not isinstance(operating, Mapping) or not all(
        isinstance(v, number) for v in operating.values()
    ):
        raise ValueError(
            f"{where}.operating_point = {shown(operating)} is not an object of numbers"
        )
    fit = data.get("fit", {})
    if not isinstance(fit, Mapping):
        raise ValueError(f"{where}.fit = {shown(fit)} is not an object")
    log = data.get("log", "")
    if not isinstance(log, str):
        raise ValueError(f"{where}.log = {shown(log)} is not text")
    family = _field(data, "family", (str,), where)
    if family not in FAMILIES:
        raise ValueError(
            f"{where}.family = {shown(family)} is not known: allowed {', '.join(FAMILIES)}"
        )
    _check_family_parameters(family, parameters, f"{where}.parameters")
    return CalibratedPlant(
        family=family,
        uses_wob=bool(_field(data, "uses_wob", (bool,), where)),
        parameters=parameters,
        initial_twist_rad=float(_field(data, "initial_twist_rad", number, where)),
        window_s=(float(window[0]), float(window[1])),
        log=log,
        fit=dict(fit),
        top_drive=top,
        operating_point={str(k): float(v) for k, v in operating.items()},
    )


def load_plant(path: str | os.PathLike[str]) -> CalibratedPlant:
    """Read and schema-check a plant file; ``ValueError`` naming the bad field otherwise."""
    p = Path(path)
    status = os.stat(p)
    if not stat.S_ISREG(status.st_mode):  # a FIFO or /dev/zero would never end
        raise ValueError(
            f"plant file {str(p)!r} is not a regular file (a folder, FIFO, device or socket "
            "is never opened): expected a plant.json written by drill-gym calibrate"
        )
    with open(p, "rb") as f:
        raw = f.read(MAX_PLANT_BYTES + 1)
    if len(raw) > MAX_PLANT_BYTES:
        size = max(status.st_size, len(raw))
        raise ValueError(f"plant file {str(p)!r} is {size} bytes: allowed {MAX_PLANT_BYTES}")
    try:
        data = _strict_json(raw.decode("utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"plant file {str(p)!r} is not JSON: {printable(str(exc), 200)}") from None
    except RecursionError:
        raise ValueError(f"plant file {str(p)!r} is not JSON: nested too deeply") from None
    except ValueError as exc:  # the hooks below, or an integer with too many digits
        raise ValueError(f"plant file {str(p)!r} is not JSON: {printable(str(exc), 200)}") from None
    return plant_from_json(data, where=p.name)


def _strict_json(text: str) -> Any:
    """``json.loads`` refusing NaN and Infinity, numbers beyond the float range and repeated
    fields (a later one would silently win)."""

    def constant(name: str) -> Any:
        raise ValueError(f"{name} is not allowed: every number must be finite")

    def real(literal: str) -> float:
        value = float(literal)
        if not math.isfinite(value):
            raise ValueError(f"the number {shown(literal)} is beyond the float range")
        return value

    def integer(literal: str) -> int:
        value = int(literal) if len(literal) <= 320 else None  # the float range ends at 1.8e308
        if value is None or abs(value) > sys.float_info.max:
            raise ValueError(f"the integer {shown(literal)} is beyond the float range")
        return value

    def fields(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        result: dict[str, Any] = {}
        for key, value in pairs:
            if key in result:
                raise ValueError(f"field {shown(key)} appears twice")
            result[key] = value
        return result

    return json.loads(
        text, parse_constant=constant, parse_float=real, parse_int=integer, object_pairs_hook=fields
    )


MAP_INERTIA_FRACTION: Final = 0.05
"""Pipe and collar inertias of the 4-DOF map, as a fraction of the bit inertia each."""
MAP_TOP_INERTIA_FACTOR: Final = 5.0
"""Top-drive inertia of the 4-DOF map (when the plant has no identified top drive), in bit
inertias."""


def drill_string_parameters(
    plant: CalibratedPlant, wob_n: float | None = None
) -> DrillStringParameters:
    """The calibrated plant as 4-DOF ``DrillString-v0`` parameters.

    The string's stiffness ``k`` becomes three equal springs in series (``3 k`` each) joined by
    pipe and collar inertias of :data:`MAP_INERTIA_FRACTION` bit inertias (the bit-side model
    has none; they set modes far above the stick-slip one); its damping ``c`` three dampers of
    ``3 c``. A plant with an identified pipe (``top_drive`` keys ``pipe_*``) keeps it: the
    4-DOF pipe is that inertia on its spring and damper, and ``k``, ``c`` become two springs
    of ``2 k`` and dampers of ``2 c`` around the collar. The friction maps exactly for ``karnopp`` and ``stribeck_viscous`` (``R`` = 1 m,
    so ``mu = a`` with WOB; without WOB ``mu R WOB`` = the torque at ``wob_n`` = 1 N unless
    ``wob_n`` is given); a ``memory`` plant loses its memory time (the compiled 4-DOF kernel
    has no friction state): its lag is dropped and the rest kept. The top drive is the
    identified one (``top_drive``) or :data:`MAP_TOP_INERTIA_FACTOR` bit inertias with no
    damping to ground.
    """
    j = plant.value("bit_inertia")
    k = plant.value("stiffness")
    c = plant.value("damping")
    wob = 1.0 if plant.uses_wob or wob_n is None else float(wob_n)
    a_a = plant.value("static_friction") / wob
    a_0 = plant.value("sliding_friction") / wob
    top = plant.top_drive or {}
    pipe = float(top.get("pipe_inertia_kg_m2", 0.0))
    # With an identified pipe it is the 4-DOF pipe, on its spring; the bit-side spring then
    # joins it to the bit in two halves (2 k each) through a collar of the stated fraction.
    lower = 2 if pipe > 0 else 3
    return DrillStringParameters(
        J_dt=float(top.get("inertia_kg_m2", MAP_TOP_INERTIA_FACTOR * j)),
        J_pi=pipe if pipe > 0 else MAP_INERTIA_FRACTION * j,
        J_co=MAP_INERTIA_FRACTION * j,
        J_bi=j,
        c_dt=float(top.get("damping_nm_s_rad", 0.0)),
        c_pi=float(top.get("pipe_damping_nm_s_rad", 0.0)) if pipe > 0 else 3 * c,
        c_co=lower * c,
        c_bi=lower * c,
        c_bit=plant.value("viscous_friction"),
        k_pi=float(top["pipe_stiffness_nm_rad"]) if pipe > 0 else 3 * k,
        k_co=lower * k,
        k_bi=lower * k,
        R=1.0,
        mu_a=a_a,
        mu_0=a_0,
        xi=plant.value("stribeck_rate"),
        Dw=1e-3 * max(1.0, plant.operating_point.get("mean_bit_speed_rad_s", 1.0)),
    )


def env_keywords(plant: CalibratedPlant, plant_dt_s: float = PLANT_DT_S) -> dict[str, Any]:
    """Keywords of ``gym.make("DrillString-v0", **keywords)`` for a twin of the rig.

    * ``parameters``: :func:`drill_string_parameters`.
    * ``wob_n``: the window's mean WOB (1 N without WOB, the friction then being in N m).
    * ``reference_speed_rad_s``: the window's mean top-drive speed.
    * torque limits: ``[0, 3 T_a]`` with ``T_a`` the static torque at that WOB;
      ``residual_scale_nm``: ``0.5 T_a``.
    * ``noise_std_rad_s``: the measured bit speed's noise (the log's high-frequency part),
      floored at 0.1 % of the reference speed.
    * ``randomize``: False (the calibrated plant, not the paper's ranges).

    ``ValueError`` if a stiff map does not fit the env's ``plant_dt_s`` (the highest mode of the
    map must stay below ``1 / plant_dt_s``).
    """
    params = drill_string_parameters(plant)
    op = plant.operating_point
    wob = float(op.get("mean_wob_n", 1.0)) if plant.uses_wob else 1.0
    t_a = params.static_torque_nm(wob)
    highest = math.sqrt(2 * 3 * plant.value("stiffness") / (MAP_INERTIA_FRACTION * params.J_bi))
    if highest * plant_dt_s > 2.0:
        raise ValueError(
            f"the calibrated plant's 4-DOF map has a mode at {highest:.4g} rad/s, too fast for "
            f"the env's plant step {plant_dt_s} s (allowed below {2.0 / plant_dt_s:g} rad/s)"
        )
    reference = float(op.get("mean_top_speed_rad_s", 1.0))
    noise = max(float(op.get("bit_speed_noise_rad_s", 0.0)), 1e-3 * abs(reference))
    return {
        "parameters": params,
        "randomize": False,
        "wob_n": wob,
        "reference_speed_rad_s": reference,
        "min_torque_nm": 0.0,
        "max_torque_nm": 3.0 * t_a,
        "residual_scale_nm": 0.5 * t_a,
        "noise_std_rad_s": noise,
    }
