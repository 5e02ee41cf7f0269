"""Write docs/cli.md, the command-line reference, from the argparse parsers of ``onionsort``.

Regenerate it with ``python scripts/gen_cli_docs.py``; ``--check`` only compares and exits 1
when docs/cli.md is stale (tests/test_docs.py runs the same comparison).

Every command that :data:`onionsort.commands.COMMAND_MODULES` registers is documented, its
sub-subcommands (``train detector``, ...) included: its help line, usage, description (the
command module's docstring, its examples as a shell block) and a table of its options. The
text depends on nothing but the parsers: usage lines are wrapped here at a fixed width (never
argparse's terminal-width formatter), and a default that differs between two builds of the
parser on differently shaped machines (CPU count, home, working folder) is written as
"machine-dependent", never as this machine's value.

Examples
--------
    python scripts/gen_cli_docs.py                  # writes docs/cli.md
    python scripts/gen_cli_docs.py --check          # exit 1 if docs/cli.md is stale
    python scripts/gen_cli_docs.py --out /tmp/cli.md
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path, PurePath
from unittest import mock

__all__ = ["CLI_DOC", "REGENERATE", "Command", "cli_reference", "iter_commands", "main"]

ROOT = Path(__file__).resolve().parent.parent
#: the generated file, relative to the repository root
CLI_DOC = Path("docs/cli.md")
#: the command that regenerates it
REGENERATE = "python scripts/gen_cli_docs.py"
#: usage lines wrap at this many characters
USAGE_WIDTH = 96
#: a URL in help text: scheme://..., without the punctuation after it
_URL = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*://[^\s`]*[^\s`.,;:!?)'\"]")
#: what a default computed from the machine is rendered as
MACHINE_DEPENDENT = "machine-dependent"


@dataclass(frozen=True)
class Command:
    """One (sub)command: its words after ``onionsort``, its parser and its one-line help."""

    words: tuple[str, ...]
    parser: argparse.ArgumentParser
    help: str

    @property
    def prog(self) -> str:
        return " ".join(("onionsort", *self.words))


def _subparsers_action(parser: argparse.ArgumentParser) -> argparse._SubParsersAction | None:
    return next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)


def iter_commands(parser: argparse.ArgumentParser,
                  words: tuple[str, ...] = (), help_: str = "") -> Iterator[Command]:
    """``parser`` and every subcommand below it, depth first, in registration order (an alias
    of a subcommand is not listed again)."""
    yield Command(words, parser, help_)
    action = _subparsers_action(parser)
    if action is None:
        return
    helps = {choice.dest: choice.help or "" for choice in action._choices_actions}
    seen: set[int] = set()
    for name, sub in action.choices.items():
        if id(sub) in seen:
            continue
        seen.add(id(sub))
        yield from iter_commands(sub, (*words, name), helps.get(name, ""))


# -- stable rendering ------------------------------------------------------------------------

@contextlib.contextmanager
def _machine(cpus: int, home: Path, cwd: Path) -> Iterator[None]:
    """Pretend to be a machine with ``cpus`` CPUs, home folder ``home``, working in ``cwd``."""
    old = Path.cwd()
    patches = [mock.patch("os.cpu_count", return_value=cpus),
               mock.patch.dict(os.environ, {"HOME": str(home), "COLUMNS": "80"})]
    if hasattr(os, "sched_getaffinity"):
        patches.append(mock.patch("os.sched_getaffinity", return_value=set(range(cpus))))
    if hasattr(os, "process_cpu_count"):  # Python 3.13
        patches.append(mock.patch("os.process_cpu_count", return_value=cpus))
    with contextlib.ExitStack() as stack:
        for patch in patches:
            stack.enter_context(patch)
        os.chdir(cwd)
        try:
            yield
        finally:
            os.chdir(old)


def _defaults(parser: argparse.ArgumentParser) -> dict[tuple[str, str], object]:
    """``(prog, dest) -> default`` of every option of every command."""
    return {(cmd.prog, action.dest): action.default
            for cmd in iter_commands(parser) for action in cmd.parser._actions}


def machine_dependent_defaults(build) -> set[tuple[str, str]]:
    """The ``(prog, dest)`` of every default that ``build()`` (a parser factory) computes
    differently on two differently shaped machines."""
    build()  # import the command modules here, before the working folder changes
    runs = []
    with tempfile.TemporaryDirectory() as tmp:
        for i, cpus in enumerate((1, 61)):
            folder = Path(tmp, f"machine{i}")
            (folder / "home").mkdir(parents=True)
            with _machine(cpus, folder / "home", folder):
                runs.append(_defaults(build()))
    first, second = runs
    return {key for key in first.keys() | second.keys()
            if repr(first.get(key)) != repr(second.get(key))}


def render_value(value: object) -> str:
    """A default as the command line would spell it: paths relative where they can be, lists
    and mappings comma-joined, nothing for ``None`` or an empty container."""
    if value is None or value is False or (isinstance(value, list | tuple | set | dict)
                                            and not value):
        return ""
    if isinstance(value, PurePath):
        path = Path(value)
        for base, prefix in ((ROOT, ""), (Path.home(), "~/")):
            if path.is_absolute() and path.is_relative_to(base):
                return prefix + path.relative_to(base).as_posix()
        return path.as_posix()
    if isinstance(value, dict):
        return ",".join(f"{k}={render_value(v)}" for k, v in value.items())
    if isinstance(value, list | tuple):
        return ",".join(render_value(v) for v in value)
    if isinstance(value, set | frozenset):
        return ",".join(sorted(render_value(v) for v in value))
    if value is True:
        return "on"
    return str(value)


def _metavar(action: argparse.Action, default: str) -> str:
    if action.metavar is not None:
        return action.metavar if isinstance(action.metavar, str) else " ".join(action.metavar)
    if action.choices is not None:
        return "{" + ",".join(map(str, action.choices)) + "}"
    return default


def format_args(action: argparse.Action) -> str:
    """What follows the flag (or stands for the positional) in a usage line, by ``nargs``."""
    m = _metavar(action, action.dest if not action.option_strings else action.dest.upper())
    nargs = action.nargs
    if nargs is None:
        return m
    if nargs == argparse.OPTIONAL:
        return f"[{m}]"
    if nargs == argparse.ZERO_OR_MORE:
        return f"[{m} ...]"
    if nargs == argparse.ONE_OR_MORE:
        return f"{m} [{m} ...]"
    if nargs == argparse.PARSER:
        return f"{m} ..."
    if nargs == argparse.REMAINDER:
        return "..."
    if nargs == argparse.SUPPRESS:
        return ""
    return " ".join([m] * nargs)


def _takes_value(action: argparse.Action) -> bool:
    return action.nargs != 0


def usage(cmd: Command, width: int = USAGE_WIDTH) -> str:
    """``usage: onionsort ...`` wrapped at ``width``, every bracketed part kept whole."""
    parser = cmd.parser
    groups = {id(a): g for g in parser._mutually_exclusive_groups for a in g._group_actions}
    parts, done = [], set()

    def optional(action, bracket=True):
        text = action.option_strings[0]
        if _takes_value(action):
            text += " " + format_args(action)
        return f"[{text}]" if bracket and not action.required else text

    for action in parser._actions:
        if not action.option_strings or action.help == argparse.SUPPRESS:
            continue
        group = groups.get(id(action))
        if group is None:
            parts.append(optional(action))
        elif id(group) not in done:
            done.add(id(group))
            inner = " | ".join(optional(a, bracket=False) for a in group._group_actions
                               if a.help != argparse.SUPPRESS)
            parts.append(f"({inner})" if group.required else f"[{inner}]")
    parts += [format_args(a) for a in parser._actions
              if not a.option_strings and a.help != argparse.SUPPRESS]
    head = f"usage: {cmd.prog}"
    lines, line = [], head
    for part in filter(None, parts):
        if len(line) + 1 + len(part) > width and line.strip() != head.strip() and line.strip():
            lines.append(line)
            line = " " * len(head)
        line += " " + part
    lines.append(line)
    return "\n".join(lines)


def _cell(text: str) -> str:
    """``text`` safe inside a markdown table cell: on one line, its pipes escaped, and its
    URLs (``rerun+http://HOST:9876/proxy``) code, not links."""
    parts = " ".join(text.split()).split("`")
    parts[::2] = [_URL.sub(r"`\g<0>`", part) for part in parts[::2]]
    return "`".join(parts).replace("|", "\\|")


def _help(action: argparse.Action, default: str) -> str:
    """The help text with argparse's ``%(...)s`` expanded (``%(default)s`` as rendered), less
    a last ``(default: VALUE)`` that says what the table's Default column says."""
    if not action.help:
        return ""
    params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
    params["default"] = default
    if action.choices is not None:
        params["choices"] = ", ".join(map(str, action.choices))
    text = action.help % params
    shown = f" (default: {default})"
    return text[:-len(shown)] if default and text.endswith(shown) else text


def options_tables(cmd: Command, dependent: set[tuple[str, str]]) -> list[str]:
    """A markdown table of each argument group of ``cmd`` (positionals, options, and the
    command's own groups, e.g. ``parallel``), the help option and the subcommands left out."""
    out = []
    for group in cmd.parser._action_groups:
        actions = [a for a in group._group_actions
                   if a.help != argparse.SUPPRESS
                   and not isinstance(a, argparse._HelpAction | argparse._SubParsersAction)]
        if not actions:
            continue
        title = {"positional arguments": "Arguments", "options": "Options",
                 "optional arguments": "Options"}.get(group.title, group.title or "Options")
        out += [f"**{title[:1].upper()}{title[1:]}**", "",
                "| Argument | Value | Default | Description |", "| --- | --- | --- | --- |"]
        for action in actions:
            if action.option_strings:
                name = ", ".join(f"`{s}`" for s in action.option_strings)
                value = f"`{format_args(action)}`" if _takes_value(action) else ""
            else:
                name, value = f"`{format_args(action)}`", ""
            if (cmd.prog, action.dest) in dependent:
                default = MACHINE_DEPENDENT
            elif isinstance(action, argparse._VersionAction):
                default = ""
            else:
                default = render_value(action.default)
            if (isinstance(action, argparse._StoreTrueAction | argparse._CountAction)
                    and action.default in (False, 0)) or (
                    isinstance(action, argparse._StoreFalseAction) and action.default is True):
                default = ""  # a switch: given or not
            one_of = next((g._group_actions for g in cmd.parser._mutually_exclusive_groups
                           if g.required and action in g._group_actions), None)
            if one_of is not None:  # (--out OUT | --list): one of them must be given
                cell = "one of " + ", ".join(f"`{a.option_strings[0]}`" for a in one_of)
            else:
                cell = "required" if action.required and action.option_strings else \
                    (f"`{default}`" if default and default != MACHINE_DEPENDENT else default)
            out.append(f"| {name} | {_cell(value)} | {_cell(cell)} | "
                       f"{_cell(_help(action, default))} |")
        out.append("")
    return out


def _markdown_prose(text: str) -> str:
    """reStructuredText literals and roles (````x````, ``:mod:`x```) as markdown code."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"`\1`", text)
    return re.sub(r"``(.+?)``", r"`\1`", text, flags=re.S)


def description(cmd: Command) -> list[str]:
    """The parser's description as markdown: its prose, then its numpydoc ``Examples``
    section as a shell block."""
    text = (cmd.parser.description or "").strip("\n")
    if not text:
        return []
    match = re.search(r"^Examples\n-{3,}\n", text, flags=re.M)
    prose, examples = (text[:match.start()], text[match.end():]) if match else (text, "")
    out = []
    if prose.strip():
        out += [_markdown_prose(prose.strip()), ""]
    lines = examples.rstrip().splitlines()
    if lines:
        indent = min(len(x) - len(x.lstrip()) for x in lines if x.strip())
        out += ["Examples:", "", "```bash", *(x[indent:].rstrip() for x in lines), "```", ""]
    return out


def _anchor(title: str) -> str:
    """GitHub's anchor of a heading ``title`` (plain text)."""
    return re.sub(r"[^\w\- ]", "", title.lower()).replace(" ", "-")


def cli_reference(build=None) -> str:
    """The text of docs/cli.md for the parser ``build()`` returns (default
    :func:`onionsort.cli.build_parser`)."""
    if build is None:
        from onionsort.cli import build_parser as build
    dependent = machine_dependent_defaults(build)
    commands = list(iter_commands(build()))
    out = ["# Command-line reference", "",
           f"_Generated from the parsers of `onionsort.cli`; do not edit by hand. Regenerate it "
           f"with `{REGENERATE}` (`--check` tells whether it is stale)._", "",
           "Every command also takes `-h`/`--help`, which prints its usage and options. "
           "Placeholders in capitals (`RUN_DIR`, `N`) stand for values you give.", ""]
    out += [f"- [{c.prog}](#{_anchor(c.prog)}){': ' + _cell(c.help) if c.help else ''}"
            for c in commands]
    out.append("")
    for cmd in commands:
        out += [f"## {cmd.prog}", ""]
        if cmd.help:
            out += [cmd.help[:1].upper() + cmd.help[1:] + ("" if cmd.help.endswith(".") else "."),
                    ""]
        out += ["```text", usage(cmd), "```", ""]
        out += description(cmd)
        sub = _subparsers_action(cmd.parser)
        if sub is not None:
            seen, rows = set(), []
            for name, parser in sub.choices.items():
                if id(parser) not in seen:
                    seen.add(id(parser))
                    prog = f"{cmd.prog} {name}"
                    rows.append(f"- [`{name}`](#{_anchor(prog)})")
            out += [f"**{_metavar(sub, 'COMMAND')}** (one of):", "", *rows, ""]
        out += options_tables(cmd, dependent)
    return "\n".join(out).rstrip("\n") + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="gen_cli_docs.py", description="Write docs/cli.md from the onionsort CLI parsers.")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; exit 1 if the file is not what would be written")
    parser.add_argument("--out", type=Path, default=ROOT / CLI_DOC,
                        help="the file to write or check (docs/cli.md)")
    args = parser.parse_args(argv)
    text = cli_reference()
    if args.check:
        if not args.out.is_file() or args.out.read_text(encoding="utf-8") != text:
            print(f"{args.out}: stale; regenerate it with `{REGENERATE}`", file=sys.stderr)
            return 1
        return 0
    from onionsort.stages.base import write_text

    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text(args.out, text)  # through a temporary name
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    # document this checkout's parsers, not those of another installed copy of onionsort
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
