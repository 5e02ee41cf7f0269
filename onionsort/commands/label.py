"""``onionsort label``: labelled frames out to annotation tools and back in.

``label export`` writes a dataset folder in the COCO 2017 layout (``annotations/
instances_<split>.json`` beside ``<split>/`` images) or Ultralytics' YOLO layout (``data.yaml``,
``images/<split>/``, ``labels/<split>/`` with lines ``class cx cy w h``, normalised), with the
state labels in ``states.csv`` (split, image, session, step, frame, occluded, one column per
factor of the task and action, in the task's words) and depth as 16-bit PNG in millimetres in
``depth/<split>/``: the main camera's frames at the top, the inspection views in
``inspection/`` in the same layout (the robot's line-up, onion and view numbers in
``inspection/lineups.csv``). CVAT, Label Studio, FiftyOne and Ultralytics open it.

``label select`` chooses the frames of recorded sessions where the models are least sure (the
chance, by their own probabilities and what the sorter later did with the onion, that a step's
state guess is wrong): the steps more likely wrong than right first, then in rounds over the
sessions; it writes them as a labelling task
pre-annotated with the models' boxes and state guesses: COCO with scores and a states.csv
(what ``label import`` reads back once corrected), or Label Studio's import format with
predictions.

``label import`` reads such a folder, or what CVAT, Label Studio or Roboflow export
(``<split>/_annotations.coco.json``; one file without splits; ``--format labelstudio``: Label
Studio's JSON export beside the images, its state choices as the state labels), into a
dataset folder that
``train``, ``calibrate`` and ``eval-perception`` read. Frames without a row in the states CSV
are box-only: the detector and the inspection classifier learn from them, the state
classifier and calibration do not. A set without splits is split by session, as ``onionsort
dataset`` splits its sessions. Images may be JPEG or PNG of any size: larger ones are shrunk
to the detector's 320x256 canvas, their boxes with them.

Examples
--------
    onionsort label export runs/data --format coco --out runs/data-coco
    onionsort label import runs/data-coco --format coco --out runs/data-again
    onionsort label import cvat-export --format coco --states lab-states.csv \\
        --classes good=sound,blemished=rotten --out runs/lab
    onionsort label import yolo-set --format yolo --depth yolo-set/depth --out runs/lab-yolo
    onionsort label select runs/line/*.mcap --frames 200 --out runs/to-label
    onionsort label select runs/line/*.mcap --frames 200 --format labelstudio --out runs/ls
    onionsort label import runs/ls --format labelstudio --out runs/lab
"""

from __future__ import annotations

import argparse
from pathlib import Path

from onionsort.commands._args import (
    IMPORT_FORMATS,
    LABEL_FORMATS,
    SELECT_FORMATS,
    add_device_argument,
    add_models_argument,
    subcommand,
)

__all__ = ["register"]


