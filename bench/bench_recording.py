"""Benchmark: render speed and recording throughput, as ratios against a baseline of this run.

The baseline is a bare render: the same camera and renderer (PyBullet TinyRenderer, headless)
looking at an empty scene with one floor box. Everything else is reported as frames per second
and as a fraction of that baseline, so the numbers compare across machines.

Example
-------
    .venv/bin/python bench/bench_recording.py --frames 60
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import pybullet as p


def _rate(n: int, seconds: float) -> float:
    return n / seconds if seconds > 0 else float("inf")


def bench_empty_render(camera, n: int) -> float:
    """Frames/s of the bare baseline render."""
    from robot.camera import render
    from robot.scene import connect

    client = connect()
    vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[4, 4, 0.01], physicsClientId=client)
    p.createMultiBody(0, -1, vis, [0, 0, -0.01], physicsClientId=client)
    render(client, camera)
    t0 = time.perf_counter()
    for _ in range(n):
        render(client, camera)
    dt = time.perf_counter() - t0
    p.disconnect(physicsClientId=client)
    return _rate(n, dt)


def bench_scene_render(config, policy, initial, n: int) -> float:
    """Frames/s of the main camera rendering the full workcell (no simulation, no encoding)."""
    from robot.camera import render
    from robot.simulation import SortingSession

    with SortingSession(config, policy, initial, seed=0) as session:
        next(session.frames())
        t0 = time.perf_counter()
        for _ in range(n):
            render(session.client, config.camera, session.lighting)
        return _rate(n, time.perf_counter() - t0)


def bench_simulation(config, policy, initial) -> tuple[int, float]:
    """Frames and seconds of simulating a session with all ground truth, without writing."""
    from robot.simulation import SortingSession

    t0 = time.perf_counter()
    with SortingSession(config, policy, initial, seed=1) as session:
        n = sum(1 for _ in session.frames())
    return n, time.perf_counter() - t0


def bench_recording(config, policy, initial, folder: Path) -> tuple[int, float, int]:
    """Frames, seconds and bytes of simulating and writing one session to MCAP."""
    from recordings import SessionWriter
    from robot.camera import intrinsics
    from robot.simulation import SortingSession

    path = folder / "bench.mcap"
    t0 = time.perf_counter()
    with SortingSession(config, policy, initial, seed=1) as session, SessionWriter(
        path, {"seed": 1}, intrinsics(config.camera), intrinsics(config.inspection),
        frames_per_step=config.frames_per_step, overwrite=True,
    ) as writer:
        for frame in session.frames():
            writer.write_frame(frame)
    return writer.n_frames, time.perf_counter() - t0, path.stat().st_size


def bench_reading(path: Path) -> tuple[int, float]:
    """Frames and seconds of opening a session and decoding every colour and depth image."""
    from recordings import open_session

    t0 = time.perf_counter()
    session = open_session(path)
    for frame in session.frames():
        _ = frame.color, frame.depth
    return len(session), time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=60, help="renders per render benchmark")
    parser.add_argument("--steps", type=int, default=20, help="steps of the recorded session")
    parser.add_argument("--width", type=int, default=320)
    parser.add_argument("--height", type=int, default=240)
    args = parser.parse_args(argv)

    from robot.camera import CameraSpec
    from robot.simulation import SessionConfig, expert_model

    camera = dataclasses.replace(CameraSpec(), width=args.width, height=args.height)
    config = SessionConfig(n_steps=args.steps, camera=camera)
    policy, initial = expert_model()

    base = bench_empty_render(camera, args.frames)
    scene = bench_scene_render(config, policy, initial, args.frames)
    n_sim, t_sim = bench_simulation(config, policy, initial)
    with tempfile.TemporaryDirectory() as tmp:
        n_rec, t_rec, size = bench_recording(config, policy, initial, Path(tmp))
        n_read, t_read = bench_reading(Path(tmp) / "bench.mcap")
    sim, rec, read = _rate(n_sim, t_sim), _rate(n_rec, t_rec), _rate(n_read, t_read)

    print(f"camera {args.width}x{args.height}, TinyRenderer, {args.frames} renders; "
          f"session of {args.steps} steps x {config.frames_per_step} frames "
          f"(+ inspection view each step)")
    print(f"{'benchmark':<44}{'frames/s':>10}{'x baseline':>12}")
    rows = [
        ("baseline: empty-scene render", base),
        ("workcell render (main camera)", scene),
        ("simulate + render + ground truth", sim),
        ("simulate + render + write MCAP", rec),
        ("read MCAP + decode colour and depth", read),
    ]
    for name, fps in rows:
        print(f"{name:<44}{fps:>10.1f}{fps / base:>12.3f}")
    print(f"MCAP: {size / n_rec / 1024:.1f} KiB/frame, {size / t_rec / 2**20:.2f} MiB/s written; "
          f"writing costs {100 * (1 - rec / sim):.0f}% of the simulation's frame rate")
    print(f"12 default sessions would take about {12 * n_rec / rec:.0f} s of recording")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
