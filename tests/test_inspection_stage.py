"""The inspection stage end to end on a small rendered dataset: training writes a classifier
the pipeline loads, ``fusion`` fixes its rule, and the measurement reports every level it saw."""

import json

import pytest

from onionsort.stages import DatasetConfig, make_dataset
from onionsort.stages.inspection import (
    InspectionTrainStageConfig,
    inspection_views,
    measure_inspection,
    train_inspection_stage,
)
from onionsort.stages.models import PerceptionModels


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("inspection") / "data"
    make_dataset(DatasetConfig(out=root, frames=90, steps_per_session=5, robot_onions=30,
                               robot_views=3, seed=3))  # 3 line-ups: one a split
    return root


def test_training_writes_a_classifier_with_the_fusion_rule_asked_for(dataset, tmp_path):
    metrics = train_inspection_stage(InspectionTrainStageConfig(
        data=dataset, out=tmp_path, epochs=1, batch_size=64, fusion="log-odds", visibility=0.3,
        device="cpu"))
    assert metrics["rule"] == "log-odds"
    assert set(metrics["rules"]) == {"noisy-or", "log-odds"}
    assert json.loads((tmp_path / "inspection_metrics.json").read_text())["rule"] == "log-odds"
    shipped = PerceptionModels.load(device="cpu")
    for name in ("detector.pt", "state_classifier.pt"):
        (tmp_path / name).write_bytes((shipped.folder / name).read_bytes())
    models = PerceptionModels.load(tmp_path, device="cpu")
    assert models.inspection.rule == "log-odds" and models.inspection.visibility == 0.3
    report = measure_inspection(models, dataset, "all", views=2)
    assert set(report["levels"]) == {"clean"}  # the dataset's one level, from its records
    robot = report["levels"]["clean"]["robot"]
    assert robot["views"] == 30 * 2  # the first 2 of each onion's 3 views
    assert set(robot["fused"]) == {"noisy-or", "log-odds"}
    assert robot["fused"]["noisy-or"]["onions"] == 30
    for fused in robot["fused"].values():  # ECE beside chance's median and 90th percentile
        assert 0 < fused["ece_by_chance"] < fused["ece_by_chance_90"] < 1
    # the class call's two errors, weighed by the views of each class, are its error
    views = inspection_views(dataset, "all", detector=models.detector)
    found = views.found & (views.source == "robot") & (views.view < 2)
    good, blemished = int((found & (views.classes == 0)).sum()), int(
        (found & (views.classes == 1)).sum())
    assert good and blemished
    errors = (good * robot["good_views_called_blemished"]
              + blemished * robot["blemished_views_called_good"])
    assert errors / (good + blemished) == pytest.approx(1 - robot["view_accuracy"])


