"""``onionsort.policy``: a learn run's policy as a robot's process runs it. It imports no
simulator, writer or Ray; its action and confidence are the learn run's in every state; its
inspection runs on the shipped models or a lab's fine-tuned ones."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from irl.domains.onion_sorting import N_STATES, SORTING_TASK, Prediction, decode_state
from onionsort.cli import main
from onionsort.policy import SortingPolicy
from onionsort.stages.models import CALIBRATION_FILE, DEFAULT_MODELS

ROOT = Path(__file__).resolve().parent.parent
#: what a robot's own process must not load
FORBIDDEN = {"pybullet", "rerun", "ray", "mcap"}


def _imported(stderr: str) -> set[str]:
    """The top-level modules ``python -X importtime`` reports."""
    names = set()
    for line in stderr.splitlines():
        if line.startswith("import time:") and "|" in line:
            name = line.rsplit("|", 1)[1].strip()
            if name and name != "imported package":
                names.add(name.split(".")[0])
    return names


def test_importing_the_runtime_loads_no_simulator_writer_or_ray():
    done = subprocess.run([sys.executable, "-X", "importtime", "-c", "import onionsort.policy"],
                          capture_output=True, text=True, cwd=ROOT, check=True)
    imported = _imported(done.stderr)
    assert {"onionsort", "numpy", "irl"} <= imported  # the report was read
    assert not imported & FORBIDDEN, sorted(imported & FORBIDDEN)


def test_loading_a_policy_and_inspecting_loads_none_of_them_either(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "model.json").write_text(json.dumps({
        "method": "made-up", "policy_indices": SortingPolicy.expert().actions.tolist()}))
    script = (
        "import sys, numpy as np\n"
        "from onionsort.policy import SortingPolicy\n"
        f"policy = SortingPolicy.load({str(run)!r})\n"
        "inspect = policy.inspection(device='cpu')\n"
        "verdict = inspect([np.zeros((240, 320, 3), np.uint8)])\n"
        "print(int(policy.action((0, 0, 1))), verdict.prediction)\n"
        f"print(sorted(m for m in {sorted(FORBIDDEN)!r} if m in sys.modules))\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=ROOT, check=True)
    lines = done.stdout.strip().splitlines()
    assert lines[-1] == "[]", done.stdout
    assert lines[0].split()[1] == str(SORTING_TASK.value_index("prediction", "unknown"))


@pytest.fixture(scope="module")
def learned(tmp_path_factory, perceived_sessions):
    """A learn run with its posterior (``learn --posterior``)."""
    out = tmp_path_factory.mktemp("runtime") / "run"
    assert main(["learn", *map(str, perceived_sessions), "--posterior", "--samples", "200",
                 "--posterior-method", "laplace", "--observation-model",
                 str(DEFAULT_MODELS / CALIBRATION_FILE), "--allow-model-mismatch",
                 "--out", str(out)]) == 0
    return out


def test_its_action_and_confidence_are_the_learn_runs_in_every_state(learned):
    model = json.loads((learned / "model.json").read_text())
    doc = json.loads((learned / "policy_confidence.json").read_text())
    policy = SortingPolicy.load(learned)
    assert policy.method == model["method"] == "mmap-birl"
    unsure = 0
    for s in range(N_STATES):
        row = doc["states"][s]
        action = policy.action(s)
        assert int(action) == model["policy_indices"][s]
        assert SORTING_TASK.action_names[action] == model["policy"][s]["action"]
        assert action == policy.action(decode_state(s)) == policy.action(tuple(decode_state(s)))
        assert policy.confidence(s) == row["confidence"][row["map_action"]]
        for name, share in row["confidence"].items():
            assert policy.confidence(s, SORTING_TASK.action_names.index(name)) == share
        threshold = row["confidence"][row["map_action"]]
        assert not policy.defers(s, threshold)
        if threshold < 1.0:
            assert policy.defers(s, threshold + 1e-4)
            unsure += 1
    assert unsure > 0  # the posterior is unsure somewhere: defers was tried both ways


def test_an_inspected_onion_weighs_the_confidence_by_what_it_may_be(learned):
    policy = SortingPolicy.load(learned)
    held = decode_state(0)._replace(onion=2, end_effector=2, prediction=Prediction.BAD)
    a = policy.action(held)
    good, bad = (policy.confidence(held._replace(prediction=p), a)
                 for p in (Prediction.GOOD, Prediction.BAD))
    assert policy.confidence(held, None, 0.25) == pytest.approx(0.75 * good + 0.25 * bad)


def test_a_run_without_a_posterior_has_no_confidence_and_bad_runs_are_named(tmp_path):
    expert = SortingPolicy.expert()
    assert expert.method == "expert" and expert.action((0, 0, 2)) == 1  # pick the unknown
    with pytest.raises(ValueError, match="has no confidence; learn with"):
        expert.confidence(0)
    with pytest.raises(FileNotFoundError, match="holds no learned model"):
        SortingPolicy.load(tmp_path)
    (tmp_path / "model.json").write_text("{bad")
    with pytest.raises(ValueError, match="is not a learned model"):
        SortingPolicy.load(tmp_path)
    with pytest.raises(ValueError, match="state must be"):
        expert.action("face")
    with pytest.raises(ValueError, match="threshold must be in"):
        expert.defers(0, 1.5)


@pytest.mark.slow
def test_it_inspects_with_a_labs_fine_tuned_models(tmp_path, capsys):
    """The robot's inspection classifier fine-tuned on a few of its views, in a lab's models
    folder (the walk of docs/lab.md): the runtime and ``evaluate --lineup --models`` read it."""
    data, models = tmp_path / "data", tmp_path / "lab-models"
    assert main(["dataset", "--frames", "36", "--steps-per-session", "4", "--robot-onions", "30",
                 "--robot-views", "2", "--val", "0.34", "--test", "0.33", "--seed", "9",
                 "--workers", "1", "--out", str(data)]) == 0
    assert main(["train", "inspection", "--init", str(DEFAULT_MODELS / "inspection_classifier.pt"),
                 "--camera", "robot", "--data", str(data), "--epochs", "1", "--device", "cpu",
                 "--out", str(models)]) == 0
    for name in ("detector.pt", "state_classifier.pt", "inspection_classifier.pt"):
        shutil.copy(DEFAULT_MODELS / name, models / name)
    assert (models / "robot_inspection_classifier.pt").is_file()
    rec = tmp_path / "rec"
    assert main(["evaluate", "--policy", "expert", "--onions", "2", "--blemished", "1",
                 "--seed", "3", "--difficulty", "realistic", "--record-lineup", str(rec),
                 "--out", str(tmp_path / "expert"), "--no-rerun", "--no-mcap"]) == 0
    import cv2

    views = [cv2.imread(str(p))[..., ::-1] for p in sorted((rec / "images").glob("*-onion000-*"))]
    policy = SortingPolicy.expert()
    shipped = policy.inspection(device="cpu")(views)
    tuned = policy.inspection(models, device="cpu")(views)
    assert tuned.view_p_blemished != shipped.view_p_blemished  # another classifier read them
    assert main(["evaluate", "--policy", "expert", "--lineup", str(rec), "--truth",
                 str(rec / "truth.csv"), "--models", str(models), "--every-view", "--out",
                 str(tmp_path / "tuned"), "--json"]) == 0
    capsys.readouterr()
    evaluation = json.loads((tmp_path / "tuned" / "evaluation.json").read_text())
    first = evaluation["onions"][0]["p_blemished"]
    assert first == pytest.approx(tuned.p_blemished, abs=1e-5)
    assert np.isfinite(first)
