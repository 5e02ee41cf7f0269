"""``onionsort label select``: the least-sure frames of recorded sessions, spread over
sessions and steps, as a pre-annotated labelling task that ``label import`` reads back."""

import json

import numpy as np
import pytest

from onionsort.cli import main
from onionsort.stages.label_select import _choose, _draw
from recordings.labels.dataset import read_records, split_sessions


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    out = tmp_path_factory.mktemp("select") / "rec"
    assert main(["record", "--sessions", "3", "--steps-per-session", "6", "--seed", "41",
                 "--workers", "1", "--out", str(out)]) == 0
    return sorted(out.glob("*.mcap"))


def test_the_choice_takes_the_likely_wrong_first_then_rounds_over_sessions():
    scores = [[0.1, 0.9, 0.8, 0.2], [0.3, 0.0, 0.0, 0.0]]
    # rounds: session 0's step 1 (0.4), session 1's step 0 (0.35); session 0's step 2 (0.3),
    # then session 1's least sure left (step 1, the first of equals)...
    assert _choose([[0.1, 0.4, 0.3, 0.2], [0.35, 0.0, 0.0, 0.0]], 1, 4) == [
        (0, 1), (1, 0), (0, 2), (1, 1)]
    # ...but steps more likely wrong than right (>= 1/2) come first, wherever they are
    assert _choose(scores, 1, 4) == [(0, 1), (0, 2), (1, 0), (0, 3)]
    assert _choose(scores, 1, 8) == [(0, 1), (0, 2), (1, 0), (0, 3), (0, 0), (1, 1), (1, 2),
                                     (1, 3)]
    assert _choose(scores, 3, 7) == [(0, 1), (0, 2), (1, 0)]  # whole steps up to 7 frames
    assert _choose([[0.1], [0.2, 0.3]], 1, 9) == [(1, 1), (0, 0), (1, 0)]  # then none left
    assert _choose([[0.6, 0.7], [0.9]], 3, 6) == [(1, 0), (0, 1)]  # the budget binds first


def test_a_random_sample_is_whole_steps_drawn_uniformly_whatever_their_uncertainty():
    scores = [[0.1, 0.9, 0.8, 0.2], [0.3, 0.0, 0.0, 0.0]]
    drawn = _draw(scores, 3, 7, seed=5)
    assert len(drawn) == 3 and len(set(drawn)) == 3  # whole steps up to 7 frames
    assert drawn == _draw(scores, 3, 7, seed=5)  # reproducible from its seed
    assert drawn == _draw([[0.0] * 4, [1.0] * 4], 3, 7, seed=5)  # the scores play no part
    assert sorted(_draw(scores, 1, 99, seed=5)) == [(k, t) for k in (0, 1) for t in range(4)]
    counts = np.zeros((2, 4))
    for seed in range(4000):
        for k, t in _draw(scores, 1, 2, seed=seed):
            counts[k, t] += 1
    # each of 8 steps drawn 2 times in 8: 1000 of 4000, binomial sd about 27
    assert np.abs(counts - 1000).max() < 110, counts


def test_label_select_draws_at_random_from_its_seed(sessions, tmp_path):
    argv = ["label", "select", *map(str, sessions), "--frames", "12", "--device", "cpu",
            "--sample", "random"]
    picked = []
    for name, seed in (("a", "3"), ("b", "3"), ("c", "4")):
        assert main([*argv, "--seed", seed, "--out", str(tmp_path / name)]) == 0
        doc = json.loads((tmp_path / name / "selection.json").read_text())
        picked.append([(f["session"], f["step"], f["frame"]) for f in doc["frames"]])
    assert len(picked[0]) == 12 and picked[0] == picked[1]
    assert picked[0] != picked[2]


def _step(onion, p_blemished=None, prediction=2, occluded=False, waiting=False):
    from state_abstraction.perceive import PerceivedStep

    probs = {"occluded": np.array([0.0, 1.0]) if occluded else np.array([1.0, 0.0]),
             "onion": np.eye(4)[onion], "end_effector": np.eye(4)[onion],
             "waiting": np.array([0.0, 1.0]) if waiting else np.array([1.0, 0.0])}
    return PerceivedStep(step=0, occluded=occluded, p_occluded=float(occluded), probs=probs,
                         onion=onion, end_effector=onion, action=0, prediction=prediction,
                         p_blemished=p_blemished)


