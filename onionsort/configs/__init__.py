"""The stages' configs, light enough for the command line to read, and the builder that makes
their fields into command-line options.

Each option is declared once, on a config field, with :func:`option`: its default, its help,
and where the command line differs from the field (the flag's name, a positional argument, a
metavar, choices). :func:`add_config_arguments` adds a config's options to an argparse parser
and :func:`config_from_args` builds the config from the parsed arguments; :func:`documented`
writes the config's ``Attributes`` from the same help, which is each option's only text (a
field that is no option has a ``#:`` comment instead). The modules of this package import
nothing but the standard library (a config's checks import what they need when a config is
made) and nothing from the stages (a constant or a check that a config and its stage share
lives here, and the stage imports it), so that building the parser (every command does, at
start) loads neither torch, ``irl`` (and scipy), the robot's world nor the stages; each stage
module re-exports its config from here. Options several stages share are field factories in
:mod:`onionsort.configs.common`; where a stage's pieces run, the fields of
:class:`onionsort.configs.parallel.ParallelOptions`.

Every option's help says what it does and ends with its default, one way: ``(default:
VALUE)``, which :func:`add_config_arguments` appends from the field's default, so a help never
states it. Where the default is None, empty or worked out (the shipped models, one worker per
core, 4 with ``--quick``), the help ends with ``(default: ...)`` in words instead. A switch
(a ``bool`` field, off by default) and a required option show none.

Example::

    @documented
    @dataclass(frozen=True, kw_only=True)
    class SuggestConfig:
        run: Path = option(positional=True, metavar="RUN_DIR", help="a folder of ...")
        top: int = option(5, help="states to list")          # shown: states to list (default: 5)

    add_config_arguments(parser, SuggestConfig)        # RUN_DIR and --top
    config = config_from_args(SuggestConfig, args)     # SuggestConfig(run=..., top=...)
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import textwrap
import types
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any

__all__ = ["DEFAULT", "Option", "add_config_arguments", "config_from_args", "config_options",
           "config_values", "documented", "option", "shown_default"]

#: the metadata key of a field's :class:`Option`
_KEY = "onionsort.option"
#: how every option's help shows its default: ``(default: VALUE)``, last
DEFAULT = "(default: "


def shown_default(value) -> str:
    """A default as the help shows it, spelled as the command line would take it: a path as
    given, a list or mapping joined by commas, ``on``/``off`` for a boolean; nothing for None
    or an empty container (the help then says it in words)."""
    if value is None or (isinstance(value, list | tuple | set | frozenset | dict) and not value):
        return ""
    if isinstance(value, bool):
        return "on" if value else "off"
    if isinstance(value, PurePath):
        return value.as_posix()
    if isinstance(value, dict):
        return ",".join(f"{k}={shown_default(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return ",".join(shown_default(v) for v in value)
    if isinstance(value, set | frozenset):
        return ",".join(sorted(shown_default(v) for v in value))
    return str(value)


@dataclass(frozen=True)
class Option:
    """How a config field appears on the command line (see :func:`option`)."""

    help: str | None
    flag: str | None = None
    positional: bool = False
    choices: Sequence[str] | None = None
    metavar: str | None = None
    type: Callable[[str], Any] | None = None
    group: str | None = None
    nargs: str | None = None
    action: Any = None
    exclusive: str | None = None
    required: bool | None = None
    after: str | None = None

    def flags(self, name: str, default) -> list[str]:
        """The option strings of the field ``name``: its positional name, or two dashes and
        the name with dashes for underscores (a boolean that defaults to true is switched off
        by the same with ``no-`` before the name)."""
        if self.positional:
            return [name]
        if self.flag is not None:
            return [self.flag]
        negated = "no-" if default is True and self.action is None else ""
        return ["--" + negated + name.replace("_", "-")]

    def text(self, words: dict[str, str]) -> str | None:
        """The help with each ``{name}`` replaced by ``words[name]`` (a config's
        ``cli_help``)."""
        return self.help.format(**words) if self.help and "{" in self.help else self.help

    def shown(self, words: dict[str, str], default, *, switch: bool, required: bool
              ) -> str | None:
        """The help as the command line shows it: :meth:`text`, and ``(default: VALUE)``
        after it where the option takes a value (or is argparse's
        ``BooleanOptionalAction``), is not required, and the help does not say its default in
        words already (``VALUE`` is :func:`shown_default` of ``default``, its ``%`` doubled
        for argparse)."""
        text = self.text(words)
        if text is None or switch or required or self.positional or DEFAULT in text:
            return text
        shown = shown_default(default)
        return f"{text} {DEFAULT}{shown.replace('%', '%%')})" if shown else text


def option(default=dataclasses.MISSING, *, help: str | None, flag: str | None = None,
           positional: bool = False, choices: Sequence[str] | None = None,
           metavar: str | None = None, type: Callable[[str], Any] | None = None,
           group: str | None = None, nargs: str | None = None, action: Any = None,
           exclusive: str | None = None, required: bool | None = None,
           after: str | None = None, default_factory=dataclasses.MISSING):
    """A config field that is also a command-line option.

    Parameters
    ----------
    default, default_factory
        The field's default, or what makes it (as :func:`dataclasses.field`'s); neither makes
        the field required (a positional argument when ``positional``, else a required
        option).
    help
        The option's help, and the field's documentation (:func:`documented`).
    flag
        The option string where it is not ``--`` and the field's name with dashes.
    positional, choices, metavar
        As argparse's.
    type
        Parses the text; by default the field's annotation (``Path``, ``int``, ``float``,
        ``str``, or one of them ``| None``). A ``bool`` field is a switch that sets a false
        default to true (a true one, to false: its flag has ``no-`` before the name).
    group
        The title of the argument group the option is listed under in the command's help.
        A ``{name}`` in ``help`` is replaced by the config class's ``cli_help[name]`` (a
        class variable: words that differ between the commands that share the option).
    nargs
        As argparse's; a field of several values (``+``, ``*``) is a tuple.
    action
        argparse's ``append`` (the field is a tuple of every value given) or
        ``argparse.BooleanOptionalAction`` (the flag, and the same with ``no-`` before the
        name).
    exclusive
        The options of one name are mutually exclusive; where one of them is required, one
        of them must be given (argparse's required group: ``(--out OUT | --list)``).
    required
        Whether the option must be given, where that is not what the default says (an
        option whose absence the command itself answers).
    after
        The field this option is listed after (by default: the fields of a class first,
        then those it inherits, each in the order they are declared).
    """
    meta = {_KEY: Option(help=help, flag=flag, positional=positional,
                         choices=tuple(choices) if choices is not None else None,
                         metavar=metavar, type=type, group=group, nargs=nargs, action=action,
                         exclusive=exclusive, required=required, after=after)}
    return dataclasses.field(default=default, default_factory=default_factory, metadata=meta)


def config_options(config_cls) -> list[tuple[dataclasses.Field, Option, Any]]:
    """The fields of ``config_cls`` that are command-line options, in the order they are
    listed: each with its :class:`Option` and its resolved annotation.

    The fields come in the dataclass's order (a base's first; a field a class declares again
    stays where its base lists it), except that those of a base whose ``cli_last`` is true
    (the shared options of where the pieces run) come last; then every option with ``after``
    is moved to just after the field it names."""
    hints = typing.get_type_hints(config_cls)
    fields = {f.name: f for f in dataclasses.fields(config_cls) if _KEY in f.metadata}
    last = {n for base in config_cls.__mro__ if vars(base).get("cli_last")
            for n in vars(base).get("__annotations__", {})}
    names = [n for n in fields if n not in last] + [n for n in fields if n in last]
    for name in [n for n in names if fields[n].metadata[_KEY].after is not None]:
        names.remove(name)
        names.insert(names.index(fields[name].metadata[_KEY].after) + 1, name)
    return [(fields[n], fields[n].metadata[_KEY], hints[n]) for n in names]


def _text_type(annotation):
    """What parses an option's text for a field annotated ``annotation`` (``X | None``: X;
    ``tuple[X, ...]``: X)."""
    if typing.get_origin(annotation) is tuple:
        return typing.get_args(annotation)[0]
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return _text_type(args[0])
        raise TypeError(f"an option's type must be one type or it | None; got {annotation}")
    return annotation


def _default(f: dataclasses.Field):
    """A field's default (its factory's value), or ``dataclasses.MISSING``."""
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return f.default


def add_config_arguments(parser: argparse.ArgumentParser, config_cls) -> None:
    """Add an argument to ``parser`` for every :func:`option` field of ``config_cls``; each
    is parsed into the attribute of the field's name."""
    groups: dict[str, Any] = {}
    exclusive: dict[str, Any] = {}
    words = getattr(config_cls, "cli_help", {})
    options = config_options(config_cls)
    # an exclusive group one of whose options is required: one of them must be given
    one_of = {opt.exclusive for f, opt, _ in options
              if opt.exclusive is not None and _required(f, opt)}
    for f, opt, annotation in options:
        default = _default(f)
        missing = default is dataclasses.MISSING
        default = None if missing else default
        switch = opt.action is None and opt.type is None and _text_type(annotation) is bool
        required = _required(f, opt) and opt.exclusive is None
        kwargs: dict[str, Any] = {"help": opt.shown(words, default, switch=switch,
                                                    required=required or missing)}
        if not opt.positional:
            kwargs["dest"] = f.name
        if switch:
            kwargs["action"] = "store_false" if default is True else "store_true"
        else:
            if opt.action is not None:
                kwargs["action"] = opt.action
            if opt.type is not None or opt.action is not argparse.BooleanOptionalAction:
                kwargs["type"] = opt.type or _text_type(annotation)
            for key in ("choices", "metavar", "nargs"):
                if getattr(opt, key) is not None:
                    kwargs[key] = getattr(opt, key)
            if not missing:
                kwargs["default"] = default
            if required:
                kwargs["required"] = True
        target = parser
        if opt.group is not None:
            if opt.group not in groups:
                groups[opt.group] = parser.add_argument_group(opt.group)
            target = groups[opt.group]
        if opt.exclusive is not None:
            if opt.exclusive not in exclusive:
                exclusive[opt.exclusive] = target.add_mutually_exclusive_group(
                    required=opt.exclusive in one_of)
            target = exclusive[opt.exclusive]
        target.add_argument(*opt.flags(f.name, default), **kwargs)


