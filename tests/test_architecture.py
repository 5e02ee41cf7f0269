"""The import rules of docs/architecture.md, checked by parsing every module's imports.

Each package may import the standard library, itself, and what its row of the table allows;
``irl`` stays a numpy/scipy library (its optional compiled backend, one module, may import
numba inside a function: ``irl`` imports without it, tests/irl/test_numba.py checks), and the
packages below ``onionsort`` never import each other except ``irl`` (and ``perception``'s
training loop and checkpoint files, which ``state_abstraction`` shares). Imports inside
functions count too. No module takes part in an import circle (a function's lazy import is
still an edge), and no module of the packages is over 700 lines.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: package -> the non-standard top-level modules it may import (itself always).
RULES: dict[str, set[str]] = {
    "irl": {"numpy", "scipy"},
    "perception": {"torch", "torchvision", "cv2", "numpy"},
    "state_abstraction": {"torch", "cv2", "numpy", "irl", "perception"},
    "recordings": {"mcap", "mcap_protobuf", "foxglove_schemas_protobuf", "rosbags", "rerun",
                   "cv2", "numpy", "irl", "yaml"},
    "robot": {"pybullet", "cv2", "gymnasium", "numpy", "irl"},
    "onionsort": {"irl", "perception", "state_abstraction", "recordings", "robot", "numpy",
                  "scipy", "torch", "matplotlib", "tqdm", "pybullet", "ray", "threadpoolctl",
                  "rerun"},
}


#: module -> what it may import beyond its package's rule: optional backends, imported lazily.
OPTIONAL: dict[str, set[str]] = {
    "irl/_numba.py": {"numba"},
    "irl/posterior/chains.py": {"mici"},
    # one BLAS thread inside a large MDP's solve (a core dependency, imported when first used)
    "irl/_blas.py": {"threadpoolctl"},
}


def imported_modules(source: str) -> set[str]:
    """Top-level names of every absolute import in a module (relative imports stay inside)."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def violations(package: str, root: Path = ROOT) -> list[str]:
    """``module: name`` for every import of ``package``'s modules that its rule forbids."""
    allowed = RULES[package] | {package} | set(sys.stdlib_module_names) | {"__future__"}
    out = []
    for path in sorted((root / package).rglob("*.py")):
        extra = OPTIONAL.get(path.relative_to(root).as_posix(), set())
        for name in sorted(imported_modules(path.read_text()) - allowed - extra):
            out.append(f"{path.relative_to(root)}: {name}")
    return out


#: the longest a module of the packages may be, in lines
MAX_LINES = 700


def module_names(root: Path = ROOT) -> dict[str, Path]:
    """Every module of the packages of :data:`RULES` by dotted name (a package by its own)."""
    names = {}
    for package in RULES:
        for path in (root / package).rglob("*.py"):
            parts = path.relative_to(root).with_suffix("").parts
            names[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return names


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """``module -> the modules of the packages it imports``, anywhere in its source.

    ``from a.b import c`` is an edge to ``a.b.c`` where that is a module, else to ``a.b``;
    relative imports are resolved against the importing module's package.
    """
    names = module_names(root)

    def known(name: str) -> str | None:
        while name and name not in names:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for name, path in names.items():
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets.update(known(a.name) for a in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[:len(package) - node.level + 1]
                                    + ([node.module] if node.module else []))
                targets.update(known(f"{base}.{a.name}") if f"{base}.{a.name}" in names
                               else known(base) for a in node.names)
        graph[name] = targets - {None, name}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm,
    iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, edges = work[-1]
            for nxt in edges:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph.get(nxt, ())))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return sorted(found)


def test_no_module_takes_part_in_an_import_circle():
    assert circles(import_graph()) == []


def test_the_circle_check_finds_a_lazy_import_circle_and_resolves_relative_imports(tmp_path):
    (tmp_path / "irl" / "sub").mkdir(parents=True)
    (tmp_path / "irl" / "__init__.py").write_text("")
    (tmp_path / "irl" / "sub" / "__init__.py").write_text("from .a import f\n")
    (tmp_path / "irl" / "sub" / "a.py").write_text("from irl.sub import b\n")
    (tmp_path / "irl" / "sub" / "b.py").write_text("def g():\n    from . import c\n")
    (tmp_path / "irl" / "sub" / "c.py").write_text("from ..sub.a import f\n")
    (tmp_path / "irl" / "d.py").write_text("import irl.sub.a\n")
    graph = import_graph(tmp_path)
    assert graph["irl.d"] == {"irl.sub.a"}
    assert circles(graph) == [["irl.sub.a", "irl.sub.b", "irl.sub.c"]]
    (tmp_path / "irl" / "sub" / "b.py").write_text("def g():\n    pass\n")
    assert circles(import_graph(tmp_path)) == []


def test_no_module_is_over_the_line_limit():
    assert {name: n for name, path in module_names().items()
            if (n := len(path.read_text().splitlines())) > MAX_LINES} == {}


@pytest.mark.parametrize("package", sorted(RULES))
def test_every_module_keeps_its_package_import_rule(package):
    assert violations(package) == []


def test_the_check_catches_a_forbidden_import_even_inside_a_function(tmp_path):
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "ok.py").write_text("import numpy\nfrom irl.mdp import TabularMDP\n")
    assert violations("robot", tmp_path) == []
    (tmp_path / "robot" / "bad.py").write_text(
        "import os\n\ndef f():\n    from recordings.session.reader import open_session\n")
    (tmp_path / "robot" / "worse.py").write_text("import state_abstraction.classifier as c\n")
    assert violations("robot", tmp_path) == ["robot/bad.py: recordings",
                                             "robot/worse.py: state_abstraction"]


def test_the_rules_match_the_table_in_the_architecture_doc():
    doc = (ROOT / "docs" / "architecture.md").read_text()
    for package, allowed in RULES.items():
        row = next((line for line in doc.splitlines() if line.startswith(f"| `{package}/`")),
                   None)
        assert row is not None, f"docs/architecture.md has no row for {package}/"
        may_import = row.split("|")[3]
        for name in allowed - {"numpy"}:
            assert f"`{name}`" in may_import or name in may_import, (package, name)
