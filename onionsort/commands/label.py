"""``onionsort label``: labelled frames out to annotation tools and back in.

``label export`` writes a dataset in the COCO or YOLO layout that CVAT, Label Studio,
FiftyOne and Ultralytics open; ``label select`` chooses the frames of recorded sessions worth
a person's time and writes them as a pre-annotated labelling task; ``label import`` reads
what the tools export back as a dataset that ``train``, ``calibrate`` and ``eval-perception``
read. Each action's ``--help`` gives it in full.

Examples
--------
    onionsort label export runs/data --format coco --out runs/data-coco
    onionsort label select runs/line/*.mcap --frames 200 --format labelstudio --out runs/ls
    onionsort label select runs/sel/*.mcap --frames 60 --recall --out runs/sel-task
    onionsort label import runs/ls --format labelstudio --out runs/lab
"""

from __future__ import annotations

import argparse

from onionsort.commands import add_command, add_group
from onionsort.configs import config_from_args
from onionsort.configs.label import LabelExportConfig, LabelImportConfig, LabelSelectConfig

__all__ = ["register"]


EXPORT = """``onionsort label export``: a dataset folder in a layout annotation tools open.

``--format coco`` writes the COCO 2017 layout (``annotations/instances_<split>.json`` beside
``<split>/`` images), ``--format yolo`` Ultralytics' layout (``data.yaml``,
``images/<split>/``, ``labels/<split>/`` with lines ``class cx cy w h``, normalised), each with
the state labels in ``states.csv`` (split, image, session, step, frame, occluded, one column
per factor of the task and action, in the task's words) and depth as 16-bit PNG in
millimetres in ``depth/<split>/``: the main camera's frames at the top, the inspection views
in ``inspection/`` in the same layout (the robot's line-up, onion and view numbers in
``inspection/lineups.csv``). CVAT, Label Studio, FiftyOne and Ultralytics open it.

Examples
--------
    onionsort label export runs/data --format coco --out runs/data-coco
    onionsort label export runs/data --format yolo --out runs/data-yolo
"""

IMPORT = """``onionsort label import``: a labelled image set as a dataset folder.

It reads the folder ``label export`` or ``label select`` wrote, or what CVAT, Label Studio or
Roboflow export (``<split>/_annotations.coco.json``; one file without splits; ``--format
labelstudio``: Label Studio's JSON export beside the images, its state choices as the state
labels), into a new dataset folder that ``train``, ``calibrate`` and ``eval-perception`` read.
Frames without a row in the states CSV are box-only: the detector and the inspection
classifier learn from them, the state classifier and calibration do not. A set without splits
is split by session, as ``onionsort dataset`` splits its sessions. Images may be JPEG or PNG
of any size: larger ones are shrunk to the detector's 320x256 canvas, their boxes with them.

Examples
--------
    onionsort label import runs/data-coco --format coco --out runs/data-again
    onionsort label import cvat-export --format coco --states lab-states.csv \\
        --classes good=sound,blemished=rotten --out runs/lab
    onionsort label import yolo-set --format yolo --depth yolo-set/depth --out runs/lab-yolo
    onionsort label import runs/ls --format labelstudio --out runs/lab
"""

SELECT = """``onionsort label select``: the frames worth labelling, as a pre-annotated task.

It perceives recorded sessions and chooses the steps where the models are least sure (the
chance, by their own probabilities and what the sorter later did with the onion, that a
step's state guess is wrong): the steps more likely wrong than right first, then in rounds
over the sessions, until ``--frames`` frames. It writes them pre-annotated with the models'
boxes and state guesses: ``--format coco``, COCO with scores and a states.csv (what ``label
import`` reads back once corrected), or ``--format labelstudio``, Label Studio's import format
with predictions (``tasks.json``) and its labelling interface (``labeling_config.xml``).
``--sample random`` draws the steps uniformly (from ``--seed``) instead: held-out frames
to calibrate on must be a fair sample, not the hardest. ``--recall``, on recorded sessions that
carry the truth, also scores the choice: how many
steps have a wrong state guess, how many of those chosen do, and each wrong step left out (the
truth is read after choosing, never by the choice).

Examples
--------
    onionsort label select runs/line/*.mcap --frames 200 --out runs/to-label
    onionsort label select runs/line/*.mcap --frames 200 --format labelstudio --out runs/ls
    onionsort label select runs/sel/*.mcap --frames 60 --recall --out runs/sel-task
    onionsort label select runs/heldout/*.mcap --frames 120 --sample random --out runs/cal-task
"""


def register(subparsers) -> None:
    """Add the ``label`` subcommand and its actions."""
    actions = add_group(subparsers, "label", __doc__,
                        "labelled frames in and out: COCO, YOLO and a states CSV",
                        dest="action", metavar="ACTION")
    add_command(actions, "export", EXPORT, "write a dataset as COCO or YOLO with states.csv",
                LabelExportConfig, run_export)
    add_command(actions, "import", IMPORT, "read COCO or YOLO (and a states CSV) as a dataset",
                LabelImportConfig, run_import)
    add_command(actions, "select", SELECT, "the frames of sessions where the models are least "
                                           "sure, as a pre-annotated labelling task",
                LabelSelectConfig, run_select)


def run_export(args: argparse.Namespace) -> int:
    from onionsort.stages.label import export_labels

    summary = export_labels(config_from_args(LabelExportConfig, args))
    for view, counts in summary["images"].items():
        boxes = ", ".join(f"{n} {c}" for c, n in summary["boxes"][view].items())
        print(f"{view}: " + ", ".join(f"{s} {n}" for s, n in counts.items())
              + f" images; boxes: {boxes}")
    print(f"wrote {args.out}")
    return 0


def run_import(args: argparse.Namespace) -> int:
    from onionsort.stages.label import import_labels

    summary = import_labels(config_from_args(LabelImportConfig, args))
    for view, counts in summary["images"].items():
        if any(counts.values()):
            print(f"{view}: " + ", ".join(f"{s} {n}" for s, n in counts.items())
                  + f" images, {summary['with_states'][view]} with state labels")
    print(f"{summary['depth']} with depth; wrote {args.out}")
    return 0


def run_select(args: argparse.Namespace) -> int:
    from onionsort.stages.label_select import select_frames

    result = select_frames(config_from_args(LabelSelectConfig, args))
    chosen = result["frames"]
    steps = {(f["session"], f["step"]) for f in chosen}
    sessions = {f["session"] for f in chosen}
    print(f"chose {len(chosen)} frames ({len(steps)} steps of {len(sessions)} sessions) of "
          f"{result['steps_seen']} steps, those whose state guess is the most likely wrong")
    if "recall" in result:
        r = result["recall"]
        ratio = "" if r["ratio"] is None else f": {r['ratio']:.1f} times as often"
        print(f"against the truth: {r['wrong']} of {r['steps']} steps wrong "
              f"({r['wrong'] / r['steps']:.3f}); {r['wrong_taken']} of the {r['taken']} "
              f"taken ({r['wrong_taken'] / r['taken']:.3f}){ratio}; "
              f"{len(r['missed'])} wrong steps left out")
        for m in r["missed"]:
            print(f"  left out: session {m['session']} step {m['step']}, uncertainty "
                  f"{m['uncertainty']:.4f}, wrong: {', '.join(m['wrong'])}")
    print(f"wrote {args.out}")
    return 0