def _required(f: dataclasses.Field, opt: Option) -> bool:
    """Whether the option ``f`` must be given on the command line (a positional argument is
    required by argparse's own rule)."""
    if opt.positional:
        return False
    return opt.required if opt.required is not None else _default(f) is dataclasses.MISSING


def config_values(config_cls, args: argparse.Namespace) -> dict[str, Any]:
    """The parsed ``args`` of the :func:`option` fields of ``config_cls``, by field name (the
    values of several, ``nargs`` and ``append``, as tuples)."""
    values = {}
    for f, opt, _ in config_options(config_cls):
        value = getattr(args, f.name)
        several = opt.nargs in ("+", "*") or opt.action == "append"
        values[f.name] = tuple(value) if several and value is not None else value
    return values


def config_from_args(config_cls, args: argparse.Namespace, **overrides):
    """``config_cls`` built from the parsed ``args`` of its :func:`option` fields, with
    ``overrides`` (the fields that are not options, or whose value the command works out)."""
    return config_cls(**{**config_values(config_cls, args), **overrides})


def documented(config_cls):
    """``config_cls`` with a numpydoc ``Attributes`` section appended to its docstring: each
    :func:`option` field, in the order the command lists it, with its type (its choices where
    it has some), its default and its help, after its flag where that is not the field's name
    (the help is the option's only text; a field that is no option has a ``#:`` comment)."""
    if config_cls.__doc__ is None:  # docstrings stripped (python -OO)
        return config_cls
    words = getattr(config_cls, "cli_help", {})
    lines = ["Attributes", "----------"]
    for f, opt, _ in config_options(config_cls):
        kind = f.type if isinstance(f.type, str) else inspect.formatannotation(f.type)
        if opt.choices is not None:
            kind = ("{" + ", ".join(map(repr, opt.choices)) + "}"
                    + (" or None" if "None" in kind else ""))
        default = _default(f)
        if default is not dataclasses.MISSING:
            shown = str(default) if isinstance(default, PurePath) else repr(default)
            kind += f", default {shown}"
        lines.append(f"{f.name} : {kind}")
        text = (opt.text(words) or "").replace("%%", "%")
        flag = opt.flags(f.name, default)[0]
        if not opt.positional and flag != "--" + f.name.replace("_", "-"):
            text = f"``{flag}``: {text}"
        lines += textwrap.wrap(text, 92, initial_indent="    ", subsequent_indent="    ")
    config_cls.__doc__ = inspect.cleandoc(config_cls.__doc__) + "\n\n" + "\n".join(lines)
    return config_cls
