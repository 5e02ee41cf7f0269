"""Make ``docs/figures/viewer.png``: a Rerun recording as Rerun's web viewer shows it.

The recording is served by the Rerun CLI (``rerun FILE.rrd --serve-web``: the web viewer over
HTTP and the recording over gRPC, on free ports), opened in headless Chromium driven by
Playwright, and photographed once the viewer has loaded and drawn it: a minute or two on a
CPU, where the viewer renders in software; the picture is taken when two pictures 5 s apart
agree. The README's picture is the evaluation recording of a demo run,
``onionsort demo --out runs/demo`` (its ``mmap-birl/evaluation.rrd``); the script makes that
run when it is missing, or with ``--no-run`` stops with one line naming the command.

Needs, beyond onionsort: Chromium (Debian: ``apt-get install chromium``) and the ``playwright``
package (``pip install playwright``; its own browsers are not needed). The PNG is written
through a temporary name as a 256-colour palette (a few hundred KB).

Usage::

    python docs/make_viewer_figure.py                    # runs/demo, docs/figures/viewer.png
    python docs/make_viewer_figure.py --rrd runs/demo/sessions.rrd --out /tmp/sessions.png
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
import urllib.request
from collections.abc import Iterator
from pathlib import Path

logger = logging.getLogger("make_viewer_figure")

#: The run the README's picture comes from, and the command that makes it.
DEMO_RUN = Path("runs/demo")
DEMO_COMMAND = ("demo",)
#: Chromium as a headless screenshot taker: no GPU (the viewer falls back to WebGL in
#: software), no network beyond the local viewer, no first-run or update chatter.
CHROMIUM_ARGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync")


class FigureError(RuntimeError):
    """What stops the picture: a missing run, tool or viewer; said in one line."""


def free_port() -> int:
    """A TCP port that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rerun_cli() -> str:
    """The ``rerun`` CLI of this Python's environment (or on PATH)."""
    local = Path(sys.executable).parent / "rerun"
    found = str(local) if local.exists() else shutil.which("rerun")
    if found is None:
        raise FigureError("the rerun CLI is not installed (pip install rerun-sdk)")
    return found


@contextlib.contextmanager
def served(rrd: Path, timeout: float = 60.0) -> Iterator[str]:
    """Serve ``rrd`` with ``rerun --serve-web`` while the block runs; yields the web viewer's
    URL with the recording's gRPC address in it (the viewer follows the recording to its
    end). The server is stopped after, its whole process group."""
    web, grpc = free_port(), free_port()
    with tempfile.TemporaryFile() as log:
        proc = subprocess.Popen(
            [rerun_cli(), str(rrd), "--serve-web", "--web-viewer-port", str(web), "--port",
             str(grpc), "--bind", "127.0.0.1"],
            stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        try:
            deadline = time.monotonic() + timeout
            while not _answers(f"http://127.0.0.1:{web}/"):
                if proc.poll() is not None or time.monotonic() > deadline:
                    log.seek(0)
                    said = log.read().decode(errors="replace").strip().splitlines()
                    raise FigureError(f"rerun --serve-web did not start for {rrd}: "
                                      f"{said[-1] if said else 'no output'}")
                time.sleep(0.5)
            proxy = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc}/proxy", safe="")
            yield f"http://127.0.0.1:{web}/?url={proxy}"
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


def _answers(url: str) -> bool:
    """Whether an HTTP server answers at ``url``."""
    try:
        with urllib.request.urlopen(url, timeout=2):
            return True
    except OSError:
        return False


