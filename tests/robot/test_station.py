"""The Sawyer station: each motion primitive takes the world to the state the MDP predicts."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pybullet as p
import pytest

from irl.domains.onion_sorting import Location, Prediction, SortAction, SortingState, next_state
from robot.belt import make_lineup
from robot.camera import boxes_from_segmentation
from robot.classifier import GROUND_TRUTH
from robot.inspection_poses import INSPECTION_VIEWS, inspection_poses
from robot.primitives import ROBOT_TARGETS, target_errors
from robot.sawyer import flange_down
from robot.scene import GATE_X
from robot.state_map import PICK_SPOT, hand_location, in_bin, on_belt
from robot.station import START_STATE, SawyerStation

C, P, I, PC, PB = SortAction  # CLAIM, PICK, INSPECT, PLACE_ON_CONVEYOR, PLACE_IN_BIN


def always(prediction: Prediction):
    return lambda views: prediction


#: (name, actions from the start, classifier): one starting state each
_SCENARIOS = {
    "start": ((), GROUND_TRUTH),
    "claimed": ((C,), GROUND_TRUTH),
    "hover": ((C, P), GROUND_TRUTH),
    "face-good": ((C, P, I), always(Prediction.GOOD)),
    "face-bad": ((C, P, I), always(Prediction.BAD)),
    "binned": ((C, P, I, PB), always(Prediction.BAD)),
    "left-on-line": ((C, P, I, PC), always(Prediction.GOOD)),
    "put-back-unknown": ((C, P, PC), GROUND_TRUTH),
    "claimed-from-bin": ((C, P, PB, C), GROUND_TRUTH),
}


@pytest.fixture(scope="module")
def station():
    with SawyerStation(GROUND_TRUTH, n_onions=4, n_blemished=2, seed=5) as st:
        yield st


@contextlib.contextmanager
def _station_in(scenario: str) -> Iterator[SawyerStation]:
    prefix, classify = _SCENARIOS[scenario]
    with SawyerStation(classify, n_onions=3, n_blemished=1, seed=2) as st:
        for a in prefix:
            st.step(a)
        yield st


def _check_step(st: SawyerStation, action: SortAction) -> None:
    s, flange, focus = st.state, st.flange, st.focus
    done = st.step(action)
    perceived_bad = st.focus is not None and st.perceived(st.focus) == Prediction.BAD
    expected = next_state(s, action, blemished=perceived_bad)
    assert done.state == s and done.next_state == expected == st.state, action.name
    if expected == s:  # nothing happens physically
        assert st.focus == focus and np.allclose(st.flange, flange, atol=1e-3), action.name
    else:  # the flange ends at its target for the new end-effector location
        assert np.linalg.norm(st.flange - ROBOT_TARGETS[expected.end_effector]) < 0.01
        assert done.reach_error < 0.01, action.name
    assert (done.perceived is not None) == (done.inspection is not None)


@pytest.mark.parametrize("scenario", list(_SCENARIOS))
def test_each_primitive_reaches_the_mdps_next_state(scenario):
    """Every action from the scenario's state; the no-ops share one station."""
    with _station_in(scenario) as shared:
        s = shared.state
        for action in SortAction:
            if next_state(s, action, False) == s == next_state(s, action, True):
                _check_step(shared, action)
            else:
                with _station_in(scenario) as st:
                    _check_step(st, action)


def test_the_station_starts_in_the_mdps_initial_state(station):
    assert station.state == START_STATE
    assert hand_location(station.flange, ROBOT_TARGETS) == Location.CONVEYOR


@pytest.mark.parametrize("loc", list(Location))
def test_every_flange_target_is_reached_exactly_with_the_flange_down(station, loc):
    position_error, angle_error = target_errors(station.arm)[loc]
    assert position_error < 1e-3 and angle_error < 0.02
    assert hand_location(ROBOT_TARGETS[loc], ROBOT_TARGETS) == loc


