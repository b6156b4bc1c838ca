"""Controllers named on the command line: a registered name, or a user's own class.

``compare``, ``map``, ``evaluate`` and ``benchmark`` take ``--controllers`` as registered names
(:func:`drill_env.control.controller_names`) or as a user's class, written

* ``MODULE:CLASS``: an importable module (``my_package.loops:SpeedPI``; the current folder is
  searched after the installed packages), or
* ``PATH.py:CLASS``: a Python file (``examples/custom_controller.py:SpeedPI``).

:func:`load_controller` imports it, checks that the class makes a controller with ``reset()``
and ``torque(measurement, reference_speed_rad_s, dt_s)`` (made once with no arguments), and
registers it in this process under a short name (``custom_controller.SpeedPI``: the file or
module's last part and the class), by which the studies then run it like any built-in one.
Importing runs the module's code: naming it is the user's consent to run that code, and
nothing but the command line names one (a model file's ``base_controller`` never does).

A class with only ``torque`` is called from Python at every 1 ms plant step, 20-40 times
slower than a compiled law (``examples/compiled_controller.py`` times both); give it ``compiled_law(model=None, torque_limits=None)`` returning
a :class:`drill_env.control.CompiledLaw` (``examples/compiled_controller.py``) and it runs
inside the compiled plant loop at the built-in controllers' speed.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import importlib
import importlib.util
import inspect
import os
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, Final

from drill_env.control import controller_names, register_controller
from drill_env.validation import printable, shown

__all__ = [
    "CONTROLLERS_OPTION_HELP",
    "ControllerError",
    "controller_type",
    "is_user_controller",
    "load_controller",
    "refuse_on_ray",
    "resolve_controller_name",
    "user_code_fingerprints",
    "user_controller_errors",
    "user_controllers",
]

CONTROLLERS_OPTION_HELP: Final = (
    "registered names, or your class as MODULE:CLASS or PATH.py:CLASS (naming it runs its "
    "code: name only code you trust)"
)
"""The help of the ``--controllers`` options (and of benchmark's POLICY) on user classes;
how to compile one is in docs/controllers.md."""

_LOADED: dict[str, str] = {}
"""Spec as typed -> the name it was registered under (a spec is loaded once per process)."""
_CODE: dict[str, str] = {}
"""Registered name -> SHA-256 of the file that defined the class when it was loaded."""
_NAME: Final = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*")


def is_user_controller(name: str) -> bool:
    """Whether ``name`` was registered by :func:`load_controller` in this process."""
    return name in _LOADED.values()


def user_controllers(names: Sequence[str]) -> list[str]:
    """Those of ``names`` that are users' classes loaded by :func:`load_controller`."""
    return [n for n in names if is_user_controller(n)]


class ControllerError(ValueError):
    """A user's controller (:func:`load_controller`) failed while it ran: its ``torque()``
    returned something that is not a real number (a string, an array of several values) or it
    raised. A user error, reported on one line naming the controller."""


@contextlib.contextmanager
def user_controller_errors(name: str, where: str = "") -> Iterator[None]:
    """Run the block; when ``name`` is a user's controller (:func:`is_user_controller`), an
    exception raised in the block becomes a :class:`ControllerError` naming the controller
    (and ``where``, the run: `` on nominal``), the exception's type and its message on one
    line. A built-in controller's exceptions pass unchanged, with their traceback."""
    try:
        yield
    except ControllerError:
        raise
    except Exception as err:
        if not is_user_controller(name):
            raise
        message = " ".join(str(err).split())
        raise ControllerError(
            f"controller {printable(name)} failed{where}: {type(err).__name__}: "
            f"{printable(message, 400)}"
        ) from err


def _identifier(text: str) -> str:
    return re.sub(r"\W", "_", text)


def _split(spec: str) -> tuple[str, str]:
    where, sep, attribute = spec.rpartition(":")
    if not sep or not where or not attribute:
        raise ValueError(
            f"controller {shown(spec)} is not a registered name nor MODULE:CLASS or PATH.py:CLASS"
        )
    if not _NAME.fullmatch(attribute):
        raise ValueError(f"controller {shown(spec)}: {shown(attribute)} is not a Python class name")
    return where, attribute


def _is_file(where: str) -> bool:
    return where.endswith(".py") or "/" in where or os.sep in where


def _search_path() -> list[Path]:
    _current_folder_on_path()
    cwd = os.getcwd()
    return [Path(p or cwd).resolve() for p in sys.path]


def _current_folder_on_path() -> None:
    """Put the current folder on the import path, after the installed packages (which it then
    never shadows), as ``python -m`` does (the ``drill-gym`` script does not)."""
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.append(cwd)


def _module_name_of(file: Path) -> str | None:
    """The dotted name under which ``file`` is importable from the current folder or the
    import path (``examples.compiled_controller``), or ``None``. A file imported by its
    module name and by its path is then one module (numba's on-disk cache of a compiled law
    knows its module by name, and would not find a second one)."""
    for root in _search_path():
        try:
            parts = file.with_suffix("").relative_to(root).parts
        except ValueError:
            continue
        if parts and all(p.isidentifier() for p in parts):
            return ".".join(parts)
    return None


def _import_file(path_text: str, spec: str) -> Any:
    path = Path(path_text).expanduser()
    if not path.is_file():
        raise ValueError(f"controller {shown(spec)}: no Python file {shown(path_text)}")
    resolved = path.resolve()
    dotted = _module_name_of(resolved)
    if dotted is not None:  # importable: one module, whether named by path or by module
        try:
            module = importlib.import_module(dotted)
        except ModuleNotFoundError:
            module = None  # another package of that name is in the way: load the file
        if module is not None and Path(str(getattr(module, "__file__", ""))).resolve() == resolved:
            return module
    digest = hashlib.sha256(str(resolved).encode()).hexdigest()[:12]
    module_name = f"drill_gym_user_{_identifier(path.stem)}_{digest}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    loader_spec = importlib.util.spec_from_file_location(module_name, resolved)
    if loader_spec is None or loader_spec.loader is None:
        raise ValueError(
            f"controller {shown(spec)}: {shown(path_text)} cannot be imported as Python"
        )
    module = importlib.util.module_from_spec(loader_spec)
    sys.modules[module_name] = module  # so that dataclasses and pickling find it
    try:
        loader_spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[module_name]
        raise
    return module


def _import_module(name: str, spec: str) -> Any:
    if not _NAME.fullmatch(name):
        raise ValueError(
            f"controller {shown(spec)}: {shown(name)} is not a module name (or a PATH.py)"
        )
    _current_folder_on_path()
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as err:
        if err.name is not None and name.startswith(err.name):
            raise ValueError(
                f"controller {shown(spec)}: no module named {shown(err.name)}"
            ) from None
        raise


def _check_controller(obj: Any, spec: str, *, made: bool = True) -> None:
    """``obj`` has ``reset()`` and ``torque()``; when ``made`` (an instance, not the class),
    ``torque`` takes the three arguments the env passes."""
    missing = [m for m in ("reset", "torque") if not callable(getattr(obj, m, None))]
    if missing:
        raise ValueError(
            f"controller {shown(spec)} has no {' and no '.join(f'{m}()' for m in missing)}: a "
            "controller needs reset() and torque(measurement, reference_speed_rad_s, dt_s)"
        )
    if not made:
        return
    try:
        inspect.signature(obj.torque).bind(None, 0.0, 0.0)
    except TypeError:
        raise ValueError(
            f"controller {shown(spec)}: torque{inspect.signature(obj.torque)} does not take "
            "(measurement, reference_speed_rad_s, dt_s)"
        ) from None
    except ValueError:  # no introspectable signature (a builtin): let the env call it
        pass


def load_controller(spec: str) -> str:
    """Import the user's controller class ``spec`` and register it; return its name.

    Args:
        spec: ``MODULE:CLASS`` or ``PATH.py:CLASS`` (``CLASS`` may be dotted:
            ``Outer.Inner``).

    Returns:
        The name it is registered under: the module's last part (or the file's stem) and the
        class, ``custom_controller.SpeedPI``; the same spec again returns the same name.

    Raises:
        ValueError: one line, for a malformed spec, a missing file, module or class, a module
            that fails to import, a class that cannot be made without arguments or lacks
            ``reset()``/``torque(measurement, reference_speed_rad_s, dt_s)``, or a name taken
            by another controller.
    """
    if spec in _LOADED:
        return _LOADED[spec]
    where, attribute = _split(spec)
    try:
        if _is_file(where):
            module = _import_file(where, spec)
            stem = Path(where).stem
        else:
            module = _import_module(where, spec)
            stem = where.rpartition(".")[2]
    except ValueError:
        raise
    except Exception as err:
        raise ValueError(
            f"controller {shown(spec)}: importing {where!r} failed: {type(err).__name__}: {err}"
        ) from None
    target: Any = module
    for part in attribute.split("."):
        if not hasattr(target, part):
            raise ValueError(f"controller {shown(spec)}: {where!r} has no {shown(attribute)}")
        target = getattr(target, part)
    if not callable(target):
        raise ValueError(f"controller {shown(spec)}: {shown(attribute)} is not a class")
    if inspect.isclass(target):  # before it is made
        _check_controller(target, spec, made=False)
    try:
        controller = target()
    except Exception as err:
        raise ValueError(
            f"controller {shown(spec)}: {attribute}() failed: {type(err).__name__}: {err} (the "
            "command line makes it with no arguments: give every parameter a default)"
        ) from None
    _check_controller(controller, spec)
    name = f"{_identifier(stem)}.{attribute}"
    if name in controller_names():
        raise ValueError(
            f"controller {shown(spec)}: its name {shown(name)} is already taken by another controller"
        )
    register_controller(name, target)
    _LOADED[spec] = name
    _CODE[name] = _source_sha256(module)
    return name


def _source_sha256(module: Any) -> str:
    """SHA-256 of ``module``'s source file as it was imported (empty: it has none)."""
    try:
        source = inspect.getsourcefile(module)
    except TypeError:  # a built-in or namespace module
        return ""
    if source is None:
        return ""
    try:
        return hashlib.sha256(Path(source).read_bytes()).hexdigest()
    except OSError:
        return ""


def user_code_fingerprints(settings: Any) -> dict[str, str]:
    """The SHA-256 of the file that defines each user class named in ``settings``.

    A study's settings name controllers by their registered names (a field run's label adds
    `` (observation)``); a user's class is identified by its name and by its code, so that a
    results database never gives the rows of an edited class to the new one.

    Args:
        settings: A study's settings, any nesting of mappings, lists and scalars.

    Returns:
        Registered name -> SHA-256 (hex) of its file when loaded, for the user classes named in
        ``settings`` (empty when there are none).
    """
    found: dict[str, str] = {}
    stack = [settings]
    while stack:
        value = stack.pop()
        if isinstance(value, dict):
            stack.extend(value.values())
        elif isinstance(value, list | tuple):
            stack.extend(value)
        elif isinstance(value, str):
            name = value.split(" (")[0]
            if name in _CODE:
                found[name] = _CODE[name]
    return dict(sorted(found.items()))


def resolve_controller_name(text: str) -> str:
    """A registered controller name from ``text``: a registered name as it is, a user's class
    (``MODULE:CLASS``, ``PATH.py:CLASS``) loaded by :func:`load_controller`.

    Raises:
        ValueError: for an unknown name (listing the registered ones) or a bad user class.
    """
    names = controller_names()
    if text in names:
        return text
    if ":" in text:
        return load_controller(text)
    raise ValueError(
        f"unknown controller {shown(text)}: allowed {', '.join(names)}, or MODULE:CLASS or "
        "PATH.py:CLASS for your own class"
    )


def controller_type(text: str) -> str:
    """The argparse ``type`` of a ``--controllers`` entry: :func:`resolve_controller_name`."""
    try:
        return resolve_controller_name(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


controller_type.__name__ = "controller"


def refuse_on_ray(fail: Callable[[str, str], Any], distributed: bool, names: Sequence[str]) -> None:
    """``fail("--controllers", message)`` when a user's class is to run on Ray
    (``distributed``): it is registered in this process only, and Ray's workers are other
    processes."""

    mine = user_controllers(names)
    if mine and distributed:
        fail(
            "--controllers",
            f"{', '.join(mine)} is your own class, registered in this process only: run it "
            "without --workers, --ray and --address",
        )
