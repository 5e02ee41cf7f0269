"""Does fine-tuning on a new camera's labelled frames pay? One reproducible measurement.

A lab's camera, made from renders: a fresh ``realistic`` dataset (``--data``, or rendered from
``--seed``) seen through ONE camera, ``CameraShift.draw(C)`` (:mod:`perception.camera_shift`).
The steps, each fixed before the test sessions are looked at:

1. **The camera.** A camera that costs the models nothing makes the question empty, so ``C``
   is the candidate of ``--cameras`` under which ``--models`` lose the most (per-view class
   call of the sorter's inspection views plus the prediction factor) on the dataset's VAL
   sessions, measured against the same sessions unchanged; the test sessions play no part.
2. **The lab's labels.** The first train sessions that hold ``--views`` sorter's inspection
   views with an onion in them (``bench/through_camera.py --train-sessions K``), through the
   camera; val and test through it too.
3. **Fine-tuning.** ``onionsort train inspection --init MODELS/inspection_classifier.pt`` on
   the lab's frames mixed with rendered ones (``--mix``, counted ``--data-weights``), once per
   learning rate of ``--lrs``; the trainer keeps its best epoch on the pooled validation
   split, and the learning rate is the one whose models score best (the same sum as step 1)
   on the lab's VAL sessions. The detector and the state classifier stay ``--models``'.
4. **The answer, on the TEST sessions only**: ``--models`` on the unchanged frames and through
   the camera, and the fine-tuned models through the camera: the sorter's per-view class
   call, the prediction factor (every unoccluded step), and the share of each drop that
   fine-tuning recovers (``(fine-tuned - through) / (unchanged - through)``; none where there
   is no drop).

Everything goes into the new folder ``--out``: the datasets written, the fine-tuned models and
``result.json``.

Example
-------
    onionsort dataset --frames 4800 --robot-onions 0 --seed 6101 --difficulty realistic \\
        --val 0.1 --test 0.4 --out runs/fresh-realistic-6101
    onionsort dataset --frames 1200 --robot-onions 0 --seed 6102 \\
        --difficulty clean,realistic,paper,hard --out runs/rendered-6102
    python bench/finetune_camera.py --models onionsort/models --data runs/fresh-realistic-6101 \\
        --mix runs/rendered-6102 --cameras 6131,6132,6133,6134 --out runs/finetune-6101
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.through_camera import through_camera

logger = logging.getLogger("finetune_camera")

_CLI = "import sys; from onionsort.cli import main; sys.exit(main(sys.argv[1:]))"
_FILES = ("detector.pt", "state_classifier.pt", "inspection_classifier.pt")


class _OneCamera:
    """Every colour image and view through one camera (an ``image_map``)."""

    def __init__(self, seed: int) -> None:
        from perception.camera_shift import CameraShift

        self.camera = CameraShift.draw(seed)

    def __call__(self, image, record):
        return self.camera.apply(image)


def figures(models, data: Path, split: str, image_map=None) -> dict:
    """The sorter's per-view class call and onion-found share (realistic level), and the
    prediction factor on unoccluded steps, of ``models`` on ``data``'s ``split``."""
    from onionsort.stages.calibrate import measure_perception
    from onionsort.stages.inspection import measure_inspection

    _, m = measure_perception(models, data, split, image_map=image_map)
    ins = measure_inspection(models, data, split, image_map=image_map)
    human = [s["human"] for s in ins["levels"].values() if "human" in s]
    views = sum(h["views"] for h in human)
    return {"view_class_call": sum(h["view_accuracy"] * h["views"] for h in human) / views,
            "view_rot_call": sum(h["rot_accuracy"] * h["views"] for h in human) / views,
            "onion_found": sum(h["found"] * h["views"] for h in human) / views,
            "views": views, "prediction": m["accuracy"]["prediction"],
            "prediction_after_first_inspection": m["prediction_after_first_inspection"],
            "steps": m["n_steps"]}


def _score(f: dict) -> float:
    return f["view_class_call"] + f["prediction"]