def test_a_sorting_cycle_moves_the_onion_where_the_mdp_says():
    with SawyerStation(always(Prediction.BAD), n_onions=3, n_blemished=1, seed=0) as st:
        st.step(C)
        first = st.focus
        pos = st.position(first)
        assert st.gate.raised and st.place_of(first) == "waiting"
        assert abs(pos[0] - PICK_SPOT[0]) < 0.02 and pos[0] < GATE_X and on_belt(pos)
        st.step(P)
        assert not st.gate.raised and st.place_of(first) == "held"
        held = st.position(first)
        assert held[2] > pos[2] + 0.15  # lifted with the flange
        assert np.allclose(held[:2], st.flange[:2], atol=1e-3)
        st.step(I)
        st.step(PB)
        assert st.place_of(first) == "bin" and in_bin(st.position(first))
        assert st.state == SortingState(Location.BIN, Location.BIN, Prediction.BAD)

        st.step(C)
        second = st.focus
        assert second == first + 1 and st.gate.raised
        assert abs(st.position(second)[0] - PICK_SPOT[0]) < 0.02
        assert in_bin(st.position(first))  # the binned onion stays in the bin


def test_an_inspected_onion_put_back_rides_away_downstream():
    with SawyerStation(always(Prediction.GOOD), n_onions=9, n_blemished=1, seed=0) as st:
        for a in (C, P, I, PC):
            st.step(a)
        first = st.focus
        placed = st.position(first)
        assert on_belt(placed) and placed[0] > GATE_X + 0.03 and not st.gate.raised
        assert st.state == SortingState(Location.CONVEYOR, Location.CONVEYOR, Prediction.GOOD)
        st.step(C)
        assert st.position(first)[0] > placed[0] + 0.1  # carried downstream by the belt
        assert st.focus == first + 1
        for _ in range(6):  # ... and, a few onions later, off the belt's end, out of the world
            for a in (P, I, PC, C):
                st.step(a)
        assert st.place_of(first) == "gone" and st.position(first)[2] < -1
        assert st.place_of(st.focus + 1) == "queued" and on_belt(st.position(st.focus + 1))


def test_an_uninspected_onion_put_back_waits_at_the_gate_to_be_picked_again():
    with SawyerStation(GROUND_TRUTH, n_onions=2, n_blemished=1, seed=0) as st:
        for a in (C, P, PC):
            st.step(a)
        assert st.gate.raised and st.place_of(0) == "waiting"
        assert st.state == SortingState(Location.CONVEYOR, Location.CONVEYOR, Prediction.UNKNOWN)
        assert not st.step(C).changed  # still in focus: nothing to claim
        assert st.step(P).next_state.onion == Location.HOVER


def test_the_inspection_view_shows_the_held_onion_large_and_centred():
    with SawyerStation(GROUND_TRUTH, n_onions=2, n_blemished=1, seed=1) as st:
        done = [st.step(a) for a in (C, P, I)][-1]
        assert done.inspection.shape == (st.inspection.height, st.inspection.width, 3)
        body = st.belt.onions[st.focus].body
        seg = st.cameras.render_inspection(body).seg
        x0, y0, x1, y1, n = boxes_from_segmentation(seg, [body])[body]
        h, w = seg.shape
        assert n > 0.1 * h * w  # large: a tenth of the view or more
        assert abs((x0 + x1) / 2 - w / 2) < 0.1 * w and abs((y0 + y1) / 2 - h / 2) < 0.15 * h
        assert x0 > 0 and y0 > 0 and x1 < w and y1 < h  # whole


def test_the_classifier_sees_every_view_and_its_answer_is_the_prediction():
    seen = []

    def classify(views):
        seen.append([v.copy() for v in views])
        return Prediction.BAD

    with SawyerStation(classify, n_onions=2, n_blemished=0, seed=0) as st:
        for a in (C, P, I):
            done = st.step(a)
        assert len(seen) == 1 and len(seen[0]) == INSPECTION_VIEWS == len(done.views)
        assert all(np.array_equal(a, b) for a, b in zip(seen[0], done.views, strict=True))
        assert np.array_equal(done.inspection, done.views[0])
        assert done.perceived == Prediction.BAD == done.next_state.prediction
        assert not st.step(I).changed and len(seen) == 1  # a known onion is not re-inspected


