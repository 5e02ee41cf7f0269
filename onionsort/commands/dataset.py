"""``onionsort dataset``: render labelled frames (train/val/test) for perception.

Frames come from whole simulated sessions, split into train, val and test by session. See
``recordings.labels.dataset`` for the folder layout and the label records.

Examples
--------
    onionsort dataset --frames 3000 --seed 0 --out runs/data
    onionsort dataset --frames 300 --occlusion 0.4 --seed 1 --out runs/data-small
    onionsort dataset --frames 8000 --difficulty clean,realistic,paper,hard --out runs/data-mix
    onionsort dataset --frames 8000 --randomize-look --out runs/data-looks
    onionsort dataset --frames 1500 --difficulty hard --inspection-size 320x240 --out runs/sharp

``--randomize-look`` gives each session and robot line-up a look of its own, drawn from its
seed (``robot.look``: the light's colour, intensity and direction; the colours of the floor,
belt, stand and bin; the cameras' exposure and white balance), for models that must survive
another camera. The difficulty levels are unchanged by it.

``--inspection-size`` renders the sorter's inspection view at another resolution: the same
camera, spot and field of view. A session's states, actions, onions and the sorter's poses
are those of the default size; at a level with image effects the hand's patches and the
cameras' noise are drawn anew (their draws depend on the images' size), and an onion is
labelled in a view from 25 visible pixels at any size, so the views pair by onion and pose,
not pixel for pixel. The detector reads any size; the inspection classifier reads a fixed
crop round the onion. Use it to ask what a sharper or coarser camera at the inspection spot
would change.
"""

from __future__ import annotations

from onionsort.commands import add_command
from onionsort.configs import config_from_args
from onionsort.configs.dataset import DatasetConfig


def register(subparsers) -> None:
    add_command(subparsers, "dataset", __doc__,
                "render labelled frames (train/val/test) for perception", DatasetConfig, run)


def run(args) -> int:
    from onionsort.stages import make_dataset

    summary = make_dataset(config_from_args(DatasetConfig, args))
    sessions = ", ".join(f"{s}: {n} sessions" for s, n in summary.sessions.items())
    print(f"wrote {summary.frames} frames ({sessions}) to {args.out}")
    if summary.robot_views:
        print(f"wrote {summary.robot_views} inspection views of the Sawyer holding "
              f"{args.robot_onions} onions")
    return 0
