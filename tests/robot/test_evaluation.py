"""The sorting evaluation: the Sawyer executes a greedy policy and TP/FP/TN/FN are counted."""

from __future__ import annotations

import itertools
import json
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from typing import ClassVar

import numpy as np
import pytest

from irl.domains.onion_sorting import (
    N_ACTIONS,
    N_STATES,
    Prediction,
    SortAction,
    onion_sorting,
)
from robot.evaluation import SortingResult, evaluate_policy, greedy_actions


@pytest.fixture(scope="module")
def expert_pi():
    return onion_sorting().expert_policy()


@pytest.fixture(scope="module")
def expert_run(expert_pi):
    events = []
    result = evaluate_policy(expert_pi, n_onions=8, n_blemished=5, seed=3,
                             classify="ground-truth", on_step=events.append)
    return result, events


def always(prediction):
    return lambda rgb: prediction


def test_the_expert_with_perfect_perception_sorts_perfectly(expert_run):
    result, _ = expert_run
    assert (result.tp, result.fp, result.tn, result.fn) == (5, 0, 3, 0)
    assert result.precision == result.recall == 1.0
    assert result.undecided == 0 and result.n_steps == 8 * 4  # claim, pick, inspect, place
    assert [o.index for o in result.onions] == list(range(8))
    for o in result.onions:
        assert o.decided and o.fate == ("bin" if o.blemished else "line")
        assert o.perceived == (Prediction.BAD if o.blemished else Prediction.GOOD)


def test_the_step_events_tell_the_episode(expert_run):
    result, events = expert_run
    assert [e.step for e in events] == list(range(result.n_steps))
    assert all(a.next_state == b.state for a, b in itertools.pairwise(events))
    last = events[-1]
    assert (last.tp, last.fp, last.tn, last.fn) == (result.tp, result.fp, result.tn, result.fn)
    inspected = [e for e in events if e.inspection is not None]
    assert len(inspected) == 8
    assert all(e.action == SortAction.INSPECT and e.perceived is not None for e in inspected)
    assert sum(e.fate is not None for e in events) == 8
    assert all(e.color is None and e.depth is None and e.q.shape == (7,) for e in events)


def test_a_classifier_that_always_says_good_finds_no_blemished_onion(expert_pi):
    r = evaluate_policy(expert_pi, n_onions=8, n_blemished=5, seed=3,
                        classify=always(Prediction.GOOD))
    assert (r.tp, r.fp, r.tn, r.fn) == (0, 0, 3, 5)
    assert r.recall == 0.0 and r.precision == 0.0  # 0/0 is defined as 0
    assert all(o.perceived == Prediction.GOOD for o in r.onions)


def test_perception_errors_propagate_as_in_the_mdp(expert_pi):
    r = evaluate_policy(expert_pi, n_onions=6, n_blemished=2, seed=0,
                        classify=always(Prediction.BAD))
    assert (r.tp, r.fp, r.tn, r.fn) == (2, 4, 0, 0)
    assert r.precision == pytest.approx(2 / 6) and r.recall == 1.0


def test_a_policy_that_never_claims_leaves_everything_on_the_line():
    never = np.full(N_STATES, int(SortAction.PICK))
    r = evaluate_policy(never, n_onions=5, n_blemished=2, classify="ground-truth",
                        max_steps_per_onion=2)
    assert (r.tp, r.fp, r.tn, r.fn) == (0, 0, 3, 2)
    assert r.undecided == 5 and r.n_steps == 10
    assert all(not o.decided and o.fate == "line" and o.perceived is None for o in r.onions)


def test_a_policy_array_and_its_greedy_actions_give_the_same_episode(expert_pi):
    kwargs = {"n_onions": 3, "n_blemished": 1, "seed": 7, "classify": "ground-truth"}
    assert evaluate_policy(expert_pi, **kwargs) == evaluate_policy(greedy_actions(expert_pi),
                                                                    **kwargs)
    assert np.array_equal(greedy_actions(expert_pi), onion_sorting().optimal_policy())


