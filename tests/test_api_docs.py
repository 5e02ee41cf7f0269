"""The reference of ``irl``: every public function and class has numpydoc ``Parameters`` and
``Returns`` sections (``Attributes`` for a class) naming what it takes and gives, docs/api.md
names every name ``irl`` exports, and the reference pdoc generates builds with no warning.

Public means listed in the ``__all__`` of a module of ``irl`` whose path has no part starting
with ``_``. A function's ``Parameters`` names each of its parameters (``*args`` and
``**kwargs`` included, by their names); its ``Returns`` (or ``Yields``) is required unless it is
annotated ``-> None``. A class's ``Attributes`` is required, and each parameter of its
constructor is named in its ``Parameters`` or its ``Attributes`` (a dataclass's fields are
both); an exception or a warning class, whose attributes are its message, needs neither.
"""

from __future__ import annotations

import enum
import importlib
import inspect
import os
import re
import sys
from pathlib import Path

import pytest

import irl

ROOT = Path(__file__).resolve().parent.parent
_SECTION = re.compile(r"^(?P<title>[A-Z][A-Za-z ]+)\n-{3,}\n", flags=re.M)


def _load_builder():
    spec = importlib.util.spec_from_file_location("build_api_docs",
                                                  ROOT / "scripts" / "build_api_docs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


builder = _load_builder()  # scripts/build_api_docs.py
public_modules = builder.public_modules


def public_objects() -> dict[str, object]:
    """``qualified name -> object`` of every public function and class, each once (under the
    first module that lists it)."""
    seen: dict[int, tuple[str, object]] = {}
    for name in public_modules():
        module = importlib.import_module(name)
        for attr in getattr(module, "__all__", ()):
            obj = getattr(module, attr)
            if inspect.isfunction(obj) or inspect.isclass(obj):
                seen.setdefault(id(obj), (f"{name}.{attr}", obj))
    return dict(seen.values())


def sections(doc: str | None) -> dict[str, list[str]]:
    """The numpydoc sections of ``doc`` (cleaned), each as the names it lists: the part before
    `` : `` of each line at the section's own indentation, split at commas."""
    doc = inspect.cleandoc(doc or "")
    found = {}
    matches = list(_SECTION.finditer(doc))
    for i, m in enumerate(matches):
        body = doc[m.end():matches[i + 1].start() if i + 1 < len(matches) else len(doc)]
        names = []
        for line in body.splitlines():
            if line.strip() and not line.startswith((" ", "\t")):
                head = line.split(" : ")[0].strip()
                names += [n.strip().lstrip("*") for n in head.split(",") if n.strip()]
        found[m.group("title")] = names
    return found


def _parameters(func) -> list[str]:
    try:
        signature = inspect.signature(func)
    except (TypeError, ValueError):
        return []
    return [p.name for p in signature.parameters.values() if p.name not in ("self", "cls")]


def docstring_problems(name: str, obj) -> list[str]:
    """What the numpydoc docstring of ``obj`` lacks, each naming ``name``."""
    doc = inspect.getdoc(obj)
    if not doc:
        return [f"{name}: no docstring"]
    found = sections(doc)
    problems = []
    if inspect.isclass(obj):
        if issubclass(obj, BaseException):
            return []
        if "Attributes" not in found:
            problems.append(f"{name}: no Attributes section")
        named = set(found.get("Parameters", [])) | set(found.get("Attributes", []))
        if not issubclass(obj, enum.Enum):
            for p in _parameters(obj):
                if p not in named:
                    problems.append(f"{name}: constructor parameter {p!r} is in neither "
                                    "Parameters nor Attributes")
        return problems
    params = _parameters(obj)
    if params and "Parameters" not in found:
        problems.append(f"{name}: no Parameters section")
    elif params:
        problems += [f"{name}: parameter {p!r} not in Parameters" for p in params
                     if p not in found["Parameters"]]
    returns = inspect.signature(obj).return_annotation
    if returns not in (None, "None") and not ({"Returns", "Yields"} & set(found)):
        problems.append(f"{name}: no Returns section")
    return problems


def test_the_checker_finds_what_it_should():
    def good(a, b=1, *, c=None) -> int:
        """Add.

        Parameters
        ----------
        a, b : int
        c : int, optional
            Ignored.

        Returns
        -------
        int
        """

    def bad(a, b) -> int:
        """Add.

        Parameters
        ----------
        a : int
        """

    class Plain:
        """A thing.

        Parameters
        ----------
        x : int
        """

        def __init__(self, x, y):
            self.x = x

    assert docstring_problems("good", good) == []
    assert docstring_problems("bad", bad) == ["bad: parameter 'b' not in Parameters",
                                              "bad: no Returns section"]
    assert docstring_problems("Plain", Plain) == [
        "Plain: no Attributes section",
        "Plain: constructor parameter 'y' is in neither Parameters nor Attributes"]
    assert docstring_problems("err", irl.NotFittedError) == []


def test_the_public_api_is_found():
    objects = public_objects()
    assert {"irl.MMAPBIRL", "irl.TaskDescription", "irl.register_learner",
            "irl.posterior.sample_posterior", "irl.inference.forward_backward"} <= set(objects)
    assert not any("._" in name for name in objects)


def test_every_public_function_and_class_has_its_numpydoc_sections():
    problems = [p for name, obj in public_objects().items() for p in docstring_problems(name, obj)]
    assert not problems, f"{len(problems)} docstring(s) short of numpydoc:\n" + "\n".join(problems)


def test_the_api_page_names_everything_irl_exports():
    text = (ROOT / "docs" / "api.md").read_text()
    missing = [n for n in irl.__all__ if not re.search(rf"\b{re.escape(n)}\b", text)]
    missing += [f"domains.{n}" for n in irl.domains.__all__
                if not re.search(rf"\b{re.escape(n)}\b", text)]
    assert not missing, f"docs/api.md never mentions: {', '.join(missing)}"


def test_the_registrys_example_runs():
    import doctest

    import irl.learners.registry

    failures, tried = doctest.testmod(irl.learners.registry, verbose=False)
    assert tried >= 3 and failures == 0
    assert "map-birl-b3" not in irl.LEARNERS


def test_the_api_pages_demonstration_example_runs():
    text = (ROOT / "docs" / "api.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", text, flags=re.S)
                 if "from_pairs" in b)
    scope: dict = {}
    exec(compile(block, "docs/api.md", "exec"), scope)
    assert scope["demo"].observations == (13, None, 17, 12)


def test_the_api_reference_builds_without_a_warning(tmp_path):
    """pdoc (the ``dev`` extra) renders every public module of ``irl``; any warning it gives
    (a module that fails to import, an annotation or a docstring it cannot read) fails."""
    if importlib.util.find_spec("pdoc") is None:
        if os.environ.get("ONIONSORT_REQUIRE_TOOLS"):
            pytest.fail("pdoc is missing: pip install -e '.[dev]'")
        pytest.skip("pdoc is not installed (pip install -e '.[dev]')")
    out = tmp_path / "api"
    warnings_given = builder.build(out)
    assert warnings_given == []
    pages = {p.relative_to(out).as_posix() for p in out.rglob("*.html")}
    expected = {name.replace(".", "/") + ".html" for name in public_modules()}
    assert expected <= pages, sorted(expected - pages)
    page = (out / "irl.html").read_text()
    assert "MMAPBIRL" in page and "Parameters" in page
    assert builder.main(["--out", str(tmp_path / "again")]) == 0
