"""Every ``--help`` a user reads: each command and subcommand says what it does and shows
examples that run, and each option has a help that ends with its default, written one way.

The rules hold for the whole parser, so a command or an option added later is checked with no
change here:

- a command's description is plain text (no reStructuredText ````x```` or ``:mod:`x```) and
  ends with a numpydoc ``Examples`` section: command lines of that command which its parser
  accepts, one per line (a long one continued with a backslash), a comment after two spaces;
- an option (or an optional positional argument) has a help; if it takes a value and may be
  left out, its help ends with ``(default: ...)``, the only place it says "default", and that
  starts with the default itself where the default is a value (``onionsort.configs`` appends
  it from the field); a switch (on when given) and a required option say no default.
"""

from __future__ import annotations

import argparse
import re

import pytest

from onionsort.cli import build_parser
from onionsort.configs import DEFAULT, shown_default
from tests.doccheck import onionsort_argv, parse_problem, placeholder_parser, shell_commands
from tests.test_docs import gen  # scripts/gen_cli_docs.py

#: reStructuredText that must not reach a terminal
REST = re.compile(r"``|:[a-z]+:`")
EXAMPLES = re.compile(r"^Examples\n-{3,}\n", flags=re.M)


def _commands() -> list[gen.Command]:
    return list(gen.iter_commands(build_parser()))


def _ids(commands) -> list[str]:
    return [c.prog for c in commands]


COMMANDS = _commands()


