"""``onionsort evaluate``: a run's policy sorts onions (evaluation.json, .rrd, .mcap); bad run
folders are clear errors."""

import json
from types import SimpleNamespace

import numpy as np

from irl.domains.onion_sorting import onion_sorting
from onionsort.cli import main


def _run_dir(tmp_path, actions):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text(json.dumps({"method": "expert",
                                                "policy_indices": [int(a) for a in actions]}))
    return run


def test_the_experts_policy_sorts_perfectly_with_perfect_inspection(tmp_path, capsys):
    expert = onion_sorting().expert_policy().argmax(axis=1)
    run = _run_dir(tmp_path, expert)
    assert main(["evaluate", str(run), "--onions", "6", "--blemished", "4",
                 "--ground-truth-inspection", "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert (printed["tp"], printed["fp"], printed["tn"], printed["fn"]) == (4, 0, 2, 0)
    assert printed["precision"] == 1.0 and printed["recall"] == 1.0
    saved = json.loads((run / "evaluation.json").read_text())
    assert saved["inspection"] == "ground truth" and len(saved["onions"]) == 6
    assert (run / "evaluation.rrd").stat().st_size > 0
    # the run as a session: one frame per action, its counts ending at evaluation.json's
    from recordings import open_session

    session = open_session(run / "evaluation.mcap")
    assert session.n_frames == len(session.decisions) == saved["n_steps"]
    last = session.sorting_counts[saved["n_steps"] - 1]
    assert {k: last[k] for k in ("tp", "fp", "tn", "fn")} == {"tp": 4, "fp": 0, "tn": 2, "fn": 0}
    assert not list(run.glob("*.partial"))


def test_no_rerun_and_no_mcap_write_the_evaluation_only(tmp_path, capsys):
    run = _run_dir(tmp_path, onion_sorting().expert_policy().argmax(axis=1))
    assert main(["evaluate", str(run), "--onions", "2", "--blemished", "1",
                 "--ground-truth-inspection", "--no-rerun", "--no-mcap"]) == 0
    assert f"wrote {run / 'evaluation.json'}, {run / 'tally.csv'}\n" in capsys.readouterr().out
    assert {p.name for p in run.iterdir()} == {"model.json", "evaluation.json", "tally.csv"}


def test_run_folders_without_a_valid_model_are_refused(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path), "--ground-truth-inspection"]) == 2
    assert "holds no learned model" in capsys.readouterr().err
    run = _run_dir(tmp_path, np.zeros(12, int))
    assert main(["evaluate", str(run), "--ground-truth-inspection"]) == 2
    assert "one action in [0, 5) for each of the 48" in capsys.readouterr().err


class _CountingDetector:
    """Finds an onion in every image, counting the images it is run on."""

    def __init__(self) -> None:
        self.images = 0

    def detect(self, images):
        from perception.detector import Detections

        self.images += len(images)
        return [Detections(boxes=np.array([[10.0, 10.0, 50.0, 50.0]]), scores=np.array([0.9]),
                           classes=np.array([1])) for _ in images]


def _fake_models(detector):
    """Models whose inspection runs ``detector`` and an untrained classifier."""
    import torch

    from perception.inspection import (
        InspectionClassifier,
        InspectionNet,
        InspectionNetConfig,
        Inspector,
    )

    torch.manual_seed(0)
    classifier = InspectionClassifier(InspectionNet(InspectionNetConfig(width=4)))
    models = SimpleNamespace(
        detector=detector,
        inspector=lambda rule=None, threshold=0.5, camera="sorter": Inspector(
            detector, classifier, rule=rule, threshold=threshold))
    models.at_level = lambda level: models  # one calibration for every level
    return models


def test_the_rerun_log_draws_the_inspections_boxes_without_running_the_detector_again(
        tmp_path):
    from onionsort.stages import EvaluateConfig, evaluate

    expert = onion_sorting().expert_policy().argmax(axis=1)
    calls = {}
    for logged in (False, True):
        (tmp_path / str(logged)).mkdir()
        run = _run_dir(tmp_path / str(logged), expert)
        detector = _CountingDetector()
        evaluate(EvaluateConfig(run=run, onions=3, blemished=1, rerun=logged, mcap=False,
                                inspection_views=2, every_view=True), _fake_models(detector))
        calls[logged] = detector.images
    assert calls[True] == calls[False] == 3 * 2  # two views per onion, each found once


