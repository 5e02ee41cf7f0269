"""The command line built from the stages' configs (:mod:`onionsort.configs`): every flag of
every command is declared on a config field and sets that field, and every flag that
docs/cli.md listed before the options moved onto the configs (issue 39; kept in
tests/data/cli_flags_before_issue_39.tsv) still exists with the same default."""

from __future__ import annotations

import argparse
import dataclasses
import sys
import typing
from pathlib import Path

import pytest

from onionsort.cli import build_parser
from onionsort.configs import DEFAULT, config_options, config_values, shown_default
from tests.test_docs import gen  # scripts/gen_cli_docs.py

ROOT = Path(__file__).resolve().parent.parent
BEFORE = ROOT / "tests" / "data" / "cli_flags_before_issue_39.tsv"
#: A command-line text for each option parser that is not a plain type, by its name.
TEXTS = {"floats": "0.5,0.25", "parse": "bc", "levels": "paper,hard", "weights": "3,1",
         "level_weights": "clean=2", "level_forms": "hard=powers", "classes": "good=sound",
         "camera_seeds": "11,12,13", "image_size": "320x240"}


def _commands() -> dict[str, argparse.ArgumentParser]:
    return {cmd.prog: cmd.parser for cmd in gen.iter_commands(build_parser())}


def _declared() -> dict[str, argparse.ArgumentParser]:
    """The commands whose options come from a config class: every one that runs."""
    return {prog: p for prog, p in _commands().items()
            if getattr(p, "config_class", None) is not None}


def test_every_command_that_runs_is_built_from_a_config():
    for prog, parser in _commands().items():
        runs = parser.get_default("func") is not None
        assert runs == (getattr(parser, "config_class", None) is not None), prog


def _default(field):
    """``field``'s default (made by its factory), or ``dataclasses.MISSING``."""
    if field.default_factory is not dataclasses.MISSING:
        return field.default_factory()
    return field.default


def _other_value(field, opt, annotation, tmp_path: Path):
    """Command-line words for ``field`` that give it a value other than its default, and
    that value as the config receives it."""
    default = None if _default(field) is dataclasses.MISSING else _default(field)
    several = opt.nargs in ("+", "*") or opt.action == "append"
    kind = annotation
    while typing.get_args(kind) and typing.get_origin(kind) is not dict:
        kind = next(a for a in typing.get_args(kind) if a is not type(None))
    if opt.action is argparse.BooleanOptionalAction:
        return ["--no-" + field.name.replace("_", "-") if default else None], not default
    if kind is bool and opt.type is None:
        return [], not default
    if opt.type is not None and opt.type.__name__ in TEXTS:
        text = TEXTS[opt.type.__name__]
        value = opt.type(text)
    elif opt.choices is not None:
        # a choice other than the default (the default where it is the only one)
        text = value = next((c for c in opt.choices if c != default), default)
    elif (opt.type or kind) is Path:
        text, value = str(tmp_path / f"new_{field.name}"), tmp_path / f"new_{field.name}"
    elif kind is int:
        value = (default or 0) + 2
        text = str(value)
    elif kind is float:
        value = (default or 0.0) + 0.25
        text = str(value)
    elif kind is str:
        text = value = f"new-{field.name}"
    else:
        raise AssertionError(f"no test value for {field.name} ({kind})")
    return [text], ((value,) if several else value)


@pytest.mark.parametrize("prog", sorted(_declared()))
def test_each_flag_is_the_config_field_it_sets(prog, tmp_path):
    parser = _declared()[prog]
    config_cls = parser.config_class
    options = config_options(config_cls)
    assert options, f"{config_cls.__name__} declares no option"
    actions = {a.dest: a for a in parser._actions if not isinstance(a, argparse._HelpAction)}
    assert set(actions) == {f.name for f, _, _ in options}, "an option not on the config"
    words = getattr(config_cls, "cli_help", {})
    required, argv_required = {}, []
    for field, opt, annotation in options:
        action = actions[field.name]
        text = opt.text(words)  # the help, and the default the builder shows after it
        shown = shown_default(None if _default(field) is dataclasses.MISSING
                              else _default(field)).replace("%", "%%")
        assert action.help in (text, f"{text} {DEFAULT}{shown})"), field.name
        if opt.action is not argparse.BooleanOptionalAction:
            assert action.option_strings == ([] if opt.positional else
                                             opt.flags(field.name, field.default))
        assert (tuple(action.choices) if action.choices else None) == opt.choices
        if _default(field) is dataclasses.MISSING:
            # one of a required group, (--out OUT | --list): given here, left out below where
            # another of its group is tested
            in_group = opt.exclusive is not None
            assert opt.positional or action.required or opt.required is False or in_group
            if opt.required is False:
                continue
            text, value = _other_value(field, opt, annotation, tmp_path)
            required[field.name] = value
            argv_required += text if opt.positional else [action.option_strings[0], *text]
        else:
            assert action.default == _default(field)
            assert action.required == bool(opt.required)
            if opt.required:  # a default for the library, none on the command line
                text, value = _other_value(field, opt, annotation, tmp_path)
                required[field.name] = value
                argv_required += [action.option_strings[0], *text]
    # only the required values given: every other field takes the config's default
    values = config_values(config_cls, parser.parse_args(argv_required))
    defaults = {f.name: _default(f) for f, _, _ in options if f.name not in required}
    assert values == {**{k: None if v is dataclasses.MISSING else v
                         for k, v in defaults.items()}, **required}
    # each option given a value other than its default: that field, and no other, changes
    exclusive = {f.name: o.exclusive for f, o, _ in options}
    for field, opt, annotation in options:
        if field.name in required:
            continue
        # a required group's member given above makes way for this one of its group
        rivals = [n for n in required if opt.exclusive and exclusive[n] == opt.exclusive]
        base, expected = list(argv_required), dict(values)
        for name in rivals:
            flag = actions[name].option_strings[0]
            at = base.index(flag)
            del base[at:at + 2]
            expected[name] = None
        text, value = _other_value(field, opt, annotation, tmp_path)
        if opt.positional:
            argv = [*text, *base]
        else:
            flag = opt.flags(field.name, field.default)[0]
            argv = [*base, *([flag, *text] if text[:1] != [None] else [])] \
                if opt.action is not argparse.BooleanOptionalAction else [*base, *text]
        args = parser.parse_args([w for w in argv if w is not None] or [])
        assert config_values(config_cls, args) == {**expected, field.name: value}, field.name