def test_a_robot_classifier_reads_the_robots_views_and_the_sorters_stay_shared(dataset,
                                                                            tmp_path):
    import numpy as np

    metrics = train_inspection_stage(InspectionTrainStageConfig(
        data=dataset, out=tmp_path, epochs=1, batch_size=64, fusion="log-odds", device="cpu",
        camera="robot"))
    assert metrics["camera"] == "robot" and metrics["file"] == "robot_inspection_classifier.pt"
    assert (tmp_path / "robot_inspection_classifier.pt").is_file()
    assert (tmp_path / "robot_inspection_metrics.json").is_file()
    assert not (tmp_path / "inspection_classifier.pt").exists()
    assert not (tmp_path / "inspection_metrics.json").exists()
    shipped = PerceptionModels.load(device="cpu")
    for name in ("detector.pt", "state_classifier.pt", "inspection_classifier.pt"):
        (tmp_path / name).write_bytes((shipped.folder / name).read_bytes())
    models = PerceptionModels.load(tmp_path, device="cpu")
    robot, sorter = models.inspector(camera="robot"), models.inspector()
    assert robot.classifier is models.robot_inspection and robot.rule == "log-odds"
    assert sorter.classifier is models.inspection and sorter.rule == shipped.inspection.rule
    assert shipped.robot_inspection is None or shipped.inspector(camera="robot").classifier \
        is shipped.robot_inspection
    assert "robot_inspection_sha256" in models.describe()
    if "fused_calibration" in metrics:  # fitted on the robot's val onions, applied on loading
        assert models.robot_inspection.fused_calibration == {
            rule: (fit["low"], fit["high"], fit["form"])
            for rule, fit in metrics["fused_calibration"]["rules"].items()}
        assert models.inspection.fused_calibration == {}
    # the robot's views are measured with its own classifier, the sorter's with the shared one
    report = measure_inspection(models, dataset, "all", views=3)
    assert report["robot_rule"] == "log-odds" and report["rule"] == shipped.inspection.rule
    level = report["levels"]["clean"]
    only_robot = measure_inspection(PerceptionModels(
        classifier=None, detector=models.detector, folder=tmp_path,
        inspection=models.robot_inspection), dataset, "all", views=3)["levels"]["clean"]
    assert level["robot"]["fused"] == only_robot["robot"]["fused"]
    if "human" in level:
        only_sorter = measure_inspection(PerceptionModels(
            classifier=None, detector=models.detector, folder=tmp_path,
            inspection=models.inspection), dataset, "all", views=3)["levels"]["clean"]
        assert level["human"]["fused"] == only_sorter["human"]["fused"]
    with pytest.raises(ValueError, match="camera must be 'sorter' or 'robot'"):
        models.inspection_for("wrist")
    # it validated on the robot's views the detector found, and on no view of the sorter's
    val = inspection_views(dataset, "val", detector=models.detector)
    robot_val = int(np.sum(val.found & (val.source == "robot")))
    assert metrics["n_val"] == robot_val < int(np.sum(val.found))


def test_an_unknown_fusion_rule_or_a_visibility_out_of_range_is_refused(tmp_path):
    with pytest.raises(ValueError, match="fusion must be one of"):
        InspectionTrainStageConfig(data=tmp_path, out=tmp_path, fusion="mean")
    with pytest.raises(ValueError, match=r"visibility must be in \(0, 1\]; got 0"):
        InspectionTrainStageConfig(data=tmp_path, out=tmp_path, visibility=0.0)
    with pytest.raises(ValueError, match="camera must be one of"):
        InspectionTrainStageConfig(data=tmp_path, out=tmp_path, camera="wrist")


def test_the_clis_fusion_rules_and_calibration_forms_are_the_librarys():
    from onionsort.configs import common as _args
    from perception.fusion import CALIBRATION_FORMS, FUSION_RULES

    assert _args.FUSION_RULES == FUSION_RULES
    assert _args.CALIBRATION_FORMS == CALIBRATION_FORMS


def test_the_clis_inspection_cameras_are_the_stages():
    from onionsort.configs import common as _args
    from onionsort.stages.inspection import INSPECTION_CAMERAS

    assert _args.INSPECTION_CAMERAS == INSPECTION_CAMERAS


def test_robot_fusion_fits_each_levels_own_calibration_where_asked(dataset, tmp_path, capsys):
    import shutil

    from onionsort.configs.inspection import FusionCalibrationConfig
    from onionsort.stages.inspection import fit_robot_fusion_stage
    from onionsort.stages.models import DEFAULT_MODELS, ROBOT_FUSION_FILE

    folder = tmp_path / "models"
    shutil.copytree(DEFAULT_MODELS, folder)
    plain = fit_robot_fusion_stage(FusionCalibrationConfig(data=dataset, out=tmp_path / "one",
                                                           models=folder, device="cpu"))
    assert plain["format"] == 1 and "levels" not in plain
    from onionsort.cli import main

    assert main(["train", "robot-fusion", "--data", str(dataset), "--by-level", "--models",
                 str(folder), "--out", str(folder), "--device", "cpu"]) == 0
    said = capsys.readouterr().out.splitlines()
    assert said[0] == "all levels" and "clean" in said  # the pooled fit, then each level's
    doc = json.loads((folder / ROBOT_FUSION_FILE).read_text())
    assert doc["format"] == 2 and set(doc["levels"]) == {"clean"}  # the data's one level
    assert doc["levels"]["clean"] == doc["rules"] == plain["rules"]  # the same onions
    models = PerceptionModels.load(folder, "cpu")
    assert models.at_level("clean").robot_inspection.fused_calibration == \
        models.robot_inspection.fused_calibration
    report = measure_inspection(models, dataset, "all", views=3)
    assert report["levels"]["clean"]["robot"]["fused_calibration"] == "clean"
    # the measurement on a level's onions applies that level's calibration: a sharper one
    # written for `clean` moves the robot's fused ECE, the pooled one left as it was
    saved = json.loads((folder / ROBOT_FUSION_FILE).read_text())
    for fit in saved["levels"]["clean"].values():
        fit.update(low=fit["low"] * 4, high=fit["high"] * 4)
    (folder / ROBOT_FUSION_FILE).write_text(json.dumps(saved))
    sharper = measure_inspection(PerceptionModels.load(folder, "cpu"), dataset, "all", views=3)
    before = report["levels"]["clean"]["robot"]["fused"]
    after = sharper["levels"]["clean"]["robot"]["fused"]
    for rule in before:
        assert after[rule]["accuracy"] == before[rule]["accuracy"]  # the same calls
        assert after[rule]["ece"] != pytest.approx(before[rule]["ece"])


