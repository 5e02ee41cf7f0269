"""Write a dataset as one other camera would have taken it: a new lab's camera, made from renders.

``onionsort eval-perception --camera-shift SEED`` gives each session a camera of its own. A lab
has one camera: this script writes a copy of a dataset folder whose colour frames and
inspection views (the sorter's and the robot's alike) all went through ONE camera,
``CameraShift.draw(SEED)`` (:mod:`perception.camera_shift`); depth, labels and file names are
copied as they are. ``train``, ``calibrate`` and ``eval-perception`` read the copy as they read
the original; ``eval-perception`` on it without ``--camera-shift`` measures through that one
camera. ``dataset.json`` records the camera (``camera_shift``: its seed and settings).

``--train-sessions K`` keeps, of the train split, the first K sessions only (their frames and
the sorter's views of them; the robot's train line-ups are left out), for a small labelled set
such as a lab would make; val and test are kept whole.

Example
-------
    onionsort dataset --frames 3600 --robot-onions 0 --seed 93 --difficulty realistic \\
        --val 0.1 --test 0.45 --out runs/fresh-realistic-93
    python bench/through_camera.py runs/fresh-realistic-93 --camera 3737 --out runs/cam-3737
    python bench/through_camera.py runs/fresh-realistic-93 --camera 3737 --train-sessions 21 \\
        --out runs/lab-3737
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import cv2

from perception.camera_shift import CameraShift
from recordings.labels.dataset import SPLITS, read_metadata, read_records

_LABELS = {"camera": "labels.json", "inspection": "inspection.json"}


def _kept_sessions(root: Path, train_sessions: int | None) -> set[int] | None:
    """The first ``train_sessions`` sessions of the train split (None: all)."""
    if train_sessions is None:
        return None
    sessions = sorted({int(r["session"]) for r in read_records(root, "train")
                       if "session" in r})
    if train_sessions > len(sessions):
        raise ValueError(f"--train-sessions {train_sessions}: the train split of {root} has "
                         f"{len(sessions)} sessions")
    return set(sessions[:train_sessions])


def through_camera(src: Path | str, out: Path | str, seed: int,
                   train_sessions: int | None = None) -> dict:
    """Write ``src`` through the camera ``CameraShift.draw(seed)`` into the new folder ``out``
    (see the module docstring); returns the new ``dataset.json``. Written under a temporary
    name and renamed when complete; ``src`` is only read."""
    src, out = Path(src), Path(out)
    meta = read_metadata(src)
    if train_sessions is not None and train_sessions < 1:
        raise ValueError(f"--train-sessions must be >= 1; got {train_sessions}")
    if out.exists():
        raise FileExistsError(f"{out} exists; give a new folder")
    camera = CameraShift.draw(seed)
    kept = _kept_sessions(src, train_sessions)
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        new_meta = _write(src, tmp, meta, camera, kept)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if train_sessions is not None:
        new_meta["train_sessions"] = sorted(kept)
    new_meta["camera_shift"] = {"seed": seed, **camera.to_dict()}
    (tmp / "dataset.json").write_text(json.dumps(new_meta))
    tmp.rename(out)
    return new_meta


def _write(src: Path, tmp: Path, meta: dict, camera: CameraShift,
           kept: set[int] | None) -> dict:
    """The images and records of :func:`through_camera` under ``tmp``; its metadata."""
    counts: dict[str, dict[str, int]] = {view: {} for view in _LABELS}
    for split in SPLITS:
        if not (src / split).is_dir():
            continue
        (tmp / split).mkdir(parents=True)
        for view in meta.get("views", ["camera"]):
            records = read_records(src, split, view)
            if split == "train" and kept is not None:
                records = [r for r in records if r.get("session") in kept
                           and r.get("source", "human") != "robot"]
            for rec in records:
                for key in ("color", "depth"):
                    if key in rec:
                        (tmp / split / rec[key]).parent.mkdir(parents=True, exist_ok=True)
                bgr = cv2.imread(str(src / split / rec["color"]), cv2.IMREAD_COLOR)
                if bgr is None:
                    raise ValueError(f"{src / split}: frame {rec['color']} is missing or "
                                     "unreadable")
                rgb = camera.apply(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
                if not cv2.imwrite(str(tmp / split / rec["color"]),
                                   cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
                    raise OSError(f"could not write {tmp / split / rec['color']}")
                if "depth" in rec:
                    shutil.copyfile(src / split / rec["depth"], tmp / split / rec["depth"])
            (tmp / split / _LABELS[view]).write_text(json.dumps(records))
            counts[view][split] = len(records)
    new_meta = {**meta, "splits": counts["camera"], "source_dataset": src.resolve().name}
    if "inspection" in meta.get("views", ["camera"]):
        new_meta["inspection_splits"] = counts["inspection"]
    return new_meta


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("src", type=Path, help="dataset folder (onionsort dataset)")
    p.add_argument("--camera", type=int, required=True,
                   help="seed of the one camera (CameraShift.draw(SEED)), an int >= 0")
    p.add_argument("--out", type=Path, required=True, help="new dataset folder")
    p.add_argument("--train-sessions", type=int, default=None,
                   help="keep only the first K sessions of the train split (default: all)")
    args = p.parse_args(argv)
    try:
        meta = through_camera(args.src, args.out, args.camera, args.train_sessions)
    except (ValueError, TypeError, OSError) as exc:
        print(f"through_camera: error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps({"out": str(args.out), "splits": meta["splits"],
                      "inspection_splits": meta.get("inspection_splits"),
                      "camera_shift": meta["camera_shift"]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
