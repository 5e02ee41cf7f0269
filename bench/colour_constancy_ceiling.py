"""What perfect colour constancy would buy: its ceiling, measured before building one.

Colour constancy brings each session's colours back to a reference look (issue 36, item 2).
Before building an estimator of a session's colour cast, this script measures what a perfect
one would give, with the truth that only a renderer has:

- **The level's light.** Each session (and robot line-up) of a level is lit with a gain and a
  colour cast of its own (:class:`robot.difficulty.ImageEffects`). The same seed rendered at
  ``clean`` (``--clean``) has the same sessions without them, so the per-channel ratio of the
  two, pixel for pixel (the median over pixels neither dark nor clipped), is the session's
  true gain; dividing every colour image of the session by it is perfect colour constancy for
  the level's light (the drift of the gain within a session stays).
- **Another camera** (``--camera-shift SEED``, :class:`onionsort.stages.calibrate.SessionCameras`):
  each session's camera with its white balance, exposure and tone curve set back to the
  renderer's, its blur, noise and JPEG kept, is perfect colour constancy for that camera.

It prints each figure of ``onionsort eval-perception`` (the detector's mAP aside) as rendered
and with the colours made constant, and, with a camera, through the camera and through it with
its colours undone. Run it from the repository's root.

Example
-------
    onionsort dataset --frames 1500 --robot-onions 60 --seed 7105 --difficulty hard \
        --out runs/x7105
    onionsort dataset --frames 1500 --robot-onions 60 --seed 7105 --difficulty clean \
        --out runs/c7105
    python bench/colour_constancy_ceiling.py --data runs/x7105 --clean runs/c7105
    python bench/colour_constancy_ceiling.py --data runs/x7106 --clean runs/c7106 \
        --camera-shift 7402
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from onionsort.stages.calibrate import SessionCameras, measure_perception, perception_figures
from onionsort.stages.inspection import measure_inspection
from onionsort.stages.models import PerceptionModels
from perception.camera_shift import REFERENCE_TEMPERATURE_K
from recordings.labels.dataset import SPLITS, read_metadata, read_split

_DARK, _CLIPPED = 20, 235


def _key(record: dict) -> tuple[str, int]:
    robot = record.get("source", "human") == "robot"
    return ("lineup", record["lineup"]) if robot else ("session", record["session"])


def _images(root: Path, split: str, view: str) -> dict[tuple[str, int], list[np.ndarray]]:
    out: dict[tuple[str, int], list[np.ndarray]] = {}
    where = None if view == "camera" else (lambda r: r.get("source") == "robot")
    for frame in read_split(root, split, view=view, where=where):
        out.setdefault(_key(frame.record), []).append(frame.color)
    return out


def true_gains(data: Path, clean: Path) -> dict[tuple[str, int], np.ndarray]:
    """Each session's and line-up's per-channel gain (3,): its colour images over the same
    seed's ``clean`` ones, the median ratio over the pixels neither dark nor clipped in the
    clean image."""
    gains = {}
    for split in SPLITS:
        for view in ("camera", "inspection"):
            lit, plain = _images(data, split, view), _images(clean, split, view)
            for key, images in lit.items():
                if key not in plain or len(plain[key]) != len(images):
                    raise ValueError(f"{clean} is not {data}'s seed at clean: {key} differs")
                a, b = np.stack(images).astype(float), np.stack(plain[key]).astype(float)
                ok = (b > _DARK) & (b < _CLIPPED)
                gains[key] = np.array([np.median(a[..., c][ok[..., c]] / b[..., c][ok[..., c]])
                                       for c in range(3)])
    return gains


@dataclasses.dataclass(frozen=True)
class ConstantLight:
    """Every colour image divided by its session's (line-up's) true gain: an image map."""

    gains: dict

    def __call__(self, image: np.ndarray, record: dict) -> np.ndarray:
        out = image / self.gains[_key(record)]
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)


@dataclasses.dataclass(frozen=True)
class ColourUndone:
    """Each session's camera of :class:`SessionCameras` with its white balance, exposure and
    tone curve set back to the renderer's (blur, noise and JPEG kept): an image map."""

    cameras: SessionCameras

    def __call__(self, image: np.ndarray, record: dict) -> np.ndarray:
        camera = dataclasses.replace(self.cameras.camera(record), gamma=1.0, exposure_ev=0.0,
                                     temperature_k=REFERENCE_TEMPERATURE_K)
        return camera.apply(image)


def figures(models, data: Path, image_map) -> dict:
    """The figures of :func:`perception_figures` (the detector's mAP aside), and the sessions
    read backwards."""
    _, m = measure_perception(models, data, "all", image_map=image_map)
    r = {"map_by_view": {}, "accuracy": m["accuracy"],
         "prediction_after_first_inspection": m["prediction_after_first_inspection"],
         "occlusion_recall": m["occlusion_recall"],
         "occlusion_precision": m["occlusion_precision"],
         "inspection_classifier": measure_inspection(models, data, "all", views=5,
                                                     image_map=image_map)}
    out = perception_figures(r)
    swaps = m["session_swaps"]
    out["sessions read backwards"] = f"{swaps['swapped']} of {swaps['sessions']}"
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", type=Path, required=True, help="a dataset at one level")
    parser.add_argument("--clean", type=Path, required=True,
                        help="the same seed and size rendered at clean")
    parser.add_argument("--camera-shift", type=int, default=None, metavar="SEED",
                        help="also through other cameras, and with their colours undone")
    parser.add_argument("--models", type=Path, default=None, help="(default: shipped)")
    args = parser.parse_args()
    for root in (args.data, args.clean):
        read_metadata(root)  # a one-line error for a folder that is not a dataset
    models = PerceptionModels.load(args.models, "cpu")
    variants = {"as rendered": None,
                "light made constant": ConstantLight(true_gains(args.data, args.clean))}
    if args.camera_shift is not None:
        cameras = SessionCameras(args.camera_shift)
        variants["through the cameras"] = cameras
        variants["cameras' colour undone"] = ColourUndone(cameras)
    results = {name: figures(models, args.data, m) for name, m in variants.items()}
    print("| figure | " + " | ".join(results) + " |")
    print("|---" * (len(results) + 1) + "|")
    for name in results["as rendered"]:
        cells = [results[v].get(name) for v in results]
        print(f"| {name} | " + " | ".join(f"{c:.3f}" if isinstance(c, float) else str(c)
                                          for c in cells) + " |")


if __name__ == "__main__":
    main()