def test_robot_fusion_fits_a_levels_own_map_in_the_form_named_for_it(dataset, tmp_path,
                                                                      capsys):
    from onionsort.cli import main

    out = tmp_path / "fit"
    assert main(["train", "robot-fusion", "--data", str(dataset), "--by-level", "--level-forms",
                 "clean=powers", "--out", str(out), "--device", "cpu"]) == 0
    assert "E^" in capsys.readouterr().out  # the powers printed beside the slopes
    doc = json.loads((out / "robot_fusion_calibration.json").read_text())
    assert doc["level_forms"] == {"clean": "powers"}
    for rule, fit in doc["levels"]["clean"].items():
        assert fit["form"] == "powers" and fit["low_power"] > 0 and fit["high_power"] > 0
        assert doc["rules"][rule]["form"] == "log"  # the pooled map keeps --form
    # a level that the data do not hold: one line, nothing written
    assert main(["train", "robot-fusion", "--data", str(dataset), "--by-level", "--level-forms",
                 "hard=powers", "--out", str(tmp_path / "none"), "--device", "cpu"]) == 2
    err = capsys.readouterr().err.strip()
    assert "level_forms names ['hard']" in err and "\n" not in err
    assert not (tmp_path / "none").exists()


def test_robot_fusion_by_level_refuses_a_level_whose_onions_are_one_class(dataset, tmp_path,
                                                                          monkeypatch):
    import dataclasses

    import numpy as np

    from onionsort.configs.inspection import FusionCalibrationConfig
    from onionsort.stages import inspection as stage

    read = stage.inspection_views

    def good_ones_at_hard(*args, **kwargs):  # good onions `hard`, blemished `clean`: each one class
        views = read(*args, **kwargs)
        return dataclasses.replace(views, level=np.where(views.classes == 0, "hard",
                                                         views.level))

    monkeypatch.setattr(stage, "inspection_views", good_ones_at_hard)
    config = FusionCalibrationConfig(data=dataset, out=tmp_path, device="cpu")
    stage.fit_robot_fusion_stage(config)  # pooled, both classes: fitted
    with pytest.raises(ValueError, match=r"level '(clean|hard)': .*good and blemished onions"
                       ) as err:
        stage.fit_robot_fusion_stage(dataclasses.replace(config, by_level=True))
    assert "\n" not in str(err.value)


def test_a_sorter_classifier_learns_and_validates_on_the_sorters_views_alone(dataset,
                                                                            tmp_path):
    import numpy as np

    metrics = train_inspection_stage(InspectionTrainStageConfig(
        data=dataset, out=tmp_path, epochs=1, batch_size=64, fusion="noisy-or",
        visibility=0.3, device="cpu", camera="sorter"))
    assert metrics["camera"] == "sorter" and metrics["file"] == "inspection_classifier.pt"
    assert (tmp_path / "inspection_classifier.pt").is_file()
    assert not (tmp_path / "robot_inspection_classifier.pt").exists()
    val = inspection_views(dataset, "val", detector=PerceptionModels.load(device="cpu").detector)
    sorter_val = int(np.sum(val.found & (val.source == "human")))
    assert 0 < metrics["n_val"] == sorter_val < int(np.sum(val.found))
    train = inspection_views(dataset, "train")
    assert metrics["n_train"] + metrics["n_train_unclear"] == int(np.sum(train.source == "human"))


