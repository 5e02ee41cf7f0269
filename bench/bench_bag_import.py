"""Benchmark: importing a robot's bag against importing the same frames as an MP4.

A 640x480, 30 fps, 2-minute stream (3,600 frames: a moving scene drawn with OpenCV) is written
twice: as a rosbag2 folder (MCAP storage, ``sensor_msgs/CompressedImage`` JPEG, quality 90, the
form a camera driver's ``image_transport`` records, written by ``rosbags``) and as an MP4
(``mp4v``, the codec this OpenCV build writes). Each is imported with a 2-second step clock
(``onionsort import SOURCE --step-seconds 2``, the stage function, in this process), the two
alternating ``--repeats`` times; the bench prints each one's median rate in source frames a
second and the ratio bag / MP4.

Why the bag is faster: with a clock, or a step topic, the bag import decodes only the frames a
step keeps (3 of every 60), while a video must be decoded frame by frame. With perceived
segmentation both decode every frame.

Example
-------
    python bench/bench_bag_import.py             # 3,600 frames, 3 repeats (about 2 minutes)
    python bench/bench_bag_import.py --seconds 20 --repeats 1
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np


def frames(n: int, width: int = 640, height: int = 480):
    """``n`` RGB frames of a scene that moves: a gradient, a belt of stripes, three discs."""
    yy, xx = np.mgrid[0:height, 0:width]
    base = np.stack([(xx * 255 // width), (yy * 255 // height),
                     np.full_like(xx, 90)], axis=2).astype(np.uint8)
    for i in range(n):
        img = base.copy()
        shift = (i * 4) % 64
        img[height // 2 - 40: height // 2 + 40, :, :] = np.where(
            ((xx[:80] + shift) // 32 % 2)[..., None] == 0, 60, 120).astype(np.uint8)
        for k in range(3):
            x = int((i * (3 + k) + 200 * k) % width)
            cv2.circle(img, (x, height // 2), 22, (200, 180 - 50 * k, 40 + 60 * k), -1)
        yield img


def write_bag(path: Path, n: int, fps: float) -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    msgtype = "sensor_msgs/msg/CompressedImage"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection("/camera/color/image_raw/compressed", msgtype,
                                           typestore=store)
        for i, rgb in enumerate(frames(n)):
            t = 1_700_000_000 * 10**9 + round(i * 1e9 / fps)
            _, buf = cv2.imencode(".jpg", rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
            stamp = types["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
            header = types["std_msgs/msg/Header"](stamp=stamp, frame_id="camera")
            msg = types[msgtype](header=header, format="jpeg", data=buf.ravel())
            writer.write(connection, t, store.serialize_cdr(msg, msgtype))
    return path


def timed_import(source: Path, out: Path) -> float:
    from onionsort.stages import ImportConfig, import_video

    t0 = time.perf_counter()
    import_video(ImportConfig(out=out, video=source, step_seconds=2.0))
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=120.0, help="stream length (120)")
    parser.add_argument("--fps", type=float, default=30.0, help="frame rate (30)")
    parser.add_argument("--repeats", type=int, default=3, help="imports of each (3)")
    args = parser.parse_args()
    from recordings import write_video

    n = round(args.seconds * args.fps)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        bag = write_bag(tmp / "bag", n, args.fps)
        video = write_video(tmp / "stream.mp4", frames(n), args.fps)
        size = sum(f.stat().st_size for f in bag.iterdir())
        print(f"{n} frames of 640x480 at {args.fps:g} fps: bag {size / 1e6:.0f} MB "
              f"(JPEG), MP4 {video.stat().st_size / 1e6:.0f} MB (mp4v)")
        times: dict[str, list[float]] = {"bag": [], "mp4": []}
        for r in range(args.repeats):
            for name, source in (("bag", bag), ("mp4", video)):
                times[name].append(timed_import(source, tmp / f"{name}-{r}.mcap"))
        rate = {k: n / statistics.median(v) for k, v in times.items()}
        for k in ("bag", "mp4"):
            print(f"import {k:4s}: {rate[k]:7.0f} frames/s (median of {args.repeats}; "
                  f"{', '.join(f'{t:.1f}' for t in times[k])} s)")
        print(f"ratio bag / mp4: {rate['bag'] / rate['mp4']:.2f} (floor 1.0)")


if __name__ == "__main__":
    main()
