"""The readers and writers of labelled image sets: COCO, YOLO and the states CSV."""

import json

import cv2
import numpy as np
import pytest

from irl.domains.onion_sorting import SORTING_TASK
from recordings.labels.annotated import BadAnnotations, check_box, split_name
from recordings.labels.coco import CocoImage, read_coco, write_coco
from recordings.labels.states_csv import StatesRow, read_states, write_states
from recordings.labels.yolo import read_yolo, write_data_yaml, yolo_lines


def _image(path, width=40, height=30):
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.full((height, width, 3), 90, np.uint8))


def test_coco_written_reads_back_with_the_same_boxes_and_names(tmp_path):
    images = [CocoImage("a.png", 40, 30, [[1, 2, 11, 12], [20, 5, 30.5, 9]], [0, 1]),
              CocoImage("b.png", 40, 30, [], [])]
    write_coco(tmp_path / "annotations" / "instances_val.json", images, ("good", "blemished"))
    for name in ("a.png", "b.png"):
        _image(tmp_path / "val" / name)
    read = read_coco(tmp_path)
    assert [(i.split, i.name, i.path) for i in read] == [
        ("val", "a.png", tmp_path / "val" / "a.png"), ("val", "b.png", tmp_path / "val" / "b.png")]
    assert read[0].boxes == ((1, 2, 11, 12), (20, 5, 30.5, 9))
    assert read[0].labels == ("good", "blemished") and read[1].boxes == ()


def test_coco_reads_roboflow_splits_and_a_set_without_splits(tmp_path):
    doc = {"images": [{"id": 0, "file_name": "x.jpg", "width": 40, "height": 30}],
           "annotations": [{"id": 0, "image_id": 0, "category_id": 1, "bbox": [1, 1, 5, 5]}],
           "categories": [{"id": 0, "name": "onions"}, {"id": 1, "name": "rotten"}]}
    for split in ("train", "valid"):
        (tmp_path / "rf" / split).mkdir(parents=True)
        (tmp_path / "rf" / split / "_annotations.coco.json").write_text(json.dumps(doc))
    assert [(i.split, i.labels) for i in read_coco(tmp_path / "rf")] == [
        ("train", ("rotten",)), ("val", ("rotten",))]
    (tmp_path / "flat" / "annotations").mkdir(parents=True)
    (tmp_path / "flat" / "annotations" / "instances_default.json").write_text(json.dumps(doc))
    _image(tmp_path / "flat" / "images" / "x.jpg")
    (only,) = read_coco(tmp_path / "flat")
    assert only.split is None and only.path == tmp_path / "flat" / "images" / "x.jpg"


@pytest.mark.parametrize("doc, message", [
    ({"info": {}}, "is not COCO"),
    ([1, 2], "is not COCO"),
    ({"images": [{"id": 1, "file_name": "a.png"}], "categories": [{"id": 1, "name": "g"}],
      "annotations": [{"image_id": 1, "category_id": 1, "bbox": [1, 2, 3]}]}, "4 numbers"),
    ({"images": [{"id": 1, "file_name": "a.png"}], "categories": [{"id": 1, "name": "g"}],
      "annotations": [{"image_id": 7, "category_id": 1, "bbox": [1, 2, 3, 4]}]}, "image_id 7"),
])
def test_coco_that_is_not_refuses_naming_the_file(tmp_path, doc, message):
    (tmp_path / "annotations").mkdir()
    (tmp_path / "annotations" / "instances_train.json").write_text(json.dumps(doc))
    with pytest.raises(BadAnnotations, match=message) as err:
        read_coco(tmp_path)
    assert "instances_train.json" in str(err.value)


def test_yolo_lines_give_the_pixels_back_and_read_as_boxes(tmp_path):
    boxes, classes = [[3, 4, 13, 10], [0, 0, 40, 30]], [1, 0]
    write_data_yaml(tmp_path, ("train", "val"), ("good", "blemished"))
    for split in ("train", "val"):
        _image(tmp_path / "images" / split / "f.png")
        (tmp_path / "labels" / split).mkdir(parents=True)
    (tmp_path / "labels" / "train" / "f.txt").write_text(yolo_lines(boxes, classes, 40, 30))
    read = read_yolo(tmp_path)
    assert [(i.split, i.name) for i in read] == [("train", "f.png"), ("val", "f.png")]
    assert read[0].labels == ("blemished", "good") and read[1].boxes == ()
    assert np.allclose(read[0].pixel_boxes(40, 30), boxes, atol=1e-9)


