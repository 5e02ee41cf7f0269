"""``onionsort evaluate``: a run's policy sorts onions (evaluation.json, .rrd, .mcap); bad run
folders are clear errors."""

import json

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
    """Calls the onion in every image blemished (class 1), counting the images it is run on."""

    def __init__(self) -> None:
        self.images = 0

    def detect(self, images):
        from perception.detector import Detections

        self.images += len(images)
        return [Detections(boxes=np.array([[10.0, 10.0, 50.0, 50.0]]), scores=np.array([0.9]),
                           classes=np.array([1])) for _ in images]


def test_the_rerun_log_draws_the_inspections_boxes_without_running_the_detector_again(
        tmp_path):
    from types import SimpleNamespace

    from onionsort.stages import EvaluateConfig, evaluate

    expert = onion_sorting().expert_policy().argmax(axis=1)
    calls = {}
    for logged in (False, True):
        (tmp_path / str(logged)).mkdir()
        run = _run_dir(tmp_path / str(logged), expert)
        detector = _CountingDetector()
        result, _ = evaluate(EvaluateConfig(run=run, onions=3, blemished=1, rerun=logged,
                                            mcap=False), SimpleNamespace(detector=detector))
        assert (result.tp, result.fp) == (1, 2)  # every onion called blemished, one truly is
        calls[logged] = detector.images
    assert calls[True] == calls[False] == 3  # one view per onion, classified once