def test_seeded_runs_are_reproducible(expert_pi):
    kwargs = {"n_onions": 6, "n_blemished": 3, "classify": "ground-truth"}
    a, b = evaluate_policy(expert_pi, seed=1, **kwargs), evaluate_policy(expert_pi, seed=1,
                                                                          **kwargs)
    c = evaluate_policy(expert_pi, seed=2, **kwargs)
    assert a == b and a.to_dict() == b.to_dict()
    assert [o.blemished for o in a.onions] != [o.blemished for o in c.onions]


def test_the_result_is_json_ready_and_prints_a_confusion_table(expert_run):
    result, _ = expert_run
    d = json.loads(json.dumps(result.to_dict()))
    assert d["tp"] == 5 and d["precision"] == 1.0 and len(d["onions"]) == 8
    assert d["onions"][0]["perceived"] in ("good", "bad")
    table = result.table()
    assert "TP 5" in table and "TN 3" in table and "precision 1.000" in table
    with pytest.raises(ValueError, match="number of onions"):
        SortingResult(tp=1, fp=0, tn=0, fn=0, n_steps=1, undecided=0, onions=())


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"actions": np.zeros(47, int)}, r"actions must be .* shape \(48,\)"),
    ({"actions": np.zeros((48, 4))}, r"actions must be .*got shape \(48, 4\)"),
    ({"actions": np.full(48, 0.5)}, "actions must hold integer"),
    ({"actions": np.full(48, N_ACTIONS)}, r"actions must be action indices in \[0, 5\)"),
    ({"actions": np.full((48, 5), np.nan)}, "actions as pi"),
    ({"n_onions": 0}, "n_onions must be an int >= 1"),
    ({"n_onions": 2.5}, "n_onions must be an int"),
    ({"n_blemished": 9}, "n_blemished must be <= n_onions=8"),
    ({"n_blemished": -1}, "n_blemished must be an int >= 0"),
    ({"max_steps_per_onion": 0}, "max_steps_per_onion must be an int >= 1"),
    ({"classify": "oracle"}, "classify must be"),
])
def test_bad_arguments_raise_value_errors_naming_them(kwargs, match):
    args = {"actions": np.zeros(N_STATES, int), "n_onions": 8, "n_blemished": 5,
            "classify": "ground-truth", **kwargs}
    with pytest.raises(ValueError, match=match):
        evaluate_policy(args.pop("actions"), **args)


def _rerun_cli() -> str | None:
    local = Path(sys.executable).parent / "rerun"
    return str(local) if local.exists() else shutil.which("rerun")