def test_what_the_sorter_did_with_the_onion_weighs_on_the_prediction():
    from onionsort.stages.label_select import sorter_calls, step_uncertainties

    # picked (hover), held up (face) and called good at p 0.3, then occluded, then binned;
    # then a new onion claimed (waiting) and put back after a view at p 0.3
    seen = [_step(1), _step(2, 0.3, 0), _step(2, 0.3, 0, occluded=True), _step(3, 0.3, 0),
            _step(0, waiting=True), _step(2, 0.3, 0), _step(0, 0.3, 0)]
    assert sorter_calls(seen) == [0, 1, 1, 1, 0, -1, -1]
    u = step_uncertainties(seen, consistency=0.9)
    odds_bad = 0.3 / 0.7 * 9  # the bin: p(blemished) 0.3 becomes 27/34
    assert u[1] == pytest.approx(odds_bad / (1 + odds_bad))  # the call 'good' likely wrong
    assert u[2] == pytest.approx(0.0)  # occluded, and called so
    odds_bad = 0.3 / 0.7 / 9  # back on the conveyor: 'good' is likely right
    assert u[5] == pytest.approx(odds_bad / (1 + odds_bad))
    assert u[0] == pytest.approx(0.0)  # an onion just picked: 'unknown' is right
    # on the conveyor before anything was seen: the sorter may hold an onion inspected before
    # the recording began, one of three values
    assert step_uncertainties([_step(0)]) == [pytest.approx(2 / 3)]
    assert step_uncertainties(seen, consistency=0.5)[1] == pytest.approx(0.3)
    # a confident call the sorter's move contradicts is at least as likely wrong as right,
    # however sure the views: 'bad' at p 0.99995, then back on the conveyor
    contradicted = [_step(2, 0.99995, 1), _step(0, 0.99995, 1)]
    assert sorter_calls(contradicted) == [-1, -1]
    assert step_uncertainties(contradicted) == [pytest.approx(0.5)] * 2
    agreed = [_step(2, 0.99995, 1), _step(3, 0.99995, 1)]  # the same call, then the bin
    assert max(step_uncertainties(agreed)) < 1e-5
    with pytest.raises(ValueError, match="consistency"):
        step_uncertainties(seen, consistency=1.0)


def test_coco_selection_is_pre_annotated_and_comes_back_through_label_import(sessions,
                                                                             tmp_path):
    out = tmp_path / "task"
    assert main(["label", "select", *map(str, sessions), "--frames", "12", "--device", "cpu",
                 "--out", str(out)]) == 0
    chosen = json.loads((out / "selection.json").read_text())["frames"]
    assert len(chosen) == 12
    steps = {(f["session"], f["step"]) for f in chosen}
    assert len(steps) == 4 and {s for s, _ in steps} == {0, 1, 2}  # spread over sessions
    doc = json.loads((out / "annotations" / "instances_default.json").read_text())
    assert sorted(im["file_name"] for im in doc["images"]) == sorted(f["image"] for f in chosen)
    assert all({"session", "step", "frame"} <= set(im) for im in doc["images"])
    assert all(0.0 < a["score"] <= 1.0 for a in doc["annotations"])
    lines = (out / "states.csv").read_text().splitlines()
    assert len(lines) == 13 and lines[1].startswith(",")  # no split: label import splits
    back = tmp_path / "lab"
    assert main(["label", "import", str(out), "--format", "coco", "--out", str(back)]) == 0
    assert [s for _, s in split_sessions(back, "all")] == [0, 1, 2]
    assert sum(len(read_records(back, s)) for s in ("train", "val", "test")) == 12


def test_recall_scores_the_choice_against_the_truth(sessions, tmp_path, capsys):
    """``--recall``: the wrong steps counted against the truth, as an oracle that compares the
    whole state guess counts them; those chosen among them; each wrong step left out; the
    choice itself the same as without ``--recall``."""
    from onionsort.stages.models import PerceptionModels

    argv = ["label", "select", *map(str, sessions), "--frames", "12", "--device", "cpu"]
    assert main([*argv, "--out", str(tmp_path / "plain")]) == 0
    capsys.readouterr()
    assert main([*argv, "--recall", "--out", str(tmp_path / "scored")]) == 0
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "scored" / "selection.json").read_text())
    plain = json.loads((tmp_path / "plain" / "selection.json").read_text())
    assert doc["frames"] == plain["frames"] and "recall" not in plain
    r = doc["recall"]
    wrong = _wrong_steps(sessions, PerceptionModels.load(None, "cpu"))
    picked = {(f["session"], f["step"]) for f in doc["frames"]}
    assert (r["steps"], r["wrong"], r["taken"]) == (len(wrong), sum(wrong.values()), len(picked))
    assert r["wrong_taken"] == sum(wrong[s] for s in picked)
    assert {(m["session"], m["step"]) for m in r["missed"]} == {
        s for s, w in wrong.items() if w and s not in picked}
    assert all(m["wrong"] for m in r["missed"])
    assert (f"against the truth: {r['wrong']} of {r['steps']} steps wrong" in out
            and f"{r['wrong_taken']} of the {r['taken']} taken" in out)
    assert out.count("  left out: session ") == len(r["missed"])


