"""The command line built from the stages' configs (:mod:`onionsort.configs`): every flag of a
converted command sets the config field it is declared on, and the flags docs/cli.md lists
exist with the defaults it gives."""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

import pytest

from onionsort.cli import build_parser
from onionsort.configs import config_from_args, config_options
from onionsort.configs.export import ExportConfig
from onionsort.configs.report import ReportConfig
from onionsort.configs.suggest import SuggestConfig
from tests.test_docs import gen  # scripts/gen_cli_docs.py

ROOT = Path(__file__).resolve().parent.parent

#: The commands whose options are declared on their config, with that config.
CONVERTED = {"suggest": SuggestConfig, "export": ExportConfig, "report": ReportConfig}


def _commands() -> dict[str, argparse.ArgumentParser]:
    return {cmd.prog: cmd.parser for cmd in gen.iter_commands(build_parser())}


def _other_value(field, opt, annotation, tmp_path: Path):
    """A command-line value for ``field`` other than its default, and the field's value then."""
    kind = opt.type or (annotation if not hasattr(annotation, "__args__") else
                        next(a for a in annotation.__args__ if a is not type(None)))
    if kind is bool:
        return [], not field.default
    if opt.choices is not None:
        others = [c for c in opt.choices if c != field.default]
        return ([others[0]], others[0]) if others else ([field.default], field.default)
    if kind is Path:
        path = tmp_path / f"new_{field.name}"
        return [str(path)], path
    if kind is int:
        return [str(field.default + 1)], field.default + 1
    raise AssertionError(f"no test value for {field.name} ({kind})")


@pytest.mark.parametrize("command", sorted(CONVERTED))
def test_each_flag_is_the_config_field_it_sets(command, tmp_path):
    config_cls = CONVERTED[command]
    parser = _commands()[f"onionsort {command}"]
    actions = {a.dest: a for a in parser._actions}
    options = config_options(config_cls)
    assert options, f"{config_cls.__name__} declares no option"
    required, argv_required = {}, []
    for field, opt, _ in options:
        action = actions[field.name]
        assert action.help == opt.help
        assert action.option_strings == ([] if opt.positional else
                                         opt.flags(field.name, field.default))
        assert (tuple(action.choices) if action.choices else None) == opt.choices
        if field.default is dataclasses.MISSING:
            assert opt.positional or action.required
            value = tmp_path / f"given_{field.name}"
            required[field.name] = value
            argv_required += [str(value)] if opt.positional else [action.option_strings[0],
                                                                  str(value)]
        else:
            assert action.default == field.default and not action.required
    # only the required values given: the config's own defaults
    args = parser.parse_args(argv_required)
    assert config_from_args(config_cls, args) == config_cls(**required)
    # each option given a value other than its default: that field, and no other, changes
    for field, opt, annotation in options:
        if field.default is dataclasses.MISSING:
            continue
        words, value = _other_value(field, opt, annotation, tmp_path)
        flag = opt.flags(field.name, field.default)[0]
        args = parser.parse_args([*argv_required, flag, *words])
        expected = config_cls(**required, **{field.name: value})
        assert config_from_args(config_cls, args) == expected, flag


def _documented_options() -> dict[str, list[tuple[str, str]]]:
    """Every command's options in docs/cli.md: its flag and its Default cell."""
    found: dict[str, list[tuple[str, str]]] = {}
    prog = None
    for line in (ROOT / "docs" / "cli.md").read_text().splitlines():
        if line.startswith("## onionsort"):
            prog = line[3:].strip()
        elif prog and (row := re.match(r"\| `(--[^`]+)`(?:, `[^`]+`)* \| [^|]* \| ([^|]*) \|",
                                       line)):
            found.setdefault(prog, []).append((row[1], row[2].strip()))
    return found


def test_the_flags_of_the_cli_reference_exist_with_its_defaults():
    render = gen.render_value
    commands = _commands()
    documented = _documented_options()
    with_flags = {f"onionsort {c}" for c, cls in CONVERTED.items()
                  if any(not opt.positional for _, opt, _ in config_options(cls))}
    assert with_flags and with_flags <= set(documented)
    for prog, rows in documented.items():
        actions = {s: a for a in commands[prog]._actions for s in a.option_strings}
        for flag, default in rows:
            action = actions.get(flag)
            assert action is not None, f"{prog} {flag} is documented but not parsed"
            if default == "required":
                assert action.required, f"{prog} {flag}"
            elif default != "machine-dependent":
                shown = render(action.default)
                if isinstance(action, argparse._VersionAction) or (
                        isinstance(action, argparse._StoreTrueAction | argparse._CountAction)
                        and action.default in (False, 0)):
                    shown = ""
                assert default == (f"`{shown}`" if shown else ""), f"{prog} {flag}"