def test_the_inspection_trains_through_other_cameras(dataset, tmp_path, monkeypatch):
    """``--through-cameras 11,12``: the training views again through each seed's session
    cameras (as ``eval-perception --camera-shift`` sees them), the validation views through the
    first seed's, each as an onion of its own; the views as rendered stay first."""
    import numpy as np

    import perception.train_inspection
    from onionsort.stages.cameras import SessionCameras

    seen = {}

    def record(train, val, *args, **kwargs):
        seen.update(train=train, val=val)
        raise KeyboardInterrupt

    monkeypatch.setattr(perception.train_inspection, "train_inspection", record)
    with pytest.raises(KeyboardInterrupt):
        train_inspection_stage(InspectionTrainStageConfig(
            data=dataset, out=tmp_path / "s", epochs=1, device="cpu", camera="sorter",
            through_cameras=(11, 12)))
    plain = inspection_views(dataset, "train")
    plain = plain.subset(plain.source == "human")
    n = len(plain)
    assert len(seen["train"].crops) == 3 * n
    assert np.array_equal(seen["train"].crops[:n], plain.crops)
    for k, seed in enumerate((11, 12)):  # one pass per seed, after the views as rendered
        through = inspection_views(dataset, "train", image_map=SessionCameras(seed))
        through = through.subset(through.source == "human")
        assert np.array_equal(seen["train"].crops[(k + 1) * n:(k + 2) * n], through.crops)
        assert not np.array_equal(through.crops, plain.crops)
        assert np.array_equal(seen["train"].labels[(k + 1) * n:(k + 2) * n], plain.labels)
    detector = PerceptionModels.load(device="cpu").detector
    val = [inspection_views(dataset, "val", detector=detector, image_map=camera)
           for camera in (None, SessionCameras(11))]
    assert len(seen["val"].crops) == sum(int(np.sum(v.found & (v.source == "human")))
                                         for v in val)
    with pytest.raises(ValueError, match="through_cameras names seed 3 twice"):
        InspectionTrainStageConfig(data=dataset, out=tmp_path / "e", through_cameras=(3, 3))


def test_the_inspection_trains_on_the_crops_its_detector_cuts(dataset, tmp_path, monkeypatch):
    """``--crops detected``: each training crop is cut round the box the detector finds (at
    the context crop's size, so augmentation still moves it), views it finds nothing in left
    out; by default round the labelled box."""
    import numpy as np

    import perception.train_inspection
    from perception.inspection import best_box
    from perception.train_inspection import CONTEXT_SIZE, context_crop
    from recordings.labels.dataset import read_split, split_names

    seen = []

    def record(train, val, *args, **kwargs):
        seen.append(train)
        raise KeyboardInterrupt

    monkeypatch.setattr(perception.train_inspection, "train_inspection", record)
    for crops in ("labelled", "detected"):
        with pytest.raises(KeyboardInterrupt):
            train_inspection_stage(InspectionTrainStageConfig(
                data=dataset, out=tmp_path / crops, epochs=1, device="cpu", camera="robot",
                crops=crops))
    labelled, detected = seen
    plain = inspection_views(dataset, "train")
    assert np.array_equal(labelled.crops, plain.crops[plain.source == "robot"])
    detector = PerceptionModels.load(device="cpu").detector
    found = inspection_views(dataset, "train", detector=detector, context=True)
    found = found.subset(found.found & (found.source == "robot"))
    assert len(detected.crops) == len(found) > 0
    assert detected.crops.shape[1:] == (CONTEXT_SIZE, CONTEXT_SIZE, 3)
    assert np.array_equal(detected.crops, found.crops)
    assert not np.array_equal(detected.crops, labelled.crops[:len(detected.crops)])
    # the first robot view's crop is the context crop round the detector's best box
    first = next(f for name in split_names("train")
                 for f in read_split(dataset, name, view="inspection")
                 if f.record.get("source") == "robot")
    box = best_box(detector.detect([first.color])[0])
    assert np.array_equal(detected.crops[0], context_crop(first.color, box))
    with pytest.raises(ValueError, match="crops must be one of"):
        InspectionTrainStageConfig(data=dataset, out=tmp_path / "e", crops="true")


