"""The import rules of docs/architecture.md, checked by parsing every module's imports.

Each package may import the standard library, itself, and what its row of the table allows;
``irl`` stays a numpy/scipy library (its optional compiled backend, one module, may import
numba inside a function: ``irl`` imports without it, tests/irl/test_numba.py checks), and the
packages below ``onionsort`` never import each other except ``irl`` (and ``perception``'s
training loop and checkpoint files, which ``state_abstraction`` shares). Imports inside
functions count too.
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
                  "scipy", "torch", "matplotlib", "tqdm", "pybullet", "ray", "threadpoolctl"},
}


#: module -> what it may import beyond its package's rule: optional backends, imported lazily.
OPTIONAL: dict[str, set[str]] = {
    "irl/_numba.py": {"numba"},
    "irl/posterior.py": {"mici"},
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


@pytest.mark.parametrize("package", sorted(RULES))
def test_every_module_keeps_its_package_import_rule(package):
    assert violations(package) == []


def test_the_check_catches_a_forbidden_import_even_inside_a_function(tmp_path):
    (tmp_path / "robot").mkdir()
    (tmp_path / "robot" / "ok.py").write_text("import numpy\nfrom irl.mdp import TabularMDP\n")
    assert violations("robot", tmp_path) == []
    (tmp_path / "robot" / "bad.py").write_text(
        "import os\n\ndef f():\n    from recordings.reader import open_session\n")
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
