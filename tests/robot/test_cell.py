"""One sorting loop for any cell: the protocol, the loop, and a recorded line-up replayed in
place of the arm giving the live run's fates whichever policy runs."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from irl.domains.onion_sorting import (
    N_ACTIONS,
    N_STATES,
    Prediction,
    SortAction,
    onion_sorting,
)
from robot.cell import SortingCell, SortingRun, ViewReader
from robot.evaluation import evaluate_policy
from robot.replay import ReplayedLineup
from robot.station import SawyerStation
from tests.robot.test_evaluation import _SequentialByImage, _sure_of

EXPERT = onion_sorting().expert_policy().argmax(axis=1)


def _swapped(policy: np.ndarray) -> np.ndarray:
    """``policy`` with its two places swapped: good onions binned, blemished ones kept."""
    out = policy.copy()
    bin_, line = int(SortAction.PLACE_IN_BIN), int(SortAction.PLACE_ON_CONVEYOR)
    out[policy == bin_], out[policy == line] = line, bin_
    return out


def _views_of(**kwargs) -> tuple:
    """``(result, {onion: views})`` of an evaluation, every view of each inspected onion."""
    views = {}

    def keep(event):
        if event.views:
            views[event.onion] = [v.copy() for v in event.views]

    result = evaluate_policy(on_step=keep, **kwargs)
    return result, views


def test_the_station_and_a_replayed_lineup_are_cells():
    members = ("state", "focus", "execute", "inspect", "defer", "fate")
    station = SawyerStation("ground-truth", n_onions=1, n_blemished=0)  # not entered
    assert all(hasattr(SawyerStation, m) or m in vars(station) for m in members)
    assert isinstance(ReplayedLineup(2, lambda i: []), SortingCell)
    with pytest.raises(TypeError, match="has no defer, fate"):
        SortingRun(SimpleNamespace(state=None, focus=None, execute=None, inspect=None), 2,
                   ViewReader("ground-truth", max_views=1))


def test_each_view_is_the_same_whatever_the_policy_did_before():
    """Binning an onion or keeping it, stopping early or not, leaves the arm elsewhere: each
    onion's views are still bit for bit the same (arm at the pose, a noise stream per view)."""
    kwargs = {"n_onions": 4, "n_blemished": 2, "seed": 12, "difficulty": "hard"}
    classify = _SequentialByImage()
    every, seen = _views_of(actions=EXPERT, classify=classify, stop_when_settled=False,
                            **kwargs)
    swapped, other = _views_of(actions=_swapped(EXPERT), classify=classify,
                               stop_when_settled=False, **kwargs)
    stopping, first = _views_of(actions=EXPERT, classify=classify, **kwargs)
    assert [o.fate for o in every.onions] != [o.fate for o in swapped.onions]
    assert stopping.views_taken < every.views_taken  # the arm turned less
    assert set(seen) == set(other) == set(first) == set(range(4))
    for onion, views in seen.items():
        assert len(views) == 5
        assert all(np.array_equal(a, b) for a, b in zip(views, other[onion], strict=True))
        assert all(np.array_equal(a, b) for a, b in zip(first[onion], views, strict=False))


@pytest.mark.parametrize("deferring", [False, True])
def test_a_recorded_lineup_replayed_gives_the_live_run_of_any_policy(deferring):
    """Record every view with the expert, replay another policy on the recording: the same
    fates, calls, probabilities and steps as that policy sorting the line-up live."""
    kwargs = {"n_onions": 5, "n_blemished": 3, "seed": 21, "difficulty": "hard"}
    classify = _SequentialByImage()
    _, recorded = _views_of(actions=EXPERT, classify=classify, stop_when_settled=False,
                            **kwargs)
    policy = _swapped(EXPERT)
    deferral = {"confidence": _sure_of(policy), "defer_below": 0.9} if deferring else {}
    live = evaluate_policy(policy, classify=classify, **deferral, **kwargs)
    truth = np.array([o.blemished for o in live.onions])
    run = SortingRun(ReplayedLineup(5, lambda i: recorded[i]), 5,
                     ViewReader(classify, max_views=5), truth=truth, **deferral)
    run.run(policy)
    replayed = run.result()
    assert replayed.to_dict() == live.to_dict()
    assert (live.deferred > 0) == deferring