def test_label_studio_tasks_carry_predictions_and_where_each_frame_is(sessions, tmp_path):
    out = tmp_path / "ls"
    assert main(["label", "select", *map(str, sessions[:2]), "--frames", "6", "--format",
                 "labelstudio", "--device", "cpu", "--out", str(out)]) == 0
    tasks = json.loads((out / "tasks.json").read_text())
    assert len(tasks) == 6
    config = (out / "labeling_config.xml").read_text()
    for task in tasks:
        assert {"image", "session", "step", "frame"} <= set(task["data"])
        assert (out / task["data"]["image"]).is_file()
        (prediction,) = task["predictions"]
        kinds = {r["from_name"]: r for r in prediction["result"]}
        assert {"onion", "end_effector", "prediction", "action", "occluded"} <= set(kinds)
        for r in prediction["result"]:
            assert f'name="{r["from_name"]}"' in config
            if r["type"] == "rectanglelabels":
                v = r["value"]
                assert v["x"] >= 0 and v["x"] + v["width"] <= 100 + 1e-6
                assert r["value"]["rectanglelabels"][0] in ("good", "blemished")
            else:
                assert f'value="{r["value"]["choices"][0]}"' in config


def test_label_studios_sdk_validates_every_task_and_shows_the_least_sure_first(
        sessions, tmp_path, run_tool):
    """Label Studio's own SDK validates the labelling interface, every task's data and every
    prediction (its score in [0, 1]); sorted as its Data Manager sorts them, by score
    ascending, the tasks come in ``label select``'s ranking: the least sure step first."""
    out = tmp_path / "ls"
    assert main(["label", "select", *map(str, sessions), "--frames", "12", "--format",
                 "labelstudio", "--device", "cpu", "--out", str(out)]) == 0
    checked = run_tool("labelstudio", "check_labelstudio.py", str(out / "labeling_config.xml"),
                       str(out / "tasks.json"))
    tasks = json.loads((out / "tasks.json").read_text())
    assert checked == {"config": [], "tasks": [True] * 12, "predictions": [[[]]] * 12}
    uncertainty = {f"images/{f['image']}": f["uncertainty"]
                   for f in json.loads((out / "selection.json").read_text())["frames"]}
    for task in tasks:
        assert task["predictions"][0]["score"] == pytest.approx(
            1.0 - uncertainty[task["data"]["image"]])
    shown = sorted(tasks, key=lambda t: t["predictions"][0]["score"])
    ranked = [uncertainty[t["data"]["image"]] for t in shown]
    assert ranked == sorted(uncertainty.values(), reverse=True)
    assert ranked[0] > ranked[-1]  # the selection's steps differ in how sure they are


@pytest.mark.slow
@pytest.mark.parametrize("level", ["realistic", "paper", "hard"])
def test_label_studios_sdk_validates_every_task_at_every_level(level, tmp_path, run_tool):
    """The same at the harder levels (the clean one is above), on sessions of their own."""
    rec = tmp_path / "rec"
    assert main(["record", "--sessions", "3", "--steps-per-session", "8", "--seed", "47",
                 "--difficulty", level, "--workers", "1", "--out", str(rec)]) == 0
    out = tmp_path / "ls"
    assert main(["label", "select", *map(str, sorted(rec.glob("*.mcap"))), "--frames", "24",
                 "--format", "labelstudio", "--device", "cpu", "--out", str(out)]) == 0
    checked = run_tool("labelstudio", "check_labelstudio.py", str(out / "labeling_config.xml"),
                       str(out / "tasks.json"))
    assert checked == {"config": [], "tasks": [True] * 24, "predictions": [[[]]] * 24}


