"""Benchmark: perception speed at 320x240 on 2 threads, as ratios against a baseline of this run.

The baseline is the camera itself: rendering one 320x240 frame of the workcell with PyBullet's
TinyRenderer (what the simulated camera costs). Reported: the detector's frames/s at batch 1
(end to end: letterbox, network, NMS), the state classifier's steps/s, and each as a multiple of
the camera's frame rate (> 1 means perception keeps up with the camera). The issue's floor is
30 frames/s for the detector.

Example
-------
    .venv/bin/python bench/bench_perception.py --models onionsort/models --frames 100
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def _timed(fn, n: int, warmup: int = 3) -> float:
    for _ in range(warmup):
        fn()
    t0 = time.perf_counter()
    for _ in range(n):
        fn()
    return n / (time.perf_counter() - t0)


def bench_camera(n: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Frames/s of rendering the workcell, plus one frame to feed the models."""
    from robot.camera import CameraSpec, render
    from robot.scene import OnionPool, build_workcell, connect

    client = connect()
    rng = np.random.default_rng(0)
    build_workcell(client, rng)
    OnionPool(client, 8, 0.5, rng)
    cam = CameraSpec()
    image = render(client, cam)
    return _timed(lambda: render(client, cam), n), image.rgb, image.depth


def main() -> None:
    import torch

    from onionsort.stages.models import PerceptionModels
    from state_abstraction.classifier import step_input

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", default=None, help="models folder (default: shipped)")
    parser.add_argument("--frames", type=int, default=100)
    args = parser.parse_args()
    torch.set_num_threads(2)
    camera_fps, rgb, depth = bench_camera(args.frames)
    models = PerceptionModels.load(args.models)
    detector_fps = _timed(lambda: models.detector.detect([rgb]), args.frames)
    x = step_input([rgb] * models.classifier.config.frames,
                   [depth] * models.classifier.config.frames, models.classifier.config)[None]
    classifier_sps = _timed(lambda: models.classifier.predict(x), args.frames)
    print(f"camera (baseline)   {camera_fps:7.1f} frames/s  1.00x")
    print(f"detector, batch 1   {detector_fps:7.1f} frames/s  {detector_fps / camera_fps:.2f}x "
          f"(floor 30 frames/s: {'met' if detector_fps >= 30 else 'NOT met'})")
    print(f"state classifier    {classifier_sps:7.1f} steps/s   "
          f"{classifier_sps / camera_fps:.2f}x")


if __name__ == "__main__":
    main()