def test_the_log_odds_map_is_fitted_on_held_out_views_where_asked(dataset, tmp_path_factory,
                                                                 tmp_path):
    """``--log-odds-data``: the map the log-odds fusion reads is fitted on every view of the
    held-out data (both cameras', every split, found by the detector), not on the validation
    views; the temperature, which noisy-or reads, stays the validation views'."""
    import numpy as np

    from perception.inspection import InspectionClassifier
    from perception.train_inspection import fit_class_map

    held = tmp_path_factory.mktemp("held-out") / "data"
    make_dataset(DatasetConfig(out=held, frames=45, steps_per_session=5, robot_onions=12,
                               robot_views=2, seed=4))
    config = dict(data=dataset, epochs=1, batch_size=64, fusion="noisy-or", visibility=0.3,
                  device="cpu", camera="sorter")
    plain = train_inspection_stage(InspectionTrainStageConfig(out=tmp_path / "a", **config))
    mapped = train_inspection_stage(InspectionTrainStageConfig(
        out=tmp_path / "b", log_odds_data=(held,), **config))
    clf = InspectionClassifier.load(tmp_path / "b" / "inspection_classifier.pt")
    assert clf.temperature == pytest.approx(plain["temperature"])
    assert mapped["log_odds_map"]["platt_on_val"] == pytest.approx(plain["platt"])
    views = inspection_views(held, "all", detector=PerceptionModels.load(device="cpu").detector)
    views = views.subset(views.found.astype(bool))
    assert set(views.source.tolist()) == {"human", "robot"}
    assert mapped["log_odds_map"]["views"] == len(views)
    expected = fit_class_map(clf.logits(views.crops), views.classes, views.weights())
    assert clf.platt == pytest.approx(expected) and mapped["platt"] == pytest.approx(expected)
    assert not np.allclose(clf.platt, plain["platt"])
    assert clf.metadata["log_odds_map"]["data"] == [str(held)]
    with pytest.raises(ValueError, match="is also training data"):
        InspectionTrainStageConfig(out=tmp_path / "c", log_odds_data=(dataset,), **config)


@pytest.mark.parametrize("level", ["clean", "realistic"])
def test_the_sorters_inspection_view_renders_at_another_size_with_the_same_onions(tmp_path,
                                                                                   level):
    import cv2
    import numpy as np

    from recordings.labels.dataset import read_metadata
    from robot.simulation import INSPECTION_CAMERA

    def render(name, size):
        root = tmp_path / name
        make_dataset(DatasetConfig(out=root, frames=45, steps_per_session=5, robot_onions=0,
                                   seed=4, inspection_size=size, difficulty=level, workers=1))
        return root, [r for s in ("train", "val", "test")
                      for r in json.loads((root / s / "inspection.json").read_text())]

    default = DatasetConfig(out=tmp_path / "unused").inspection_pixels
    assert default == (INSPECTION_CAMERA.width, INSPECTION_CAMERA.height)
    _, a = render("default", "160x120")
    sharp, b = render("sharp", "320x240")
    assert read_metadata(sharp)["config"]["inspection"]["width"] == 320
    # the same sessions: states, actions and the onion the sorter holds, frame by frame
    keys = ("session", "frame", "state", "action", "onion")
    assert [[r[k] for k in keys] for r in a] == [[r[k] for k in keys] for r in b]
    held = [r for r in b if r["boxes"]]
    assert held  # the sorter held an onion up in some frame
    for r in held[:3]:
        split = next(s for s in ("train", "val", "test") if (sharp / s / r["color"]).exists())
        assert cv2.imread(str(sharp / split / r["color"])).shape == (240, 320, 3)
    # the same onion where both label it, seen twice as large
    pairs = [(dict(zip(ra["onions"], ra["boxes"], strict=True)),
              dict(zip(rb["onions"], rb["boxes"], strict=True)))
             for ra, rb in zip(a, b, strict=True)]
    both = [(pa[k], pb[k]) for pa, pb in pairs for k in pa.keys() & pb.keys()]
    assert len(both) >= len(held) // 2
    assert np.allclose([y for _, y in both], [2 * np.asarray(x) for x, _ in both], atol=3)