def _sessions_for_views(data: Path, views: int) -> int:
    """The fewest first train sessions (``bench/through_camera.py --train-sessions K``'s
    order) whose sorter's inspection views show ``views`` onions."""
    from recordings.labels.dataset import read_records

    per = dict.fromkeys(sorted({int(r["session"]) for r in read_records(data, "train")
                                if "session" in r}), 0)
    for r in read_records(data, "train", "inspection"):
        if r.get("source", "human") == "human" and r.get("boxes"):
            per[int(r["session"])] = per.get(int(r["session"]), 0) + 1
    total = 0
    for k, s in enumerate(sorted(per)):
        total += per[s]
        if total >= views:
            return k + 1
    raise ValueError(f"{data}: its train sessions hold {total} sorter's views of an onion, "
                     f"fewer than --views {views}")


def _first_test_sessions(src: Path, out: Path, n: int | None) -> Path:
    """``src`` with its test split cut to its first ``n`` sessions (None: ``src`` itself), as
    a new dataset folder ``out`` whose image folders link to ``src``'s."""
    from recordings.labels.dataset import SPLITS, read_metadata, read_records

    if n is None:
        return src
    meta = read_metadata(src)
    sessions = sorted({int(r["session"]) for r in read_records(src, "test")})[:n]
    for split in SPLITS:
        (out / split).mkdir(parents=True)
        for entry in (src / split).iterdir():
            if entry.is_dir():
                (out / split / entry.name).symlink_to(entry.resolve())
        for view, name in (("camera", "labels.json"), ("inspection", "inspection.json")):
            if (src / split / name).is_file():
                records = read_records(src, split, view)
                if split == "test":
                    records = [r for r in records if r.get("session") in sessions]
                (out / split / name).write_text(json.dumps(records))
    meta["test_sessions_kept"] = sessions
    (out / "dataset.json").write_text(json.dumps(meta))
    return out


def _recovered(unchanged: float, through: float, tuned: float) -> float | None:
    drop = unchanged - through
    return None if drop <= 0 else (tuned - through) / drop


def _figures_job(models: Path, device: str, data: Path, split: str,
                 camera: int | None = None) -> dict:
    """:func:`figures` in a worker process: loads ``models`` there, one torch thread."""
    import torch

    from onionsort.stages.models import PerceptionModels

    torch.set_num_threads(1)
    return figures(PerceptionModels.load(models, device), data, split,
                   None if camera is None else _OneCamera(camera))


def _train_job(args: argparse.Namespace, lab: Path, lr: float) -> Path:
    """Fine-tune the inspection classifier at ``lr`` (a subprocess); the folder of the
    models with it (the detector and the state classifier copied from ``--models``)."""
    folder = args.out / f"ft-lr{lr:g}"
    subprocess.run([sys.executable, "-c", _CLI, "train", "inspection", "--init",
                    str(args.models / "inspection_classifier.pt"), "--detector",
                    str(args.models), "--data", str(lab), "--data", str(args.mix),
                    "--data-weights", args.data_weights, "--epochs", str(args.epochs),
                    "--lr", f"{lr:g}", "--device", args.device, "--out", str(folder)],
                   check=True)
    for name in _FILES[:2]:
        shutil.copyfile(args.models / name, folder / name)
    return folder