def test_accepting_every_label_studio_prediction_imports_the_predicted_labels(sessions,
                                                                               tmp_path):
    """Exported, "annotated" by accepting every prediction as it is, and imported with
    ``label import --format labelstudio``: the dataset holds exactly the predicted labels."""
    from irl.domains.onion_sorting import SORTING_TASK as task

    out = tmp_path / "ls"
    assert main(["label", "select", *map(str, sessions), "--frames", "12", "--format",
                 "labelstudio", "--device", "cpu", "--out", str(out)]) == 0
    tasks = json.loads((out / "tasks.json").read_text())
    exported = _label_studio_export(tasks, lambda k, result: result)
    (out / "export.json").write_text(json.dumps(exported))
    back = tmp_path / "back"
    assert main(["label", "import", str(out), "--format", "labelstudio",
                 "--out", str(back)]) == 0
    records = {r["image"]: r for split in ("train", "val", "test")
               for r in read_records(back, split)}
    assert len(records) == len(tasks)
    for t in tasks:
        rec = records[t["data"]["image"].rsplit("/", 1)[1]]
        result = t["predictions"][0]["result"]
        choices = {r["from_name"]: r["value"]["choices"][0] for r in result
                   if r["type"] == "choices"}
        for factor in ("onion", "end_effector", "prediction"):
            assert task.value_name(factor, rec[factor]) == choices[factor]
        assert task.action_names[rec["action"]] == choices["action"]
        assert rec["occluded"] == (choices["occluded"] == "yes")
        boxes = [r for r in result if r["type"] == "rectanglelabels"]
        assert len(rec["boxes"]) == len(boxes)
        for (x0, y0, x1, y1), r, c in zip(rec["boxes"], boxes, rec["classes"], strict=True):
            v = r["value"]
            assert [x0, y0, x1 - x0, y1 - y0] == pytest.approx(
                [v["x"] * 3.2, v["y"] * 2.4, v["width"] * 3.2, v["height"] * 2.4], abs=2e-3)
            assert ("good", "blemished")[c] == v["rectanglelabels"][0]


def _label_studio_export(tasks: list, fix) -> list:
    """What Label Studio's JSON export gives once a person has labelled ``tasks`` (its import
    format): each task with an ``annotations`` entry whose result is the prediction's,
    changed by ``fix(k, result)`` (None: the person skipped the task), and the image served
    through local file storage."""
    out = []
    for k, task in enumerate(tasks):
        result = fix(k, json.loads(json.dumps(task["predictions"][0]["result"])))
        annotations = [{"id": 100 + k, "result": result or [], "was_cancelled": result is None,
                        "lead_time": 3.2}]
        data = {**task["data"], "image": "/data/local-files/?d=" + task["data"]["image"]}
        out.append({"id": k + 1, "data": data, "annotations": annotations,
                    "predictions": task["predictions"], "project": 1})
    return out


def test_a_label_studio_export_comes_back_through_label_import(sessions, tmp_path, capsys):
    from irl.domains.onion_sorting import SORTING_TASK as task

    out = tmp_path / "ls"
    assert main(["label", "select", *map(str, sessions), "--frames", "12", "--format",
                 "labelstudio", "--device", "cpu", "--out", str(out)]) == 0
    tasks = json.loads((out / "tasks.json").read_text())

    def fix(k, result):
        if k == 0:
            return None  # skipped: not labelled
        for r in result:
            if r["type"] == "choices" and r["from_name"] == "prediction":
                r["value"]["choices"] = ["bad" if k % 2 else "good"]
            if r["type"] == "choices" and r["from_name"] == "occluded":
                r["value"]["choices"] = ["no"]
            if r["type"] == "rectanglelabels":
                r["value"]["x"] = min(r["value"]["x"] + 1.0, 100 - r["value"]["width"])
                r["value"]["rectanglelabels"] = ["blemished"]
        if k == 1:  # a box the model missed
            result.append({"id": "new", "type": "rectanglelabels", "from_name": "label",
                           "to_name": "image", "value": {"x": 10, "y": 20, "width": 5,
                                                         "height": 4, "rotation": 0,
                                                         "rectanglelabels": ["good"]}})
        return result

    exported = _label_studio_export(tasks, fix)
    (out / "project-1-at-2026-11-26.json").write_text(json.dumps(exported))
    back = tmp_path / "back"
    assert main(["label", "import", str(out), "--format", "labelstudio",
                 "--out", str(back)]) == 0
    records = {r["image"]: r for split in ("train", "val", "test")
               for r in read_records(back, split)}
    assert len(records) == len(tasks) - 1  # the skipped task is not in it
    for t in exported[1:]:
        name = t["data"]["image"].rsplit("/", 1)[1]
        rec = records[name]
        assert (rec["session"], rec["step"], rec["frame"]) == (
            t["data"]["session"], t["data"]["step"], t["data"]["frame"])
        answers = {r["from_name"]: r["value"]["choices"][0]
                   for r in t["annotations"][0]["result"] if r["type"] == "choices"}
        assert task.value_name("prediction", rec["prediction"]) == answers["prediction"]
        assert task.value_name("onion", rec["onion"]) == answers["onion"]
        assert task.action_names[rec["action"]] == answers["action"]
        assert rec["occluded"] is False
        boxes = [r["value"] for r in t["annotations"][0]["result"]
                 if r["type"] == "rectanglelabels"]
        assert len(rec["boxes"]) == len(boxes)
        for (x0, y0, x1, y1), v, c in zip(rec["boxes"], boxes, rec["classes"], strict=True):
            assert x1 - x0 == pytest.approx(v["width"] * 320 / 100, abs=2e-3)
            assert x0 == pytest.approx(v["x"] * 320 / 100, abs=1e-3)
            assert y1 - y0 == pytest.approx(v["height"] * 240 / 100, abs=2e-3)
            assert c == (0 if v["rectanglelabels"] == ["good"] else 1)

    # a choice that is not a value of the task: one line, exit 2, nothing written
    exported[2]["annotations"][0]["result"] = [
        r if r["from_name"] != "onion" else {**r, "value": {"choices": ["table"]}}
        for r in exported[2]["annotations"][0]["result"]]
    (out / "project-1-at-2026-11-26.json").write_text(json.dumps(exported))
    capsys.readouterr()
    assert main(["label", "import", str(out), "--format", "labelstudio",
                 "--out", str(tmp_path / "bad")]) == 2
    (err,) = capsys.readouterr().err.splitlines()
    assert "onion 'table' is not a value of the task" in err and "task 3" in err
    assert not (tmp_path / "bad").exists()


