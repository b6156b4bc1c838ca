"""The controller hook of the environment: what a base controller provides, how a compiled
one runs inside the plant loop, and the registry of controllers by name.

Any object with ``reset()`` and ``torque(measurement, reference_speed_rad_s, dt_s)`` can be a
base controller; the env then calls it from Python at every plant step (the slow path). A
controller that also has ``compiled_law(model, torque_limits)`` runs inside the compiled plant
loop instead, state and all, at full speed; if its ``compiled_law`` also takes a ``channel``
keyword, the env passes its :class:`drill_env.sensors.MeasurementChannel` there (what is
measured, how often, how noisy: what an observer inside the law is designed for; see
:func:`compile_law`). Its law is a numba ``cfunc`` with the signature
:data:`LAW_SIGNATURE`::

    torque_nm = law(params*, state*, measurement*, reference_rad_s, dt_s)

reading its parameter vector and the measurement vector (``drill_env.layout.M_*``: the
measured state), updating its own state vector in place, and returning the top-drive torque in
N m. The kernel calls it through its address, so the core runs controllers it does not know:
the controllers live in the packages that define them and are found by name through the
registry below (the built-in ones of :mod:`baselines` through the
``drill_string_gym.controllers`` entry point group).
"""

from __future__ import annotations

import ctypes
import functools
import inspect
from collections.abc import Callable
from importlib import metadata
from typing import Any, Final, NamedTuple, Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt
from llvmlite import ir
from numba import cfunc, types
from numba.extending import intrinsic

from drill_env._cache import announce_compilation
from drill_env.layout import (
    M_STATE,
    M_TELEMETRY_AGE,
    M_TELEMETRY_BIT_SPEED,
    MEASUREMENT_NAMES,
    N_MEASUREMENT,
    N_STATE,
)
from drill_env.limits import TorqueLimits
from drill_env.parameters import DrillStringParameters
from drill_env.sensors import MeasurementChannel
from drill_env.validation import shown

__all__ = [
    "ENTRY_POINT_GROUP",
    "LAW_SIGNATURE",
    "CompiledController",
    "CompiledLaw",
    "Controller",
    "Measurement",
    "MissingSignalError",
    "LazyLaw",
    "call_law",
    "compile_law",
    "compiled_law_function",
    "controller_names",
    "make_controller",
    "register_controller",
    "resolve_controller",
]


class MissingSignalError(LookupError):
    """A controller read a signal by name that the env's measurement channel does not provide."""


_PROVIDERS: Final = {
    **{name: "observation='state'" for name in MEASUREMENT_NAMES[M_STATE : M_STATE + N_STATE]},
    MEASUREMENT_NAMES[M_TELEMETRY_BIT_SPEED]: "telemetry_period_s=<period in s>",
    MEASUREMENT_NAMES[M_TELEMETRY_AGE]: "telemetry_period_s=<period in s>",
}
"""The env keyword that makes each optional signal available (the surface signals always
are)."""