def screenshot(url: str, *, size: tuple[int, int] = (1600, 900), wait_s: float = 40.0,
               settle_s: float = 240.0, chromium: str = "/usr/bin/chromium") -> bytes:
    """The PNG of the page at ``url`` in headless Chromium of window ``size``, once the viewer
    has loaded the recording: at least ``wait_s`` seconds after the page loaded, then when two
    pictures 5 s apart are equal (the viewer has streamed and drawn everything), or after
    ``settle_s`` seconds at most (with a warning)."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise FigureError("the playwright package is not installed (pip install playwright)") \
            from None
    if not Path(chromium).exists():
        raise FigureError(f"no Chromium at {chromium} (Debian: apt-get install chromium)")
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=chromium, args=list(CHROMIUM_ARGS))
        try:
            page = browser.new_page(viewport={"width": size[0], "height": size[1]})
            page.goto(url, wait_until="load", timeout=120_000)
            start = time.monotonic()
            page.wait_for_timeout(wait_s * 1000)
            last = page.screenshot()
            while time.monotonic() - start < settle_s:
                page.wait_for_timeout(5000)
                now = page.screenshot()
                if now == last:
                    logger.info("the viewer settled after %.0f s", time.monotonic() - start)
                    return now
                last = now
            logger.warning("the viewer was still drawing after %.0f s; taking the picture",
                           settle_s)
            return last
        finally:
            browser.close()


def save_png(png: bytes, path: Path, colors: int = 256) -> Path:
    """Write ``png`` to ``path`` as an optimized palette PNG through a temporary name."""
    from make_figures import save_png as save_image  # docs/, this script's folder
    from PIL import Image

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return save_image(Image.open(io.BytesIO(png)), Path(path), colors=colors)


def ensure_demo(run: Path, *, allow_run: bool = True) -> Path:
    """The evaluation recording of the demo in ``run``, made by ``onionsort demo --out run``
    if missing (resumed if interrupted)."""
    rrd = run / "mmap-birl" / "evaluation.rrd"
    if (run / "results.json").exists() and rrd.exists():
        return rrd
    command = ["onionsort", *DEMO_COMMAND, "--out", str(run)]
    if run.is_dir() and any(run.iterdir()):  # an interrupted demo: finish it
        command.append("--resume")
    if not allow_run:
        raise FigureError(f"no demo in {run}; make it with `{' '.join(command)}`")
    logger.info("making the run: %s", " ".join(command))
    done = subprocess.run([sys.executable, "-m", "onionsort.cli", *command[1:]])
    if done.returncode != 0 or not rrd.exists():
        raise FigureError(f"`{' '.join(command)}` failed (exit {done.returncode})")
    return rrd


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="make_viewer_figure", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--run", type=Path, default=DEMO_RUN,
                        help="the demo run whose mmap-birl/evaluation.rrd is shown (made when "
                             "missing)")
    parser.add_argument("--rrd", type=Path, default=None,
                        help="show this recording instead of the demo's evaluation")
    parser.add_argument("--out", type=Path, default=Path("docs/figures/viewer.png"))
    parser.add_argument("--size", default="1600x900", help="the browser window, WxH (1600x900)")
    parser.add_argument("--wait", type=float, default=40.0,
                        help="seconds the viewer loads at least before the picture (40)")
    parser.add_argument("--settle", type=float, default=240.0,
                        help="seconds at most until the viewer stops drawing (240)")
    parser.add_argument("--chromium", default="/usr/bin/chromium")
    parser.add_argument("--no-run", action="store_true",
                        help="fail, naming the command, instead of making a missing run")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        print(f"make_viewer_figure: error: --size must be WxH, e.g. 1600x900; got "
              f"{args.size!r}", file=sys.stderr)
        return 2
    try:
        if args.rrd is not None:
            if not args.rrd.is_file():
                raise FigureError(f"no recording {args.rrd}")
            rrd = args.rrd
        else:
            rrd = ensure_demo(args.run, allow_run=not args.no_run)
        with served(rrd) as url:
            logger.info("%s served at %s", rrd, url)
            png = screenshot(url, size=(width, height), wait_s=args.wait,
                             settle_s=args.settle, chromium=args.chromium)
        path = save_png(png, args.out)
    except FigureError as exc:
        print(f"make_viewer_figure: error: {exc}", file=sys.stderr)
        return 2
    print(f"{path}: {path.stat().st_size / 1024:.0f} KB, {width} x {height} px, of {rrd}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