def register(subparsers) -> None:
    """Add the ``label`` subcommand and its actions."""
    parser = subcommand(subparsers, "label", __doc__,
                        "labelled frames in and out: COCO, YOLO and a states CSV")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    exp = actions.add_parser("export", help="write a dataset as COCO or YOLO with states.csv")
    exp.add_argument("data", type=Path, metavar="DATASET", help="a dataset folder")
    exp.add_argument("--format", choices=LABEL_FORMATS, required=True,
                     help="coco (COCO 2017 layout) or yolo (Ultralytics layout)")
    exp.add_argument("--out", type=Path, required=True, help="a new folder")
    exp.set_defaults(func=run_export)
    imp = actions.add_parser("import", help="read COCO or YOLO (and a states CSV) as a dataset")
    imp.add_argument("source", type=Path, metavar="DIR", help="the labelled image set")
    imp.add_argument("--format", choices=IMPORT_FORMATS, required=True,
                     help="coco (COCO 2017, Roboflow, CVAT, Label Studio), yolo "
                          "(Ultralytics, Roboflow) or labelstudio (Label Studio's JSON "
                          "export: boxes and state choices)")
    imp.add_argument("--states", type=Path, default=None, metavar="FILE.csv",
                     help="the state labels (default: DIR/states.csv where there is one); "
                          "frames without a row are box-only")
    imp.add_argument("--depth", type=Path, default=None, metavar="DIR",
                     help="16-bit PNG depth in millimetres, matched by file name (default: "
                          "DIR/depth where there is one)")
    imp.add_argument("--inspection", type=Path, default=None, metavar="DIR",
                     help="the inspection views, in the same format with their own "
                          "states.csv (default: DIR/inspection where there is one)")
    imp.add_argument("--classes", type=_classes, default={},
                     metavar="good=NAME,blemished=NAME",
                     help="the set's names of the dataset's classes (default: good, "
                          "blemished)")
    imp.add_argument("--out", type=Path, required=True, help="a new dataset folder")
    imp.set_defaults(func=run_import)
    sel = actions.add_parser("select", help="the frames of sessions where the models are least "
                                            "sure, as a pre-annotated labelling task")
    sel.add_argument("sessions", type=Path, nargs="+", metavar="SESSION",
                     help="recorded sessions (.mcap)")
    sel.add_argument("--frames", type=int, required=True, metavar="N",
                     help="how many frames to choose (whole steps, in rounds over the "
                          "sessions)")
    sel.add_argument("--format", choices=SELECT_FORMATS, default="coco",
                     help="coco (images, annotations with scores, states.csv; what label "
                          "import reads back) or labelstudio (tasks.json with predictions and "
                          "labeling_config.xml)")
    sel.add_argument("--out", type=Path, required=True, help="a new folder")
    add_models_argument(sel)
    add_device_argument(sel)
    sel.set_defaults(func=run_select)


def _classes(text: str) -> dict[str, str]:
    """``class=NAME`` pairs joined by commas, for argparse ``type=``."""
    out = {}
    for part in filter(None, (x.strip() for x in text.split(","))):
        cls, sep, name = part.partition("=")
        if not sep or cls.strip() not in ("good", "blemished") or not name.strip():
            raise argparse.ArgumentTypeError(
                f"expected good=NAME,blemished=NAME; got {part!r}")
        out[cls.strip()] = name.strip()
    return out


def run_export(args: argparse.Namespace) -> int:
    from onionsort.stages.label import LabelExportConfig, export_labels

    summary = export_labels(LabelExportConfig(data=args.data, out=args.out, format=args.format))
    for view, counts in summary["images"].items():
        boxes = ", ".join(f"{n} {c}" for c, n in summary["boxes"][view].items())
        print(f"{view}: " + ", ".join(f"{s} {n}" for s, n in counts.items())
              + f" images; boxes: {boxes}")
    print(f"wrote {args.out}")
    return 0


def run_import(args: argparse.Namespace) -> int:
    from onionsort.stages.label import LabelImportConfig, import_labels

    summary = import_labels(LabelImportConfig(
        source=args.source, out=args.out, format=args.format, states=args.states,
        depth=args.depth, inspection=args.inspection, classes=args.classes))
    for view, counts in summary["images"].items():
        if any(counts.values()):
            print(f"{view}: " + ", ".join(f"{s} {n}" for s, n in counts.items())
                  + f" images, {summary['with_states'][view]} with state labels")
    print(f"{summary['depth']} with depth; wrote {args.out}")
    return 0


def run_select(args: argparse.Namespace) -> int:
    from onionsort.stages.label_select import LabelSelectConfig, select_frames

    result = select_frames(LabelSelectConfig(
        sessions=tuple(args.sessions), out=args.out, frames=args.frames, format=args.format,
        models=args.models, device=args.device))
    chosen = result["frames"]
    steps = {(f["session"], f["step"]) for f in chosen}
    sessions = {f["session"] for f in chosen}
    print(f"chose {len(chosen)} frames ({len(steps)} steps of {len(sessions)} sessions) of "
          f"{result['steps_seen']} steps, those whose state guess is the most likely wrong")
    print(f"wrote {args.out}")
    return 0
