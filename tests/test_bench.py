"""bench/ holds benchmarks: each a script a maintainer runs again, whose figures
docs/performance.md quotes. docs/performance.md names every one; no test imports bench/; and
nothing names a bench script that has gone, except a note that says which commit holds it."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
#: A frozen copy of an earlier implementation that bench/bench_irl.py times the library
#: against: a module, not a script.
MODULES = {"irl_baseline.py"}
#: Where a bench script may be named: the code, the tests, the docs, the README, CI.
SEARCHED = ("README.md", "pyproject.toml", "docs", "irl", "onionsort", "perception",
            "recordings", "robot", "state_abstraction", "scripts", "tests", "bench", "examples",
            ".ci")
_NAMED = re.compile(r"bench/([A-Za-z0-9_]+\.py)")


def _scripts() -> list[Path]:
    return sorted(p for p in BENCH.glob("*.py") if p.name not in MODULES)


def _texts():
    for name in SEARCHED:
        path = ROOT / name
        files = [path] if path.is_file() else sorted(
            p for p in path.rglob("*") if p.is_file() and p.suffix in (".py", ".md", ".toml", "")
            and "__pycache__" not in p.parts) if path.is_dir() else []
        for f in files:
            try:
                yield f, f.read_text(encoding="utf-8")
            except UnicodeDecodeError:
                continue


def test_performance_md_names_every_bench_script():
    text = (ROOT / "docs" / "performance.md").read_text(encoding="utf-8")
    missing = [p.name for p in sorted(BENCH.glob("*.py")) if f"bench/{p.name}" not in text]
    assert not missing, f"docs/performance.md does not name {missing}"
    assert _scripts(), "bench/ holds no benchmark"


def test_no_test_imports_bench():
    found = []
    for path in sorted((ROOT / "tests").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            found += [f"{path.relative_to(ROOT)}:{node.lineno}: {n}" for n in names
                      if n == "bench" or n.startswith("bench.")]
    assert not found, "tests import bench/: " + "; ".join(found)


def test_nothing_names_a_bench_script_that_has_gone():
    """Outside docs/notes/ every ``bench/<NAME>.py`` named exists; a note may name one that has
    gone only with the commit that holds it (``git show COMMIT:bench/<NAME>.py``)."""
    wrong = []
    for path, text in _texts():
        rel = path.relative_to(ROOT).as_posix()
        for m in _NAMED.finditer(text):
            name = m.group(1)
            if (BENCH / name).is_file():
                continue
            held = re.search(rf"git show [0-9a-f]{{7,40}}:bench/{re.escape(name)}", text)
            if rel.startswith("docs/notes/") and held:
                continue
            line = text.count("\n", 0, m.start()) + 1
            wrong.append(f"{rel}:{line}: bench/{name}")
    assert not wrong, "names of bench scripts that have gone:\n" + "\n".join(sorted(set(wrong)))


@pytest.mark.parametrize("script", _scripts(), ids=lambda p: p.name)
def test_every_bench_script_runs_its_help(script):
    """Each benchmark at least imports and parses its options (its own run takes minutes)."""
    done = subprocess.run([sys.executable, str(script), "--help"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("usage:"), done.stdout[:200]
