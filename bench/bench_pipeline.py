"""Benchmark: the parallel stages on 2 workers against 1, measured in the same run.

Each piece of work runs as a whole command (``python -m onionsort.cli ...``), alternating 1
worker and 2 workers ``--repeats`` times; the bench prints each one's median wall time and the
ratio (1 worker / 2 workers: the speed-up). The work, and the floors of issue 23:

==================================  =====
work                                floor
==================================  =====
``record --sessions 4``             1.6x
``perceive`` of 4 sessions          1.6x
``demo --quick --repeats 2``        1.4x
==================================  =====

One worker runs the pieces in the command's own process (torch on its default threads); two
run them on two worker processes of one thread each. The machine's other load counts against
both alike.

Example
-------
    python bench/bench_pipeline.py                # about 20 minutes on 2 cores
    python bench/bench_pipeline.py --repeats 1 --only record,perceive
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RECORD = ["record", "--sessions", "4", "--steps-per-session", "20", "--seed", "11"]
DEMO = ["demo", "--quick", "--repeats", "2", "--seed", "7"]
FLOORS = {"record": 1.6, "perceive": 1.6, "demo": 1.4}


def onionsort(*argv: str) -> float:
    """Run ``onionsort ARGV``; its wall time in seconds."""
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "onionsort.cli", *argv], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def work(name: str, tmp: Path, workers: int, k: int, recorded: Path) -> float:
    out = tmp / f"{name}-{workers}-{k}"
    if name == "record":
        return onionsort(*RECORD, "--workers", str(workers), "--out", str(out))
    if name == "perceive":
        shutil.copytree(recorded, out)
        return onionsort("perceive", *map(str, sorted(out.glob("*.mcap"))), "--workers",
                         str(workers))
    return onionsort(*DEMO, "--workers", str(workers), "--out", str(out))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=2, help="runs of each (2)")
    parser.add_argument("--only", default="record,perceive,demo",
                        help="comma-separated: record, perceive, demo")
    args = parser.parse_args()
    names = [n for n in args.only.split(",") if n]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        recorded = tmp / "recorded"
        onionsort(*RECORD, "--out", str(recorded))  # the sessions perceive reads
        print(f"{'work':<10}{'1 worker (s)':>14}{'2 workers (s)':>15}{'ratio':>8}{'floor':>7}")
        for name in names:
            times: dict[int, list[float]] = {1: [], 2: []}
            for k in range(args.repeats):
                for workers in (1, 2):
                    times[workers].append(work(name, tmp, workers, k, recorded))
            one, two = statistics.median(times[1]), statistics.median(times[2])
            print(f"{name:<10}{one:>14.1f}{two:>15.1f}{one / two:>7.2f}x"
                  f"{FLOORS[name]:>6.1f}x", flush=True)


if __name__ == "__main__":
    main()
