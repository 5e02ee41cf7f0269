"""Pure geometry of the world: the state map, the sorter's arm, the passer-by's schedule."""

from __future__ import annotations

import numpy as np
import pytest

from irl.domains.onion_sorting import Location, Prediction, SortingState
from robot.avatar import FOREARM, UPPER_ARM, min_jerk, path_point, two_bone_ik
from robot.occluder import occlusion_schedule
from robot.state_map import (
    BIN_CENTER,
    HAND_TARGETS,
    PICK_SPOT,
    SHOULDER,
    WorldSnapshot,
    hand_location,
    onion_location,
    state_of_world,
)


@pytest.mark.parametrize("loc", list(Location))
def test_hand_targets_map_back_to_their_location(loc):
    assert hand_location(HAND_TARGETS[loc]) == loc


@pytest.mark.parametrize("loc", list(Location))
def test_every_hand_target_is_within_the_sorters_reach(loc):
    assert np.linalg.norm(HAND_TARGETS[loc] - SHOULDER) < UPPER_ARM + FOREARM


def test_hand_between_locations_is_refused():
    midway = (HAND_TARGETS[Location.CONVEYOR] + HAND_TARGETS[Location.BIN]) / 2
    with pytest.raises(ValueError, match="hand must be within"):
        hand_location(midway)


def test_state_of_world_reads_all_three_factors():
    bin_spot = np.array([BIN_CENTER[0], BIN_CENTER[1], 0.4])
    world = WorldSnapshot(hand=HAND_TARGETS[Location.BIN], focus=bin_spot, held=False,
                          prediction=Prediction.BAD)
    assert state_of_world(world) == SortingState(Location.BIN, Location.BIN, Prediction.BAD)
    on_belt = [*PICK_SPOT, 0.0, 0.0, 0.04]
    world = WorldSnapshot(hand=HAND_TARGETS[Location.FACE], focus=on_belt, held=False,
                          prediction=Prediction.UNKNOWN)
    assert state_of_world(world) == SortingState(Location.CONVEYOR, Location.FACE,
                                                 Prediction.UNKNOWN)
    assert onion_location(np.zeros(3), held=True, hand=HAND_TARGETS[Location.HOVER]) == \
        Location.HOVER
    with pytest.raises(ValueError, match="on the belt or in the bin"):
        onion_location(np.array([0.0, 2.0, 0.0]), held=False, hand=HAND_TARGETS[Location.BIN])


@pytest.mark.parametrize("target", [[0.1, 0.1, 0.9], [0.0, 0.4, 1.5], [0.5, 0.3, 0.8]])
def test_two_bone_ik_keeps_bone_lengths_and_reaches_reachable_targets(target):
    elbow, hand = two_bone_ik(SHOULDER, np.array(target), 0.38, 0.36, np.array([0.6, 0.3, -1]))
    assert np.linalg.norm(elbow - SHOULDER) == pytest.approx(0.38)
    assert np.linalg.norm(hand - elbow) == pytest.approx(0.36)
    assert np.allclose(hand, target, atol=1e-6)


def test_two_bone_ik_stretches_towards_unreachable_targets():
    target = SHOULDER + np.array([2.0, 0.0, 0.0])
    _, hand = two_bone_ik(SHOULDER, target, 0.38, 0.36, np.array([0, 0, -1.0]))
    assert np.linalg.norm(hand - SHOULDER) == pytest.approx(0.74, abs=1e-5)
    assert np.allclose((hand - SHOULDER)[1:], 0.0, atol=1e-6)


def test_min_jerk_and_paths_start_and_end_at_rest():
    assert min_jerk(0.0) == 0.0 and min_jerk(1.0) == 1.0 and min_jerk(0.5) == 0.5
    way = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 1.0, 0]])
    assert np.allclose(path_point(way, 0.0), way[0])
    assert np.allclose(path_point(way, 0.5), way[1])
    assert np.allclose(path_point(way, 1.0), way[2])
    with pytest.raises(ValueError, match="waypoints"):
        path_point(np.zeros((2, 2)), 0.5)


@pytest.mark.parametrize("rate", [0.0, 0.2, 0.5, 1.0])
def test_occlusion_schedule_matches_the_rate_within_sampling_error(rate):
    n = 5000
    hidden = occlusion_schedule(n, rate, np.random.default_rng(1))
    se = np.sqrt(rate * (1 - rate) / n)
    assert abs(hidden.mean() - rate) <= 4 * se + 1e-12


def test_occlusion_schedule_validates_its_arguments():
    with pytest.raises(ValueError, match="rate must be in"):
        occlusion_schedule(5, 1.5, np.random.default_rng(0))
    with pytest.raises(ValueError, match="n_steps must be"):
        occlusion_schedule(0, 0.2, np.random.default_rng(0))