def test_the_views_show_the_onion_from_every_side_and_from_below():
    # each view shows the held onion, whole, from another side: the turned and tilted poses
    with SawyerStation(GROUND_TRUTH, n_onions=2, n_blemished=1, seed=1,
                       inspection_views=4) as st:
        done = [st.step(a) for a in (C, P, I)][-1]
        body = st.belt.onions[st.focus].body
        assert len(st.last_views) == 4
        for image in st.last_views:
            x0, y0, x1, y1, n = boxes_from_segmentation(image.seg, [body])[body]
            h, w = image.seg.shape
            assert n > 0.1 * h * w and x0 > 0 and y0 > 0 and x1 < w and y1 < h
        views = [v.astype(float) for v in done.views]
        assert all(np.abs(a - b).mean() > 2.0 for i, a in enumerate(views) for b in views[:i])
        # and the arm is back at the inspection pose, where the state says the onion is
        assert st.state == SortingState(Location.FACE, Location.FACE, Prediction.GOOD) \
            or st.state == SortingState(Location.FACE, Location.FACE, Prediction.BAD)
        assert st.step(PB).reach_error < 0.01


def test_every_view_holds_the_onion_at_its_designed_pose():
    # the flange at each pose's orientation, the onion's centre where the first view holds it:
    # the wrist's own joint turns it, rather than an IK that stalls at the joint's limit
    poses = inspection_poses(8)
    with SawyerStation(GROUND_TRUTH, n_onions=2, n_blemished=1, seed=9209,
                       difficulty="hard") as st:
        st.step(C), st.step(P)
        onion = st.belt.onions[st.focus]
        st.motions.hold_up()
        centre = None
        for k in st.motions.show(onion, poses, []):
            _, orn = st.arm.end_effector()
            angle = 2 * np.arccos(min(1.0, abs(float(np.dot(orn, flange_down(*poses[k]))))))
            assert angle < 0.01, (k, np.degrees(angle))
            at = st.belt.position(onion.index)
            centre = at if centre is None else centre
            assert np.linalg.norm(at - centre) < 1e-3, k


def test_the_poses_spread_around_the_onion_and_nest():
    poses = inspection_poses(8)
    assert inspection_poses(4) == poses[:4] and inspection_poses(1) == ((0.0, 0.0),)
    yaws = np.degrees([y for y, _ in poses]) % 360
    np.testing.assert_allclose(sorted(yaws), np.arange(0, 360, 45), atol=1e-9)
    assert [t > 0 for _, t in poses] == [False, True] * 4
    for n in (2, 3, 4):  # the first n turns leave no gap wider than half a turn
        turns = np.sort(np.degrees([y for y, _ in inspection_poses(n)]) % 360)
        assert np.diff(np.r_[turns, turns[0] + 360]).max() <= 180 + 1e-9
    with pytest.raises(ValueError, match="n_views"):
        inspection_poses(0)
    with pytest.raises(ValueError, match="tilt"):
        inspection_poses(2, tilt=2.0)


def test_a_verdict_carries_its_probabilities_into_the_step():
    @dataclass(frozen=True)
    class Verdict:
        prediction: int
        p_blemished: float
        view_p_blemished: tuple

    with SawyerStation(lambda views: Verdict(1, 0.8, (0.1, 0.9)), n_onions=2,
                       n_blemished=0, seed=0, inspection_views=2) as st:
        done = [st.step(a) for a in (C, P, I)][-1]
        assert done.perceived == Prediction.BAD and done.p_blemished == 0.8
        assert done.view_p_blemished == (0.1, 0.9) and len(done.views) == 2


def test_labelled_views_count_the_rot_each_one_shows():
    # ground truth for the inspection classifier: a good onion shows no rot in any view, a
    # blemished one (clean world: 5-9 patches all round) shows rot in some
    with SawyerStation(GROUND_TRUTH, n_onions=2, n_blemished=1, seed=3, inspection_views=4,
                       label_blemishes=True) as st:
        rot = {}
        for a in (C, P, I, PB if st.blemished[0] else PC, C, P, I):
            done = st.step(a)
            if done.views:
                held = st.belt.onions[st.focus]
                labels = [max(labels, key=lambda lb: lb.visible_pixels)
                          for labels in st.last_labels]
                assert all(lb.blemished == held.appearance.blemished for lb in labels)
                rot[bool(held.appearance.blemished)] = [lb.rot_pixels for lb in labels]
    assert rot[False] == [0, 0, 0, 0]
    assert max(rot[True]) > 0.01 * 10_000