class Measurement(np.ndarray):
    """The measurement a Python controller receives at every plant step: the float64 vector
    of ``N_MEASUREMENT`` entries (``drill_env.layout.M_*``; index access works as on any
    array) whose entries are also attributes, named by ``drill_env.layout.MEASUREMENT_NAMES``:

    * ``top_drive_speed_rad_s``, ``top_drive_pipe_twist_rad``, ``pipe_speed_rad_s``,
      ``pipe_collar_twist_rad``, ``collar_speed_rad_s``, ``collar_bit_twist_rad``,
      ``bit_speed_rad_s``: the measured 4-DOF state x1..x7 (speeds rad/s with the speed
      noise, twists rad); only with ``observation="state"`` (the default of
      ``DrillString-v0``, not of ``DrillStringField-v0``);
    * ``surface_top_drive_speed_rad_s`` (rad/s) and ``surface_torque_nm`` (N m): the surface
      signals, sampled every ``sensor_period_s`` and held; always;
    * ``telemetry_bit_speed_rad_s`` (rad/s) and ``telemetry_age_s`` (s): the last bit speed
      received by telemetry and its age; only with a ``telemetry_period_s``, NaN until the
      first value arrives;
    * ``applied_torque_nm``: the torque the drive applied over the last step, N m; always.

    Reading by name a signal the env does not provide raises :class:`MissingSignalError`
    naming the signal and the env keyword that provides it (by index it reads NaN).
    """

    _missing: frozenset[str]

    def __new__(
        cls, values: npt.ArrayLike, missing: frozenset[str] | set[str] = frozenset()
    ) -> Measurement:
        array = np.asarray(values, dtype=np.float64)
        if array.shape != (N_MEASUREMENT,):
            raise ValueError(f"a measurement has shape ({N_MEASUREMENT},), got {array.shape}")
        unknown = sorted(set(missing) - set(MEASUREMENT_NAMES))
        if unknown:
            raise ValueError(
                f"missing = {unknown} is not valid: allowed {', '.join(MEASUREMENT_NAMES)}"
            )
        obj = array.view(cls)
        obj._missing = frozenset(missing)
        return obj

    def __array_finalize__(self, obj: Any) -> None:
        self._missing = getattr(obj, "_missing", frozenset())

    @staticmethod
    def missing_signals(channel: MeasurementChannel) -> frozenset[str]:
        """The signals ``channel`` does not provide (their entries read NaN)."""
        missing = set()
        if channel.observation != "state":
            missing |= set(MEASUREMENT_NAMES[M_STATE : M_STATE + N_STATE])
        if channel.telemetry_period_s is None:
            missing |= {MEASUREMENT_NAMES[M_TELEMETRY_BIT_SPEED]}
            missing |= {MEASUREMENT_NAMES[M_TELEMETRY_AGE]}
        return frozenset(missing)

    def signal(self, name: str) -> float:
        """The entry ``name`` of ``MEASUREMENT_NAMES`` (also readable as an attribute).

        Raises:
            MissingSignalError: the env does not provide it.
            KeyError: an unknown name.
        """
        if name not in MEASUREMENT_NAMES:
            raise KeyError(
                f"{shown(name)} is not a signal of the measurement: allowed "
                f"{', '.join(MEASUREMENT_NAMES)}"
            )
        if name in self._missing:
            if name in _PROVIDERS:
                raise MissingSignalError(
                    f"measurement.{name} is not provided by this env's measurement channel: "
                    f"make the env with {_PROVIDERS[name]} to measure it"
                )
            raise MissingSignalError(
                f"measurement.{name} is not available here: this measurement was rebuilt from "
                "an observation that does not carry it (run the controller as the env's "
                "base_controller to receive every signal)"
            )
        return float(self[MEASUREMENT_NAMES.index(name)])

    def __getattr__(self, name: str) -> float:
        if name in MEASUREMENT_NAMES:
            return self.signal(name)
        raise AttributeError(
            f"Measurement has no attribute {shown(name)}; its signals are {', '.join(MEASUREMENT_NAMES)}"
        )


_DOUBLE_P = types.CPointer(types.float64)
LAW_SIGNATURE: Final = types.float64(_DOUBLE_P, _DOUBLE_P, _DOUBLE_P, types.float64, types.float64)
"""``float64(float64* params, float64* state, float64* measurement, float64 reference_rad_s,
float64 dt_s)``: the signature of every compiled law (a numba ``cfunc``)."""

_CTYPES_ARGS: Final = (
    ctypes.POINTER(ctypes.c_double),
    ctypes.POINTER(ctypes.c_double),
    ctypes.POINTER(ctypes.c_double),
    ctypes.c_double,
    ctypes.c_double,
)


