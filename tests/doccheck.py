"""Checks of the project's markdown: the ``onionsort`` commands it shows, and its links.

A command is found in a shell block (```` ```bash ````, ``sh``, ``shell``, ``console`` or no
language) or in an inline code span that starts with ``onionsort`` or ``python -m
onionsort.cli``; prompts (``$``), ``# comments``, environment assignments (``RAY_ADDRESS=...``)
and backslash continuations are handled as a shell would. A block's command is parsed in full
by the CLI's parser; an inline span may abbreviate, so only its (sub)commands and flags are
checked. Placeholders in capitals (``RUN_DIR``, ``LEVEL``, ``N``) stand for values: one is
accepted where a value goes, also where the option has ``choices`` or a ``type`` that would
refuse it, but never as a (sub)command or a flag.

A page of the manual (every markdown file under docs/ but the generated docs/cli.md and the
dated notes of docs/notes/) says what is true today: it holds no date, commit hash, issue
number or load average (those belong to a dated note), and no more than ``MAX_PAGE_LINES``
lines.

A link is checked where it is not code: ``[text](path#anchor)``, ``![alt](path)`` and
``[label]: path`` must name a file or folder of the repository relative to the linking file,
and an anchor into a markdown file must be one of its headings' GitHub slugs. Links out of
the repository (``http://``, ``https://``, any other scheme) are refused.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import shlex
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

__all__ = [
    "DocCommand",
    "code_spans",
    "command_problem",
    "doc_commands",
    "fenced_blocks",
    "flag_problem",
    "github_slug",
    "heading_anchors",
    "link_problems",
    "manual_pages",
    "markdown_files",
    "page_problems",
    "parse_problem",
    "placeholder_parser",
    "shell_commands",
]

#: the info strings of fenced blocks whose lines are shell commands
SHELL_BLOCKS = {"", "bash", "sh", "shell", "console", "zsh", "shell-session"}
#: a value that stands for one the reader gives
PLACEHOLDER = re.compile(r"[A-Z][A-Z0-9_]*")
_PLACEHOLDER_WORD = re.compile(r"(?<![A-Za-z0-9_])[A-Z][A-Z0-9_]*(?![A-Za-z0-9_])")
#: words before a command that are not the command
_PREFIXES = {"$", "%", "do", "then", "else", "time", "nohup", "exec", "command", "env", "!"}
_ASSIGNMENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*=")
_SEPARATORS = {"&&", "||", ";", ";;", "|", "|&", "&", "(", ")"}
_REDIRECTS = {">", ">>", "<", "<<", ">&", "<&", "&>", "&>>", ">|", "<>"}
_NEGATIVE_NUMBER = re.compile(r"-\d+(\.\d*)?|-\.\d+")
_FENCE = re.compile(r"^(\s*)(`{3,}|~{3,})\s*([^`\s]*)[^`]*$")


@dataclass(frozen=True)
class DocCommand:
    """An ``onionsort`` command shown in a markdown file."""

    path: Path
    #: 1-based line the command starts on
    line: int
    #: the command as the file shows it (continuations joined, comment dropped)
    text: str
    #: the words after ``onionsort``
    argv: tuple[str, ...]
    #: from an inline code span (which may abbreviate), not a shell block
    inline: bool


@dataclass(frozen=True)
class FencedBlock:
    info: str
    #: 1-based line of the block's first line of content
    line: int
    lines: tuple[str, ...]


# -- markdown structure ----------------------------------------------------------------------

def fenced_blocks(text: str) -> list[FencedBlock]:
    """The fenced code blocks of ``text`` (```` ``` ```` or ``~~~``, any indentation); an
    unclosed fence runs to the end, as in CommonMark."""
    blocks, lines, i = [], text.splitlines(), 0
    while i < len(lines):
        match = _FENCE.match(lines[i])
        if match is None:
            i += 1
            continue
        fence, info = match.group(2), match.group(3).lower()
        end = i + 1
        while end < len(lines) and not re.fullmatch(
                rf"\s*{re.escape(fence[0])}{{{len(fence)},}}\s*", lines[end]):
            end += 1
        blocks.append(FencedBlock(info, i + 2, tuple(lines[i + 1:end])))
        i = end + 1
    return blocks


def _blank(text: str) -> str:
    """``text`` with every character but newlines replaced by a space (offsets kept)."""
    return re.sub(r"[^\n]", " ", text)


def _without_fences(text: str) -> str:
    """``text`` with its fenced blocks (fences included) blanked."""
    lines = text.split("\n")
    inside, fence = False, ""
    for i, line in enumerate(lines):
        if not inside:
            match = _FENCE.match(line)
            if match:
                inside, fence = True, match.group(2)
                lines[i] = _blank(line)
        else:
            if re.fullmatch(rf"\s*{re.escape(fence[0])}{{{len(fence)},}}\s*", line):
                inside = False
            lines[i] = _blank(line)
    return "\n".join(lines)


def _spans(text: str) -> Iterator[tuple[int, int, str]]:
    """``(start, end, content)`` of each inline code span of ``text`` (no fenced blocks in
    it): a run of n backticks up to the next run of exactly n, within one paragraph."""
    runs = [(m.start(), m.end()) for m in re.finditer(r"`+", text)]
    i = 0
    while i < len(runs):
        start, stop = runs[i]
        n = stop - start
        for j in range(i + 1, len(runs)):
            if runs[j][1] - runs[j][0] == n:
                content = text[stop:runs[j][0]]
                if re.search(r"\n[ \t]*\n", content):
                    break
                yield start, runs[j][1], content
                i = j
                break
        i += 1


def code_spans(text: str) -> list[tuple[int, str]]:
    """``(line, content)`` of each inline code span outside fenced blocks; a span may break
    across lines, its line breaks read as spaces."""
    prose = _without_fences(text)
    return [(prose.count("\n", 0, start) + 1, " ".join(content.split()))
            for start, _, content in _spans(prose)]


def _prose(text: str) -> str:
    """``text`` with fenced blocks, inline code and HTML comments blanked (offsets kept)."""
    prose = _without_fences(text)
    for start, end, _ in list(_spans(prose)):
        prose = prose[:start] + _blank(prose[start:end]) + prose[end:]
    return re.sub(r"<!--.*?-->", lambda m: _blank(m.group()), prose, flags=re.S)


def markdown_files(root: Path) -> list[Path]:
    """README.md and every markdown file under docs/."""
    files = [root / "README.md"] if (root / "README.md").is_file() else []
    return files + sorted((root / "docs").rglob("*.md"))


# -- commands --------------------------------------------------------------------------------

def _strip_comment(line: str) -> str:
    """``line`` without its shell comment: a ``#`` that starts a word, outside quotes."""
    quote, escaped = "", False
    for i, char in enumerate(line):
        if escaped:
            escaped = False
        elif char == "\\" and quote != "'":
            escaped = True
        elif quote:
            quote = "" if char == quote else quote
        elif char in "'\"":
            quote = char
        elif char == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip()
    return line


def shell_commands(lines: list[str] | tuple[str, ...], first_line: int = 1
                   ) -> list[tuple[int, str, list[str]]]:
    """``(line, text, words)`` of each simple command in shell ``lines``: continuations
    joined, comments dropped, split at ``&&``, ``;``, ``|`` and the like, redirections
    dropped. ``first_line`` is the line number of ``lines[0]``."""
    out, i = [], 0
    while i < len(lines):
        start, text = first_line + i, _strip_comment(lines[i])
        while text.endswith("\\") and i + 1 < len(lines):
            i += 1
            text = text[:-1].rstrip() + " " + _strip_comment(lines[i]).strip()
        i += 1
        text = text.strip()
        if text.startswith(("$ ", "% ")):
            text = text[2:]
        try:
            lexer = shlex.shlex(text, posix=True, punctuation_chars=True)
            lexer.whitespace_split, lexer.commenters = True, ""
            tokens = list(lexer)
        except ValueError:  # an unclosed quote: not a command a shell would run
            tokens = text.split()
        words: list[str] = []
        tokens.append(";")
        skip = False
        for token in tokens:
            if skip:
                skip = False
            elif token in _REDIRECTS:
                skip = True
            elif token in _SEPARATORS:
                if words:
                    out.append((start, text, words))
                words = []
            else:
                words.append(token)
    return out


def onionsort_argv(words: list[str]) -> tuple[str, ...] | None:
    """The arguments of ``onionsort`` (or ``python -m onionsort.cli``) in a command's
    ``words``, after prompts, shell keywords and environment assignments; ``None`` if the
    command is not onionsort."""
    i = 0
    while i < len(words) and (words[i] in _PREFIXES or _ASSIGNMENT.match(words[i])):
        i += 1
    rest = words[i:]
    if rest[:1] == ["onionsort"]:
        return tuple(rest[1:])
    if len(rest) >= 3 and re.fullmatch(r"(.*/)?python(3(\.\d+)?)?", rest[0]) \
            and rest[1:3] == ["-m", "onionsort.cli"]:
        return tuple(rest[3:])
    return None


def doc_commands(path: Path) -> list[DocCommand]:
    """Every onionsort command of the markdown file ``path``: those of its shell blocks, then
    those of its inline code spans."""
    text = path.read_text(encoding="utf-8")
    out = []
    for block in fenced_blocks(text):
        if block.info not in SHELL_BLOCKS:
            continue
        for line, command, words in shell_commands(block.lines, block.line):
            argv = onionsort_argv(words)
            if argv is not None:
                out.append(DocCommand(path, line, command, argv, inline=False))
    for line, content in code_spans(text):
        try:
            words = shlex.split(content)
        except ValueError:
            words = content.split()
        argv = onionsort_argv(words)
        if argv is not None:
            out.append(DocCommand(path, line, content, argv, inline=True))
    return out


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction | None:
    return next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)


