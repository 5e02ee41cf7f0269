"""The simulated sorter acts on the expert's policy and the world shows the MDP's states."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from irl.domains.onion_sorting import N_STATES, decode_state, next_state
from robot.simulation import SessionConfig, SortingSession, expert_model


@pytest.fixture(scope="module")
def expert():
    return expert_model()


@pytest.fixture(scope="module")
def session_run(expert):
    policy, initial = expert
    config = SessionConfig(n_steps=16, occlusion=0.4, frames_per_step=2)
    with SortingSession(config, policy, initial, seed=11) as session:
        frames = list(session.frames())
    return session, frames


def test_steps_follow_the_mdp_transitions(session_run):
    session, frames = session_run
    steps = session.steps
    assert len(steps) == 16 and len(frames) == 32
    for prev, nxt in itertools.pairwise(steps):
        assert prev.next_state == nxt.state
    for st in steps:  # next_state is the MDP's for one of the two onion classes
        s, a = decode_state(st.state), st.action
        options = {next_state(s, a, blemished=b) for b in (False, True)}
        assert decode_state(st.next_state) in options


def test_inspection_reveals_the_physical_onions_class(session_run):
    _session, frames = session_run
    for f in frames:
        s = decode_state(f.step.state)
        focus = [o for o in f.onions if o.in_focus]
        if s.prediction.name in ("GOOD", "BAD") and s.onion.name in ("HOVER", "FACE"):
            assert len(focus) == 1
            assert focus[0].blemished == (s.prediction.name == "BAD")


def test_frames_carry_ground_truth_from_segmentation(session_run):
    _, frames = session_run
    assert [f.index for f in frames] == list(range(len(frames)))
    for f in frames:
        assert f.color.shape == (240, 320, 3) and f.color.dtype == np.uint8
        assert f.depth.shape == (240, 320) and np.all(f.depth > 0)
        assert f.inspection is not None  # every frame has its inspection view
        for o in f.onions:
            assert (o.box is None) == (o.visible_pixels == 0)
            if o.box is not None:
                x0, y0, x1, y1 = o.box
                assert 0 <= x0 < x1 <= 320 and 0 <= y0 < y1 <= 240
                assert o.visible_pixels <= (x1 - x0) * (y1 - y0)
        if not f.step.occluded:
            assert any(o.box is not None for o in f.onions)


def test_the_passer_by_blocks_the_view_only_on_occluded_steps(session_run):
    session, frames = session_run
    assert session.occluded.any() and not session.occluded.all()
    for f in frames:
        if f.step.occluded:
            assert f.occluded_fraction > 0.05
        else:
            assert f.occluded_fraction == 0.0


def test_sessions_are_reproducible_from_their_seed(expert):
    policy, initial = expert
    config = SessionConfig(n_steps=5, frames_per_step=1)
    runs = []
    for _ in range(2):
        with SortingSession(config, policy, initial, seed=3) as session:
            frames = list(session.frames())
        runs.append((session.steps, frames[-1].color))
    assert runs[0][0] == runs[1][0]
    assert np.array_equal(runs[0][1], runs[1][1])


def test_occlusion_rate_over_many_sessions_matches_the_request(expert):
    policy, initial = expert
    rate, n_sessions, n_steps = 0.2, 200, 20
    config = SessionConfig(n_steps=n_steps, occlusion=rate)
    seeds = np.random.SeedSequence(0).spawn(n_sessions)
    hidden = np.concatenate([SortingSession(config, policy, initial, s).occluded for s in seeds])
    se = np.sqrt(rate * (1 - rate) / hidden.size)
    assert abs(hidden.mean() - rate) < 4 * se


def test_bad_policy_shapes_are_refused(expert):
    _, initial = expert
    with pytest.raises(ValueError, match="policy must be"):
        SortingSession(SessionConfig(), np.ones((3, 5)) / 5, initial, 0)
    with pytest.raises(ValueError, match="occlusion must be"):
        SessionConfig(occlusion=2.0)
    assert initial.shape == (N_STATES,)