def _before() -> list[tuple[str, str, str]]:
    rows = [line.split("\t") for line in BEFORE.read_text().splitlines()
            if line and not line.startswith("#")]
    return [(prog, flag, default) for prog, flag, default in rows]


def _shown_default(action: argparse.Action) -> str:
    """``action``'s default as docs/cli.md shows it (none for a switch)."""
    if isinstance(action, argparse._VersionAction) or (
            isinstance(action, argparse._StoreTrueAction | argparse._CountAction)
            and action.default in (False, 0)) or (
            isinstance(action, argparse._StoreFalseAction) and action.default is True):
        return ""
    shown = gen.render_value(action.default)
    return f"`{shown}`" if shown else ""


def test_the_flags_of_the_cli_reference_before_the_configs_exist_with_its_defaults():
    commands = _commands()
    rows = _before()
    assert len(rows) > 200 and len({prog for prog, _, _ in rows}) >= 18
    for prog, flag, default in rows:
        actions = {s: a for a in commands[prog]._actions for s in a.option_strings}
        action = actions.get(flag)
        assert action is not None, f"{prog} {flag} was documented but is not parsed"
        if default == "required":
            assert action.required, f"{prog} {flag}"
        elif default != "machine-dependent":
            assert _shown_default(action) == default, f"{prog} {flag}"


def test_the_cli_reference_shows_the_defaults_of_the_configs():
    """docs/cli.md (generated) gives each option the default of the field it sets."""
    text = (ROOT / "docs" / "cli.md").read_text()
    for prog, parser in _declared().items():
        section = text.split(f"## {prog}\n", 1)[1].split("\n## ", 1)[0]
        for field, opt, _ in config_options(parser.config_class):
            if opt.positional or opt.required or isinstance(field.default, bool) or \
                    field.default in (None, dataclasses.MISSING):
                continue
            flag = opt.flags(field.name, field.default)[0]
            row = next(r for r in section.splitlines() if r.startswith(f"| `{flag}`"))
            shown = gen.render_value(field.default)
            assert f"| `{shown}` |" in row if shown else "|  |" in row, (prog, flag)


def test_a_commands_help_imports_no_stage_torch_irl_scipy_numpy_or_robot():
    """A command's start builds every parser from the configs; ``python -X importtime`` lists
    each module that start imports: none of the stages, the learners (and scipy), torch, or
    the robot's world (numpy and gymnasium)."""
    import subprocess

    done = subprocess.run([sys.executable, "-X", "importtime", "-m", "onionsort.cli", "record",
                           "--help"], capture_output=True, text=True, cwd=ROOT)
    assert done.returncode == 0, done.stderr[-2000:]
    imported = {line.rsplit("|", 1)[1].strip() for line in done.stderr.splitlines()
                if line.startswith("import time:") and "|" in line}
    assert {"onionsort.configs.record", "onionsort.configs.parallel"} <= imported
    heavy = ("torch", "irl", "scipy", "numpy", "robot", "gymnasium", "perception", "recordings")
    assert sorted(m for m in imported if m.split(".")[0] in heavy
                  or m.startswith("onionsort.stages")) == []


def test_the_repeated_choices_are_the_librarys():
    from irl.posterior import METHODS as POSTERIOR_METHODS
    from onionsort.configs import common
    from robot.difficulty import DIFFICULTY_LEVELS
    from robot.inspection_poses import INSPECTION_VIEWS

    assert tuple(DIFFICULTY_LEVELS) == common.DIFFICULTY_LEVELS
    assert common.INSPECTION_VIEWS == INSPECTION_VIEWS
    assert set(POSTERIOR_METHODS) == set(common.POSTERIOR_METHODS)  # in the order of the help