class LazyLaw:
    """A compiled law (a numba ``cfunc`` of :data:`LAW_SIGNATURE`, cached on disk) that is
    compiled, or loaded from numba's cache, at its first use instead of at import: a package of
    many controllers then compiles only the laws that run. Every attribute of the ``cfunc``
    (``address``, ``ctypes``, ...) is read through to it; made by
    :func:`compiled_law_function`."""

    def __init__(self, py_func: Callable[..., float]) -> None:
        functools.update_wrapper(self, py_func)
        self.py_func = py_func
        self._compiled: Any = None

    @property
    def compiled(self) -> Any:
        """The ``cfunc`` (compiled now if it is not yet)."""
        if self._compiled is None:
            name = getattr(self.py_func, "__name__", "law")
            with announce_compilation(f"the controller law {name}", 3):
                self._compiled = cfunc(LAW_SIGNATURE, cache=True)(self.py_func)
        return self._compiled

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name in ("py_func", "_compiled"):
            raise AttributeError(name)
        return getattr(self.compiled, name)

    def __call__(self, *args: Any) -> float:
        return float(self.compiled(*args))

    def __repr__(self) -> str:
        return f"<compiled law {getattr(self.py_func, '__qualname__', self.py_func)!r}>"


def compiled_law_function(py_func: Callable[..., float]) -> LazyLaw:
    """Decorator: ``py_func`` (``torque = law(params*, state*, measurement*, reference_rad_s,
    dt_s)``) as a law compiled at its first use (:class:`LazyLaw`), the lazy form of
    ``@numba.cfunc(LAW_SIGNATURE, cache=True)``."""
    return LazyLaw(py_func)


