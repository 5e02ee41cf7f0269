"""``onionsort label``: a dataset out as COCO and YOLO and back in, sets that tools write, and
bad input (one line, exit 2, nothing written)."""

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from onionsort.cli import main
from recordings.labels.dataset import (
    CLASSES,
    SPLITS,
    VIEWS,
    read_records,
    read_steps,
    split_sessions,
)

#: The record fields export then import keeps: boxes, classes, the state labels and the
#: robot's line-up fields.
KEPT = ("boxes", "classes", "state", "onion", "end_effector", "prediction", "action",
        "occluded", "phase", "step", "session", "frame", "source", "lineup", "index", "view")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A small rendered dataset: 3 sessions of 4 steps of 3 frames, and the Sawyer's views."""
    out = tmp_path_factory.mktemp("label") / "data"
    assert main(["dataset", "--frames", "36", "--steps-per-session", "4", "--robot-onions",
                 "10", "--robot-views", "2", "--seed", "3", "--workers", "1",
                 "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def exported(rendered, tmp_path_factory):
    """``{format: folder}``: the rendered dataset exported in each format."""
    root = tmp_path_factory.mktemp("exported")
    for fmt in ("coco", "yolo"):
        assert main(["label", "export", str(rendered), "--format", fmt,
                     "--out", str(root / fmt)]) == 0
    return {fmt: root / fmt for fmt in ("coco", "yolo")}


def _same_dataset(a: Path, b: Path) -> None:
    """Frames bit-equal (colour and depth PNG files), boxes, classes and states equal."""
    for view in VIEWS:
        for split in SPLITS:
            ra, rb = read_records(a, split, view), read_records(b, split, view)
            assert len(ra) == len(rb) > 0, (view, split)
            for x, y in zip(ra, rb, strict=True):
                assert {k: x[k] for k in KEPT if k in x} == {k: y[k] for k in KEPT if k in y}
                assert (a / split / x["color"]).read_bytes() == (b / split / y["color"]
                                                                 ).read_bytes()
                assert ("depth" in x) == ("depth" in y)
                if "depth" in x:
                    assert (a / split / x["depth"]).read_bytes() == (b / split / y["depth"]
                                                                     ).read_bytes()


@pytest.mark.parametrize("fmt", ["coco", "yolo"])
def test_export_then_import_gives_the_same_dataset(rendered, exported, tmp_path, fmt):
    robot = [r for s in SPLITS for r in read_records(rendered, s, "inspection")
             if r.get("source") == "robot"]
    assert robot and all({"lineup", "index", "view"} <= set(r) for r in robot)
    assert main(["label", "import", str(exported[fmt]), "--format", fmt,
                 "--out", str(tmp_path / "back")]) == 0
    _same_dataset(rendered, tmp_path / "back")
    assert [len(s) for s in read_steps(tmp_path / "back", "all", 3)] == [
        len(s) for s in read_steps(rendered, "all", 3)]


def test_the_coco_export_loads_in_pycocotools_with_the_same_counts(rendered, exported):
    coco_api = pytest.importorskip("pycocotools.coco")
    for view, base in (("camera", exported["coco"]), ("inspection",
                                                      exported["coco"] / "inspection")):
        for split in SPLITS:
            records = read_records(rendered, split, view)
            coco = coco_api.COCO(str(base / "annotations" / f"instances_{split}.json"))
            assert len(coco.getImgIds()) == len(records)
            for k, name in enumerate(CLASSES):
                (cat,) = coco.getCatIds(catNms=[name])
                assert len(coco.getAnnIds(catIds=[cat])) == sum(
                    c == k for r in records for c in r["classes"])
            for img in coco.loadImgs(coco.getImgIds()):
                assert (base / split / img["file_name"]).is_file()


def test_the_yolo_export_has_ultralytics_layout(rendered, exported):
    import yaml

    data = yaml.safe_load((exported["yolo"] / "data.yaml").read_text())
    assert data["names"] == dict(enumerate(CLASSES))
    records = read_records(rendered, "val")
    labels = sorted((exported["yolo"] / "labels" / "val").glob("*.txt"))
    assert len(labels) == len(records) == len(list(
        (exported["yolo"] / data["val"]).glob("*.png")))
    rec = records[0]
    h, w = cv2.imread(str(rendered / "val" / rec["color"])).shape[:2]
    lines = (exported["yolo"] / "labels" / "val" / Path(rec["color"]).with_suffix(
        ".txt").name).read_text().splitlines()
    cls, cx, cy, bw, bh = lines[0].split()
    x0, y0, x1, y1 = rec["boxes"][0]
    assert int(cls) == rec["classes"][0]
    assert np.allclose([float(cx), float(cy), float(bw), float(bh)],
                       [(x0 + x1) / 2 / w, (y0 + y1) / 2 / h, (x1 - x0) / w, (y1 - y0) / h])


def test_ultralytics_own_loader_reads_every_box_of_the_yolo_export(rendered, exported,
                                                                     tmp_path, run_tool):
    """Ultralytics' dataset check and loader (as its trainer reads a set) read every split of
    the YOLO export: no corrupt, missing or empty label file, every image, and every box of
    each class that the dataset holds."""
    shutil.copytree(exported["yolo"], tmp_path / "yolo")  # the loader writes its caches
    read = run_tool("ultralytics", "check_yolo.py", str(tmp_path / "yolo" / "data.yaml"),
                    env={"YOLO_OFFLINE": "1", "YOLO_CONFIG_DIR": str(tmp_path / "config")})
    assert read["names"] == {str(k): name for k, name in enumerate(CLASSES)}
    for split in SPLITS:
        records = read_records(rendered, split)
        boxes = {str(k): sum(c == k for r in records for c in r["classes"])
                 for k in range(len(CLASSES))}
        empty = sum(not r["classes"] for r in records)
        assert read[split] == {
            "found": len(records) - empty, "missing": 0, "empty": empty, "corrupt": 0,
            "images": len(records), "total": len(records),
            "boxes": {k: n for k, n in boxes.items() if n}}, split


def test_a_set_without_splits_in_jpeg_and_larger_splits_by_session_and_keeps_boxes(
        rendered, exported, tmp_path):
    """One COCO file and a states CSV without splits, images four times larger as JPEG:
    split by session as `onionsort dataset` does; shrunk to the detector's canvas, boxes with
    them; depth matched by file name, shrunk too."""
    src, flat = exported["coco"], tmp_path / "flat"
    (flat / "images").mkdir(parents=True)
    (flat / "depth").mkdir()
    doc = {"images": [], "annotations": [], "categories": [{"id": 0, "name": "sound"},
                                                           {"id": 1, "name": "rotten"}]}
    rows = ["split,image,session,step,frame,occluded,onion,end_effector,prediction,action"]
    states = {tuple(line.split(",")[:2]): line.split(",")
              for line in (src / "states.csv").read_text().splitlines()[1:]}
    for split in SPLITS:
        cam = json.loads((src / "annotations" / f"instances_{split}.json").read_text())
        for im in cam["images"]:
            name = f"{split}-{Path(im['file_name']).stem}.jpg"
            big = cv2.resize(cv2.imread(str(src / split / im["file_name"])), None, fx=4, fy=4,
                             interpolation=cv2.INTER_NEAREST)
            cv2.imwrite(str(flat / "images" / name), big, [cv2.IMWRITE_JPEG_QUALITY, 95])
            depth = cv2.imread(str(src / "depth" / split / im["file_name"]),
                               cv2.IMREAD_UNCHANGED)
            cv2.imwrite(str(flat / "depth" / Path(name).with_suffix(".png")),
                        cv2.resize(depth, None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST))
            doc["images"].append({"id": len(doc["images"]), "file_name": name,
                                  "width": big.shape[1], "height": big.shape[0]})
            for a in cam["annotations"]:
                if a["image_id"] == im["id"]:
                    doc["annotations"].append({"id": len(doc["annotations"]),
                                               "image_id": doc["images"][-1]["id"],
                                               "category_id": a["category_id"] - 1,
                                               "bbox": [4 * v for v in a["bbox"]]})
            row = states[split, im["file_name"]]
            rows.append(",".join(["", name, *row[2:]]))
    (flat / "_annotations.coco.json").write_text(json.dumps(doc))
    (flat / "states.csv").write_text("\n".join(rows) + "\n")
    out = tmp_path / "lab"
    assert main(["label", "import", str(flat), "--format", "coco", "--classes",
                 "good=sound,blemished=rotten", "--out", str(out)]) == 0
    assert split_sessions(out, "all") == split_sessions(rendered, "all")
    for split in SPLITS:
        mine, theirs = read_records(out, split), read_records(rendered, split)
        assert [r["frame"] for r in mine] == [r["frame"] for r in theirs]
        for x, y in zip(mine, theirs, strict=True):
            h, w = cv2.imread(str(rendered / split / y["color"])).shape[:2]
            scale = 4 * min(320 / (4 * w), 256 / (4 * h))  # 4x larger, shrunk to the canvas
            assert x["boxes"] == [[scale * v for v in b] for b in y["boxes"]]
            assert x["classes"] == y["classes"] and x["state"] == y["state"]
            color = cv2.imread(str(out / split / x["color"]))
            assert color.shape == (round(4 * h * scale / 4), round(4 * w * scale / 4), 3)
            depth = cv2.imread(str(out / split / x["depth"]), cv2.IMREAD_UNCHANGED)
            assert depth.dtype == np.uint16 and depth.shape == color.shape[:2]


def test_frames_without_states_are_box_only(rendered, exported, tmp_path):
    """Rows of the first session only: its steps reach the state classifier and calibration,
    the other sessions' frames only the detector."""
    src = tmp_path / "coco"
    shutil.copytree(exported["coco"], src)
    lines = (src / "states.csv").read_text().splitlines()
    kept = [line for line in lines[1:] if line.split(",")[2] == "0"]
    (src / "partial.csv").write_text("\n".join([lines[0], *kept]) + "\n")
    out = tmp_path / "out"
    assert main(["label", "import", str(src), "--format", "coco", "--states",
                 str(src / "partial.csv"), "--out", str(out)]) == 0
    train = read_records(out, "train")
    assert len(train) == len(read_records(rendered, "train"))
    assert split_sessions(out, "all") == [("train", 0)]
    assert [len(s) for s in read_steps(out, "all", 3)] == [4]
    boxed = [r for r in read_records(out, "val")]
    assert boxed and all(set(r) == {"color", "depth", "source", "image", "boxes", "classes"}
                         for r in boxed)
    from onionsort.stages.train import detector_images

    assert len(detector_images(out, "val")) >= len(boxed)
    # calibration measures the steps with states alone; the detector's mAP every frame
    assert main(["calibrate", "--data", str(out), "--split", "all", "--workers", "1",
                 "--out", str(tmp_path / "cal")]) == 0
    saved = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert saved["metrics"]["n_steps"] == 4


# -- bad input -------------------------------------------------------------------------------


def _drop_image(d: Path) -> str:
    (d / "train" / "s0000_0001.png").unlink()
    return "image 's0000_0001.png' is not in the folder"


def _box_outside(d: Path) -> str:
    path = d / "annotations" / "instances_val.json"
    doc = json.loads(path.read_text())
    doc["annotations"][0]["bbox"] = [300, 220, 40, 40]
    path.write_text(json.dumps(doc))
    return "box [300, 220, 340, 260] lies outside its 320x240 image"


def _not_coco(d: Path) -> str:
    (d / "annotations" / "instances_test.json").write_text(json.dumps({"images": {}}))
    return "instances_test.json is not COCO"


def _csv_value(d: Path) -> str:
    path = d / "states.csv"
    lines = path.read_text().splitlines()
    fields = lines[3].split(",")
    fields[6] = "flying"
    path.write_text("\n".join([*lines[:3], ",".join(fields), *lines[4:]]) + "\n")
    return "states.csv line 4: onion 'flying' is not a value of the task"


def _csv_row_without_image(d: Path) -> str:
    path = d / "states.csv"
    lines = path.read_text().splitlines()
    fields = lines[1].split(",")
    fields[1] = "nowhere.png"
    path.write_text("\n".join([*lines, ",".join(fields)]) + "\n")
    return f"line {len(lines) + 1}: image 'nowhere.png' of split train is not among"


def _yolo_four_numbers(d: Path) -> str:
    label = d / "labels" / "test" / "s0002_0000.txt"
    label.write_text(label.read_text() + "1 0.5 0.5 0.1\n")
    return "s0002_0000.txt line"


def _lineup_without_image(d: Path) -> str:
    path = d / "inspection" / "lineups.csv"
    path.write_text(path.read_text() + "train,nowhere.png,0,1,0\n")
    return "lineups.csv line 22: image 'nowhere.png' of split train is not among"


def _lineup_negative(d: Path) -> str:
    path = d / "inspection" / "lineups.csv"
    lines = path.read_text().splitlines()
    lines[2] = lines[2].rsplit(",", 1)[0] + ",-1"
    path.write_text("\n".join(lines) + "\n")
    return "lineups.csv line 3: view must be an integer >= 0; got '-1'"


BAD = [("coco", _drop_image, []), ("coco", _box_outside, []), ("coco", _not_coco, []),
       ("coco", None, ["--classes", "good=sound"]), ("coco", _csv_value, []),
       ("coco", _csv_row_without_image, []), ("yolo", _yolo_four_numbers, []),
       ("yolo", _lineup_without_image, []), ("coco", _lineup_negative, [])]


@pytest.mark.parametrize("fmt, spoil, extra", BAD,
                         ids=["missing image", "box outside", "not COCO", "class not mapped",
                              "CSV value", "CSV row without image", "YOLO 4 numbers",
                              "line-up row without image", "line-up view negative"])
def test_bad_input_is_one_line_exit_2_and_nothing_written(exported, tmp_path, capsys, fmt,
                                                          spoil, extra):
    src = tmp_path / "in"
    shutil.copytree(exported[fmt], src)
    expected = spoil(src) if spoil else "class 'good' of s000"
    given = {p: p.read_bytes() for p in src.rglob("*") if p.is_file()}
    code = main(["label", "import", str(src), "--format", fmt, *extra,
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and len(err) == 1, err
    assert expected in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]  # no dataset, no leftovers
    assert {p: p.read_bytes() for p in given} == given


def test_export_refuses_a_folder_that_holds_files(rendered, tmp_path, capsys):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "keep.txt").write_text("mine")
    assert main(["label", "export", str(rendered), "--format", "coco",
                 "--out", str(tmp_path / "out")]) == 2
    assert "is not an empty folder" in capsys.readouterr().err
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["keep.txt"]


def test_the_canvas_imports_fit_is_the_detectors():
    from onionsort.stages.label import FIT
    from perception.model import DetectorConfig

    assert (DetectorConfig().width, DetectorConfig().height) == FIT


# -- sets the project did not write ----------------------------------------------------------


def _their_sets(rendered: Path, out: Path) -> dict[str, Path]:
    """A COCO and a YOLO set of ``rendered`` as another tool writes them, built here from the
    records with json and plain text (not with the project's writers): JPEG at quality 95,
    file names of its own, a states CSV per view, the Sawyer's views box-only."""
    task_columns = ["onion", "end_effector", "prediction"]
    from irl.domains.onion_sorting import SORTING_TASK as task

    sets = {"coco": out / "coco", "yolo": out / "yolo"}
    for view in VIEWS:
        sub = "" if view == "camera" else "inspection"
        rows = ["split,image,session,step,frame,occluded," + ",".join(task_columns)
                + ",action"]
        yaml_lines = []
        for split in SPLITS:
            doc = {"images": [], "annotations": [],
                   "categories": [{"id": 7, "name": "good"}, {"id": 9, "name": "blemished"}]}
            for k, rec in enumerate(read_records(rendered, split, view)):
                name = f"frame-{k:05d}.jpg"
                bgr = cv2.imread(str(rendered / split / rec["color"]))
                h, w = bgr.shape[:2]
                for folder in (sets["coco"] / sub / f"{split}2017",
                               sets["yolo"] / sub / "images" / split):
                    folder.mkdir(parents=True, exist_ok=True)
                    cv2.imwrite(str(folder / name), bgr, [cv2.IMWRITE_JPEG_QUALITY, 95])
                doc["images"].append({"id": 100 + k, "file_name": name, "width": w,
                                      "height": h})
                lines = []
                for (x0, y0, x1, y1), c in zip(rec["boxes"], rec["classes"], strict=True):
                    doc["annotations"].append({
                        "id": len(doc["annotations"]) + 1, "image_id": 100 + k,
                        "category_id": (7, 9)[c], "bbox": [x0, y0, x1 - x0, y1 - y0],
                        "area": (x1 - x0) * (y1 - y0), "iscrowd": 0})
                    lines.append(f"{c} {(x0 + x1) / 2 / w:.6f} {(y0 + y1) / 2 / h:.6f} "
                                 f"{(x1 - x0) / w:.6f} {(y1 - y0) / h:.6f}")
                labels = sets["yolo"] / sub / "labels" / split
                labels.mkdir(parents=True, exist_ok=True)
                (labels / f"frame-{k:05d}.txt").write_text("\n".join(lines))
                if "state" in rec:
                    rows.append(",".join(str(v) for v in (
                        split, name, rec["session"], rec["step"], rec["frame"],
                        int(rec["occluded"]),
                        *(task.factors[f][rec[f]] for f in task_columns),
                        task.action_names[rec["action"]])))
            ann = sets["coco"] / sub / "annotations"
            ann.mkdir(parents=True, exist_ok=True)
            (ann / f"instances_{split}2017.json").write_text(json.dumps(doc))
            yaml_lines.append(f"{split}: images/{split}")
        (sets["yolo"] / sub / "data.yaml").write_text(
            "\n".join(yaml_lines) + "\nnc: 2\nnames: [good, blemished]\n")
        for folder in sets.values():
            (folder / sub / "states.csv").write_text("\n".join(rows) + "\n")
    return sets


def _within_a_hundredth(imported: dict, original: dict) -> None:
    assert imported["n_steps"] == original["n_steps"] > 0
    for key in ("map50", "map50_95"):
        assert abs(imported[key] - original[key]) <= 0.01, (key, imported[key], original[key])
    for factor, value in original["accuracy"].items():
        assert abs(imported["accuracy"][factor] - value) <= 0.01, (factor, imported, original)


def test_their_sets_in_jpeg_measure_as_the_original(rendered, tmp_path):
    """Acceptance, fast: eval-perception --no-depth (the stage, the models loaded once) on
    the small set's test split gives mAP and every factor's accuracy within 0.01 on each
    imported set and on the dataset it was made from (the slow test below: 600 fresh frames
    at the command line)."""
    from onionsort.stages import PerceptionEvalConfig, eval_perception
    from onionsort.stages.models import PerceptionModels

    models = PerceptionModels.load(None, "cpu")

    def measured(data: Path) -> dict:
        return eval_perception(PerceptionEvalConfig(data=data, split="test", depth=False),
                               models=models)

    original = measured(rendered)
    for fmt, theirs in _their_sets(rendered, tmp_path / "theirs").items():
        out = tmp_path / f"imported-{fmt}"
        assert main(["label", "import", str(theirs), "--format", fmt, "--out", str(out)]) == 0
        _within_a_hundredth(measured(out), original)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["coco", "yolo"])
def test_their_sets_of_a_larger_fresh_dataset_measure_as_the_original(tmp_path, capsys, fmt):
    """Acceptance at the command line, on 600 fresh frames of every difficulty level."""
    data = tmp_path / "data"
    assert main(["dataset", "--frames", "600", "--seed", "37", "--robot-onions", "20",
                 "--difficulty", "clean,realistic,paper,hard", "--out", str(data)]) == 0
    theirs = _their_sets(data, tmp_path / "theirs")[fmt]
    out = tmp_path / "imported"
    assert main(["label", "import", str(theirs), "--format", fmt, "--out", str(out)]) == 0
    capsys.readouterr()
    measured = []
    for folder in (data, out):
        assert main(["eval-perception", "--data", str(folder), "--split", "all", "--no-depth",
                     "--json"]) == 0
        measured.append(json.loads(capsys.readouterr().out.strip().splitlines()[-1]))
    with capsys.disabled():
        for name, m in zip(("original", f"imported {fmt}"), measured, strict=True):
            print(f"\n{name}: mAP@0.5 {m['map50']:.4f}, mAP@0.5:0.95 {m['map50_95']:.4f}, "
                  + ", ".join(f"{k} {v:.4f}" for k, v in m["accuracy"].items())
                  + f" ({m['n_steps']} steps)")
    _within_a_hundredth(measured[1], measured[0])
