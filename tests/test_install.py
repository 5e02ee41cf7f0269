"""The README's install instructions are the ones CI runs, and say what pyproject.toml says."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def readme_install_line(text: str) -> str:
    """The first ``pip install`` command of the README's Quick start block, comment dropped."""
    quick = text.split("## Quick start", 1)[1]
    block = re.search(r"```bash\n(.*?)```", quick, flags=re.S).group(1)
    line = next(x for x in block.splitlines() if x.lstrip().startswith("pip install"))
    return line.split("  #", 1)[0].strip()


def test_ci_installs_with_the_readmes_own_line():
    line = readme_install_line((ROOT / "README.md").read_text())
    assert line.startswith('pip install -e ".[dev]"')
    ci = [x.strip() for x in (ROOT / ".ci" / "run").read_text().splitlines()]
    assert line in ci, f".ci/run does not install with the README's line: {line}"


def test_the_install_line_is_found_where_the_readme_puts_it():
    text = "intro\n## Quick start\n\n```bash\npip install -e .   # install\nonionsort demo\n```\n"
    assert readme_install_line(text) == "pip install -e ."


def test_the_readme_states_the_python_and_torch_that_pyproject_requires():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    oldest = re.fullmatch(r">=\s*(3\.\d+)", project["requires-python"]).group(1)
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert f"Python {oldest} or newer" in readme
    pins = dict(re.fullmatch(r"(torch|torchvision)==(\S+)", d).groups()
                for d in project["dependencies"] if re.match(r"torch(vision)?==", d))
    assert set(pins) == {"torch", "torchvision"}
    # the README names the pins, and its command for another build of torch installs them
    assert f"`torch=={pins['torch']}` and `torchvision=={pins['torchvision']}`" in readme
    pinned = f"pip install torch=={pins['torch']} torchvision=={pins['torchvision']} --index-url"
    assert pinned in readme, f"the README's command for a CPU-only torch must install {pinned}"
