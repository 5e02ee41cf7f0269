"""The ``train`` stage: read a labelled dataset, train the state classifier or the detector.

The libraries (:mod:`state_abstraction`, :mod:`perception`) train on samples held in memory and
read no dataset; this stage reads them with :mod:`recordings.labels.dataset` and chooses which
images the detector trains on. Both write into ``out`` (checkpoints, a metrics file).

Examples
--------
::

    from onionsort.stages.train import ClassifierTrainConfig, train_state_classifier
    metrics = train_state_classifier(ClassifierTrainConfig(data=Path("runs/data"),
                                                           out=Path("runs/models"), epochs=14))
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from onionsort.configs.train import ClassifierTrainConfig, DetectorTrainConfig
from onionsort.stages.base import check_output_folder, log_config, resolve_device
from onionsort.stages.parallel import torch_threads

__all__ = ["ClassifierTrainConfig", "DetectorTrainConfig", "detector_images",
           "frames_through_cameras", "train_detector", "train_state_classifier"]

logger = logging.getLogger(__name__)

#: Inspection views without an onion are many (the onion is in view only while it is
#: inspected): this share of them is kept as negatives.
EMPTY_INSPECTION_SHARE = 0.15
#: Inspection views with an onion are few next to the camera frames: repeated this many times
#: in the training split.
INSPECTION_REPEAT = 3


@contextmanager
def epoch_bar(desc: str, epochs: int) -> Iterator[Callable[[dict], None]]:
    """A progress bar over epochs; yields the trainers' ``on_epoch``, which moves it to each
    record's epoch (so a resumed run starts where it left off)."""
    from tqdm import tqdm

    with tqdm(total=epochs, desc=desc, unit="epoch") as bar:
        yield lambda record: bar.update(int(record["epoch"]) + 1 - bar.n)


def _metadata(root: Path) -> dict:
    from recordings.labels.dataset import read_metadata

    return read_metadata(root)


def train_state_classifier(config: ClassifierTrainConfig) -> dict:
    """Train the state classifier on ``config.data``'s train split, pick the epoch on val.

    Returns
    -------
    dict
        The metrics of :func:`state_abstraction.classifier.train_classifier` (``test``,
        ``test_without_depth``, ``history``, ...); the checkpoint is
        ``config.out / "state_classifier.pt"``.
    """
    import torch

    from perception.photometric import PhotometricAugment
    from recordings.labels.dataset import read_steps
    from state_abstraction.classifier import ClassifierConfig, train_classifier

    log_config("train state-classifier", config)
    frames = {d: int(_metadata(d).get("config", {}).get("frames_per_step", 3))
              for d in config.data}
    if len(set(frames.values())) > 1:
        raise ValueError("the datasets' steps have different numbers of frames: "
                         + ", ".join(f"{d} {n}" for d, n in frames.items()))
    if config.init is not None and not Path(config.init).is_file():
        raise FileNotFoundError(f"--init {config.init}: no such state classifier checkpoint")
    check_output_folder(config.out)
    torch.set_num_threads(torch_threads())
    model = ClassifierConfig(frames=frames[config.data[0]],
                             epochs=config.epochs, batch_size=config.batch_size,
                             seed=config.seed, depth_dropout=config.depth_dropout,
                             lr=config.lr)
    splits = {}
    for split in ("train", "val", "test"):
        splits[split] = [step for data, weight in zip(config.data, config.data_weights,
                                                      strict=True)
                         for session in read_steps(data, split, model.frames)
                         for step in session
                         for _ in range(weight if split == "train" else 1)]
        logger.info("%s: %d steps of %d frames", split, len(splits[split]), model.frames)
    for split in ("train", "val"):
        if not splits[split]:
            raise ValueError(f"split {split!r} of {', '.join(map(str, config.data))} holds no "
                             f"complete step of {model.frames} frames")
    with epoch_bar("state classifier", model.epochs) as on_epoch:
        return train_classifier(splits["train"], splits["val"], splits["test"], model,
                                config.out, on_epoch=on_epoch,
                                device=resolve_device(config.device), init=config.init,
                                photometric=PhotometricAugment() if config.augment else None)


