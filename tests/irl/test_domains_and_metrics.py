import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import irl
from irl.domains.onion_sorting import (
    N_STATES,
    Location,
    Prediction,
    SortAction,
    decode_state,
    encode_state,
    next_state,
)


def test_onion_sorting_sizes_and_expert_cycle():
    dom = irl.domains.onion_sorting()
    assert (dom.mdp.n_states, dom.mdp.n_actions, dom.mdp.n_features) == (48, 5, 6)
    pol = dom.optimal_policy()
    for blemished, place in ((True, SortAction.PLACE_IN_BIN),
                             (False, SortAction.PLACE_ON_CONVEYOR)):
        s = (Location.CONVEYOR, Location.CONVEYOR, Prediction.GOOD)
        seen = []
        for _ in range(5):
            a = SortAction(pol[encode_state(s)])
            seen.append(a)
            s = next_state(s, a, blemished)
        assert seen == [SortAction.CLAIM, SortAction.PICK, SortAction.INSPECT, place,
                        SortAction.CLAIM]


@given(st.integers(0, N_STATES - 1))
def test_state_encoding_round_trips(s):
    assert encode_state(decode_state(s)) == s


def test_decode_rejects_out_of_range():
    with pytest.raises(ValueError, match=r"state index must be in \[0, 48\)"):
        decode_state(48)


def test_forestworld_tunnel_noise():
    dom = irl.domains.forestworld(noise=0.3)
    O = dom.observation_model.probs
    goal, tunnel = 15, 11
    north = 0
    assert O[goal, north, goal * 4 + north] == pytest.approx(0.7)
    assert O[goal, north, tunnel * 4 + north] == pytest.approx(0.3)
    assert O[5, 2, 5 * 4 + 2] == 1.0
    T = dom.mdp.transitions
    assert T[0, 0, 1] == pytest.approx(0.9)  # north from (0,0) -> (0,1)
    assert T[0, 0, 0] == pytest.approx(2 * 0.1 / 3)  # south and west bump into the edge


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(0.0, 0.9), min_size=1, max_size=3), st.integers(1, 4))
def test_factored_model_rows_sum_to_one(errors, n_actions):
    from irl.domains.onion_sorting import factor_confusion

    mats = [factor_confusion(n, e) for n, e in zip((2, 3, 4), errors, strict=False)]
    om = irl.factored_observation_model(mats, n_actions=n_actions)
    np.testing.assert_allclose(om.probs.sum(axis=2), 1.0)
    assert om.n_observations == om.n_states * n_actions


def test_sorting_noise_is_the_joint_state_error():
    om = irl.domains.onion_sorting(noise=0.3).observation_model
    assert om.error_rate() == pytest.approx(0.3)


def test_ile_zero_for_true_weights_positive_for_wrong_ones():
    dom = irl.domains.onion_sorting()
    assert irl.inverse_learning_error(dom.mdp, dom.true_theta, dom.true_theta) == 0.0
    assert irl.inverse_learning_error(dom.mdp, dom.true_theta, 3 * dom.true_theta) == 0.0
    wrong = dom.true_theta.copy()
    wrong[[2, 3]] = wrong[[3, 2]]  # prefer binning good onions
    assert irl.inverse_learning_error(dom.mdp, dom.true_theta, wrong) > 0
    assert 0 < irl.normalized_inverse_learning_error(dom.mdp, dom.true_theta, wrong) <= 200
    assert irl.policy_mismatch(dom.mdp, dom.true_theta, wrong) > 0
    assert irl.reward_distance(dom.true_theta, 2 * dom.true_theta) == pytest.approx(0.0)


def test_sorting_transition_table_in_the_docs_is_current():
    from pathlib import Path

    from irl.domains.onion_sorting import transition_table_markdown

    doc = (Path(__file__).parents[2] / "docs" / "onion-sorting.md").read_text()
    assert transition_table_markdown() in doc


def test_grid_mdp_is_a_sparse_noisy_grid():
    mdp = irl.domains.grid_mdp(5, 4, slip=0.2, n_features=3, seed=1)
    assert (mdp.n_states, mdp.n_actions, mdp.n_features) == (20, 4, 3) and mdp.is_sparse
    T = np.stack([m.toarray() for m in mdp.transitions], axis=1)  # [s, a, s']
    np.testing.assert_allclose(T.sum(axis=2), 1.0, rtol=1e-14)
    s = 2 * 4 + 1  # cell (2, 1): moving +y reaches (2, 2) with 1 - slip, (3, 1) with slip / 3
    assert T[s, 0, 2 * 4 + 2] == pytest.approx(0.8)
    assert T[s, 0, 3 * 4 + 1] == pytest.approx(0.2 / 3)
    assert T[0, 0, 0] == pytest.approx(2 * 0.2 / 3)  # slips off the grid (-y, -x) stay put
    with pytest.raises(ValueError, match="slip"):
        irl.domains.grid_mdp(3, 3, slip=1.5)
