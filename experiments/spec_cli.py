"""Command lines generated from a study's frozen ``Spec`` dataclass.

Each study states its settings once, as the fields of a frozen dataclass with a default and a
docstring (units included); :func:`spec_parser` turns them into the subcommand's options and
:func:`spec_from_args` turns the parsed options back into the Spec. A field's option is its
name with dashes (``duration_s`` -> ``--duration-s``); its help is the field's docstring and its
default. :func:`option` adds what a type hint cannot say: a numeric range and unit, choices, a
custom parser, old names still accepted.

Types: ``bool`` is a switch (``--no-plots``; a field whose default is true gets ``--no-NAME``),
``int``/``float`` a number checked by :func:`experiments.arguments.number_type`, ``str`` and
``Path`` a value, ``tuple[X, ...]`` one or more values, ``X | None`` a value whose default is
none. The shared options of the sweep runner are the fields of
:class:`experiments.sweep.RunnerSpec`, given to :func:`spec_parser` after the study's Spec.

The project keeps this small generator instead of a library such as tyro so that every usage
error stays one line on standard error with exit code 2 (:mod:`experiments.arguments`), the
numeric checks keep the core's messages, and the core install needs no other package.
"""

from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, TypeVar

from agents.config import field_docs, plain_text
from drill_env.validation import shown
from experiments.arguments import ArgumentParser, number_type

__all__ = ["Option", "option", "option_name", "spec_from_args", "spec_options", "spec_parser"]

SpecT = TypeVar("SpecT")

OPTION_KEY: Final = "drill_gym_option"
"""Key of a field's :class:`Option` in ``dataclasses.field(metadata=...)``."""


@dataclass(frozen=True)
class Option:
    """What a Spec field's command-line option needs beyond its type and default.

    Attributes:
        low, high: Range of a number (``None``: unbounded); ``open_low`` excludes ``low``.
        unit: Unit of a number, shown in its messages (``"s"``, ``"rad/s"``).
        choices: The allowed values, or a function returning them (read when parsing, so
            plugins registered at import time count).
        parse: The argparse ``type`` of a value (overrides the number check and choices).
        metavar: Name of the value in the help (default from the type: ``N``, ``X``, ``TEXT``).
        aliases: Older names of the option, still accepted, not shown in the help.
        flag: The option's name when it is not the field's (``--env`` for ``env_id``).
        default_text: The default as the help shows it (default: the field's default).
        group: Title of the help section the option is listed under (default: the options).
        positional: A positional argument instead of an option (a tuple field takes any
            number of values, others one or none).
        repeat: An option given once per value (``--grid a=1,2 --grid b=3``) instead of one
            option with several values (tuple fields).
        help: The help of an option whose text has its home elsewhere (default: the field's
            docstring).
    """

    low: float | None = None
    high: float | None = None
    open_low: bool = False
    unit: str = ""
    choices: Sequence[str] | Callable[[], Sequence[str]] | None = None
    parse: Callable[[str], Any] | None = None
    metavar: str | None = None
    aliases: tuple[str, ...] = ()
    flag: str | None = None
    default_text: str | None = None
    group: str | None = None
    positional: bool = False
    repeat: bool = False
    help: str | None = None


def option(**kwargs: Any) -> dict[str, Option]:
    """The ``metadata`` of a Spec field: ``field(default=..., metadata=option(low=0.0))``."""
    return {OPTION_KEY: Option(**kwargs)}


def option_name(field_name: str) -> str:
    """A field's option as the command line spells it: ``duration_s`` -> ``--duration-s``."""
    return "--" + field_name.replace("_", "-")


def _unwrap_optional(hint: Any) -> tuple[Any, bool]:
    """``(X, True)`` for ``X | None``, else ``(hint, False)``."""
    origin = typing.get_origin(hint)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) == 1 and len(typing.get_args(hint)) == 2:
            return args[0], True
    return hint, False


def _element(hint: Any) -> tuple[Any, bool]:
    """``(X, True)`` for ``tuple[X, ...]`` or ``list[X]``, else ``(hint, False)``."""
    if typing.get_origin(hint) in (tuple, list):
        args = [a for a in typing.get_args(hint) if a is not Ellipsis]
        return (args[0] if args else str), True
    return hint, False


def _default_text(value: Any) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, (tuple, list)):
        return " ".join(_default_text(v) for v in value) if value else "none"
    if isinstance(value, float):
        return f"{value:g}"
    if value == "":
        return "empty"
    return str(value)