class CompiledLaw(NamedTuple):
    """A controller's law as the compiled loop runs it.

    Attributes:
        function: The law, a numba ``cfunc`` compiled with :data:`LAW_SIGNATURE`.
        params: Its parameter vector (gains and the controller's model of the string).
        initial_state: Its state vector at the start of an episode (integrals, adaptive gains,
            filters); the kernel updates a copy in place.
        error_slot: Index in the state of the law's error signal (rad/s) that the env reports
            (``sliding_variable_rad_s``) and shows in the residual observation; -1 for none.
        gain_slot: Index in the state of its adaptive gain (``adaptive_gain``); -1 for none.
        info_slots: ``(info key, state index)`` pairs: state entries the env reports in
            ``info`` under these keys (their value after the last plant step of a decision).
        estimate_slots: ``(X_* index, state index)`` pairs: state entries that hold the law's
            estimate of an entry of the 4-DOF state (``drill_env.layout.STATE_NAMES``) at the
            plant step of its last call; the env reports each as ``estimated_<name>`` and its
            error, the estimate minus the true value at that step, as
            ``estimate_error_<name>``.
    """

    function: Any
    params: npt.NDArray[np.float64]
    initial_state: npt.NDArray[np.float64]
    error_slot: int = -1
    gain_slot: int = -1
    info_slots: tuple[tuple[str, int], ...] = ()
    estimate_slots: tuple[tuple[int, int], ...] = ()

    @property
    def address(self) -> int:
        """Address of the compiled law, for the kernel."""
        return int(self.function.address)

    def torque(
        self,
        state: npt.NDArray[np.float64],
        measurement: npt.NDArray[np.float64],
        reference_rad_s: float,
        dt_s: float,
    ) -> float:
        """Call the compiled law once from Python through its address, as the kernel does
        (for tests and debugging): ``state`` (a float64 copy of ``initial_state``) is updated in
        place; ``measurement`` is the law's measurement vector (``drill_env.layout.M_*``)."""
        arrays = (self.params, state, measurement)
        for name, array in zip(("params", "state", "measurement"), arrays, strict=True):
            if (
                not isinstance(array, np.ndarray)
                or array.dtype != np.float64
                or not array.flags.c_contiguous
            ):
                raise TypeError(f"{name} must be a C-contiguous float64 array")
        if state.shape != self.initial_state.shape or measurement.shape != (N_MEASUREMENT,):
            raise ValueError(
                f"state must have shape {self.initial_state.shape} and measurement "
                f"({N_MEASUREMENT},), got {state.shape} and {measurement.shape}"
            )
        pointer = ctypes.POINTER(ctypes.c_double)
        return float(
            self.function.ctypes(
                *(a.ctypes.data_as(pointer) for a in arrays), float(reference_rad_s), float(dt_s)
            )
        )

    def validated(self) -> CompiledLaw:
        """This law with float64 vectors, checked against :data:`LAW_SIGNATURE`.

        Raises:
            TypeError: when ``function`` is not a cfunc of the law signature.
            ValueError: when a vector is empty or not 1-D, or a slot is out of the state.
        """
        fn = getattr(self.function, "ctypes", None)
        if fn is None or tuple(fn.argtypes) != _CTYPES_ARGS or fn.restype is not ctypes.c_double:
            raise TypeError(
                "CompiledLaw.function must be a numba cfunc with signature "
                f"{LAW_SIGNATURE}, got {shown(self.function)}"
            )
        params = np.ascontiguousarray(self.params, dtype=np.float64)
        state = np.ascontiguousarray(self.initial_state, dtype=np.float64)
        for name, vector in (("params", params), ("initial_state", state)):
            if vector.ndim != 1 or vector.size == 0:
                raise ValueError(f"CompiledLaw.{name} must be a non-empty 1-D vector")
        for name, slot in (("error_slot", self.error_slot), ("gain_slot", self.gain_slot)):
            if not -1 <= slot < state.size:
                raise ValueError(
                    f"CompiledLaw.{name} = {shown(slot)} is out of range: allowed -1 (none) to "
                    f"{state.size - 1}"
                )
        info = tuple((str(key), int(slot)) for key, slot in self.info_slots)
        estimates = tuple((int(index), int(slot)) for index, slot in self.estimate_slots)
        for key, _ in info:
            if not key:
                raise ValueError("CompiledLaw.info_slots: an info key must be a non-empty string")
        for index, _ in estimates:
            if not 0 <= index < N_STATE:
                raise ValueError(
                    f"CompiledLaw.estimate_slots: state index {shown(index)} is out of range: "
                    f"allowed 0 to {N_STATE - 1}"
                )
        for name, pairs in (("info_slots", info), ("estimate_slots", estimates)):
            for _, slot in pairs:
                if not 0 <= slot < state.size:
                    raise ValueError(
                        f"CompiledLaw.{name}: slot {shown(slot)} is out of range: allowed 0 to "
                        f"{state.size - 1}"
                    )
        return self._replace(
            params=params, initial_state=state, info_slots=info, estimate_slots=estimates
        )


