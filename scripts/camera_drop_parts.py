"""Which part of another camera costs the detector its camera-view mAP.

``eval-perception --camera-shift S`` sees each session through a camera of its own
(``onionsort.stages.cameras.SessionCameras``). This study splits each of those cameras in two
and measures the detector's camera-view mAP@0.5 through each part alone:

- ``colour``: the camera's white balance, exposure and tone curve, with a sharp lens, no noise
  and no JPEG;
- ``degradation``: its defocus, sensor noise and JPEG, with the renderer's colour;
- ``full``: the whole camera, as ``eval-perception`` has it.

It gives each figure twice: as ``eval-perception`` counts it (the mean of the good and the
blemished class's AP), and class-agnostic (every box one class: does it find the onions, apart
from calling them good or blemished, which the inspection classifier does downstream).

With ``--sorter`` it measures the sorter's inspection through the same parts as well
(:func:`onionsort.stages.inspection.measure_inspection` on the sorter's views): its class call
per view and which way it errs (good views called blemished, blemished views called good), and
its fused call per onion (``noisy-or``), beside the fused call of a perfect rot reader, whose
views say rot exactly where the renderer's label says they show it: the ceiling of any
classifier of those views, the same through every camera.

Usage::

    python scripts/camera_drop_parts.py --data runs/d9102 --seeds 9301,9302,9303 \
        --models shipped --models runs/m-d1 --out runs/parts.json
    python scripts/camera_drop_parts.py --data runs/d9102 --seeds 9301,9302,9303 \
        --models shipped --sorter --out runs/parts-sorter.json
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
from onionsort.stages.calibrate import detector_map
from onionsort.stages.cameras import SessionCameras
from onionsort.stages.inspection import inspection_views, measure_inspection
from perception.camera_shift import REFERENCE_TEMPERATURE_K

PARTS = ("full", "colour", "degradation")
SORTER = ("view_accuracy", "good_views_called_blemished", "blemished_views_called_good")
FUSED = ("accuracy", "precision", "recall")


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
    parser.add_argument("--sorter", action="store_true",
                        help="measure the sorter's inspection through each part too")
    args = parser.parse_args(argv)
    torch.set_num_threads(2)
    seeds = [int(s) for s in args.seeds.split(",")]
    res = json.loads(args.out.read_text()) if args.out.exists() else {}
    if args.sorter and "rot reader" not in res:
        res["rot reader"] = rot_reader_ceiling(args.data)
        write_json(args.out, res)
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
            if args.sorter and "sorter" not in r[key]:
                r[key]["sorter"] = sorter_figures(models, args.data, image_map)
                write_json(args.out, res)
                print(m, key, r[key]["sorter"], flush=True)
        for part in PARTS:
            for metric in ("map50", "map50_any_class"):
                drop = np.mean([r["unchanged"][metric] - r[f"{part} {s}"][metric]
                                for s in seeds])
                print(f"{m}: {part:<12} {metric:<15} mean drop {drop:+.3f}")
            if args.sorter:
                for level, row in r["unchanged"]["sorter"].items():
                    mean = {k: np.mean([r[f"{part} {s}"]["sorter"][level][k] for s in seeds])
                            for k in row}
                    print(f"{m}: {part:<12} sorter at {level}: "
                          + ", ".join(f"{k} {row[k]:.3f} -> {mean[k]:.3f}" for k in row))
    for level, ceiling in res.get("rot reader", {}).items():
        print(f"a perfect rot reader: the sorter's fused call at {level} {ceiling:.3f}")
    return 0


def sorter_figures(models: PerceptionModels, data: Path, image_map) -> dict:
    """Per level, the sorter's class call per view (and its two errors) and its fused call
    (``noisy-or``) per onion, each view seen through ``image_map``."""
    levels = measure_inspection(models, data, "all", views=0, image_map=image_map)["levels"]
    out = {}
    for level, report in levels.items():
        if "human" in report:
            row = report["human"]
            out[level] = {**{k: row[k] for k in SORTER},
                          **{f"fused {k}": row["fused"]["noisy-or"][k] for k in FUSED}}
    return out


def rot_reader_ceiling(data: Path) -> dict:
    """Per level, the sorter's fused call per onion if each of its views were read
    perfectly: blemished exactly where some view shows rot by the renderer's label
    (:func:`perception.inspection.rot_label`)."""
    views = inspection_views(data, "all")
    out = {}
    for level in sorted(set(views.level[views.source == "human"])):
        mine = (views.source == "human") & (views.level == level)
        onions = {}
        for key, label, blemished in zip(views.onion[mine], views.labels[mine],
                                         views.classes[mine], strict=True):
            shows, truth = onions.get(key, (False, blemished))
            onions[key] = (shows or label == 1, truth)
        out[str(level)] = float(np.mean([shows == bool(truth)
                                         for shows, truth in onions.values()]))
    return out


if __name__ == "__main__":
    sys.exit(main())