def test_yolo_polygons_give_their_bounding_box_and_roboflow_folders_read(tmp_path):
    (tmp_path / "data.yaml").write_text(
        "train: ../train/images\nval: ../valid/images\nnc: 1\nnames: ['rotten']\n")
    for split in ("train", "valid"):
        _image(tmp_path / split / "images" / "f.jpg")
        (tmp_path / split / "labels").mkdir()
        (tmp_path / split / "labels" / "f.txt").write_text("0 0.1 0.2 0.5 0.2 0.3 0.6\n")
    read = read_yolo(tmp_path)
    assert [i.split for i in read] == ["train", "val"]
    assert read[0].boxes == ((0.1, 0.2, 0.5, 0.6),)


@pytest.mark.parametrize("line, message", [
    ("0 0.5 0.5 0.1", "expected 5 numbers"),
    ("0 0.5 0.5 0.1 0.1 0.2", "expected 5 numbers"),
    ("3 0.5 0.5 0.1 0.1", "class 3 is not among"),
    ("good 0.5 0.5 0.1 0.1", "integer class"),
])
def test_a_bad_yolo_line_names_its_file_and_line(tmp_path, line, message):
    write_data_yaml(tmp_path, ("train",), ("good", "blemished"))
    _image(tmp_path / "images" / "train" / "f.png")
    (tmp_path / "labels" / "train").mkdir(parents=True)
    (tmp_path / "labels" / "train" / "f.txt").write_text(f"1 0.5 0.5 0.2 0.2\n{line}\n")
    with pytest.raises(BadAnnotations, match=message) as err:
        read_yolo(tmp_path)
    assert "f.txt line 2" in str(err.value)


def test_a_box_past_the_edge_is_clipped_within_a_pixel_and_refused_beyond():
    assert check_box((-0.5, 0, 40.4, 30), 40, 30, "x") == (0, 0, 40, 30)
    with pytest.raises(BadAnnotations, match="outside its 40x30 image"):
        check_box((30, 20, 45, 28), 40, 30, "x")
    with pytest.raises(BadAnnotations, match="empty"):
        check_box((5, 5, 5, 9), 40, 30, "x")
    assert split_name("valid") == "val" and split_name("holdout") is None


def _rows():
    return [StatesRow("train", "a.png", 0, 0, 0, False,
                      {"onion": 0, "end_effector": 1, "prediction": 2}, 1),
            StatesRow(None, "b.png", 4, 7, 21, True,
                      {"onion": 3, "end_effector": 0, "prediction": 1}, 4)]


def test_states_csv_round_trips_in_the_tasks_words(tmp_path):
    path = write_states(tmp_path / "states.csv", _rows(), SORTING_TASK)
    text = path.read_text()
    assert text.splitlines()[0] == ("split,image,session,step,frame,occluded,onion,"
                                    "end_effector,prediction,action")
    assert SORTING_TASK.factors["onion"][3] in text.splitlines()[2]
    back = read_states(path, SORTING_TASK)
    assert [(r.split, r.image, r.session, r.step, r.frame, r.occluded, r.factors, r.action)
            for r in back] == [(r.split, r.image, r.session, r.step, r.frame, r.occluded,
                                r.factors, r.action) for r in _rows()]


@pytest.mark.parametrize("column, value, message", [
    ("onion", "flying", "onion 'flying' is not a value of the task"),
    ("action", "juggle", "action 'juggle' is not a value"),
    ("step", "two", "step must be an integer"),
    ("occluded", "maybe", "occluded must be 0 or 1"),
    ("split", "holdout", "split 'holdout' is not"),
])
def test_a_bad_csv_value_names_the_line_and_column(tmp_path, column, value, message):
    path = write_states(tmp_path / "states.csv", _rows(), SORTING_TASK)
    lines = path.read_text().splitlines()
    k = lines[0].split(",").index(column)
    fields = lines[2].split(",")
    fields[k] = value
    path.write_text("\n".join([lines[0], lines[1], ",".join(fields)]) + "\n")
    with pytest.raises(BadAnnotations, match=message) as err:
        read_states(path, SORTING_TASK)
    assert "states.csv line 3" in str(err.value)


def test_a_csv_without_a_factors_column_is_refused(tmp_path):
    (tmp_path / "s.csv").write_text("split,image,session,step,frame,occluded,onion,action\n")
    with pytest.raises(BadAnnotations, match="'end_effector', 'prediction'"):
        read_states(tmp_path / "s.csv", SORTING_TASK)