def test_zero_frames_is_one_line(sessions, tmp_path, capsys):
    assert main(["label", "select", str(sessions[0]), "--frames", "0",
                 "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == ["onionsort label: error: frames must be >= 1; got 0"]
    assert not (tmp_path / "x").exists()


def _wrong_steps(paths, models) -> dict:
    """``(session, step) -> bool``: the step's state guess is wrong (the truth, which the
    selection never reads, checks it)."""
    from recordings.session.reader import open_session

    wrong = {}
    for k, path in enumerate(paths):
        session = open_session(path)
        steps = session.step_frames()
        seen = models.perceive([([f.color for f in st], [f.depth for f in st],
                                 [f.inspection if f.inspection_png is not None else None
                                  for f in st]) for st in steps])
        for st, guess in zip(steps, seen, strict=True):
            truth = st[0].state
            wrong[k, st[0].step] = bool(guess.occluded != truth["occluded"] or (
                not truth["occluded"] and guess.state != truth["state"]))
    return wrong


@pytest.mark.slow
def test_the_frames_chosen_are_wrong_three_times_as_often_and_hold_every_wrong_one(tmp_path,
                                                                                 capsys):
    """Acceptance on 6 fresh `paper` sessions of 20 steps (seed 6124; the measure was set on
    seeds 900, 902, 6111 and 6121-6123): the 60 frames chosen have a wrong state guess at
    least 3x as often as the sessions' steps on average, and where fewer than their 20 steps
    are wrong, every wrong step is among them."""
    from onionsort.stages.label_select import LabelSelectConfig, select_frames
    from onionsort.stages.models import PerceptionModels

    assert main(["record", "--sessions", "6", "--steps-per-session", "20", "--difficulty",
                 "paper", "--seed", "6124", "--out", str(tmp_path / "rec")]) == 0
    paths = sorted((tmp_path / "rec").glob("*.mcap"))
    models = PerceptionModels.load(None, "cpu")
    wrong = _wrong_steps(paths, models)
    chosen = select_frames(LabelSelectConfig(sessions=tuple(paths), out=tmp_path / "task",
                                             frames=60, device="cpu"), models=models)
    picked = {(f["session"], f["step"]) for f in chosen["frames"]}
    rate, rate_picked = (np.mean(list(wrong.values())),
                         np.mean([wrong[s] for s in picked]))
    with capsys.disabled():
        print(f"\n{sum(wrong.values())} of {len(wrong)} steps wrong ({rate:.3f}); "
              f"{sum(wrong[s] for s in picked)} of the {len(picked)} chosen ({rate_picked:.3f})")
    assert len(picked) == 20
    assert rate_picked >= 3 * rate
    if sum(wrong.values()) < len(picked):
        assert {s for s, w in wrong.items() if w} <= picked
