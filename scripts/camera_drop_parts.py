"""Which part of another camera costs the detector its camera-view mAP.

``eval-perception --camera-shift S`` sees each session through a camera of its own
(``onionsort.stages.calibrate.SessionCameras``). This study splits each of those cameras in two
and measures the detector's camera-view mAP@0.5 through each part alone:

- ``colour``: the camera's white balance, exposure and tone curve, with a sharp lens, no noise
  and no JPEG;
- ``degradation``: its defocus, sensor noise and JPEG, with the renderer's colour;
- ``full``: the whole camera, as ``eval-perception`` has it.

It gives each figure twice: as ``eval-perception`` counts it (the mean of the good and the
blemished class's AP), and class-agnostic (every box one class: does it find the onions, apart
from calling them good or blemished, which the inspection classifier does downstream).

Usage::

    python scripts/camera_drop_parts.py --data runs/d9102 --seeds 9301,9302,9303 \
        --models shipped --models runs/m-d1 --out runs/parts.json
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import torch

from onionsort.perception_models import PerceptionModels
from onionsort.stages.base import write_json
from onionsort.stages.calibrate import SessionCameras, detector_map
from perception.camera_shift import REFERENCE_TEMPERATURE_K

PARTS = ("full", "colour", "degradation")


@dataclasses.dataclass(frozen=True)
class PartCameras:
    """``SessionCameras(seed)`` with only ``part`` of each camera kept."""

    seed: int
    part: str

    def __call__(self, image: np.ndarray, record: dict) -> np.ndarray:
        cam = SessionCameras(self.seed).camera(record)
        if self.part == "colour":
            cam = dataclasses.replace(cam, defocus_px=0.0, noise=0.0, jpeg_quality=0)
        elif self.part == "degradation":
            cam = dataclasses.replace(cam, temperature_k=REFERENCE_TEMPERATURE_K,
                                      exposure_ev=0.0, gamma=1.0)
        return cam.apply(image)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="dataset folder")
    parser.add_argument("--seeds", required=True, help="camera seeds, comma-separated")
    parser.add_argument("--models", action="append", required=True,
                        help="'shipped' or a models folder (repeat)")
    parser.add_argument("--out", type=Path, required=True, help="JSON results (resumed)")
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    seeds = [int(s) for s in args.seeds.split(",")]
    res = json.loads(args.out.read_text()) if args.out.exists() else {}
    for m in args.models:
        models = PerceptionModels.load(None if m == "shipped" else Path(m), "cpu")
        r = res.setdefault(m, {})
        keys = [("unchanged", None)] + [(f"{part} {s}", PartCameras(s, part))
                                        for s in seeds for part in PARTS]
        for key, image_map in keys:
            if key not in r:
                camera = detector_map(models, args.data, "all", image_map=image_map,
                                      views=["camera"])["camera"]
                r[key] = {k: camera[k] for k in ("map50", "map50_any_class")}
                write_json(args.out, res)
                print(m, key, r[key], flush=True)
        for part in PARTS:
            for metric in ("map50", "map50_any_class"):
                drop = np.mean([r["unchanged"][metric] - r[f"{part} {s}"][metric]
                                for s in seeds])
                print(f"{m}: {part:<12} {metric:<15} mean drop {drop:+.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
