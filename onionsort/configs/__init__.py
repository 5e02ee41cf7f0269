"""The stages' configs, light enough for the command line to read, and the builder that makes
their fields into command-line options.

Each option is declared once, on a config field, with :func:`option`: its default, its help,
and where the command line differs from the field (the flag's name, a positional argument, a
metavar, choices). :func:`add_config_arguments` adds a config's options to an argparse parser
and :func:`config_from_args` builds the config from the parsed arguments. The modules of this
package import nothing but the standard library, so that building the parser (every command
does, at start) loads neither torch, ``irl`` (and scipy) nor the stages; each stage module
re-exports its config from here.

Example::

    @dataclass(frozen=True, kw_only=True)
    class SuggestConfig:
        run: Path = option(positional=True, metavar="RUN_DIR", help="a folder of ...")
        top: int = option(5, help="states to list (5)")

    add_config_arguments(parser, SuggestConfig)        # RUN_DIR and --top
    config = config_from_args(SuggestConfig, args)     # SuggestConfig(run=..., top=...)
"""

from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = ["Option", "add_config_arguments", "config_from_args", "config_options", "option"]

#: the metadata key of a field's :class:`Option`
_KEY = "onionsort.option"


@dataclass(frozen=True)
class Option:
    """How a config field appears on the command line (see :func:`option`)."""

    help: str
    flag: str | None = None
    positional: bool = False
    choices: Sequence[str] | None = None
    metavar: str | None = None
    type: Callable[[str], Any] | None = None
    group: str | None = None

    def flags(self, name: str, default) -> list[str]:
        """The option strings of the field ``name``: its positional name, or two dashes and
        the name with dashes for underscores (a boolean that defaults to true is switched off
        by the same with ``no-`` before the name)."""
        if self.positional:
            return [name]
        if self.flag is not None:
            return [self.flag]
        negated = "no-" if default is True else ""
        return ["--" + negated + name.replace("_", "-")]


def option(default=dataclasses.MISSING, *, help: str, flag: str | None = None,
           positional: bool = False, choices: Sequence[str] | None = None,
           metavar: str | None = None, type: Callable[[str], Any] | None = None,
           group: str | None = None):
    """A config field that is also a command-line option.

    Parameters
    ----------
    default
        The field's default; none makes the field required (a positional argument when
        ``positional``, else a required option).
    help
        The option's help (also the field's documentation).
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
    """
    meta = {_KEY: Option(help=help, flag=flag, positional=positional,
                         choices=tuple(choices) if choices is not None else None,
                         metavar=metavar, type=type, group=group)}
    return dataclasses.field(default=default, metadata=meta)


def config_options(config_cls) -> list[tuple[dataclasses.Field, Option, Any]]:
    """The fields of ``config_cls`` that are command-line options, in order: each with its
    :class:`Option` and its resolved annotation."""
    hints = typing.get_type_hints(config_cls)
    return [(f, f.metadata[_KEY], hints[f.name]) for f in dataclasses.fields(config_cls)
            if _KEY in f.metadata]


def _text_type(annotation):
    """What parses an option's text for a field annotated ``annotation`` (``X | None``: X)."""
    if isinstance(annotation, types.UnionType) or typing.get_origin(annotation) is typing.Union:
        args = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return args[0]
        raise TypeError(f"an option's type must be one type or it | None; got {annotation}")
    return annotation


def add_config_arguments(parser: argparse.ArgumentParser, config_cls) -> None:
    """Add an argument to ``parser`` for every :func:`option` field of ``config_cls``; each
    is parsed into the attribute of the field's name."""
    groups: dict[str, Any] = {}
    for f, opt, annotation in config_options(config_cls):
        default = None if f.default is dataclasses.MISSING else f.default
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        kwargs: dict[str, Any] = {"help": opt.help}
        if not opt.positional:
            kwargs["dest"] = f.name
        if _text_type(annotation) is bool:
            kwargs["action"] = "store_false" if default is True else "store_true"
        else:
            kwargs["type"] = opt.type or _text_type(annotation)
            if opt.choices is not None:
                kwargs["choices"] = opt.choices
            if opt.metavar is not None:
                kwargs["metavar"] = opt.metavar
            if not required:
                kwargs["default"] = default
            elif not opt.positional:
                kwargs["required"] = True
        target = parser
        if opt.group is not None:
            if opt.group not in groups:
                groups[opt.group] = parser.add_argument_group(opt.group)
            target = groups[opt.group]
        target.add_argument(*opt.flags(f.name, default), **kwargs)


def config_from_args(config_cls, args: argparse.Namespace, **overrides):
    """``config_cls`` built from the parsed ``args`` of its :func:`option` fields (and
    ``overrides``, for the fields that are not options)."""
    values = {f.name: getattr(args, f.name) for f, _, _ in config_options(config_cls)}
    return config_cls(**values, **overrides)
