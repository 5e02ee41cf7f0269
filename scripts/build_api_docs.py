"""Build the API reference of ``irl`` from its docstrings with pdoc, into build/api/.

Every public module of ``irl`` (each module whose path has no part starting with ``_``)
becomes a page, showing the names of its ``__all__`` with their numpydoc sections rendered.
Any warning pdoc gives (a module that fails to import, a docstring or an annotation it cannot
read) fails the build: each is printed on one line and the exit code is 1
(tests/test_api_docs.py builds it the same way). The pages are written to a temporary folder
and renamed into place when complete; build/ is not committed.

Examples
--------
    pip install -e ".[dev]"                      # pdoc is in the dev extra
    python scripts/build_api_docs.py             # writes build/api/ (open build/api/irl.html)
    python scripts/build_api_docs.py --out build/api-irl
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import warnings
from pathlib import Path

__all__ = ["OUT", "PACKAGES", "build", "main", "public_modules"]

ROOT = Path(__file__).resolve().parent.parent
#: the packages documented
PACKAGES = ("irl",)
#: where the reference goes by default
OUT = ROOT / "build" / "api"


def public_modules() -> list[str]:
    """The modules of :data:`PACKAGES` that are documented: each package and its submodules,
    but none whose dotted name has a part starting with ``_``.

    Returns
    -------
    list of str
        Dotted module names, sorted.
    """
    import importlib
    import pkgutil

    names = []
    for package in PACKAGES:
        module = importlib.import_module(package)
        names += [package, *(m.name for m in pkgutil.walk_packages(module.__path__,
                                                                   f"{package}."))]
    return sorted(n for n in names if not any(p.startswith("_") for p in n.split(".")))


def _specs() -> list[str]:
    """The fewest module names whose pdoc walks cover :func:`public_modules`: pdoc walks a
    package into the submodules its ``__all__`` names (all of them where it has none), so
    ``irl`` alone would leave out ``irl.inference`` and the rest; naming a module twice is a
    warning."""
    from pdoc.extract import walk_specs

    specs: list[str] = []
    covered: set[str] = set()
    for name in public_modules():
        if name not in covered:
            specs.append(name)
            covered.update(walk_specs([name]))
    return specs


def build(out: Path) -> list[str]:
    """Render :func:`public_modules` into the folder ``out`` (replaced if it exists).

    Parameters
    ----------
    out : Path
        The folder to write; its parent is created if need be.

    Returns
    -------
    list of str
        The warnings pdoc gave, one line each (empty when the build is clean). The folder is
        written either way.
    """
    import pdoc
    import pdoc.render

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    pdoc.render.configure(docformat="numpy", show_source=False, search=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}-", dir=out.parent))
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            pdoc.pdoc(*_specs(), output_directory=tmp)
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return [" ".join(f"{w.category.__name__}: {w.message}".split()) for w in caught]


def main(argv: list[str] | None = None) -> int:
    """Build the reference; 1 if pdoc warned (each warning on one line on stderr), else 0.

    Parameters
    ----------
    argv : list of str, optional
        The command line (``--out DIR``); ``sys.argv[1:]`` by default.

    Returns
    -------
    int
        The exit code.
    """
    parser = argparse.ArgumentParser(prog="build_api_docs.py",
                                     description="Build the irl API reference with pdoc.")
    parser.add_argument("--out", type=Path, default=OUT,
                        help="the folder to write (default: build/api)")
    args = parser.parse_args(argv)
    try:
        import pdoc  # noqa: F401
    except ImportError:
        print("build_api_docs.py: pdoc is not installed: pip install -e '.[dev]'",
              file=sys.stderr)
        return 2
    problems = build(args.out)
    for line in problems:
        print(f"build_api_docs.py: {line}", file=sys.stderr)
    if problems:
        return 1
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    # document this checkout's irl, not another installed copy
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