class _Reads:
    """A classifier that calls an onion by its one view's first pixel (255: blemished)."""

    def __call__(self, views):
        return Prediction.BAD if views[0][0, 0, 0] == 255 else Prediction.GOOD


def test_the_loop_sorts_a_replayed_lineup_by_its_calls_and_counts_against_the_truth():
    calls = [True, False, True, True]  # the third onion's call is wrong: a good one binned
    truth = np.array([True, False, False, True])
    views = [[np.full((4, 4, 3), 255 if bad else 0, np.uint8)] for bad in calls]
    cell = ReplayedLineup(4, lambda i: views[i])
    run = SortingRun(cell, 4, ViewReader(_Reads(), max_views=3), truth=truth)
    run.run(EXPERT)
    result = run.result()
    assert [cell.fate(i) for i in range(4)] == ["bin", "line", "bin", "bin"]
    assert (result.tp, result.fp, result.tn, result.fn) == (2, 1, 1, 0)
    assert result.n_steps == 16 and run.over and cell.focus == 3
    assert [o.perceived for o in result.onions] == [Prediction.BAD, Prediction.GOOD,
                                                    Prediction.BAD, Prediction.BAD]


def test_the_budget_ends_a_loop_that_never_decides():
    never = np.full(N_STATES, int(SortAction.PICK))  # picks, never places
    run = SortingRun(ReplayedLineup(3, lambda i: []), 3, ViewReader("ground-truth",
                                                                    max_views=1),
                     truth=np.zeros(3, bool), max_steps_per_onion=2)
    run.run(never)
    assert run.n_steps == 6 and run.result().undecided == 3


def test_a_cell_that_does_not_reach_the_mdps_state_is_an_error():
    class Stuck(ReplayedLineup):
        def execute(self, action):  # claims, then never moves
            if self.focus is None:
                super().execute(action)

    run = SortingRun(Stuck(2, lambda i: []), 2, ViewReader("ground-truth", max_views=1))
    with pytest.raises(RuntimeError, match=r"after PICK .* the MDP says"):
        run.run(EXPERT)


def test_ground_truth_inspection_needs_the_truth():
    cell = ReplayedLineup(1, lambda i: [np.zeros((2, 2, 3), np.uint8)])
    run = SortingRun(cell, 1, ViewReader("ground-truth", max_views=1))
    with pytest.raises(ValueError, match="needs each onion's true class"):
        run.run(EXPERT)


def test_a_replayed_lineup_refuses_what_a_line_cannot_do():
    cell = ReplayedLineup(1, lambda i: [])
    with pytest.raises(RuntimeError, match="no onion is in focus to PICK"):
        cell.execute(SortAction.PICK)
    cell.execute(SortAction.CLAIM)
    with pytest.raises(RuntimeError, match="exhausted"):
        cell.execute(SortAction.CLAIM)
    with pytest.raises(ValueError, match="inspect"):
        cell.execute(SortAction.INSPECT)
    assert cell.defer() == 0 and cell.fate(0) == "tray" and cell.focus is None


def test_the_sawyer_and_the_gymnasium_env_go_through_the_loop(monkeypatch):
    import gymnasium

    from robot import SORTING_ENV_ID
    from robot.cell import SortingRun as Loop

    cells = []
    real = Loop.act

    def spy(self, action):
        cells.append(type(self.cell).__name__)
        return real(self, action)

    monkeypatch.setattr(Loop, "act", spy)
    result = evaluate_policy(EXPERT, n_onions=1, n_blemished=1, classify="ground-truth",
                             move_steps=40)
    assert cells == ["SawyerStation"] * result.n_steps == ["SawyerStation"] * 4
    env = gymnasium.make(SORTING_ENV_ID, n_onions=1, n_blemished=0, move_steps=40)
    try:
        env.reset(seed=0)
        env.step(int(SortAction.CLAIM))
    finally:
        env.close()
    assert cells[-1] == "SawyerStation" and len(cells) == 5
    assert N_ACTIONS == 5