def _options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    skip = (argparse._HelpAction, argparse._SubParsersAction, argparse._VersionAction)
    return [a for a in parser._actions if not isinstance(a, skip)]


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The help as ``--help`` prints it (argparse's ``%(...)s`` expanded)."""
    return parser._get_formatter()._expand_help(action) if action.help else ""


def _is_switch(action: argparse.Action) -> bool:
    """On (or off) when given, with nothing after it: no default to show."""
    return action.nargs == 0 and not isinstance(action, argparse.BooleanOptionalAction)


def _required(action: argparse.Action, parser: argparse.ArgumentParser | None) -> bool:
    """Whether ``action`` must be given, alone or as one of a required group's options."""
    groups = parser._mutually_exclusive_groups if parser is not None else []
    return action.required or any(g.required and action in g._group_actions for g in groups)


def _needs_default(action: argparse.Action, parser: argparse.ArgumentParser | None) -> bool:
    """Whether the help must end with the default: the argument takes a value (or is a
    ``--x/--no-x`` pair) and may be left out."""
    if _is_switch(action) or _required(action, parser):
        return False
    return bool(action.option_strings) or action.nargs in (argparse.OPTIONAL,
                                                           argparse.ZERO_OR_MORE)


def default_problem(action: argparse.Action, text: str,
                    parser: argparse.ArgumentParser | None = None) -> str | None:
    """What is wrong with how ``text``, an option of ``parser``'s help, shows its default, or
    None."""
    mentions = len(re.findall(r"\bdefault", text, flags=re.I))
    if not _needs_default(action, parser):
        return (f"says 'default' {mentions} time(s), but a "
                f"{'switch' if _is_switch(action) else 'required argument'} shows no default"
                if mentions else None)
    at = text.rfind(DEFAULT)
    if at < 0 or not text.endswith(")"):
        return f"does not end with its default, {DEFAULT}...)"
    if mentions != 1:
        return f"says 'default' {mentions} times; only its last {DEFAULT}...) may"
    shown = shown_default(action.default)
    if shown and not text[at + len(DEFAULT):].startswith(shown):
        return f"shows {text[at:]!r}, but the default is {shown!r}"
    if shown and f"({shown})" in text[:at]:
        return f"also writes the default as ({shown})"
    return None


def example_problems(command: gen.Command, parser: argparse.ArgumentParser) -> list[str]:
    """What is wrong with the examples of ``command``'s description."""
    text = command.parser.description or ""
    match = EXAMPLES.search(text)
    if match is None:
        return ["no Examples section"]
    lines = text[match.end():].rstrip().splitlines()
    problems = [f"line {line.strip()!r}: two spaces inside a command (a lost line break?)"
                for line in lines if re.search(r"\S {2,}(?!#| )\S", line.split("  #")[0])]
    found = [(text, argv) for _, text, words in shell_commands(lines)
             if (argv := onionsort_argv(words)) is not None]
    if not any(argv[:len(command.words)] == tuple(command.words) for _, argv in found):
        problems.append(f"no example of `{command.prog}`")
    for text, argv in found:
        problem = parse_problem(argv, parser)
        if problem is not None:
            problems.append(f"`{text}`: {problem}")
    return problems


@pytest.fixture(scope="module")
def placeholders() -> argparse.ArgumentParser:
    return placeholder_parser(build_parser)


@pytest.mark.parametrize("command", COMMANDS, ids=_ids(COMMANDS))
def test_each_command_is_described_in_plain_text_with_examples_that_parse(command,
                                                                          placeholders):
    description = command.parser.description or ""
    prose = EXAMPLES.split(description)[0].strip()
    assert prose, f"{command.prog} has no description"
    assert not REST.search(description), f"{command.prog}: reStructuredText in the description"
    if command.words:
        assert command.help and not REST.search(command.help), command.prog
    problems = example_problems(command, placeholders)
    assert not problems, f"{command.prog}: " + "; ".join(problems)


@pytest.mark.parametrize("command", COMMANDS, ids=_ids(COMMANDS))
def test_each_option_has_a_help_ending_with_its_default(command):
    problems = []
    for action in _options(command.parser):
        name = (action.option_strings or [action.metavar or action.dest])[0]
        text = _help(command.parser, action)
        if not text.strip():
            problems.append(f"{name}: no help")
            continue
        if REST.search(text):
            problems.append(f"{name}: reStructuredText in the help")
        problem = default_problem(action, text, command.parser)
        if problem is not None:
            problems.append(f"{name}: {problem}")
    assert not problems, f"{command.prog}:\n" + "\n".join(problems)


def test_the_whole_parser_is_covered():
    progs = {c.prog for c in COMMANDS}
    assert {"onionsort", "onionsort train inspection", "onionsort label select",
            "onionsort label import", "onionsort import"} <= progs
    assert len(progs) >= 23


# -- the rules catch what they should --------------------------------------------------------

def _action(parser: argparse.ArgumentParser, *flags, **kwargs) -> argparse.Action:
    return parser.add_argument(*flags, **kwargs)


@pytest.mark.parametrize(("kwargs", "text", "wrong"), [
    ({"type": int, "default": 10}, "trials per point (default: 10)", None),
    ({"type": int, "default": 10}, "trials per point (10)", "does not end"),
    ({"type": int, "default": 10}, "trials per point (default 10)", "does not end"),
    ({"type": int, "default": 10}, "trials (default: 10; 3 with --quick)", None),
    ({"type": int, "default": 10}, "trials (default: 3)", "the default is '10'"),
    ({"type": int, "default": 10}, "trials (10) (default: 10)", "also writes"),
    ({"type": int, "default": None}, "trials (default: one per core)", None),
    ({"type": int, "default": None}, "trials, by default one per core", "does not end"),
    ({"choices": ("a", "b"), "default": "a"}, "a (default) or b (default: a)", "2 times"),
    ({"action": "store_true"}, "be quick", None),
    ({"action": "store_true"}, "be quick (default: off)", "a switch shows no default"),
    ({"type": int, "required": True}, "trials (default: 10)", "required argument"),
    ({"action": argparse.BooleanOptionalAction, "default": True}, "augment", "does not end"),
    ({"action": argparse.BooleanOptionalAction, "default": True}, "augment (default: on)",
     None),
])
def test_default_rules_on_made_up_options(kwargs, text, wrong):
    action = _action(argparse.ArgumentParser(), "--x", help=text, **kwargs)
    problem = default_problem(action, text)
    assert (problem is None) if wrong is None else (wrong in (problem or "")), problem


def test_example_rules_on_a_made_up_command(placeholders):
    parser = argparse.ArgumentParser(prog="onionsort report", description=(
        "Write a report.\n\nExamples\n--------\n"
        "    onionsort report runs/demo         # fine\n"
        "    onionsort report runs/a         --quick\n"
        "    onionsort report --pages 3 runs/b\n"))
    command = gen.Command(("report",), parser, "a report")
    problems = example_problems(command, placeholders)
    assert any("lost line break" in p for p in problems)
    assert any("--quick" in p and "unrecognized" in p for p in problems)
    assert any("--pages" in p for p in problems)
    parser.description = "Write a report."
    assert example_problems(command, placeholders) == ["no Examples section"]