def detector_images(root: Path | str, split: str, *, inspection_repeat: int = 1,
                    empty_inspection_share: float = EMPTY_INSPECTION_SHARE, seed: int = 0,
                    allow_empty: bool = False) -> list[tuple[np.ndarray, list, list]]:
    """The labelled images the detector uses from a dataset split: ``(image, boxes, classes)``.

    Every camera frame; inspection views with an onion (each ``inspection_repeat`` times, the
    same triple object); ``empty_inspection_share`` of the views without one (chosen with
    ``seed``). A split without frames is an error, or empty with ``allow_empty``.
    """
    from recordings.labels.dataset import read_split

    root = Path(root)
    views = _metadata(root).get("views", ["camera"])
    rng = np.random.default_rng(seed)
    images = [(f.color, f.record["boxes"], f.record["classes"]) for f in read_split(root, split)]
    if "inspection" in views:
        for f in read_split(root, split, view="inspection"):
            if f.record["boxes"]:
                images.extend([(f.color, f.record["boxes"], f.record["classes"])]
                              * inspection_repeat)
            elif rng.random() < empty_inspection_share:
                images.append((f.color, [], []))
    if not images and not allow_empty:
        raise ValueError(f"split {split!r} of {root} holds no frames")
    return images


def frames_through_cameras(data: Sequence[Path], weights: Sequence[int], split: str,
                           seeds: Sequence[int]) -> list[tuple[np.ndarray, list, list]]:
    """The camera frames of ``split`` of each dataset of ``data`` (its ``weights`` times for
    the train split) seen through the camera each session has in the evaluation through other
    cameras (:class:`onionsort.stages.cameras.SessionCameras`), once per seed of ``seeds``:
    ``(image, boxes, classes)``, as :func:`detector_images` gives them."""
    from onionsort.stages.cameras import SessionCameras
    from recordings.labels.dataset import read_split

    if not seeds:
        return []
    cameras = [SessionCameras(seed) for seed in seeds]
    frames = [(f, weight if split == "train" else 1)  # read once, seen through each camera
              for root, weight in zip(data, weights, strict=True) for f in read_split(root, split)]
    return [image for camera in cameras for f, count in frames
            for image in [(camera(f.color, f.record), f.record["boxes"], f.record["classes"])]
            * count]


def train_detector(config: DetectorTrainConfig) -> dict:
    """Train the detector on ``config.data`` (or resume the run in ``config.out``).

    Returns
    -------
    dict
        The metrics of :func:`perception.train_detector.train_detector` (``val``, ``test`` mAP,
        ``history``, ...); the checkpoint is ``config.out / "detector.pt"``.
    """
    import torch

    from perception.train_detector import TrainConfig
    from perception.train_detector import train_detector as train

    log_config("train detector", config)
    if config.resume and not (config.out / "detector_last.pt").is_file():
        raise FileNotFoundError(f"cannot resume: {config.out / 'detector_last.pt'} does not "
                                "exist")
    for data in config.data:
        _metadata(data)
    check_output_folder(config.out)
    torch.set_num_threads(torch_threads())
    images = {split: [image for data, weight in zip(config.data, config.data_weights,
                                                    strict=True)
                      for image in detector_images(
                          data, split, seed=config.seed, allow_empty=len(config.data) > 1,
                          inspection_repeat=INSPECTION_REPEAT if split == "train" else 1)
                      * (weight if split == "train" else 1)]
              for split in ("train", "val", "test")}
    for split, seeds in (("train", config.through_cameras), ("val", config.through_cameras[:1])):
        images[split] += frames_through_cameras(config.data, config.data_weights, split, seeds)
    for split in ("train", "val"):
        if not images[split]:
            raise ValueError(f"split {split!r} of {', '.join(map(str, config.data))} holds no "
                             "frames")
    if config.init is not None and not Path(config.init).is_file():
        raise FileNotFoundError(f"--init {config.init}: no such detector checkpoint")
    model = TrainConfig(epochs=config.epochs, images_per_epoch=config.images_per_epoch,
                        batch_size=config.batch_size, seed=config.seed, lr=config.lr,
                        photometric=config.augment)
    with epoch_bar("detector", model.epochs) as on_epoch:
        return train(images["train"], images["val"], images["test"], model, config.out,
                     resume=config.resume, on_epoch=on_epoch,
                     device=resolve_device(config.device), init=config.init)