def test_the_experts_policy_runs_without_a_learning_run(tmp_path, capsys):
    # perception measured apart from learning: the shipped models inspect, on the CPU
    out = tmp_path / "eyes"
    assert main(["evaluate", "--policy", "expert", "--onions", "3", "--blemished", "2",
                 "--inspection-views", "2", "--difficulty", "paper", "--device", "cpu",
                 "--no-rerun", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "expert: 3 onions (2 blemished), paper camera, inspection by up to 2 views" in said
    saved = json.loads((out / "evaluation.json").read_text())
    assert saved["policy"] == "expert" and saved["inspection_views"] == 2
    assert not saved["every_view"]
    assert saved["views_taken"] == sum(o["views"] for o in saved["onions"])
    assert saved["threshold"] == 0.5 and saved["fusion"] in ("log-odds", "noisy-or")
    # the robot's P(blemished) calibrated for a line of the level it ran at, as recorded
    from onionsort.stages.models import PerceptionModels

    paper = PerceptionModels.load(device="cpu").at_level("paper").robot_inspection
    assert saved["fused_calibration"] == list(paper.fused_calibration[saved["fusion"]])
    assert len(saved["onions"]) == 3 and (out / "evaluation.mcap").is_file()
    for onion in saved["onions"]:  # every inspected onion carries the probability behind it
        assert (onion["perceived"] is None) == (onion["p_blemished"] is None)
        if onion["p_blemished"] is not None:
            assert (onion["perceived"] == "bad") == (onion["p_blemished"] >= 0.5)
    from recordings import open_session

    decisions = open_session(out / "evaluation.mcap").decisions.values()
    inspected = [d for d in decisions if d["perceived"] is not None]
    assert inspected and all(1 <= len(d["view_p_blemished"]) <= 2 for d in inspected)
    assert sorted(len(d["view_p_blemished"]) for d in inspected) == sorted(
        o["views"] for o in saved["onions"] if o["views"])


def test_the_threshold_follows_the_costs_given(tmp_path):
    from onionsort.stages import EvaluateConfig, evaluate

    run = _run_dir(tmp_path, onion_sorting().expert_policy().argmax(axis=1))
    _, summary = evaluate(EvaluateConfig(run=run, onions=2, blemished=1, rerun=False,
                                         mcap=False, miss_cost=3.0, waste_cost=1.0,
                                         inspection_views=1),
                          _fake_models(_CountingDetector()))
    assert summary["threshold"] == 0.25
    for onion in summary["onions"]:
        assert (onion["perceived"] == "bad") == (onion["p_blemished"] >= 0.25)


def _confidence_file(run, actions, unsure: dict[int, float]) -> None:
    """A policy_confidence.json sure of every action but those of the states in ``unsure``."""
    dom = onion_sorting()
    names = dom.action_names
    states = []
    for s, a in enumerate(actions):
        c = unsure.get(s, 1.0)
        conf = dict.fromkeys(names, 0.0)
        conf[names[a]] = c
        conf[names[(a + 1) % len(names)]] += 1.0 - c
        states.append({"state": dom.state_names[s], "map_action": names[a], "confidence": conf})
    (run / "policy_confidence.json").write_text(json.dumps(
        {"format": "onionsort.policy-confidence/1", "states": states}))


def test_defer_below_sends_the_onions_of_unsure_states_to_the_tray(tmp_path, capsys):
    from irl.domains.onion_sorting import Location, Prediction, SortingState, encode_state

    expert = onion_sorting().expert_policy().argmax(axis=1)
    run = _run_dir(tmp_path, expert)
    unsure = encode_state(SortingState(Location.FACE, Location.FACE, Prediction.BAD))
    _confidence_file(run, expert, {unsure: 0.6})
    argv = ["evaluate", str(run), "--onions", "6", "--blemished", "4",
            "--ground-truth-inspection", "--json", "--no-rerun"]
    assert main([*argv, "--defer-below", "0.5"]) == 0  # 0.6 is sure enough: nothing deferred
    printed = json.loads(capsys.readouterr().out)
    assert (printed["tp"], printed["tn"], printed["deferred"]) == (4, 2, 0)
    assert main([*argv, "--defer-below", "0.9"]) == 0
    printed = json.loads(capsys.readouterr().out)
    # every blemished onion, once inspected, is where the policy is unsure: all four deferred
    assert (printed["tp"], printed["fp"], printed["tn"], printed["fn"]) == (0, 0, 2, 0)
    assert printed["deferred"] == 4 and printed["deferral_rate"] == 4 / 6
    saved = json.loads((run / "evaluation.json").read_text())
    assert [o["fate"] for o in saved["onions"] if o["blemished"]] == ["tray"] * 4
    assert saved["defer_below"] == 0.9
    from recordings import open_session

    session = open_session(run / "evaluation.mcap")
    assert session.n_frames == saved["n_steps"]


def test_defer_below_needs_a_posterior_and_a_probability(tmp_path, capsys):
    run = _run_dir(tmp_path, onion_sorting().expert_policy().argmax(axis=1))
    assert main(["evaluate", str(run), "--defer-below", "0.9", "--ground-truth-inspection"]) == 2
    err = capsys.readouterr().err
    assert "holds no posterior" in err and "--posterior" in err and err.count("\n") == 1
    for bad in ("0", "1.5", "nan"):
        assert main(["evaluate", str(run), "--defer-below", bad]) == 2
        err = capsys.readouterr().err
        assert "defer_below must be in (0, 1]" in err and err.count("\n") == 1
    assert main(["evaluate", "--policy", "expert", "--out", str(tmp_path / "x"),
                 "--defer-below", "0.9"]) == 2
    assert "the expert policy has none" in capsys.readouterr().err


def test_defer_below_refuses_a_confidence_file_about_another_policy(tmp_path, capsys):
    expert = onion_sorting().expert_policy().argmax(axis=1)
    run = _run_dir(tmp_path, expert)
    other = expert.copy()
    other[0] = (other[0] + 1) % 5
    _confidence_file(run, other, {})
    assert main(["evaluate", str(run), "--defer-below", "0.9", "--ground-truth-inspection"]) == 2
    err = capsys.readouterr().err
    assert "about another policy" in err and err.count("\n") == 1
