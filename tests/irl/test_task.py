"""The task as data (irl.domains.task) and the learner registry (irl.learners.registry)."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

import irl
from irl.domains import FORESTWORLD_TASK, SORTING_TASK, TaskDescription
from irl.domains.forestworld import sector
from irl.domains.onion_sorting import (
    FACTOR_SIZES,
    N_ACTIONS,
    N_STATES,
    Location,
    Prediction,
    SortAction,
    decode_state,
    encode_state,
    state_name,
)
from irl.experiments import METHODS
from irl.experiments import make_estimator as experiments_make_estimator
from irl.learners import (
    LEARNERS,
    MAPBIRL,
    MMAPBIRL,
    BehaviorCloning,
    HiddenDataEM,
    LearnerSpec,
    MaxEntIRL,
    make_estimator,
    register_learner,
    unregister_learner,
)


def small_task(**overrides) -> TaskDescription:
    kwargs = {
        "name": "grid",
        "factors": {"x": ("a", "b", "c"), "y": ("p", "q")},
        "action_names": ("left", "right"),
        "feature_names": ("goal",),
    }
    kwargs.update(overrides)
    return TaskDescription(**kwargs)


# -- the sorting task -------------------------------------------------------------------------


def test_sorting_task_names_and_sizes():
    t = SORTING_TASK
    assert t.name == "onion-sorting"
    assert t.factor_names == ("onion", "end_effector", "prediction")
    assert t.factors["onion"] == ("conveyor", "hover", "face", "bin")
    assert t.factors["end_effector"] == ("conveyor", "hover", "face", "bin")
    assert t.factors["prediction"] == ("good", "bad", "unknown")
    assert t.action_names == ("claim", "pick", "inspect", "place_on_conveyor", "place_in_bin")
    assert t.feature_names == ("good_on_conveyor", "bad_on_conveyor", "good_in_bin",
                               "bad_in_bin", "claim_new_onion", "pick_if_unknown")
    assert (t.n_states, t.n_actions, t.n_features, t.n_pairs) == (48, 5, 6, 240)
    assert t.factor_sizes == FACTOR_SIZES == (4, 4, 3)
    assert (N_STATES, N_ACTIONS) == (48, 5)


def test_sorting_task_encoding_equals_onion_sorting_for_all_states():
    for s in range(48):
        st = decode_state(s)
        values = SORTING_TASK.decode(s)
        assert list(values) == ["onion", "end_effector", "prediction"]
        assert tuple(values.values()) == (st.onion, st.end_effector, st.prediction)
        assert SORTING_TASK.encode(values) == s
        assert SORTING_TASK.encode(tuple(st)) == encode_state(st) == s
        assert SORTING_TASK.state_names[s] == state_name(s)
    # the onion is the most significant factor, the prediction the least
    assert SORTING_TASK.encode({"onion": 1, "end_effector": 0, "prediction": 0}) == 12
    assert SORTING_TASK.encode({"onion": 0, "end_effector": 1, "prediction": 0}) == 3
    assert SORTING_TASK.encode({"onion": 0, "end_effector": 0, "prediction": 1}) == 1
    s = encode_state((Location.BIN, Location.FACE, Prediction.UNKNOWN))
    assert s == 3 * 12 + 2 * 3 + 2 == 44
    assert SORTING_TASK.encode({"onion": "bin", "end_effector": "face",
                                "prediction": "unknown"}) == 44
    assert SORTING_TASK.state_name(44) == "(bin, face, unknown)"


def test_vectorised_encoding_matches_scalar():
    states = np.arange(48).reshape(6, 8)
    idx = SORTING_TASK.decode_array(states)
    assert idx.shape == (6, 8, 3)
    assert idx[5, 4].tolist() == [3, 2, 2]  # state 44
    np.testing.assert_array_equal(SORTING_TASK.encode_array(idx), states)
    np.testing.assert_array_equal(
        idx.reshape(48, 3), np.array([tuple(decode_state(s)) for s in range(48)])
    )
    with pytest.raises(ValueError, match=r"index of factor 'prediction' must be in \[0, 3\)"):
        SORTING_TASK.encode_array([[0, 0, 3]])
    with pytest.raises(ValueError, match=r"indices must have shape \(\.\.\., F\)"):
        SORTING_TASK.encode_array([0, 0])
    with pytest.raises(ValueError, match=r"state index must be in \[0, 48\); got 48"):
        SORTING_TASK.decode_array([0, 48])


def test_onion_sorting_domain_carries_its_task():
    dom = irl.domains.onion_sorting(noise=0.1)
    assert dom.task is SORTING_TASK
    assert list(dom.state_names) == list(SORTING_TASK.state_names)
    assert tuple(dom.action_names) == SORTING_TASK.action_names
    assert tuple(dom.feature_names) == SORTING_TASK.feature_names
    assert [a.name.lower() for a in SortAction] == list(SORTING_TASK.action_names)


def test_forestworld_task_matches_sector():
    dom = irl.domains.forestworld()
    assert dom.task is FORESTWORLD_TASK
    assert FORESTWORLD_TASK.factor_sizes == (4, 4)
    for x in range(4):
        for y in range(4):
            assert FORESTWORLD_TASK.encode({"x": x, "y": y}) == sector(x, y)
    assert FORESTWORLD_TASK.decode(sector(2, 3)) == {"x": 2, "y": 3}
    assert FORESTWORLD_TASK.state_name(sector(2, 3)) == "(2, 3)"
    assert dom.state_names[sector(2, 3)] == "(2,3)"  # the MDP keeps its compact names
    assert FORESTWORLD_TASK.action_names == ("north", "east", "south", "west")


def test_domain_rejects_a_task_that_does_not_match_its_mdp():
    dom = irl.domains.forestworld()
    with pytest.raises(ValueError, match=r"match mdp .* = \(16, 4, 3\); got \(48, 5, 6\)"):
        irl.Domain(dom.name, dom.mdp, dom.true_theta, dom.observation_model, dom.beta,
                   dom.prior, task=SORTING_TASK)
    renamed = TaskDescription("forestworld", FORESTWORLD_TASK.factors,
                              ("up", "right", "down", "left"), FORESTWORLD_TASK.feature_names)
    with pytest.raises(ValueError, match=r"task\.action_names must equal mdp\.action_names"):
        irl.Domain(dom.name, dom.mdp, dom.true_theta, dom.observation_model, dom.beta,
                   dom.prior, task=renamed)
    with pytest.raises(TypeError, match="task must be a TaskDescription or None; got dict"):
        irl.Domain(dom.name, dom.mdp, dom.true_theta, dom.observation_model, dom.beta,
                   dom.prior, task=FORESTWORLD_TASK.to_dict())


# -- generic behaviour ------------------------------------------------------------------------


def test_small_task_encode_decode_names():
    t = small_task()
    assert (t.n_states, t.n_actions, t.factor_sizes) == (6, 2, (3, 2))
    assert t.state_names == ("(a, p)", "(a, q)", "(b, p)", "(b, q)", "(c, p)", "(c, q)")
    assert t.decode(3) == {"x": 1, "y": 1}
    assert t.encode([2, 0]) == 4
    assert t.encode(np.array([2, 1])) == 5
    assert t.value_name("x", 2) == "c"
    assert t.value_index("y", "q") == 1
    assert t.action_index("right") == 1


def test_pair_unpair_round_trip_and_match_from_pairs():
    t = SORTING_TASK
    for o in range(t.n_pairs):
        s, a = t.unpair(o)
        assert t.pair(s, a) == o
    assert t.pair(44, 3) == 44 * 5 + 3 == 223
    assert t.unpair(223) == (44, 3)
    states, actions = [0, 44, 47, 12], [4, 3, 0, 1]
    demo = irl.Demonstration.from_pairs(states, actions, n_actions=t.n_actions)
    assert list(demo.observations) == [t.pair(s, a) for s, a in zip(states, actions, strict=True)]
    assert list(demo.observations) == [4, 223, 235, 61]


def test_pair_matches_the_pair_observation_model():
    dom = irl.domains.forestworld(noise=0.3)
    O = dom.observation_model.probs
    goal, tunnel, north = sector(3, 3), sector(2, 3), 0
    assert O[goal, north, FORESTWORLD_TASK.pair(goal, north)] == pytest.approx(0.7)
    assert O[goal, north, FORESTWORLD_TASK.pair(tunnel, north)] == pytest.approx(0.3)


def test_pair_and_decode_reject_out_of_range():
    t = small_task()
    with pytest.raises(ValueError, match=r"state index must be in \[0, 6\); got 6"):
        t.pair(6, 0)
    with pytest.raises(ValueError, match=r"action index must be in \[0, 2\); got -1"):
        t.pair(0, -1)
    with pytest.raises(ValueError, match=r"pair index must be in \[0, 12\); got 12"):
        t.unpair(12)
    with pytest.raises(ValueError, match=r"state index must be in \[0, 6\); got -1"):
        t.decode(-1)
    with pytest.raises(TypeError, match=r"state index must be an int; got float 1\.0"):
        t.decode(1.0)
    with pytest.raises(ValueError, match=r"index of factor 'y' must be in \[0, 2\); got 2"):
        t.encode({"x": 0, "y": 2})
    with pytest.raises(ValueError, match=r"values must name exactly the factors \('x', 'y'\)"):
        t.encode({"x": 0})
    with pytest.raises(ValueError, match="values must have one index per factor"):
        t.encode([0, 0, 0])
    with pytest.raises(ValueError, match=r"value of factor 'x' must be one of .*; got 'z'"):
        t.encode({"x": "z", "y": 0})
    with pytest.raises(ValueError, match=r"factor must be one of \('x', 'y'\); got 'z'"):
        t.value_name("z", 0)


def test_to_dict_from_dict_round_trip_through_json():
    for t in (SORTING_TASK, FORESTWORLD_TASK, small_task()):
        data = json.loads(json.dumps(t.to_dict()))
        back = TaskDescription.from_dict(data)
        assert back == t
        assert hash(back) == hash(t)
        assert back.factor_names == t.factor_names
        assert back.state_names == t.state_names
    assert small_task().to_dict() == {
        "name": "grid",
        "factors": [{"name": "x", "values": ["a", "b", "c"]},
                    {"name": "y", "values": ["p", "q"]}],
        "action_names": ["left", "right"],
        "feature_names": ["goal"],
    }
    # a JSON object for the factors keeps its order
    obj = dict(small_task().to_dict(), factors={"y": ["p", "q"], "x": ["a", "b", "c"]})
    swapped = TaskDescription.from_dict(obj)
    assert swapped.factor_names == ("y", "x")
    assert swapped != small_task()  # factor order changes the encoding
    assert swapped.encode({"x": 2, "y": 1}) == 5 and small_task().encode({"x": 2, "y": 1}) == 5
    assert swapped.encode({"x": 1, "y": 1}) == 4 and small_task().encode({"x": 1, "y": 1}) == 3


def test_pickles_and_is_immutable():
    assert pickle.loads(pickle.dumps(SORTING_TASK)) == SORTING_TASK
    with pytest.raises(TypeError):
        SORTING_TASK.factors["onion"] = ("x",)
    with pytest.raises(AttributeError):
        SORTING_TASK.name = "other"


def test_from_dict_rejects_missing_and_unknown_keys():
    data = small_task().to_dict()
    with pytest.raises(ValueError, match=r"missing \['feature_names'\], unknown \[\]"):
        TaskDescription.from_dict({k: v for k, v in data.items() if k != "feature_names"})
    with pytest.raises(ValueError, match=r"missing \[\], unknown \['version'\]"):
        TaskDescription.from_dict(dict(data, version=1))
    with pytest.raises(ValueError, match=r"factors\[0\] must have exactly the keys"):
        TaskDescription.from_dict(dict(data, factors=[{"name": "x"}]))
    with pytest.raises(TypeError, match="data must be a mapping; got list"):
        TaskDescription.from_dict([data])


@pytest.mark.parametrize(
    ("overrides", "error", "message"),
    [
        ({"factors": {}}, ValueError, r"factors must not be empty"),
        ({"factors": [("x", ("a",)), ("x", ("b",))]}, ValueError,
         r"factor names must be distinct; got duplicates \['x'\]"),
        ({"factors": {"x": ()}}, ValueError, r"factors\['x'\] must not be empty"),
        ({"factors": {"x": ("a", "a")}}, ValueError,
         r"factors\['x'\] must be distinct; got duplicates \['a'\]"),
        ({"factors": {"x": "abc"}}, TypeError, r"factors\['x'\] must be a sequence of str"),
        ({"factors": {"x": ("a", 1)}}, TypeError, r"factors\['x'\]\[1\] must be a str; got int"),
        ({"factors": {"": ("a",)}}, ValueError, r"factor names\[0\] must be non-empty"),
        ({"factors": 3}, TypeError, r"factors must be a mapping"),
        ({"action_names": ()}, ValueError, r"action_names must not be empty"),
        ({"action_names": ("go", "go")}, ValueError,
         r"action_names must be distinct; got duplicates \['go'\]"),
        ({"feature_names": ("goal", " ")}, ValueError,
         r"feature_names\[1\] must be non-empty without surrounding spaces; got ' '"),
        ({"name": ""}, ValueError, r"name must be non-empty"),
        ({"name": None}, TypeError, r"name must be a str; got NoneType"),
    ],
)
def test_validation_names_argument_and_value(overrides, error, message):
    with pytest.raises(error, match=message):
        small_task(**overrides)


# -- the learner registry ---------------------------------------------------------------------


def test_registry_order_and_classes():
    assert METHODS == ("mmap-birl", "map-birl", "hidden-data-em", "maxent", "bc", "bc-em")
    assert tuple(LEARNERS)[:6] == METHODS
    dom = irl.domains.forestworld()
    expected = {"mmap-birl": MMAPBIRL, "map-birl": MAPBIRL, "hidden-data-em": HiddenDataEM,
                "maxent": MaxEntIRL, "bc": BehaviorCloning, "bc-em": BehaviorCloning}
    for name, cls in expected.items():
        est = make_estimator(name, dom, seed=3)
        assert type(est) is cls
        assert est.mdp is dom.mdp
        assert est.observation_model is dom.observation_model
        assert type(experiments_make_estimator(name, dom, seed=3)) is cls
        assert LEARNERS[name].name == name
        assert "\n" not in LEARNERS[name].description
    birl = make_estimator("mmap-birl", dom, seed=3)
    assert birl.beta == dom.beta
    assert birl.prior is dom.prior


def test_birl_seed_is_passed_through():
    dom = irl.domains.forestworld()
    a = make_estimator("map-birl", dom, seed=7).fit(dom.sample(2, 5, seed=0)[0])
    b = make_estimator("map-birl", dom, seed=7).fit(dom.sample(2, 5, seed=0)[0])
    np.testing.assert_array_equal(a.theta_, b.theta_)


def test_unknown_learner_names_the_allowed_ones():
    dom = irl.domains.forestworld()
    with pytest.raises(ValueError) as info:
        make_estimator("svm", dom)
    msg = str(info.value)
    assert "'svm'" in msg
    for name in METHODS:
        assert repr(name) in msg
    with pytest.raises(ValueError, match="'svm'"):
        experiments_make_estimator("svm", dom)


def test_duplicate_registration_is_refused():
    with pytest.raises(ValueError, match="a learner named 'maxent' is already registered"):
        register_learner(LearnerSpec("maxent", "another MaxEnt.", lambda domain, *, seed: None))
    assert type(make_estimator("maxent", irl.domains.forestworld())) is MaxEntIRL


def test_learner_spec_validation():
    def build(domain, *, seed=None):
        return None

    with pytest.raises(ValueError, match="name must be non-empty without whitespace; got 'a b'"):
        LearnerSpec("a b", "x.", build)
    with pytest.raises(ValueError, match="description must be one non-empty line"):
        LearnerSpec("ab", "two\nlines", build)
    with pytest.raises(TypeError, match="build must be callable; got 3"):
        LearnerSpec("ab", "x.", 3)
    with pytest.raises(TypeError, match="spec must be a LearnerSpec; got str"):
        register_learner("ab")
    with pytest.raises(TypeError):
        LEARNERS["ab"] = LearnerSpec("ab", "x.", build)  # read-only: use register_learner


def test_custom_learner_can_be_registered_built_and_swept():
    class ConstantLearner:
        def __init__(self, theta, seed):
            self.theta, self.seed = theta, seed

    def build(domain, *, seed=None):
        return ConstantLearner(np.zeros(domain.mdp.n_features), seed)

    spec = register_learner(LearnerSpec("constant", "Always zero weights.", build))
    try:
        assert tuple(LEARNERS)[-1] == "constant"
        est = make_estimator("constant", irl.domains.onion_sorting(), seed=5)
        assert isinstance(est, ConstantLearner)
        assert est.theta.shape == (6,)
        assert est.seed == 5
        from irl.experiments import SweepConfig

        cfg = SweepConfig("forestworld", ((0.0, 0.1),), methods=("constant",), batches=1)
        assert [t.method for t in cfg.trials()] == ["constant"]
    finally:
        assert unregister_learner("constant") is spec
    assert "constant" not in LEARNERS
    assert METHODS == ("mmap-birl", "map-birl", "hidden-data-em", "maxent", "bc", "bc-em")
    with pytest.raises(ValueError, match=r"methods must be among .*; got \['constant'\]"):
        from irl.experiments import SweepConfig

        SweepConfig("forestworld", ((0.0, 0.1),), methods=("constant",))