@intrinsic
def call_law(typingctx, address, params, state, measurement, reference, dt):
    """Call the compiled law at ``address`` (an int) on the data pointers of three float64
    arrays; compiled code only. An indirect call: a few nanoseconds."""
    sig = types.float64(types.intp, params, state, measurement, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        fn_address, lp, ls, m, ref, step = args
        double = ir.DoubleType()
        fnty = ir.FunctionType(double, [double.as_pointer()] * 3 + [double, double])
        fn = builder.inttoptr(fn_address, fnty.as_pointer())
        pointers = []
        for array_type, value in zip(signature.args[1:4], (lp, ls, m), strict=True):
            array = context.make_array(array_type)(context, builder, value)
            pointers.append(array.data)
        return builder.call(fn, [*pointers, ref, step])

    return sig, codegen


@runtime_checkable
class Controller(Protocol):
    """A top-drive torque controller driven at every plant step."""

    def reset(self) -> None:
        """Forget the state of the last episode (integrals, adaptive gains)."""

    def torque(self, measurement: Measurement, reference_speed_rad_s: float, dt_s: float) -> float:
        """Top-drive torque (N m) from the measurement (:class:`Measurement`: its signals by
        name, ``measurement.surface_top_drive_speed_rad_s``, or by index), the reference
        (rad/s) and the time until the next call (s)."""
        ...


@runtime_checkable
class CompiledController(Controller, Protocol):
    """A controller that can run inside the compiled plant loop."""

    def compiled_law(
        self,
        model: DrillStringParameters | None = None,
        torque_limits: TorqueLimits | None = None,
    ) -> CompiledLaw:
        """The law, using ``model`` as the controller's model of the string when given (the
        ``controller`` uncertainty reading) and its own otherwise, and the env's top-drive
        ``torque_limits`` (N m) when given."""
        ...


def compile_law(
    controller: CompiledController,
    model: Any = None,
    torque_limits: TorqueLimits | None = None,
    channel: MeasurementChannel | None = None,
) -> CompiledLaw:
    """``controller.compiled_law(model, torque_limits, channel=channel)`` when its
    ``compiled_law`` takes a ``channel`` keyword, else ``compiled_law(model, torque_limits)``
    (the measurement channel is news only to a law that designs something for it)."""
    law = controller.compiled_law
    try:
        parameters = inspect.signature(law).parameters
    except (TypeError, ValueError):  # a callable without an introspectable signature
        parameters = {}  # type: ignore[assignment]
    takes_channel = "channel" in parameters or any(
        p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()
    )
    if takes_channel and channel is not None:
        return law(model, torque_limits, channel=channel)  # type: ignore[call-arg]
    return law(model, torque_limits)


# ----------------------------------------------------------------------------- registry
ENTRY_POINT_GROUP: Final = "drill_string_gym.controllers"
"""Entry point group through which installed packages offer controllers by name: each entry
``name = "package.module:Factory"``, the factory taking gain keywords."""

_FACTORIES: dict[str, Callable[..., Controller]] = {}
_ENTRY_POINTS: dict[str, metadata.EntryPoint] = {}
_discovered = False


def _discover() -> None:
    """Read the entry points once (they are loaded only when their name is used)."""
    global _discovered
    if _discovered:
        return
    _discovered = True
    for entry in metadata.entry_points(group=ENTRY_POINT_GROUP):
        _ENTRY_POINTS.setdefault(entry.name, entry)


def register_controller(name: str, factory: Callable[..., Controller]) -> None:
    """Offer ``factory`` under ``name``: ``make_controller(name, **gains)`` then calls it.

    Registering the same factory twice is harmless; another factory under a taken name is an
    error.
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"controller name must be a non-empty string, got {shown(name)}")
    if not callable(factory):
        raise TypeError(
            f"controller factory for {shown(name)} must be callable, got {shown(factory)}"
        )
    known = _FACTORIES.get(name)
    if known is not None and known is not factory:
        raise ValueError(f"controller name {shown(name)} is already registered")
    _FACTORIES[name] = factory


def controller_names() -> list[str]:
    """The registered controller names: those registered in this process, then those offered
    by installed packages' entry points, in order."""
    _discover()
    return list(dict.fromkeys([*_FACTORIES, *_ENTRY_POINTS]))


def make_controller(name: str, **gains: Any) -> Controller:
    """A new controller ``name`` with default gains, overridden by ``gains``.

    Raises:
        ValueError: for an unknown name, listing the valid ones.
    """
    _discover()
    factory = _FACTORIES.get(name) if isinstance(name, str) else None
    if factory is None and isinstance(name, str) and name in _ENTRY_POINTS:
        factory = _ENTRY_POINTS[name].load()
        register_controller(name, factory)
    if factory is None:
        raise ValueError(
            f"unknown controller {shown(name)}: valid names are {', '.join(controller_names())}"
        )
    return factory(**gains)


def resolve_controller(value: str | Controller | None) -> Controller | None:
    """A controller object from a registered name, or ``value`` itself."""
    if value is None or not isinstance(value, str):
        return value
    return make_controller(value)