def flag_problem(argv: tuple[str, ...] | list[str],
                 parser: argparse.ArgumentParser) -> str | None:
    """What is wrong with the (sub)commands and flags of ``argv`` for ``parser``, or ``None``:
    a (sub)command that does not exist, a flag its command does not take. Values, positional
    arguments and missing arguments are not checked (an inline span may leave them out)."""
    prog, chosen, i = "onionsort", False, 0
    while i < len(argv):
        token = argv[i]
        i += 1
        if re.fullmatch(r"\[-[^\]]*\]?", token):  # [--no-depth], [--views K]: optional
            token = token[1:].rstrip("]")
        if token == "--":
            break
        if token.startswith("-") and token != "-" and not _NEGATIVE_NUMBER.fullmatch(token):
            flag = token.split("=", 1)[0]
            action = parser._option_string_actions.get(flag)
            if action is None and not token.startswith("--"):  # -vv: a cluster of short flags
                action = parser._option_string_actions.get(token[:2])
            if action is None:
                return f"`{flag}` is not an option of `{prog}`"
            if action.nargs != 0 and "=" not in token and i < len(argv) \
                    and not argv[i].startswith("-"):
                i += 1  # its value
            continue
        sub = _subparsers(parser)
        if sub is not None and not chosen:
            if token not in sub.choices:
                return (f"`{token}` is not a command of `{prog}` (its commands: "
                        f"{', '.join(sub.choices)})")
            prog, parser = f"{prog} {token}", sub.choices[token]
            chosen = _subparsers(parser) is None
    return None


