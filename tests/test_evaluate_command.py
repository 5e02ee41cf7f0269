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
    assert f"wrote {run / 'evaluation.json'}\n" in capsys.readouterr().out
    assert {p.name for p in run.iterdir()} == {"model.json", "evaluation.json"}


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
    return SimpleNamespace(
        detector=detector,
        inspector=lambda rule=None, threshold=0.5: Inspector(detector, classifier, rule=rule,
                                                             threshold=threshold))


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
