"""Tools of other projects that tests read our files with, each installed on first use into a
folder of its own, ``.test-tools/<name>``, that only its test puts on the path.

Each ``<name>.txt`` here pins one tool and what it needs beside the project's own packages;
it is installed with ``pip install --no-deps --target``, so nothing in the project's
environment changes (Label Studio's SDK and Ultralytics each pin an OpenCV or a numpy that
would replace ours). A test runs the tool in a child process whose ``PYTHONPATH`` is that
folder (:func:`run_tool`). ``python -m tests.tools`` installs them all (``.ci/run`` does).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: Where the tools are installed, one folder each (git ignores it).
ROOT = HERE.parent.parent / ".test-tools"
TOOLS = tuple(sorted(p.stem for p in HERE.glob("*.txt")))


def install(name: str) -> Path:
    """The folder holding tool ``name``, installed from ``tests/tools/<name>.txt`` unless the
    folder already holds that very list. Raises ``RuntimeError`` with pip's last words where
    it cannot be installed (no registry)."""
    wanted = (HERE / f"{name}.txt").read_bytes()
    folder = ROOT / name
    stamp = folder / ".installed"
    digest = hashlib.sha256(wanted).hexdigest()
    if stamp.is_file() and stamp.read_text() == digest:
        return folder
    tmp = ROOT / f".{name}.partial"
    shutil.rmtree(tmp, ignore_errors=True)
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet",
                           "--disable-pip-version-check", "--no-deps", "--target", str(tmp),
                           "-r", str(HERE / f"{name}.txt")], capture_output=True, text=True)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["pip failed"])[-1]
        raise RuntimeError(f"could not install the test tool {name}: {last}")
    (tmp / ".installed").write_text(digest)
    shutil.rmtree(folder, ignore_errors=True)
    tmp.replace(folder)
    return folder


def run_tool(name: str, script: str, *args: str, env: dict | None = None):
    """Run ``tests/tools/<script>`` with tool ``name`` on the path, in a child process; return
    what it printed as JSON."""
    folder = install(name)
    done = subprocess.run(
        [sys.executable, str(HERE / script), *args], capture_output=True, text=True,
        env={**os.environ, **(env or {}), "PYTHONPATH": str(folder)})
    if done.returncode != 0:
        raise AssertionError(f"{script} failed:\n{done.stdout}\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])