class _ParseError(Exception):
    pass


class _Placeholder(str):
    """A value that a placeholder stands for."""


class _PlaceholderChoices:
    """An option's ``choices`` that also admit a placeholder."""

    def __init__(self, choices):
        self.choices = choices

    def __contains__(self, value) -> bool:
        return (isinstance(value, str) and PLACEHOLDER.fullmatch(value) is not None) \
            or value in self.choices

    def __iter__(self):
        return iter(self.choices)


def _placeholder_type(convert: Callable) -> Callable:
    """``convert`` (an argparse ``type``) that lets a placeholder through: a value that is one,
    or one that ``convert`` refuses and that holds one (``0.1,LEVEL``)."""

    def placeholder_or(text: str):
        if PLACEHOLDER.fullmatch(text):
            return _Placeholder(text)
        try:
            return convert(text)
        except (argparse.ArgumentTypeError, TypeError, ValueError):
            if _PLACEHOLDER_WORD.search(text):
                return _Placeholder(text)
            raise

    placeholder_or.__name__ = getattr(convert, "__name__", "value")
    return placeholder_or


def placeholder_parser(build: Callable[[], argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """``build()``'s parser, changed to check documented commands: placeholders accepted as
    values, flags never abbreviated, and an error raised instead of printed and exited on."""
    parser = build()
    stack = [parser]
    while stack:
        p = stack.pop()
        p.allow_abbrev = False

        def error(message, _p=p):
            raise _ParseError(f"`{_p.prog}`: {message}")

        def exit_(status=0, message=None, _p=p):
            if status:
                raise _ParseError(f"`{_p.prog}`: {(message or '').strip()}")
            raise _ParseError("")  # --help, --version: a command that parses

        p.error, p.exit = error, exit_
        for action in p._actions:
            if isinstance(action, argparse._SubParsersAction):
                stack.extend({id(s): s for s in action.choices.values()}.values())
                continue
            if action.option_strings and action.nargs == 0:
                continue
            if action.type is not None:
                action.type = _placeholder_type(action.type)
            if action.choices is not None:
                action.choices = _PlaceholderChoices(action.choices)
    return parser


def parse_problem(argv: tuple[str, ...] | list[str],
                  parser: argparse.ArgumentParser) -> str | None:
    """argparse's complaint about ``argv`` for a :func:`placeholder_parser`, or ``None``."""
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            parser.parse_args(list(argv))
    except _ParseError as exc:
        return str(exc) or None
    return None


def command_problem(command: DocCommand, parser: argparse.ArgumentParser) -> str | None:
    """What is wrong with a documented ``command`` for a :func:`placeholder_parser`, or
    ``None``: its (sub)commands and flags, and, from a shell block, its whole parse."""
    problem = flag_problem(command.argv, parser)
    if problem is None and not command.inline:
        problem = parse_problem(command.argv, parser)
    return problem


# -- links -----------------------------------------------------------------------------------

_LINK = re.compile(
    r"!?\[(?:[^\[\]]|\[[^\[\]]*\])*\]"  # [text], one level of brackets inside
    r"\(\s*(<[^>\n]*>|[^\s()]*(?:\([^\s()]*\)[^\s()]*)*)"  # (target
    r"(?:\s+(?:\"[^\"]*\"|'[^']*'|\([^)]*\)))?\s*\)")  # "title")
_DEFINITION = re.compile(r"^ {0,3}\[[^\]]+\]:\s*(<[^>\n]*>|\S+)", re.M)
_URL = re.compile(r"\bhttps?://[^\s<>)\]]*[^\s<>)\].,;:!?'\"]"  # a bare URL, no punctuation after
                  r"|<[a-zA-Z][a-zA-Z0-9+.-]*:[^\s<>]*>")  # an autolink
_SCHEME = re.compile(r"[a-zA-Z][a-zA-Z0-9+.-]*:")


def github_slug(heading: str) -> str:
    """The anchor GitHub gives a heading of plain text ``heading`` (github-slugger: lower
    case, punctuation dropped except ``-`` and ``_``, each space a ``-``)."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def _heading_text(markdown: str) -> str:
    """The text a heading shows: links as their text, no images, code marks, emphasis
    stars or HTML tags."""
    text = re.sub(r"!\[[^\]]*\]\([^)]*\)", "", markdown)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = re.sub(r"<[^>]+>", "", text)
    return text.replace("`", "").replace("*", "")


def heading_anchors(text: str) -> set[str]:
    """Every anchor of a markdown ``text``: its headings' slugs (a repeated one numbered
    ``-1``, ``-2``, ... as GitHub does) and HTML ``id``/``name`` attributes."""
    prose = _without_fences(text)
    lines = prose.split("\n")
    titles = []
    for i, line in enumerate(lines):
        atx = re.match(r"^ {0,3}#{1,6}(?:[ \t]+(.*?))?(?:[ \t]+#+)?[ \t]*$", line)
        if atx:
            titles.append(atx.group(1) or "")
        elif i and re.fullmatch(r" {0,3}(=+|-+)[ \t]*", line) and lines[i - 1].strip() \
                and not re.match(r"^ {0,3}(#|[-*+] |>|\|)", lines[i - 1]):
            titles.append(lines[i - 1].strip())
    anchors: set[str] = set()
    counts: dict[str, int] = {}
    for title in titles:
        slug = base = github_slug(_heading_text(title))
        while slug in anchors:
            counts[base] = counts.get(base, 0) + 1
            slug = f"{base}-{counts[base]}"
        anchors.add(slug)
    anchors.update(re.findall(r"<[^>]*\b(?:id|name)=[\"']([^\"']+)[\"']", prose))
    return anchors


def _links(text: str) -> Iterator[tuple[int, str]]:
    """``(line, target)`` of every link and image of ``text`` that is not code."""
    prose = _prose(text)
    found = [(m.start(1), m.group(1)) for m in _LINK.finditer(prose)]
    found += [(m.start(1), m.group(1)) for m in _DEFINITION.finditer(prose)]
    for start, target in sorted(found):
        yield prose.count("\n", 0, start) + 1, target


def link_problems(path: Path, root: Path) -> list[str]:
    """``file:line: what`` for every link of the markdown file ``path`` that leaves the
    repository ``root`` or does not resolve: a missing file, an anchor no heading has."""
    text = path.read_text(encoding="utf-8")
    where = path.relative_to(root).as_posix()
    problems = []
    prose = _prose(text)
    for match in _URL.finditer(prose):
        line = prose.count("\n", 0, match.start()) + 1
        problems.append(f"{where}:{line}: external link {match.group().strip('<>')} (the "
                        "docs link only files of the repository)")
    reported = {p.split(": ", 1)[0] for p in problems}
    for line, raw in _links(text):
        target = raw[1:-1] if raw.startswith("<") else raw
        if not target:
            problems.append(f"{where}:{line}: empty link target")
            continue
        if _SCHEME.match(target):
            if f"{where}:{line}" not in reported:
                problems.append(f"{where}:{line}: external link {target} (the docs link only "
                                "files of the repository)")
            continue
        file_part, _, anchor = target.partition("#")
        file_part, anchor = unquote(file_part), unquote(anchor)
        base = root if file_part.startswith("/") else path.parent
        resolved = (base / file_part.lstrip("/")).resolve() if file_part else path.resolve()
        if not resolved.is_relative_to(root.resolve()):
            problems.append(f"{where}:{line}: link {target} leaves the repository")
        elif not resolved.exists():
            problems.append(f"{where}:{line}: link {target}: no such file "
                            f"{resolved.relative_to(root.resolve()).as_posix()}")
        elif anchor and resolved.suffix.lower() == ".md" and resolved.is_file():
            anchors = heading_anchors(resolved.read_text(encoding="utf-8"))
            if anchor not in anchors:
                problems.append(f"{where}:{line}: link {target}: no heading with anchor "
                                f"#{anchor} in {resolved.relative_to(root.resolve()).as_posix()}")
    return problems


# -- the manual's pages ----------------------------------------------------------------------

#: the most lines a page of the manual may have
MAX_PAGE_LINES = 400
_MONTH = (r"(?:January|February|March|April|May|June|July|August|September|October|November"
          r"|December|Jan|Feb|Mar|Apr|Jun|Jul|Aug|Sept?|Oct|Nov|Dec)")
#: what a page of the manual must not hold, by name: a dated, versioned or measured-once mark
STALE_MARKS = {
    "a date": re.compile(
        r"\b(?:19|20)\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b"  # 2026-11-26
        rf"|\b{_MONTH}\.? (?:\d{{1,2}}(?:st|nd|rd|th)?,? )?(?:19|20)\d\d\b"  # Nov 26, 2026
        rf"|\b\d{{1,2}} {_MONTH} (?:19|20)\d\d\b"),  # 26 November 2026
    "a commit hash": re.compile(r"\b(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b"
                                r"|\bcommit [0-9a-f]{4,40}\b"),
    "an issue number": re.compile(r"\b(?:[Ii]ssues?|PRs?|[Pp]ull requests?) #?\d+"
                                  r"|(?<![\w&/#])#\d+(?![\w-])"),
    "a load average": re.compile(r"\bload[ -]?averages?(?: (?:of|about|around|between|near|"
                                 r"was|is|at))?:? ~?\d|\bloadavg\b"
                                 r"|\b(?:machine|CPU|system) load (?:of )?\d"),
}

#: a link's target, or a link definition's (``](docs/notes/2026-11-26-x.md)``, ``[x]: path``)
_TARGET = re.compile(r"\]\([^)]*\)|^( {0,3}\[[^\]]+\]:)\s*\S+")


def manual_pages(root: Path) -> list[Path]:
    """The pages of the manual: every markdown file under docs/ but docs/cli.md (generated
    from the parsers) and the dated notes under docs/notes/."""
    docs = root / "docs"
    return [p for p in sorted(docs.rglob("*.md"))
            if p != docs / "cli.md" and docs / "notes" not in p.parents]


def page_problems(path: Path, root: Path) -> list[str]:
    """``file:line: what`` for each date, commit hash, issue number or load average on the
    manual's page ``path`` (code included; link targets left out, so that a page may link a
    dated note by its name), and for a page over ``MAX_PAGE_LINES`` lines."""
    text = path.read_text(encoding="utf-8")
    where = path.relative_to(root).as_posix()
    problems = []
    n = len(text.splitlines())
    if n > MAX_PAGE_LINES:
        problems.append(f"{where}: {n} lines, over {MAX_PAGE_LINES}: move what is history to a "
                        "dated note in docs/notes/, or split the page")
    for number, line in enumerate(text.splitlines(), 1):
        line = _TARGET.sub(lambda m: m.group(1) or "]()", line)
        for what, pattern in STALE_MARKS.items():
            for match in pattern.finditer(line):
                problems.append(f"{where}:{number}: {what}, {match.group()!r} (it belongs to a "
                                "dated note in docs/notes/)")
    return problems