def _value_type(name: str, hint: Any, spec: Option) -> tuple[Callable[[str], Any] | None, str]:
    """The argparse ``type`` and metavar of one value of the field ``name``."""
    if spec.parse is not None:
        return spec.parse, spec.metavar or "TEXT"
    if hint is int or hint is float:
        integer = hint is int
        check = number_type(
            spec.low, spec.high, open_low=spec.open_low, integer=integer, unit=spec.unit
        )
        return check, spec.metavar or ("N" if integer else "X")
    if hint is Path:
        return Path, spec.metavar or "PATH"
    if hint is str:
        return None, spec.metavar or "TEXT"
    raise TypeError(f"field {name}: no command-line form for the type {shown(hint)}")


def spec_options(
    parser: argparse.ArgumentParser,
    spec_class: type,
    *,
    overrides: Mapping[str, Any] | None = None,
) -> None:
    """Add one option per field of the dataclass ``spec_class`` to ``parser``.

    Args:
        parser: The parser to add to (its argument groups are created as needed).
        spec_class: A dataclass whose fields all have defaults.
        overrides: Defaults to use instead of the fields' own (the shown default too).
    """
    docs = field_docs(spec_class)
    hints = typing.get_type_hints(spec_class)
    names = [f.name for f in dataclasses.fields(spec_class)]
    groups: dict[str | None, Any] = {None: parser}
    for f in dataclasses.fields(spec_class):
        if not f.init:
            continue
        spec: Option = f.metadata.get(OPTION_KEY, Option())
        if overrides and f.name in overrides:
            default = overrides[f.name]
        elif f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            raise TypeError(f"field {f.name} of {spec_class.__name__} has no default")
        if spec.group not in groups:
            groups[spec.group] = parser.add_argument_group(spec.group)
        target = groups[spec.group]
        flag = spec.flag or option_name(f.name)
        doc = plain_text(spec.help or docs.get(f.name, ""), names)
        hint, optional = _unwrap_optional(hints[f.name])
        if hint is bool:
            switch = {
                "dest": f.name,
                "action": "store_false" if default else "store_true",
                "help": doc.replace("%", "%%"),
            }
            target.add_argument("--no-" + flag[2:] if default else flag, default=default, **switch)
            _add_aliases(target, spec.aliases, switch)
            continue
        shown_default = spec.default_text or (None if default is None else _default_text(default))
        help_text = doc if shown_default is None else f"{doc} (default: {shown_default})"
        element, many = _element(hint)
        parse, metavar = _value_type(f.name, element, spec)
        choices = spec.choices() if callable(spec.choices) else spec.choices
        if isinstance(default, Path) and spec.parse is not None:
            default = str(default)  # argparse parses a text default: the default is checked too
        kwargs: dict[str, Any] = {
            "dest": f.name,
            "default": list(default) if isinstance(default, tuple) else default,
            "help": help_text.replace("%", "%%"),
        }
        if parse is not None:
            kwargs["type"] = parse
        if choices is not None and spec.parse is None:
            kwargs["choices"] = tuple(choices)
            if spec.metavar:  # a long list of choices: the metavar in the usage, the list in errors
                kwargs["metavar"] = spec.metavar
        else:
            kwargs["metavar"] = metavar
        if spec.repeat:
            kwargs["action"] = "append"
            kwargs["help"] += " (repeatable)"
        elif many:
            kwargs["nargs"] = "*" if spec.positional else "+"
        elif spec.positional:
            kwargs["nargs"] = "?"
        del optional  # an optional value is given like any other; its default is None
        if spec.positional:
            del kwargs["dest"]
            target.add_argument(f.name, **kwargs)
            continue
        target.add_argument(flag, **kwargs)
        _add_aliases(target, spec.aliases, kwargs)


def _add_aliases(target: Any, aliases: Sequence[str], kwargs: Mapping[str, Any]) -> None:
    """Older names of an option: accepted like it, left out of the help."""
    for alias in aliases:
        hidden = dict(kwargs, default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        target.add_argument(alias, **hidden)


def spec_parser(
    prog: str,
    description: str,
    *spec_classes: type,
    overrides: Mapping[str, Any] | None = None,
) -> ArgumentParser:
    """The parser of a subcommand: one option per field of each of ``spec_classes`` (see
    :func:`spec_options`), e.g. a study's Spec and the runner's
    (:class:`experiments.sweep.RunnerSpec`); ``overrides`` replace field defaults."""
    parser = ArgumentParser(prog=prog, description=description)
    for spec_class in spec_classes:
        spec_options(parser, spec_class, overrides=overrides)
    return parser


def spec_from_args(spec_class: type[SpecT], args: argparse.Namespace) -> SpecT:
    """The Spec of parsed options (lists become tuples; attributes of other Specs are
    ignored). The Spec's own checks run as it is built."""
    values = {}
    for f in dataclasses.fields(spec_class):  # type: ignore[arg-type]
        if f.init and hasattr(args, f.name):
            value = getattr(args, f.name)
            values[f.name] = tuple(value) if isinstance(value, list) else value
    return spec_class(**values)
