"""Bad input raises ValueError/TypeError naming the argument (and demonstration and step)."""

import numpy as np
import pytest

import irl


@pytest.fixture
def mdp_parts():
    T = np.full((3, 2, 3), 1 / 3)
    phi = np.zeros((3, 2, 2))
    return T, phi, np.full(3, 1 / 3)


def test_wrong_shapes(mdp_parts):
    T, phi, p0 = mdp_parts
    with pytest.raises(ValueError, match="transitions must have shape"):
        irl.TabularMDP(transitions=T[:, :, :2], features=phi, discount=0.9, initial=p0)
    with pytest.raises(ValueError, match=r"features must have shape \(S, A, K\)"):
        irl.TabularMDP(transitions=T, features=phi[:2], discount=0.9, initial=p0)
    with pytest.raises(ValueError, match="initial must have shape"):
        irl.TabularMDP(transitions=T, features=phi, discount=0.9, initial=p0[:2])
    with pytest.raises(ValueError, match="discount must be in"):
        irl.TabularMDP(transitions=T, features=phi, discount=1.0, initial=p0)


def test_rows_must_sum_to_one_and_be_non_negative(mdp_parts):
    T, phi, p0 = mdp_parts
    bad = T.copy()
    bad[1, 0, 0] += 0.2
    with pytest.raises(ValueError, match=r"transitions rows must sum to 1.*row \(2,\)"):
        irl.TabularMDP(transitions=bad, features=phi, discount=0.9, initial=p0)
    neg = T.copy()
    neg[0, 1] = [-0.5, 1.0, 0.5]
    with pytest.raises(ValueError, match="transitions must be non-negative"):
        irl.TabularMDP(transitions=neg, features=phi, discount=0.9, initial=p0)
    O = np.full((3, 2, 4), 0.25)
    O[2, 1, 3] = 0.5
    with pytest.raises(ValueError, match=r"observation model probs rows must sum to 1.*\(2, 1\)"):
        irl.ObservationModel(O)
    O = np.full((3, 2, 4), 0.25)
    O[0, 0] = [-0.25, 0.75, 0.25, 0.25]
    with pytest.raises(ValueError, match="observation model probs must be non-negative"):
        irl.ObservationModel(O)


def test_demonstration_values():
    with pytest.raises(ValueError, match=r"observations\[1\] must be >= 0"):
        irl.Demonstration(observations=[1, -2])
    with pytest.raises(TypeError, match=r"observations\[0\] must be an int or None"):
        irl.Demonstration(observations=[1.5])
    with pytest.raises(ValueError, match="at least one step"):
        irl.Demonstration(observations=[])


@pytest.mark.parametrize("cls", [irl.MMAPBIRL, irl.MAPBIRL, irl.HiddenDataEM, irl.MaxEntIRL])
def test_observation_out_of_range_names_demo_and_step(cls):
    dom = irl.domains.forestworld()
    good = irl.Demonstration(observations=[0, 1])
    bad = irl.Demonstration(observations=[0, None, 64])
    est = cls(dom.mdp, dom.observation_model)
    with pytest.raises(ValueError, match=r"demos\[1\], step 2: observation 64 is out of"):
        est.fit([good, bad])


def test_impossible_demonstration_is_refused_by_mmap_birl():
    dom = irl.domains.forestworld(noise=0.0)
    A = dom.mdp.n_actions
    jump = irl.Demonstration.from_pairs([0, 0, 15], [0, 0, 0], A)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    with pytest.raises(ValueError, match=r"demos\[0\], step 2: .* impossible"):
        est.log_likelihood(dom.true_theta, [jump])


def test_observation_model_for_another_mdp_is_refused():
    dom = irl.domains.forestworld()
    other = irl.domains.onion_sorting().observation_model
    with pytest.raises(ValueError, match=r"observation_model is for \(S, A\) = \(48, 5\)"):
        irl.MMAPBIRL(dom.mdp, other).fit([irl.Demonstration(observations=[0])])


def test_theta_and_prior_shapes():
    dom = irl.domains.forestworld()
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model)
    with pytest.raises(ValueError, match=r"theta must have shape \(K,\) = \(3,\)"):
        est.log_likelihood(np.zeros(2), [irl.Demonstration(observations=[0])])
    with pytest.raises(ValueError, match="std must be positive"):
        irl.GaussianPrior(mean=0.0, std=0.0)
    with pytest.raises(ValueError, match="optimizer must be one of"):
        irl.MMAPBIRL(dom.mdp, dom.observation_model, optimizer="adam").fit(
            [irl.Demonstration(observations=[0])])


def test_state_only_observations_cannot_be_taken_at_face_value():
    dom = irl.domains.forestworld()
    om = irl.state_observation_model(np.eye(16), n_actions=4)
    with pytest.raises(ValueError, match="reports no action"):
        irl.MAPBIRL(dom.mdp, om).fit([irl.Demonstration(observations=[0, 1])])
    # ... but MMAP-BIRL marginalizes the unobserved actions.
    irl.MMAPBIRL(dom.mdp, om, beta=1.5, prior=dom.prior).fit(
        [irl.Demonstration(observations=[0, 1, 2])])
