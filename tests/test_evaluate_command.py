"""``onionsort evaluate``: a run's policy sorts onions; bad run folders are clear errors."""

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


def test_run_folders_without_a_valid_model_are_refused(tmp_path, capsys):
    assert main(["evaluate", str(tmp_path), "--ground-truth-inspection"]) == 2
    assert "holds no learned model" in capsys.readouterr().err
    run = _run_dir(tmp_path, np.zeros(12, int))
    assert main(["evaluate", str(run), "--ground-truth-inspection"]) == 2
    assert "one action in [0, 5) for each of the 48" in capsys.readouterr().err