def test_the_evaluation_logs_to_a_valid_rerun_recording(tmp_path, expert_pi):
    pytest.importorskip("rerun")
    from onionsort.stages.evaluate_rerun import EvaluationLogger

    path = tmp_path / "eval.rrd"
    with EvaluationLogger(path) as log:
        result = evaluate_policy(expert_pi, n_onions=2, n_blemished=1, seed=0,
                                 classify=always(Prediction.BAD), render=True,
                                 on_step=log.on_step)
    assert result.n_steps == 8 and path.stat().st_size > 10_000
    cli = _rerun_cli()
    if cli is None:
        pytest.skip("the rerun CLI is not installed")
    done = subprocess.run([cli, "rrd", "verify", str(path)], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.mark.slow
def test_the_expert_sorts_fifty_onions_perfectly(expert_pi):
    r = evaluate_policy(expert_pi, n_onions=50, n_blemished=30, seed=0, classify="ground-truth")
    assert (r.tp, r.fp, r.tn, r.fn) == (30, 0, 20, 0) and r.n_steps == 200


def test_rendering_the_main_camera_never_changes_what_the_inspection_sees(expert_pi):
    # on a noisy level the cameras draw noise from streams of their own, so a run that renders
    # every step (a Rerun log, a Gymnasium observation) sees the same inspection views
    views = {True: [], False: []}

    def classify(shown, render):
        views[render].extend(v.copy() for v in shown)
        return Prediction.BAD if shown[0].mean() > 100 else Prediction.GOOD

    results = {render: evaluate_policy(expert_pi, n_onions=2, n_blemished=1, seed=5,
                                       move_steps=40, difficulty="hard", render=render,
                                       classify=lambda shown, r=render: classify(shown, r))
               for render in (True, False)}
    assert results[True] == results[False]
    assert len(views[True]) == len(views[False]) > 0
    assert all(np.array_equal(a, b) for a, b in zip(views[True], views[False], strict=True))


def test_every_step_carries_the_world_in_3d(expert_run):
    from robot.station import SAWYER_JOINTS, STEP_DURATION_S, station_robot

    _, events = expert_run
    standing = station_robot()
    for e in events:
        robot = e.world.robot
        assert robot.joint_names == SAWYER_JOINTS
        np.testing.assert_allclose(robot.positions, e.q, atol=1e-12)
        np.testing.assert_allclose(robot.base.position, standing.base.position, atol=1e-6)
        np.testing.assert_allclose(robot.base.orientation, standing.base.orientation,
                                   atol=1e-6)
        assert set(e.world.cameras) == {"camera", "inspection"}
        assert e.time_s == (e.step + 1) * STEP_DURATION_S
        shapes = {s.name: s for s in e.world.shapes}
        assert {"workcell/belt", "workcell/pedestal", "gate"} <= set(shapes)
        # the onions in the world are the labelled ones, none parked below it
        assert {n for n in shapes if n.startswith("onions/")} == {
            f"onions/{o.onion_id}" for o in e.onions}
        for o in e.onions:
            assert shapes[f"onions/{o.onion_id}"].class_id == int(o.blemished)
            assert o.position[2] > 0 and o.box is None  # no render, no boxes
        focus = [o.onion_id for o in e.onions if o.in_focus]
        assert focus == ([] if e.onion is None else [e.onion])
    # at first the line-up's last onion waits upstream, parked out of the world (z = -10)
    assert len(events[0].onions) < 8 == len(events[-1].onions)


def test_recording_the_start_changes_no_later_render(expert_pi):
    # the view before the first action draws its noise from a stream of its own
    runs = {}
    for start in (True, False):
        views, events = [], []
        result = evaluate_policy(expert_pi, n_onions=2, n_blemished=1, seed=5, move_steps=40,
                                 difficulty="hard", render=True, classify="ground-truth",
                                 on_step=events.append,
                                 on_start=views.append if start else None)
        runs[start] = (result, views, events)
    (r_on, views, on), (r_off, none, off) = runs[True], runs[False]
    assert r_on == r_off and none == [] and len(views) == 1
    assert all(np.array_equal(a.color, b.color) and np.array_equal(a.depth, b.depth)
               for a, b in zip(on, off, strict=True))
    view = views[0]
    assert view.time_s == 0.0 and view.color.shape == on[0].color.shape
    np.testing.assert_allclose(view.q, on[0].q)  # the first claim moves no joint
    assert any(o.box is not None for o in view.onions)  # rendered: the waiting onions boxed
    with pytest.raises(TypeError, match="on_start must be callable"):
        evaluate_policy(expert_pi, n_onions=1, n_blemished=0, classify="ground-truth",
                        on_start=3)


class _SequentialByImage:
    """A sequential classifier (:class:`robot.classifier.SequentialClassifier`) whose view
    probability is drawn from the view's pixels: deterministic, and different from view to
    view; calls by ``noisy-or`` at 0.5."""

    kw: ClassVar[dict] = {"prior": 0.5, "train_prior": 0.5, "visibility": 0.5}

    def view_probabilities(self, views):
        import hashlib

        return [(int(hashlib.blake2b(v.tobytes(), digest_size=4).hexdigest(), 16) % 1000 + 0.5)
                / 1000 for v in views]

    def settled(self, view_p, remaining):
        from perception.fusion import settled

        return settled(view_p, remaining, "noisy-or", threshold=0.5, **self.kw)

    def verdict(self, view_p):
        from perception.fusion import fuse

        p = fuse(view_p, "noisy-or", **self.kw)
        return SimpleNamespace(prediction=int(Prediction.BAD if p >= 0.5 else Prediction.GOOD),
                               p_blemished=p, view_p_blemished=tuple(view_p))

    def __call__(self, views):
        return self.verdict(self.view_probabilities(views))


def test_the_robot_stops_showing_an_onion_once_its_call_is_settled(expert_pi):
    """It takes views until the call is settled (:func:`perception.fusion.settled`: no later
    view could change it), and every view without stopping."""
    from perception.fusion import settled as is_settled
    from robot.classifier import SequentialClassifier

    classify = _SequentialByImage()
    assert isinstance(classify, SequentialClassifier)
    runs, shown = {}, {True: {}, False: {}}
    for stop in (True, False):
        def keep(event, stop=stop):
            if event.views:
                shown[stop][event.onion] = list(event.view_p_blemished)
        runs[stop] = evaluate_policy(expert_pi, n_onions=6, n_blemished=3, seed=4,
                                     move_steps=40, classify=classify, inspection_views=4,
                                     stop_when_settled=stop, on_step=keep)
    stopping, every = runs[True], runs[False]
    assert all(o.views == 4 for o in every.onions) and every.views_taken == 24
    assert stopping.views_taken < every.views_taken  # some calls settled early
    for onion in stopping.onions:
        view_p = shown[True][onion.index]
        assert len(view_p) == onion.views
        k = onion.views  # settled after k views, not before (or all 4 taken)
        assert k == 4 or is_settled(view_p, 4 - k, "noisy-or", threshold=0.5, **classify.kw)
        assert not any(is_settled(view_p[:j], 4 - j, "noisy-or", threshold=0.5, **classify.kw)
                       for j in range(1, k))
        if k < 4:  # noisy-or settles early only on rot seen
            assert onion.perceived == Prediction.BAD
    # the first onion meets the same world in both runs: its views so far, and its call
    first = stopping.onions[0]
    assert shown[True][0] == shown[False][0][:first.views]
    assert first.perceived == every.onions[0].perceived


def _sure_of(policy: np.ndarray) -> np.ndarray:
    """A (48, 5) confidence that is sure of ``policy``'s action in every state."""
    confidence = np.zeros((N_STATES, N_ACTIONS))
    confidence[np.arange(N_STATES), greedy_actions(policy)] = 1.0
    return confidence


def test_the_confidence_in_an_action_weighs_what_the_inspected_onion_may_be(expert_pi):
    from irl.domains.onion_sorting import Location, SortingState, encode_state
    from robot.evaluation import confidence_in

    confidence = _sure_of(expert_pi)
    held = SortingState(Location.FACE, Location.FACE, Prediction.BAD)
    binned = int(SortAction.PLACE_IN_BIN)
    # the policy is sure to bin a blemished onion and to keep a good one: how sure the robot
    # is that binning is right is how sure it is that the onion is blemished
    assert confidence_in(confidence, held, binned, 0.7) == pytest.approx(0.7)
    assert confidence_in(confidence, held, binned, 1.0) == 1.0
    assert confidence_in(confidence, held, binned, None) == 1.0
    unknown = held._replace(prediction=Prediction.UNKNOWN)
    confidence[encode_state(unknown)] = [0.0, 0.0, 0.8, 0.0, 0.2]
    assert confidence_in(confidence, unknown, int(SortAction.INSPECT), 0.3) == 0.8
    assert confidence_in(confidence[:, 0], held, binned, 0.7) == confidence[encode_state(held), 0]


@pytest.mark.parametrize(("p", "deferred"), [(0.7, 4), (0.95, 0)])
def test_a_robot_unsure_of_what_it_saw_defers_though_its_policy_is_sure(expert_pi, p, deferred):
    """Every onion is read as blemished with probability ``p``: below 0.9 the robot is not
    sure enough that binning is right, and sends each onion to the tray."""
    def unsure(views):
        return SimpleNamespace(prediction=Prediction.BAD, p_blemished=p)

    r = evaluate_policy(expert_pi, n_onions=4, n_blemished=2, seed=5, classify=unsure,
                        confidence=_sure_of(expert_pi), defer_below=0.9)
    assert r.deferred == deferred and (r.tp, r.fp) == ((0, 0) if deferred else (2, 2))