def test_rendering_every_step_returns_the_main_view():
    with SawyerStation(GROUND_TRUTH, n_onions=2, n_blemished=1, seed=0,
                       render_every_step=True) as st:
        image = st.step(C).image
        assert image.rgb.shape == (240, 320, 3) and np.all(image.depth > 0)


def test_an_onion_the_classifier_never_classifies_counts_as_good(caplog):
    with SawyerStation(always(Prediction.UNKNOWN), n_onions=2, n_blemished=1, seed=0) as st:
        done = [st.step(a) for a in (C, P, I)][-1]
        assert done.perceived == Prediction.GOOD == done.next_state.prediction
        assert "abstained" in caplog.text
        for a in (PC, C, P):  # after the turns, the motions go on as usual
            assert st.step(a).reach_error < 0.01
        assert st.state == SortingState(Location.HOVER, Location.HOVER, Prediction.UNKNOWN)


def test_bad_classifier_answers_and_arguments_are_rejected():
    with SawyerStation(always("rotten"), n_onions=2, n_blemished=1) as st:
        st.step(C)
        st.step(P)
        with pytest.raises(ValueError, match="classify must return a Prediction"):
            st.step(I)
    with pytest.raises(ValueError, match="classify"):
        SawyerStation("oracle")
    with pytest.raises(TypeError, match="classify"):
        SawyerStation(42)
    with pytest.raises(ValueError, match="move_steps"):
        SawyerStation(GROUND_TRUTH, move_steps=1)
    with pytest.raises(ValueError, match="n_blemished"):
        SawyerStation(GROUND_TRUTH, n_onions=3, n_blemished=4)
    with pytest.raises(RuntimeError, match="entered"):
        _ = SawyerStation(GROUND_TRUTH).state


def test_bad_actions_are_rejected(station):
    for bad in (5, -1, "claim"):
        with pytest.raises(ValueError, match="action must be"):
            station.step(bad)


def test_claiming_past_the_end_of_the_line_up_fails_loudly():
    with SawyerStation(always(Prediction.GOOD), n_onions=1, n_blemished=0) as st:
        for a in (C, P, I, PC):
            st.step(a)
        with pytest.raises(RuntimeError, match="exhausted"):
            st.step(C)


def test_the_line_up_has_exactly_the_blemished_count_in_a_seeded_order():
    a = make_lineup(20, 7, np.random.default_rng(3))
    b = make_lineup(20, 7, np.random.default_rng(3))
    c = make_lineup(20, 7, np.random.default_rng(4))
    assert sum(o.blemished for o in a) == 7 and len(a) == 20
    assert [o.blemished for o in a] == [o.blemished for o in b]
    assert [o.blemished for o in a] != [o.blemished for o in c]
    assert len({o.texture_seed for o in a}) == 20  # every onion looks different
    with pytest.raises(ValueError, match="n_onions"):
        make_lineup(0, 0, np.random.default_rng(0))


def test_leaving_out_the_links_the_camera_cannot_see_changes_no_pixel():
    from robot.camera import links_outside, render

    with SawyerStation(GROUND_TRUTH, n_onions=2, n_blemished=1, seed=4,
                       inspection_views=4) as st:
        for a in (C, P):
            st.step(a)
        culled = links_outside(st.client, st.inspection, st.arm.body)
        assert culled, "the inspection camera sees all of the arm?"
        for pose, (yaw, tilt) in enumerate(st.poses):  # each inspection pose of the wrist
            centre = st.position(st.focus)
            turn = flange_down(yaw, tilt)
            st.motions.move(st.arm.flange_holding_at(centre, turn) if pose else ROBOT_TARGETS[
                Location.FACE], orientation=turn)
            full = render(st.client, st.inspection, st.lighting)
            lean = render(st.client, st.inspection, st.lighting, cull=(st.arm.body,))
            for name in ("rgb", "depth", "seg"):
                assert np.array_equal(getattr(full, name), getattr(lean, name)), (pose, name)
        # and the colours are back: the main camera sees the arm as before
        again = render(st.client, st.camera, st.lighting)
        assert np.array_equal(again.rgb, render(st.client, st.camera, st.lighting).rgb)
        colours = {d[1]: d[7] for d in p.getVisualShapeData(st.arm.body,
                                                            physicsClientId=st.client)}
        assert all(colours[link] == rgba for _, link, rgba in culled)
