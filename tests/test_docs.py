"""The docs stay true: docs/cli.md is what the parsers generate, every ``onionsort`` command
in README.md and docs/ parses, every link resolves inside the repository, and the manual's
pages (docs/ but cli.md and the dated notes) hold no date, commit hash, issue number or load
average and no more than 400 lines each.

The checkers (tests/doccheck.py) are themselves tested on small markdown files with known
faults.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import re
import sys
import types
from pathlib import Path

import pytest

from onionsort.cli import build_parser
from tests.doccheck import (
    code_spans,
    command_problem,
    doc_commands,
    fenced_blocks,
    github_slug,
    heading_anchors,
    link_problems,
    manual_pages,
    markdown_files,
    page_problems,
    placeholder_parser,
    shell_commands,
)

ROOT = Path(__file__).resolve().parent.parent


def _load_generator() -> types.ModuleType:
    spec = importlib.util.spec_from_file_location("gen_cli_docs",
                                                  ROOT / "scripts" / "gen_cli_docs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


gen = _load_generator()


@pytest.fixture(scope="module")
def parser() -> argparse.ArgumentParser:
    return placeholder_parser(build_parser)


def problems_of(paths: list[Path], parser: argparse.ArgumentParser, root: Path = ROOT
                ) -> list[str]:
    """``file:line: `command`: what is wrong`` for every documented command that fails."""
    out = []
    for path in paths:
        for command in doc_commands(path):
            problem = command_problem(command, parser)
            if problem is not None:
                out.append(f"{path.relative_to(root).as_posix()}:{command.line}: "
                           f"`{command.text}`: {problem}")
    return out


# -- docs/cli.md -----------------------------------------------------------------------------

def test_cli_reference_is_current():
    path = ROOT / gen.CLI_DOC
    assert path.is_file(), f"{gen.CLI_DOC} is missing: generate it with `{gen.REGENERATE}`"
    fresh = gen.cli_reference()
    current = path.read_text(encoding="utf-8")
    if current != fresh:
        stale = next((i + 1 for i, (a, b) in enumerate(
            zip(current.splitlines(), fresh.splitlines(), strict=False)) if a != b),
            min(len(current.splitlines()), len(fresh.splitlines())) + 1)
        pytest.fail(f"{gen.CLI_DOC} is stale (from line {stale}): regenerate it with "
                    f"`{gen.REGENERATE}`")


def test_cli_reference_documents_every_command_and_option():
    text = gen.cli_reference()
    for command in gen.iter_commands(build_parser()):
        assert f"\n## {command.prog}\n" in text
        for action in command.parser._actions:
            for flag in action.option_strings:
                if flag not in ("-h", "--help"):
                    assert f"`{flag}`" in text.split(f"\n## {command.prog}\n")[1]
    assert "## onionsort train detector\n" in text
    assert "## onionsort experiment\n" in text and "`{forestworld,sorting}`" in text


def test_cli_reference_does_not_depend_on_the_terminal_or_the_machine(monkeypatch, tmp_path):
    reference = gen.cli_reference()
    monkeypatch.setenv("COLUMNS", "37")
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setattr(os, "cpu_count", lambda: 97)
    monkeypatch.chdir(tmp_path)
    assert gen.cli_reference() == reference
    assert str(ROOT) not in reference and str(Path.home()) not in reference


def test_a_default_computed_from_the_machine_is_not_written_as_this_machines():
    def build():
        p = argparse.ArgumentParser(prog="onionsort")
        sub = p.add_subparsers(dest="command", required=True)
        c = sub.add_parser("crunch", help="crunch numbers")
        c.add_argument("--workers", type=int, default=os.cpu_count(), help="(%(default)s)")
        c.add_argument("--cache", type=Path, default=Path.home() / ".cache" / "x")
        c.add_argument("--out", type=Path, default=ROOT / "runs" / "x")
        c.add_argument("--size", type=int, default=3)
        return p

    text = gen.cli_reference(build)
    row = next(line for line in text.splitlines() if line.startswith("| `--workers`"))
    assert row == "| `--workers` | `WORKERS` | machine-dependent | (machine-dependent) |"
    assert "| `--cache` | `CACHE` | machine-dependent |" in text
    assert "| `--out` | `OUT` | `runs/x` |" in text  # a path in the repository: relative
    assert "| `--size` | `SIZE` | `3` |" in text
    assert "## onionsort crunch" in text and "Crunch numbers." in text


def test_the_reference_picks_up_every_registered_command(monkeypatch):
    """A command module registered later (a made-up ``summarize``) appears with no change here."""
    module = types.ModuleType("fake_summarize_command")

    def register(subparsers):
        p = subparsers.add_parser("summarize", help="write a summary", description="A summary.")
        p.add_argument("run", metavar="RUN_DIR")
        p.add_argument("--format", choices=("md", "html"), default="md")

    module.register = register
    monkeypatch.setitem(sys.modules, module.__name__, module)
    import onionsort.cli

    monkeypatch.setattr(onionsort.cli, "COMMAND_MODULES",
                        [*onionsort.cli.COMMAND_MODULES, module.__name__])
    text = gen.cli_reference()
    assert "- [onionsort summarize](#onionsort-summarize): write a summary" in text
    assert "usage: onionsort summarize [-h] [--format {md,html}] RUN_DIR" in text
    assert "| `--format` | `{md,html}` | `md` |" in text


def test_check_exits_1_with_one_line_when_stale(tmp_path, capsys):
    out = tmp_path / "cli.md"
    assert gen.main(["--out", str(out)]) == 0
    capsys.readouterr()
    assert gen.main(["--check", "--out", str(out)]) == 0
    out.write_text(out.read_text() + "edited by hand\n")
    assert gen.main(["--check", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "stale" in err and gen.REGENERATE in err
    out.unlink()
    assert gen.main(["--check", "--out", str(out)]) == 1


def test_usage_lines_wrap_at_the_fixed_width():
    for command in gen.iter_commands(build_parser()):
        lines = gen.usage(command).splitlines()
        assert lines[0].startswith(f"usage: {command.prog}")
        assert all(len(line) <= gen.USAGE_WIDTH for line in lines[1:] if line.count(" [") > 1)


# -- the documented commands -----------------------------------------------------------------

def test_every_documented_command_parses(parser):
    files = markdown_files(ROOT)
    commands = [c for path in files for c in doc_commands(path)]
    assert any(not c.inline for c in commands), "no onionsort command found in a shell block"
    problems = problems_of(files, parser)
    assert not problems, "documented commands the CLI refuses:\n" + "\n".join(problems)


def _write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


GOOD = r"""
# Try it

