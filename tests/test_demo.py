"""``onionsort demo --quick``: the end-to-end smoke test of the whole pipeline."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from onionsort.cli import main
from onionsort.stages.models import CLASSIFIER_FILE, DEFAULT_MODELS, DETECTOR_FILE


def _rerun_cli():
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else shutil.which("rerun")


SHIPPED = pytest.mark.skipif(not (DEFAULT_MODELS / DETECTOR_FILE).exists()
                             or not (DEFAULT_MODELS / CLASSIFIER_FILE).exists(),
                             reason="the shipped perception models are missing")
CELLS = ("tp", "fp", "tn", "fn")


def _recount(onions: list[dict]) -> dict[str, int]:
    """TP/FP/TN/FN counted onion by onion from their true class and their fate."""
    return {"tp": sum(o["blemished"] and o["fate"] == "bin" for o in onions),
            "fp": sum(not o["blemished"] and o["fate"] == "bin" for o in onions),
            "tn": sum(not o["blemished"] and o["fate"] == "line" for o in onions),
            "fn": sum(o["blemished"] and o["fate"] == "line" for o in onions)}


@SHIPPED
def test_quick_demo_runs_end_to_end(quick_demo, capsys):
    from irl.domains.onion_sorting import onion_sorting
    from irl.metrics import inverse_learning_error
    from onionsort.stages.demo import METHODS, SIZES
    from recordings import open_session
    from state_abstraction.calibration import load_calibration

    out, said = quick_demo  # `onionsort demo --quick --out OUT` and what it printed
    results = json.loads((out / "results.json").read_text())
    size = SIZES[True]
    assert set(results["methods"]) == set(METHODS)
    assert results["backends"] == ["numpy"]
    assert (results["sessions"], results["onions"], results["blemished"]) == (
        size["sessions"], size["onions"], size["blemished"])

    # every recorded step was perceived once: an observation exactly where it was not occluded
    sessions = sorted((out / "sessions").glob("*.mcap"))
    assert len(sessions) == size["sessions"]
    n_occluded = 0
    for path in sessions:
        session = open_session(path)  # CRC-validated
        assert session.status == "complete"
        assert len(session.steps) == len(session.step_frames()) == size["steps"]
        assert sorted(session.perception) == list(range(size["steps"]))
        for msg in session.perception.values():
            assert (msg["observation"] is None) == bool(msg["occluded"])
        n_occluded += sum(bool(m["occluded"]) for m in session.perception.values())

    calibration_path = out / "calibration" / "calibration.json"
    calibration = load_calibration(calibration_path)
    assert results["state_error_rate"] == pytest.approx(calibration.state_error_rate)
    assert results["pair_error_rate"] == pytest.approx(calibration.pair_error_rate)

    domain = onion_sorting()
    for method, pooled in results["methods"].items():
        run = out / method
        model = json.loads((run / "model.json").read_text())
        evaluation = json.loads((run / "evaluation.json").read_text())
        (repeat,) = pooled["per_repeat"]
        # learned from exactly the recorded, perceived steps, through this calibration
        assert model["method"] == method == evaluation["method"]
        assert model["backend"] == repeat["backend"] == "numpy"  # the default
        assert model["sessions"] == [str(p) for p in sessions]
        assert model["n_steps"] == size["sessions"] * size["steps"]
        assert model["n_occluded"] == n_occluded
        assert Path(model["observation_model"]) == calibration_path
        # the policy written is the learned one, named state by state
        assert [(p["state"], p["action"]) for p in model["policy"]] == [
            (domain.state_names[s], domain.action_names[a])
            for s, a in enumerate(model["policy_indices"])]
        # the repeat's result is this run's evaluation, recounted onion by onion
        onions = evaluation["onions"]
        assert len(onions) == size["onions"]
        assert sum(o["blemished"] for o in onions) == size["blemished"]
        counts = _recount(onions)
        assert {k: evaluation[k] for k in CELLS} == counts == {k: repeat[k] for k in CELLS}
        assert repeat["undecided"] == evaluation["undecided"] == sum(
            not o["decided"] for o in onions)
        # one repeat: the pooled counts are its counts; precision and recall are theirs
        assert {k: pooled[k] for k in CELLS} == counts
        tp, fp, fn = counts["tp"], counts["fp"], counts["fn"]
        precision = tp / (tp + fp) if tp + fp else 0.0
        recall = tp / (tp + fn) if tp + fn else 0.0
        for r in (pooled, repeat, evaluation):
            assert r["precision"] == pytest.approx(precision)
            assert r["recall"] == pytest.approx(recall)
        for key, value in (("precision_ci", precision), ("recall_ci", recall)):
            low, high = pooled[key]
            assert 0.0 <= low <= value <= high <= 1.0
        # the reward reported is the one written, and the ILE is that reward's
        assert repeat["theta"] == model["theta"]
        theta = np.array([model["theta"][name] for name in domain.task.feature_names])
        ile = inverse_learning_error(domain.mdp, domain.true_theta, theta)
        assert repeat["ile"] == pytest.approx(ile) and pooled["ile"] == pytest.approx(ile)
        # the table prints these numbers
        assert (f"| {method} | ours (simulation, 1 repeat(s)) | {tp} | {fp} | {counts['tn']} | "
                f"{fn} | {precision:.3f}") in said
    assert "| mmap-birl | paper (physical robot) | 23 | 2 | 18 | 7 |" in said

    # the Sawyer sorted with the policy of model.json: sorting again with it, seed, models and
    # the calibration of its level as the demo did, gives the same onions the same fates
    from onionsort.stages.models import PerceptionModels
    from robot.evaluation import evaluate_policy

    model = json.loads((out / "mmap-birl" / "model.json").read_text())
    again = evaluate_policy(np.array(model["policy_indices"]), n_onions=size["onions"],
                            n_blemished=size["blemished"], seed=results["seed"],
                            classify=PerceptionModels.load().at_level(
                                results["difficulty"]).inspector(camera="robot"))
    evaluation = json.loads((out / "mmap-birl" / "evaluation.json").read_text())
    assert [o.to_dict() for o in again.onions] == evaluation["onions"]

    rrds = sorted(out.rglob("*.rrd"))
    assert {p.name for p in rrds} >= {"sessions.rrd", "learn.rrd", "evaluation.rrd"}
    assert not list(out.rglob("*.partial"))
    # each opens on views that all have data, and 3D views that hold only what they can place;
    # the sessions' recording shows what perception made of them
    from tests.recordings.rerun.rrd_layout import blueprint_views, layout_problems

    for path in rrds:
        assert layout_problems(path) == [], path
    assert "observations" in {v.name for v in blueprint_views(out / "sessions.rrd")}
    cli = _rerun_cli()
    if cli is None:
        pytest.skip("the rerun CLI is not installed")
    for path in rrds:
        done = subprocess.run([cli, "rrd", "verify", str(path)], capture_output=True, text=True)
        assert done.returncode == 0, f"{path}: {done.stdout}{done.stderr}"

    # a second run into the same folder is refused rather than mixing two demos
    assert main(["demo", "--quick", "--out", str(out)]) == 2
    assert "already holds a demo" in capsys.readouterr().err


def test_precision_and_recall_intervals_pool_repeats_and_contain_the_pooled_value():
    from onionsort.stages.demo import precision_recall_intervals

    # a perfect sort of 2 x 10 onions does not prove precision and recall are exactly 1
    (p_lo, p_hi), (r_lo, r_hi) = precision_recall_intervals([[6, 0, 4, 0], [6, 0, 4, 0]])
    assert p_hi == r_hi == 1.0 and 0.5 < p_lo < 1.0 and 0.5 < r_lo < 1.0
    counts = [[5, 1, 3, 1], [3, 0, 4, 3], [6, 2, 2, 0]]
    (p_lo, p_hi), (r_lo, r_hi) = precision_recall_intervals(counts, seed=1)
    assert p_lo < 14 / 17 < p_hi and r_lo < 14 / 18 < r_hi  # the pooled precision and recall
    assert precision_recall_intervals(counts, seed=1) == ((p_lo, p_hi), (r_lo, r_hi))
    # a repeat that never sorts a blemished onion out drags the recall interval down
    (_, _), (w_lo, w_hi) = precision_recall_intervals([*counts, [0, 0, 4, 6]], seed=1)
    assert w_lo < r_lo and w_hi < r_hi
    with pytest.raises(ValueError, match="shape"):
        precision_recall_intervals([[1, 2, 3]])


@pytest.mark.slow
@SHIPPED
def test_quick_demo_with_repeats_reports_per_repeat_results_and_intervals(tmp_path):
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--repeats", "2", "--sessions", "2", "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    assert results["repeats"] == 2 and results["sessions"] == 2
    for r in results["methods"].values():
        assert [run["seed"] for run in r["per_repeat"]] == [0, 1]
        assert r["tp"] == sum(run["tp"] for run in r["per_repeat"])
        assert r["precision_ci"][0] <= r["precision"] <= r["precision_ci"][1]
        assert r["recall_ci"][0] <= r["recall"] <= r["recall_ci"][1]
    assert (out / "repeat_1" / "map-birl" / "evaluation.json").is_file()


@pytest.mark.slow
@SHIPPED
def test_quick_demo_deferring_sorts_the_same_line_up_twice_and_reports_both(tmp_path, capsys):
    from onionsort.stages.demo import METHODS

    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--sessions", "2", "--defer-below", "0.9",
                 "--posterior-method", "laplace", "--out", str(out)]) == 0
    assert "deferring below 0.9" in capsys.readouterr().out
    results = json.loads((out / "results.json").read_text())
    assert results["defer_below"] == 0.9
    assert set(results["deferring"]) == {"mmap-birl", "map-birl"}
    for method in METHODS:
        run = out / method
        plain = json.loads((run / "evaluation.json").read_text())
        if method not in results["deferring"]:
            assert not (run / "deferring").exists() and not (run / "posterior.npz").exists()
            continue
        deferring = json.loads((run / "deferring" / "evaluation.json").read_text())
        # the same line-up, sorted twice
        assert [o["blemished"] for o in deferring["onions"]] == \
            [o["blemished"] for o in plain["onions"]]
        pooled = results["deferring"][method]
        sorted_ = [o for o in deferring["onions"] if o["fate"] != "tray"]
        assert {c: pooled[c] for c in CELLS} == _recount(sorted_)
        assert pooled["deferred"] == deferring["deferred"] == \
            sum(o["fate"] == "tray" for o in deferring["onions"])
        assert pooled["deferral_rate"] == pooled["deferred"] / len(deferring["onions"])
        assert (run / "policy_confidence.json").is_file()


def test_demo_methods_are_checked_and_recorded_only_when_not_the_default(tmp_path):
    from onionsort.stages.demo import METHODS, SIZES, DemoConfig, _settings

    assert DemoConfig(out=tmp_path / "d").methods == METHODS
    assert "methods" not in _settings(DemoConfig(out=tmp_path / "d"), SIZES[True])
    chosen = DemoConfig(out=tmp_path / "d", methods=("mmap-birl", "bc", "bc-em", "bc"))
    assert chosen.methods == ("mmap-birl", "bc", "bc-em")
    assert _settings(chosen, SIZES[True])["methods"] == ["mmap-birl", "bc", "bc-em"]
    for bad, words in ((("bc", "dagger"), "got dagger"), ((), "at least one learner")):
        with pytest.raises(ValueError, match=words) as info:
            DemoConfig(out=tmp_path / "d", methods=bad)
        assert "\n" not in str(info.value)


def test_a_cloned_policy_is_scored_and_tabled_without_a_reward():
    """Behaviour cloning's model.json has no ``theta``: its ILE is its policy's, and Table 1
    lists whichever methods the demo ran."""
    from irl.domains.onion_sorting import onion_sorting
    from irl.solvers import OptimalQSolver
    from onionsort.stages.demo import _ile, _pooled, table

    dom = onion_sorting()
    expert = OptimalQSolver(dom.mdp).solve(dom.true_theta).policy
    assert _ile({"theta": None, "policy_indices": expert.tolist()}) == \
        {"ile": 0.0, "normalized_ile": 0.0}
    wrong = expert.copy()
    wrong[wrong == 4] = 3  # keeps every blemished onion
    assert _ile({"theta": None, "policy_indices": wrong.tolist()})["ile"] > 0
    run = {"tp": 3, "fp": 0, "tn": 4, "fn": 3, "ile": 0.0, "normalized_ile": 0.0}
    results = {"methods": {m: _pooled([run], 0) for m in ("mmap-birl", "bc-em")}}
    rows = table(results).splitlines()
    assert [r.split(" | ")[0] for r in rows[2:]] == ["| mmap-birl", "| mmap-birl", "| bc-em"]
