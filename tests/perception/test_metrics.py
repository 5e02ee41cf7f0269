"""Our mAP equals pycocotools' COCOeval on fixed and on random boxes."""

import contextlib
import io

import numpy as np
import pytest

from perception.metrics import box_iou, mean_average_precision


def coco_reference(gts, dts):
    """mAP@0.5 and mAP@0.5:0.95 from pycocotools for the same boxes."""
    pytest.importorskip("pycocotools")
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    images, annotations, results = [], [], []
    for i, ((gb, gc), (db, ds, dc)) in enumerate(zip(gts, dts, strict=True)):
        images.append({"id": i, "width": 320, "height": 240})
        for b, c in zip(gb, gc, strict=True):
            w, h = b[2] - b[0], b[3] - b[1]
            annotations.append({"id": len(annotations) + 1, "image_id": i, "category_id": int(c),
                                "bbox": [float(b[0]), float(b[1]), float(w), float(h)],
                                "area": float(w * h), "iscrowd": 0})
        for b, s, c in zip(db, ds, dc, strict=True):
            results.append({"image_id": i, "category_id": int(c), "score": float(s),
                            "bbox": [float(b[0]), float(b[1]), float(b[2] - b[0]),
                                     float(b[3] - b[1])]})
    with contextlib.redirect_stdout(io.StringIO()):
        coco = COCO()
        coco.dataset = {"images": images, "annotations": annotations,
                        "categories": [{"id": 0, "name": "good"}, {"id": 1, "name": "blemished"}]}
        coco.createIndex()
        ev = COCOeval(coco, coco.loadRes(results) if results else COCO(), "bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    return {"map50_95": ev.stats[0], "map50": ev.stats[1], "map75": ev.stats[2]}


def _arr(boxes):
    return np.array(boxes, float).reshape(-1, 4)


FIXED_GT = [
    (_arr([[10, 10, 24, 24], [50, 50, 64, 66], [100, 20, 113, 33]]), np.array([0, 1, 0])),
    (_arr([[5, 5, 20, 20]]), np.array([1])),
    (_arr([[30, 30, 45, 44], [31, 60, 46, 75]]), np.array([0, 0])),
    (_arr([]), np.array([], int)),
]
FIXED_DT = [
    (_arr([[11, 10, 24, 25], [50, 51, 63, 66], [101, 21, 112, 33], [200, 200, 210, 210]]),
     np.array([0.9, 0.8, 0.4, 0.7]), np.array([0, 1, 0, 0])),
    (_arr([[5, 5, 20, 20], [6, 6, 21, 21]]), np.array([0.95, 0.6]), np.array([1, 1])),
    (_arr([[30, 30, 45, 44], [31, 61, 45, 75], [30, 31, 45, 45]]),
     np.array([0.5, 0.5, 0.55]), np.array([0, 1, 0])),
    (_arr([[0, 0, 10, 10]]), np.array([0.3]), np.array([1])),
]


def test_fixed_boxes_equal_pycocotools():
    ours = mean_average_precision(FIXED_GT, FIXED_DT)
    ref = coco_reference(FIXED_GT, FIXED_DT)
    for k in ("map50", "map50_95", "map75"):
        assert ours[k] == pytest.approx(ref[k], abs=1e-9), k
    assert 0.3 < ours["map50_95"] < ours["map50"] < 1.0


@pytest.mark.parametrize("seed", range(6))
def test_random_boxes_equal_pycocotools(seed):
    rng = np.random.default_rng(seed)
    gts, dts = [], []
    for _ in range(8):
        g = rng.integers(0, 5)
        xy = rng.uniform(0, 280, (g, 2))
        gb = np.concatenate([xy, xy + rng.uniform(6, 40, (g, 2))], 1).round()
        gc = rng.integers(0, 2, g)
        keep = rng.random(g) < 0.8  # missed objects
        jitter = rng.normal(0, 2.5, (int(keep.sum()), 4))
        db = np.concatenate([gb[keep] + jitter, np.concatenate(
            [q := rng.uniform(0, 280, (2, 2)), q + 12], 1)])  # false positives
        dc = np.concatenate([np.where(rng.random(int(keep.sum())) < 0.9, gc[keep],
                                      1 - gc[keep]), rng.integers(0, 2, 2)])
        ds = rng.uniform(0.05, 1.0, len(db)).round(2)  # ties in scores too
        db[:, 2:] = np.maximum(db[:, 2:], db[:, :2] + 1)
        gts.append((gb, gc))
        dts.append((db, ds, dc))
    ours = mean_average_precision(gts, dts)
    ref = coco_reference(gts, dts)
    for k in ("map50", "map50_95"):
        assert ours[k] == pytest.approx(ref[k], abs=1e-9), k


def test_perfect_detections_score_one():
    dts = [(gb, np.ones(len(gb)), gc) for gb, gc in FIXED_GT]
    ours = mean_average_precision(FIXED_GT, dts)
    assert ours["map50"] == pytest.approx(1.0) and ours["map50_95"] == pytest.approx(1.0)


def test_iou_and_argument_checks():
    np.testing.assert_allclose(box_iou(_arr([[0, 0, 10, 10]]), _arr([[5, 0, 15, 10]])), [[1 / 3]])
    with pytest.raises(ValueError, match="same images"):
        mean_average_precision(FIXED_GT, FIXED_DT[:2])


def test_any_class_counts_the_boxes_whatever_class_they_are_called():
    # every box found, every class called wrong: nothing per class, everything found
    dts = [(gb, np.ones(len(gb)), 1 - gc) for gb, gc in FIXED_GT]
    assert mean_average_precision(FIXED_GT, dts)["map50"] == pytest.approx(0.0)
    assert mean_average_precision(FIXED_GT, dts, any_class=True)["map50"] == pytest.approx(1.0)
    # a box missed counts against any_class as well
    half = [(gb[:1], np.ones(1), gc[:1]) for gb, gc in FIXED_GT]
    assert mean_average_precision(FIXED_GT, half, any_class=True)["map50"] < 0.9