def run(args: argparse.Namespace) -> dict:
    """The measurement of the module docstring; independent evaluations and trainings run on
    ``args.workers`` processes at once."""
    from concurrent.futures import ProcessPoolExecutor

    out, models, dev = args.out, args.models, args.device
    out.mkdir(parents=True)
    args.data = _first_test_sessions(args.data, out / "data", args.test_sessions)
    with ProcessPoolExecutor(args.workers) as pool:
        # 1. the camera: the candidate the models lose most under, on the VAL sessions (the
        # unchanged test sessions are measured meanwhile: no camera is in them)
        base = pool.submit(_figures_job, models, dev, args.data, "val")
        shifted = {c: pool.submit(_figures_job, models, dev, args.data, "val", c)
                   for c in args.cameras}
        unchanged_test = pool.submit(_figures_job, models, dev, args.data, "test")
        base = base.result()
        cameras = {c: {**f.result(), "loss": _score(base) - _score(f.result())}
                   for c, f in shifted.items()}
        for c, f in cameras.items():
            logger.info("camera %d on the val sessions: class call %.3f -> %.3f, prediction "
                        "%.3f -> %.3f", c, base["view_class_call"], f["view_class_call"],
                        base["prediction"], f["prediction"])
        camera = max(cameras, key=lambda c: cameras[c]["loss"])
        # 2. the lab's labelled frames, through that camera
        k = _sessions_for_views(args.data, args.views)
        lab = out / f"lab-{camera}"
        through_camera(args.data, lab, camera, train_sessions=k)
        # 3. fine-tune once per learning rate (the shipped models' test through the camera
        # meanwhile); the learning rate is chosen on the lab's VAL sessions
        through_test = pool.submit(_figures_job, models, dev, lab, "test")
        folders = {lr: pool.submit(_train_job, args, lab, lr) for lr in args.lrs}
        folders = {lr: f.result() for lr, f in folders.items()}
        val = {lr: pool.submit(_figures_job, f, dev, lab, "val") for lr, f in folders.items()}
        # each learning rate's test figures are measured alongside; only the one chosen on
        # val is reported
        tested = {lr: pool.submit(_figures_job, f, dev, lab, "test")
                  for lr, f in folders.items()}
        val = {lr: f.result() for lr, f in val.items()}
        lr = max(val, key=lambda x: _score(val[x]))
        test = {"unchanged, shipped": unchanged_test.result(),
                "through the camera, shipped": through_test.result(),
                "through the camera, fine-tuned": tested[lr].result()}
    recovered = {key: _recovered(*(test[w][key] for w in test))
                 for key in ("view_class_call", "prediction")}
    return {"models": str(models), "data": str(args.data), "mix": str(args.mix),
            "val_sessions_base": base, "cameras": cameras, "camera": camera,
            "lab_train_sessions": k, "lab": str(lab), "epochs": args.epochs,
            "data_weights": args.data_weights, "lrs": {f"{x:g}": v for x, v in val.items()},
            "lr": lr, "test": test, "recovered": recovered}


def _print(result: dict) -> None:
    print(f"camera {result['camera']} (of {', '.join(map(str, result['cameras']))}, by the "
          f"shipped models' loss on the val sessions: " + ", ".join(
              f"{c} {v['loss']:+.3f}" for c, v in result["cameras"].items()) + ")")
    print(f"fine-tuned on the first {result['lab_train_sessions']} train sessions; lr "
          f"{result['lr']:g} chosen on the val sessions (" + ", ".join(
              f"{x}: class call {v['view_class_call']:.3f}, prediction {v['prediction']:.3f}"
              for x, v in result["lrs"].items()) + ")")
    print("test sessions:")
    for who, f in result["test"].items():
        print(f"  {who:32s} class call per view {f['view_class_call']:.3f} (rot "
              f"{f['view_rot_call']:.3f}, found {f['onion_found']:.3f}, {f['views']} views); "
              f"prediction {f['prediction']:.3f} ({f['steps']} steps)")
    for key, share in result["recovered"].items():
        print(f"  share of the drop in {key} recovered: "
              + ("no drop" if share is None else f"{share:.2f}"))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--models", type=Path, required=True, help="the models to fine-tune")
    p.add_argument("--data", type=Path, required=True,
                   help="a fresh realistic dataset (train, val and test sessions)")
    p.add_argument("--mix", type=Path, required=True, help="rendered data to mix in")
    p.add_argument("--cameras", type=lambda t: [int(x) for x in t.split(",")], required=True,
                   help="candidate camera seeds, e.g. 6131,6132")
    p.add_argument("--views", type=int, default=200,
                   help="the lab's labelled sorter's views of an onion (200)")
    p.add_argument("--lrs", type=lambda t: [float(x) for x in t.split(",")],
                   default=[3e-4, 1e-3], help="learning rates to choose from on val")
    p.add_argument("--epochs", type=int, default=6)
    p.add_argument("--data-weights", default="3,1")
    p.add_argument("--device", default="cpu")
    p.add_argument("--test-sessions", type=int, default=None,
                   help="measure on the first N test sessions only (default: all)")
    p.add_argument("--workers", type=int, default=4,
                   help="evaluations and trainings run at once (4)")
    p.add_argument("--out", type=Path, required=True, help="new folder")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    if args.out.exists():
        print(f"finetune_camera: error: {args.out} exists; give a new folder", file=sys.stderr)
        return 2
    for folder in (args.models, args.data, args.mix):
        if not folder.is_dir():
            print(f"finetune_camera: error: no such folder {folder}", file=sys.stderr)
            return 2
    result = run(args)
    (args.out / "result.json").write_text(json.dumps(result, indent=1, default=str))
    _print(result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