```bash
onionsort demo                       # the whole job
$ onionsort record --sessions 12 --out runs/rec
RAY_ADDRESS=HEAD_IP:6379 onionsort perceive runs/rec/*.mcap --executor ray
onionsort learn runs/rec/*.mcap --observation-model onionsort/models/calibration.json \
    --method mmap-birl,map-birl --out runs/learn   # two learners
onionsort evaluate RUN_DIR --difficulty LEVEL --defer-below P --workers N
onionsort dataset --frames 1200 --seed 60 --difficulty LEVEL --out D && ls D
python -m onionsort.cli train detector --data D --out runs/models --epochs 30
onionsort experiment DOMAIN --learner-beta x0.25,x1,paper --seed N
onionsort experiment sorting --occlusion 0.1,P --noise 0.3
onionsort demo --help
pip install -e ".[ray]"
```

```python
onionsort = "not a command"
```

Run `onionsort demo --quick`, or `onionsort train detector --init`, or `onionsort
evaluate --policy expert --onions 60`; `onionsort/models/` and `onionsort.stages` are not
commands, and `onionsort dataset --seed 60|61 --difficulty` abbreviates, as does
`onionsort eval-perception --data D [--no-depth] [--views K]`.
"""

BAD = r"""
```bash
onionsort demo --quik
onionsort record --sesions 2 --out runs/rec
onionsort record --sess 2 --out runs/rec
onionsort train --data runs/data --out runs/models
onionsort train detecter --data D --out D
onionsort evaluate RUN_DIR --onions many
onionsort demo --difficulty hardest
onionsort learn runs/rec/*.mcap --out runs/learn
onionsort --verbose summarize runs/x
```

Inline: `onionsort demo --repeat 3`, `onionsort train detecter`,
`onionsort suggest RUN_DIR
--tops 3`, `python -m onionsort.cli demo --quik`.
Optional: `onionsort eval-perception --data D [--no-deph]`.
"""


def test_the_command_checker_passes_good_commands(tmp_path, parser):
    path = _write(tmp_path, "good.md", GOOD)
    commands = doc_commands(path)
    assert [c.argv[:2] for c in commands if not c.inline] == [
        ("demo",), ("record", "--sessions"), ("perceive", "runs/rec/*.mcap"),
        ("learn", "runs/rec/*.mcap"), ("evaluate", "RUN_DIR"), ("dataset", "--frames"),
        ("train", "detector"), ("experiment", "DOMAIN"), ("experiment", "sorting"),
        ("demo", "--help")]
    learn = next(c for c in commands if c.argv[:1] == ("learn",))
    assert learn.line == 8 and learn.argv[-2:] == ("--out", "runs/learn")
    assert [c.argv for c in commands if c.inline] == [
        ("demo", "--quick"), ("train", "detector", "--init"),
        ("evaluate", "--policy", "expert", "--onions", "60"),
        ("dataset", "--seed", "60|61", "--difficulty"),
        ("eval-perception", "--data", "D", "[--no-depth]", "[--views", "K]")]
    assert problems_of([path], parser, tmp_path) == []


def test_the_command_checker_names_each_fault(tmp_path, parser):
    path = _write(tmp_path, "docs/bad.md", BAD)
    problems = problems_of([path], parser, tmp_path)
    expected = [
        (3, "`--quik` is not an option of `onionsort demo`"),
        (4, "`--sesions` is not an option of `onionsort record`"),
        (5, "`--sess` is not an option of `onionsort record`"),  # no abbreviations
        (6, "`--data` is not an option of `onionsort train`"),
        (7, "`detecter` is not a command of `onionsort train`"),
        (8, "invalid int value: 'many'"),
        (9, "invalid choice: 'hardest'"),
        (10, "the following arguments are required: --observation-model"),
        (11, "`summarize` is not a command of `onionsort`"),
        (14, "`--repeat` is not an option of `onionsort demo`"),
        (14, "`detecter` is not a command of `onionsort train`"),
        (15, "`--tops` is not an option of `onionsort suggest`"),
        (16, "`--quik` is not an option of `onionsort demo`"),
        (17, "`--no-deph` is not an option of `onionsort eval-perception`"),
    ]
    assert len(problems) == len(expected), "\n".join(problems)
    for problem, (line, what) in zip(problems, expected, strict=True):
        assert problem.startswith(f"docs/bad.md:{line}: `"), problem
        assert what in problem, problem


def test_a_missing_subcommand_fails_in_a_block_but_not_inline(tmp_path, parser):
    path = _write(tmp_path, "a.md", "`onionsort train` trains.\n\n```sh\nonionsort train\n```\n")
    problems = problems_of([path], parser, tmp_path)
    assert len(problems) == 1 and problems[0].startswith("a.md:4: `onionsort train`: ")
    assert "required: MODEL" in problems[0]


def test_shell_lines_become_commands():
    lines = ["FOO=1 onionsort demo \\", "    --quick   # fast", "# only a comment",
             "onionsort demo --out 'runs/a b' | tee log > out.txt; onionsort suggest R#1"]
    assert shell_commands(lines, 10) == [
        (10, "FOO=1 onionsort demo --quick", ["FOO=1", "onionsort", "demo", "--quick"]),
        (13, "onionsort demo --out 'runs/a b' | tee log > out.txt; onionsort suggest R#1",
         ["onionsort", "demo", "--out", "runs/a b"]),
        (13, "onionsort demo --out 'runs/a b' | tee log > out.txt; onionsort suggest R#1",
         ["tee", "log"]),
        (13, "onionsort demo --out 'runs/a b' | tee log > out.txt; onionsort suggest R#1",
         ["onionsort", "suggest", "R#1"]),
    ]


def test_code_spans_and_fences():
    text = "a `x` b ``y ` z``\n\n```bash\n`not a span`\n```\n~~~~\n```\n~~~~\n`p\nq` `r\n\ns`\n"
    assert code_spans(text) == [(1, "x"), (1, "y ` z"), (9, "p q")]
    blocks = fenced_blocks(text)
    assert [(b.info, b.line, b.lines) for b in blocks] == [
        ("bash", 4, ("`not a span`",)), ("", 7, ("```",))]


# -- links -----------------------------------------------------------------------------------

def test_every_link_resolves_inside_the_repository():
    problems = [p for path in markdown_files(ROOT) for p in link_problems(path, ROOT)]
    assert not problems, "broken or external links:\n" + "\n".join(problems)


def test_the_readme_is_short_and_shows_pictures():
    """Issue 25's shape: a README a newcomer reads in two minutes, with at least two pictures
    that are image files in the repository (the link check above says they exist)."""
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    images = re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", text)
    assert len(images) >= 2 and all(Path(i).suffix == ".png" for i in images), images
    assert all((ROOT / i).is_file() for i in images), images


def test_github_slugs():
    assert github_slug("Closing the loop: onionsort learn, evaluate, demo") == \
        "closing-the-loop-onionsort-learn-evaluate-demo"
    assert github_slug("What's new in 0.2 (2024)?") == "whats-new-in-02-2024"
    assert github_slug("a - b_c") == "a---b_c"
    text = ("# Top\n## Run `onionsort demo`\n## Top\n## Top\nSetext one\n---\n"
            "```\n# not a heading\n```\n<a id=\"custom\"></a>\n#nohash\n")
    assert heading_anchors(text) == {"top", "run-onionsort-demo", "top-1", "top-2",
                                     "setext-one", "custom"}


def test_the_link_checker_passes_good_links(tmp_path):
    _write(tmp_path, "docs/guide.md", "# Guide\n\n## Step two: `run` it\n")
    _write(tmp_path, "docs/img/plot.png", "png")
    readme = _write(tmp_path, "README.md", (
        "# Project\n\nSee [the guide](docs/guide.md), [step two](docs/guide.md#step-two-run-it),"
        "\n![a plot](docs/img/plot.png \"title\"), [the docs](docs/) and [top](#project).\n\n"
        "[ref]: <docs/guide.md#guide>\n\n```bash\n[x](missing.md) https://example.com\n```\n"
        "`[y](missing.md)` and `https://example.com` are code.\n"))
    guide = tmp_path / "docs/guide.md"
    guide.write_text(guide.read_text() + "[back](../README.md#project)\n")
    assert link_problems(readme, tmp_path) == []
    assert link_problems(guide, tmp_path) == []


def test_the_link_checker_names_each_fault(tmp_path):
    _write(tmp_path, "docs/guide.md", "# Guide\n")
    path = _write(tmp_path, "docs/page.md", (
        "# Page\n"
        "[gone](missing.md) and ![gone](img/none.png)\n"
        "[bad anchor](guide.md#nope) [own](#nowhere)\n"
        "[out](../../outside.md)\n"
        "[web](https://example.com/x) and a bare http://example.org here\n"
        "[mail](mailto:a@b.c)\n"
        "[ref]: guide.md#also-nope\n"))
    problems = link_problems(path, tmp_path)
    assert problems == [
        "docs/page.md:5: external link https://example.com/x (the docs link only files of "
        "the repository)",
        "docs/page.md:5: external link http://example.org (the docs link only files of the "
        "repository)",
        "docs/page.md:2: link missing.md: no such file docs/missing.md",
        "docs/page.md:2: link img/none.png: no such file docs/img/none.png",
        "docs/page.md:3: link guide.md#nope: no heading with anchor #nope in docs/guide.md",
        "docs/page.md:3: link #nowhere: no heading with anchor #nowhere in docs/page.md",
        "docs/page.md:4: link ../../outside.md leaves the repository",
        "docs/page.md:6: external link mailto:a@b.c (the docs link only files of the "
        "repository)",
        "docs/page.md:7: link guide.md#also-nope: no heading with anchor #also-nope in "
        "docs/guide.md",
    ]


# -- the manual's pages ----------------------------------------------------------------------

def test_the_manual_says_what_is_true_today():
    """No page of the manual carries a date, a commit hash, an issue number or a load average
    (a study's history goes to a dated note in docs/notes/), and none is over 400 lines."""
    pages = manual_pages(ROOT)
    assert ROOT / "docs" / "architecture.md" in pages and ROOT / "docs" / "cli.md" not in pages
    assert not any("notes" in p.relative_to(ROOT / "docs").parts for p in pages)
    problems = [p for page in pages for p in page_problems(page, ROOT)]
    assert not problems, "the manual's pages:\n" + "\n".join(problems)


def test_every_note_is_dated_and_indexed():
    notes = ROOT / "docs" / "notes"
    index = (notes / "README.md").read_text(encoding="utf-8")
    for note in sorted(notes.glob("*.md")):
        if note.name == "README.md":
            continue
        date = re.match(r"(\d{4}-\d{2}-\d{2})-[a-z0-9-]+\.md$", note.name)
        assert date, f"docs/notes/{note.name}: a note's name is YYYY-MM-DD-topic.md"
        heading = note.read_text(encoding="utf-8").splitlines()[0]
        assert heading.startswith("# ") and f"({date.group(1)})" in heading, \
            f"docs/notes/{note.name}: its heading names its date, as in its file name"
        assert f"]({note.name})" in index, f"docs/notes/README.md does not list {note.name}"


STALE = """# A page

Measured on 2026-11-26 at commit 12b54eb (load average 3.2), as issue 40 asked; see #41.
On Nov 26, 2026 and in November 2026 and on 26 November 2026, `7cd142f` again.
Fine: [the note](notes/2026-11-26-study.md), [x](#5-fine-tune-on-a-mix), COCO 2017, a
pull request 12, run `onionsort demo --seed 200`, 6,500 K, a face of 1e-9, deadbeef, 1234567,
no load average on a page, at a load average of 19-21.

[def]: notes/2026-11-23-default-beta.md
"""


def test_the_page_checker_names_each_stale_mark(tmp_path):
    page = _write(tmp_path, "docs/page.md", STALE)
    problems = page_problems(page, tmp_path)
    found = [(p.split(": ", 2)[0], p.split(": ", 2)[1].split(",")[0], p.split("'")[1])
             for p in problems]
    assert found == [
        ("docs/page.md:3", "a date", "2026-11-26"),
        ("docs/page.md:3", "a commit hash", "commit 12b54eb"),
        ("docs/page.md:3", "an issue number", "issue 40"),
        ("docs/page.md:3", "an issue number", "#41"),
        ("docs/page.md:3", "a load average", "load average 3"),
        ("docs/page.md:4", "a date", "Nov 26, 2026"),
        ("docs/page.md:4", "a date", "November 2026"),
        ("docs/page.md:4", "a date", "26 November 2026"),
        ("docs/page.md:4", "a commit hash", "7cd142f"),
        ("docs/page.md:6", "an issue number", "pull request 12"),
        ("docs/page.md:7", "a load average", "load average of 1"),
    ], problems
    long = _write(tmp_path, "docs/long.md", "# Long\n" + "line\n" * 400)
    assert page_problems(long, tmp_path) == [
        "docs/long.md: 401 lines, over 400: move what is history to a dated note in docs/notes/, "
        "or split the page"]
    assert page_problems(_write(tmp_path, "docs/ok.md", "# Ok\n" + "line\n" * 399),
                         tmp_path) == []


def test_the_manual_leaves_out_the_cli_reference_and_the_notes(tmp_path):
    for name in ("docs/a.md", "docs/cli.md", "docs/notes/2026-01-02-x.md", "docs/notes/README.md",
                 "docs/figures/FIGURES.md", "README.md"):
        _write(tmp_path, name, "# x\n")
    assert [p.relative_to(tmp_path).as_posix() for p in manual_pages(tmp_path)] == [
        "docs/a.md", "docs/figures/FIGURES.md"]
