"""Property-based fuzzing of the public ``irl`` API.

Every generated bad input (wrong shapes, rows that do not sum to 1, NaN or inf, negative or
out-of-range indices, wrong types, empty demonstrations) must raise a one-line ``ValueError`` or
``TypeError`` whose message names the argument; edge cases that are legal (a demonstration that
is all occluded, a single step, 10,000 steps, weights 1e4 times the usual) must work or, where
a learner cannot use them, say so by name. Each check is counted in :data:`TALLY`, printed at
the end of the run (``tests/irl/conftest.py``).

The default run draws a few examples per property (``QUICK``); ``pytest -m slow`` runs the same
properties with many more (``HEAVY``).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import irl
from irl.inference import posterior_stats
from irl.solvers import OptimalQSolver, log_boltzmann_policy

QUICK = settings(max_examples=30, deadline=None, derandomize=True, database=None,
                 suppress_health_check=[HealthCheck.too_slow])
HEAVY = settings(max_examples=600, deadline=None, database=None,
                 suppress_health_check=[HealthCheck.too_slow])

#: Bad inputs tried and how many were answered by a clear error; legal edge cases tried and
#: how many worked or were refused by a clear error.
TALLY = {"bad": 0, "bad_clear": 0, "edge": 0, "edge_ok": 0}

LEARNERS = [irl.MMAPBIRL, irl.MAPBIRL, irl.HiddenDataEM, irl.MaxEntIRL]


def expect_clear_error(call, *names: str) -> Exception:
    """``call()`` must raise a one-line ValueError/TypeError whose message names one of
    ``names``; anything else (acceptance, another exception, a warning turned error) fails."""
    TALLY["bad"] += 1
    try:
        call()
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        assert "\n" not in msg, f"a multi-line message: {msg!r}"
        assert any(n in msg for n in names), f"the message does not name {names}: {msg!r}"
        TALLY["bad_clear"] += 1
        return exc
    except Exception as exc:  # anything else is the failure we look for
        raise AssertionError(f"{type(exc).__name__} instead of ValueError/TypeError: {exc}") \
            from exc
    raise AssertionError(f"bad input accepted; expected an error naming {names}")


def expect_works_or_clear_error(call, *names: str):
    """A legal edge case: it works, or it is refused by a clear error naming ``names``."""
    TALLY["edge"] += 1
    try:
        out = call()
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        assert "\n" not in msg and any(n in msg for n in names), msg
        TALLY["edge_ok"] += 1
        return None
    TALLY["edge_ok"] += 1
    return out


def fuzz(body, quick=QUICK, heavy=HEAVY):
    """A quick and a slow-marked hypothesis test of ``body(data)``."""
    return (quick(given(st.data())(body)),
            pytest.mark.slow(heavy(given(st.data())(body))))


# -- shared strategies ------------------------------------------------------------------------

NONFINITE = st.sampled_from([np.nan, np.inf, -np.inf])
NOT_ARRAYS = st.sampled_from(["abc", None, {"a": 1}, b"x", {1, 2}])
NOT_REALS = st.one_of(st.booleans(), st.text(max_size=3), st.none(), st.just([0.5]),
                      st.just(np.array([0.5, 0.5])), st.just(1 + 2j))
NOT_INTS = st.one_of(st.booleans(), st.floats(allow_nan=True), st.text(max_size=3), st.none(),
                     st.just([1]))


def sizes(data):
    return (data.draw(st.integers(1, 4), "S"), data.draw(st.integers(1, 3), "A"),
            data.draw(st.integers(1, 3), "K"))


def generator(data):
    return np.random.default_rng(data.draw(st.integers(0, 2**32 - 1), "seed"))


def valid_mdp_parts(data):
    S, A, K = sizes(data)
    rng = generator(data)
    return {
        "transitions": rng.dirichlet(np.ones(S), size=(S, A)),
        "features": rng.normal(size=(S, A, K)),
        "discount": data.draw(st.floats(0.0, 0.99), "discount"),
        "initial": rng.dirichlet(np.ones(S)),
    }, rng


def corrupt_distribution(data, p: np.ndarray, rng) -> np.ndarray:
    """``p`` (last axis a distribution) with one defect: a NaN/inf, a negative entry, a row
    that does not sum to 1."""
    p = p.copy()
    idx = tuple(int(rng.integers(n)) for n in p.shape)
    kind = data.draw(st.sampled_from(["nonfinite", "negative", "sum"]), "defect")
    if kind == "nonfinite":
        p[idx] = data.draw(NONFINITE)
    elif kind == "negative":
        p[idx] = -data.draw(st.floats(1e-6, 1e6))
    else:
        p[idx[:-1]] *= data.draw(st.one_of(st.floats(0.0, 0.99), st.floats(1.01, 1e6)))
        if not np.any(np.abs(p.sum(axis=-1) - 1.0) > 1e-5):  # an all-zero row scaled by 0
            p[idx] += 0.5
    return p


def wrong_shape(data, arr: np.ndarray, resizable: tuple[int, ...]) -> np.ndarray:
    """``arr`` with a dimension dropped, added or emptied, or one of the ``resizable`` axes
    (those whose size must match something else) one longer."""
    kind = data.draw(st.sampled_from(["drop", "add", "empty", "resize"]), "shape")
    if kind == "drop":
        return arr[..., 0]
    if kind == "add":
        return arr[None]
    if kind == "empty":
        return np.take(arr, [], axis=data.draw(st.integers(0, arr.ndim - 1), "axis"))
    axis = data.draw(st.sampled_from(resizable), "axis")
    return np.concatenate([arr, np.take(arr, [0], axis=axis)], axis=axis)


# -- MDP construction ------------------------------------------------------------------------

def _mdp_case(data):
    parts, rng = valid_mdp_parts(data)
    irl.TabularMDP(**parts)  # the uncorrupted input works
    S, A, K = parts["features"].shape
    arg = data.draw(st.sampled_from(
        ["transitions", "sparse", "features", "discount", "initial", "names"]), "argument")
    bad = dict(parts)
    names = (arg,)
    if arg == "transitions":
        how = data.draw(st.sampled_from(["shape", "values", "type"]))
        bad[arg] = (wrong_shape(data, parts[arg], (0, 2)) if how == "shape" else
                    corrupt_distribution(data, parts[arg], rng) if how == "values" else
                    data.draw(NOT_ARRAYS))
    elif arg == "sparse":
        names = ("transitions",)
        mats = [sp.csr_matrix(parts["transitions"][:, a, :]) for a in range(A)]
        how = data.draw(st.sampled_from(["shape", "values", "single", "empty", "item"]))
        if how == "shape":
            mats[-1] = sp.csr_matrix(np.eye(S + 1))
        elif how == "values":
            mats[0] = sp.csr_matrix(corrupt_distribution(data, mats[0].toarray(), rng))
        elif how == "single":
            mats = mats[0]
        elif how == "empty":
            mats = []
        else:
            mats[0] = data.draw(NOT_ARRAYS.filter(lambda v: v is not None))
        bad["transitions"] = mats
    elif arg == "features":
        how = data.draw(st.sampled_from(["shape", "nonfinite", "type"]))
        if how == "shape":
            bad[arg] = wrong_shape(data, parts[arg], (0, 1))
        elif how == "nonfinite":
            bad[arg] = parts[arg].copy()
            bad[arg][tuple(int(rng.integers(n)) for n in (S, A, K))] = data.draw(NONFINITE)
        else:
            bad[arg] = data.draw(NOT_ARRAYS)
    elif arg == "discount":
        bad[arg] = data.draw(st.one_of(
            st.floats(max_value=-1e-12, allow_nan=False), st.floats(min_value=1.0),
            NONFINITE, NOT_REALS))
    elif arg == "initial":
        how = data.draw(st.sampled_from(["shape", "values", "type"]))
        bad[arg] = (wrong_shape(data, parts[arg], (0,)) if how == "shape" else
                    corrupt_distribution(data, parts[arg], rng) if how == "values" else
                    data.draw(NOT_ARRAYS))
    else:
        which = data.draw(st.sampled_from(["state_names", "action_names", "feature_names"]))
        n = {"state_names": S, "action_names": A, "feature_names": K}[which]
        bad[which] = data.draw(st.one_of(
            st.lists(st.text(max_size=2), max_size=6).filter(lambda x: len(x) != n),
            st.integers(), st.just("abc")))
        names = (which,)
    expect_clear_error(lambda: irl.TabularMDP(**bad), *names)


test_fuzz_mdp_construction, test_fuzz_mdp_construction_heavy = fuzz(_mdp_case)


# -- observation models ----------------------------------------------------------------------

def _observation_case(data):
    S, A, _ = sizes(data)
    rng = generator(data)
    n_obs = data.draw(st.integers(1, 5))
    probs = rng.dirichlet(np.ones(n_obs), size=(S, A))
    irl.ObservationModel(probs)
    C = rng.dirichlet(np.ones(S), size=S)
    CA = rng.dirichlet(np.ones(A), size=A)
    target = data.draw(st.sampled_from(
        ["probs", "nominal", "names", "pair", "pair_actions", "state", "factored",
         "identity"]), "target")
    if target == "probs":
        how = data.draw(st.sampled_from(["shape", "values", "type"]))
        bad = (wrong_shape(data, probs, (2,)) if how == "shape" else
               corrupt_distribution(data, probs, rng) if how == "values" else
               data.draw(NOT_ARRAYS))
        expect_clear_error(lambda: irl.ObservationModel(bad), "probs")
    elif target == "nominal":
        nominal = np.stack([rng.integers(S, size=n_obs), rng.integers(A, size=n_obs)], axis=1)
        how = data.draw(st.sampled_from(["shape", "state", "action", "float", "type"]))
        if how == "shape":
            nominal = nominal[:, :1] if data.draw(st.booleans()) else nominal[:-1]
        elif how == "state":
            nominal[0, 0] = data.draw(st.one_of(st.integers(max_value=-1),
                                                st.integers(min_value=S)).filter(
                lambda v: abs(v) < 2**62))
        elif how == "action":
            nominal[0, 1] = data.draw(st.one_of(st.integers(max_value=-2),
                                                st.integers(min_value=A)).filter(
                lambda v: abs(v) < 2**62))
        elif how == "float":
            nominal = nominal + 0.5
        else:
            nominal = data.draw(NOT_ARRAYS.filter(lambda v: v is not None))
        expect_clear_error(lambda: irl.ObservationModel(probs, nominal=nominal), "nominal")
    elif target == "names":
        names = data.draw(st.one_of(
            st.lists(st.text(max_size=2), max_size=7).filter(lambda x: len(x) != n_obs),
            st.integers(), st.just("abc")))
        expect_clear_error(lambda: irl.ObservationModel(probs, observation_names=names),
                           "observation_names")
    elif target == "pair":
        how = data.draw(st.sampled_from(["shape", "values", "type"]))
        bad = (C[:, :-1] if how == "shape" and S > 1 else C[None] if how == "shape" else
               corrupt_distribution(data, C, rng) if how == "values" else data.draw(NOT_ARRAYS))
        expect_clear_error(lambda: irl.pair_observation_model(bad, CA), "state_confusion")
    elif target == "pair_actions":
        how = data.draw(st.sampled_from(["matrix", "n_actions", "neither"]))
        if how == "matrix":
            bad = corrupt_distribution(data, CA, rng)
            expect_clear_error(lambda: irl.pair_observation_model(C, bad), "action_confusion")
        elif how == "n_actions":
            n = data.draw(st.one_of(st.integers(max_value=0), NOT_INTS.filter(
                lambda v: v is not None)))
            expect_clear_error(lambda: irl.pair_observation_model(C, n_actions=n), "n_actions")
        else:
            expect_clear_error(lambda: irl.pair_observation_model(C), "n_actions")
    elif target == "state":
        if data.draw(st.booleans()):
            bad = corrupt_distribution(data, C, rng)
            expect_clear_error(lambda: irl.state_observation_model(bad, A), "state_confusion")
        else:
            n = data.draw(st.one_of(st.integers(max_value=0), NOT_INTS))
            expect_clear_error(lambda: irl.state_observation_model(C, n), "n_actions")
    elif target == "factored":
        how = data.draw(st.sampled_from(["empty", "square", "values", "type"]))
        mats = [C, rng.dirichlet(np.ones(2), size=2)]
        if how == "empty":
            mats = []
        elif how == "square":
            mats[1] = mats[1][:, :1]
        elif how == "values":
            mats[1] = corrupt_distribution(data, mats[1], rng)
        else:
            mats = data.draw(st.sampled_from(["abc", None, 3, np.eye(2)]))
        expect_clear_error(lambda: irl.factored_observation_model(mats, n_actions=A),
                           "factor_confusions")
    else:
        which = data.draw(st.sampled_from(["n_states", "n_actions"]))
        value = data.draw(st.one_of(st.integers(max_value=0), NOT_INTS))
        kw = {"n_states": S, "n_actions": A, which: value}
        expect_clear_error(lambda: irl.identity_observation_model(**kw), which)


test_fuzz_observation_models, test_fuzz_observation_models_heavy = fuzz(_observation_case)


# -- demonstrations --------------------------------------------------------------------------

OBS_LISTS = st.lists(st.one_of(st.none(), st.integers(0, 50)), min_size=1, max_size=8)


def _demonstration_case(data):
    obs = data.draw(OBS_LISTS, "observations")
    demo = irl.Demonstration(observations=obs)
    assert demo.as_array().tolist() == [-1 if o is None else o for o in obs]
    target = data.draw(st.sampled_from(["entry", "empty", "container", "pairs", "trajectory"]))
    if target == "entry":
        bad = data.draw(st.one_of(
            st.integers(max_value=-1), st.floats(), st.booleans(), st.text(max_size=2),
            st.just(np.float64(1.0)), st.just([1]), st.just(np.bool_(True))))
        at = data.draw(st.integers(0, len(obs)))
        values = [*obs[:at], bad, *obs[at:]]
        expect_clear_error(lambda: irl.Demonstration(observations=values),
                           f"observations[{at}]")
    elif target == "empty":
        empty = data.draw(st.sampled_from([[], (), np.array([], dtype=int)]))
        expect_clear_error(lambda: irl.Demonstration(observations=empty), "observations")
    elif target == "container":
        value = data.draw(st.sampled_from([None, 3, 2.5, "12", {1: 2}, {1, 2}]))
        expect_clear_error(lambda: irl.Demonstration(observations=value), "observations")
    elif target == "pairs":
        n = len(obs)
        states = data.draw(st.lists(st.integers(0, 5), min_size=n, max_size=n))
        actions = data.draw(st.lists(st.integers(0, 2), min_size=n, max_size=n))
        irl.Demonstration.from_pairs(states, actions, 3)
        how = data.draw(st.sampled_from(["length", "negative", "action", "n_actions", "float",
                                         "occluded"]))
        args = [states, actions, 3]
        kw = {}
        if how == "length":
            args[1] = [*actions, 0]
            names = ("states and actions",)
        elif how == "negative":
            args[0] = [*states[:-1], -data.draw(st.integers(1, 99))]
            names = ("states",)
        elif how == "action":
            args[1] = [*actions[:-1], data.draw(st.integers(3, 99))]
            names = ("actions",)
        elif how == "n_actions":
            args[2] = data.draw(st.one_of(st.integers(max_value=0), NOT_INTS))
            names = ("n_actions",)
        elif how == "float":
            args[0] = [s + 0.5 for s in states]
            names = ("states",)
        else:
            kw["occluded"] = [True] * (n + 1)
            names = ("occluded",)
        expect_clear_error(lambda: irl.Demonstration.from_pairs(*args, **kw), *names)
    else:
        how = data.draw(st.sampled_from(["length", "negative", "float", "type"]))
        states, actions = [0, 1, 2], [0, 0, 1]
        if how == "length":
            actions = [0]
        elif how == "negative":
            states = [0, -1, 2]
        elif how == "float":
            actions = [0.0, 1.5, 1.0]
        else:
            states = data.draw(NOT_ARRAYS)
        name = "actions" if how == "float" else "states"
        expect_clear_error(lambda: irl.Trajectory(states=states, actions=actions), name)


test_fuzz_demonstrations, test_fuzz_demonstrations_heavy = fuzz(_demonstration_case)


# -- learners: fit, log_likelihood and friends -----------------------------------------------

FOREST = irl.domains.forestworld(noise=0.3)
GOOD_DEMOS = FOREST.sample(2, 5, occlusion=0.2, seed=0)[0]
N_OBS = FOREST.observation_model.n_observations

BAD_PARAMS = {
    "max_iter": st.one_of(st.integers(max_value=0), NOT_INTS),
    "tol": st.one_of(st.floats(max_value=-1e-12, allow_nan=False), NONFINITE, NOT_REALS),
    "init": st.one_of(st.just(np.zeros(2)), st.just(np.zeros((3, 1))),
                      NOT_ARRAYS.filter(lambda v: v is not None),
                      NONFINITE.map(lambda v: np.array([0.0, v, 1.0]))),
    "mdp": st.sampled_from([None, "mdp", irl.domains.onion_sorting().mdp]),
    "observation_model": st.sampled_from([None, np.eye(3), irl.domains.onion_sorting()
                                          .observation_model]),
}
BAYES_PARAMS = {
    "beta": st.one_of(st.floats(max_value=0.0, allow_nan=False), NONFINITE, NOT_REALS),
    "prior": st.sampled_from(["normal", 1.0, irl.GaussianPrior(mean=[0.0, 0.0])]),
    "optimizer": st.one_of(st.text(max_size=5), st.integers(), st.none()),
    "n_restarts": st.one_of(st.integers(max_value=0), NOT_INTS),
    "step_size": st.one_of(st.floats(max_value=0.0, allow_nan=False), NONFINITE, NOT_REALS),
    "decay": st.one_of(st.floats(max_value=0.0, allow_nan=False),
                       st.floats(min_value=1.0 + 1e-9), NONFINITE, NOT_REALS),
    "epsilon": st.one_of(st.floats(max_value=-1e-12, allow_nan=False), NONFINITE, NOT_REALS),
    "seed": st.one_of(st.integers(max_value=-1), st.floats(), st.text(max_size=2),
                      st.booleans()),
}
MCE_PARAMS = {"l2": st.one_of(st.floats(max_value=-1e-12, allow_nan=False), NONFINITE,
                              NOT_REALS)}
EM_PARAMS = {"m_step_max_iter": st.one_of(st.integers(max_value=0), NOT_INTS),
             "m_step_tol": st.one_of(st.floats(max_value=-1e-12, allow_nan=False), NONFINITE,
                                     NOT_REALS)}


def bad_params_of(cls) -> dict:
    out = dict(BAD_PARAMS)
    if cls in (irl.MMAPBIRL, irl.MAPBIRL):
        out.update(BAYES_PARAMS)
    else:
        out.update(MCE_PARAMS)
    if cls is irl.HiddenDataEM:
        out.update(EM_PARAMS)
    return out


BAD_DEMOS = st.one_of(
    st.sampled_from([[], (), None, "abc", 3, {"a": 1}]),
    st.just(irl.Demonstration(observations=[0])),
    st.lists(st.sampled_from([1, "x", None, [0]]), min_size=1, max_size=3),
    st.integers(N_OBS, 10**6).map(lambda o: [irl.Demonstration(observations=[0, None, o])]),
)


def _learner_case(data):
    cls = data.draw(st.sampled_from(LEARNERS), "learner")
    est = cls(FOREST.mdp, FOREST.observation_model)
    if data.draw(st.booleans(), "bad demos"):
        demos = data.draw(BAD_DEMOS, "demos")
        expect_clear_error(lambda: est.fit(demos), "demos")
        return
    params = bad_params_of(cls)
    name = data.draw(st.sampled_from(sorted(params)), "param")
    value = data.draw(params[name], "value")
    est.set_params(**{name: value})
    expect_clear_error(lambda: est.fit(GOOD_DEMOS), name)
    assert not hasattr(est, "theta_")


test_fuzz_learner_fit, test_fuzz_learner_fit_heavy = fuzz(_learner_case)

BAD_THETAS = st.one_of(
    st.integers(0, 6).filter(lambda k: k != 3).map(np.zeros),
    NONFINITE.map(lambda v: np.array([-1.0, v, 1.0])),
    st.just(np.zeros((3, 1))), NOT_ARRAYS, st.just(["a", "b", "c"]), st.just([[1, 2], [3]]),
)


def _likelihood_case(data):
    target = data.draw(st.sampled_from(
        ["MMAPBIRL", "MAPBIRL", "e_step", "prior", "metric"]), "target")
    theta = data.draw(BAD_THETAS, "theta")
    if target == "e_step":
        est = irl.HiddenDataEM(FOREST.mdp, FOREST.observation_model)
        expect_clear_error(lambda: est.e_step(theta, GOOD_DEMOS), "theta")
    elif target == "prior":
        prior = irl.GaussianPrior(mean=[0.0, 1.0, 2.0])
        method = data.draw(st.sampled_from(["log_prob", "grad_log_prob"]))
        expect_clear_error(lambda: getattr(prior, method)(theta), "theta", "prior")
    elif target == "metric":
        fn = data.draw(st.sampled_from([irl.inverse_learning_error,
                                        irl.normalized_inverse_learning_error,
                                        irl.policy_mismatch]))
        if data.draw(st.booleans()):
            expect_clear_error(lambda: fn(FOREST.mdp, FOREST.true_theta, theta),
                               "learned_theta")
        else:
            expect_clear_error(lambda: fn(FOREST.mdp, theta, FOREST.true_theta), "true_theta")
    else:
        cls = getattr(irl, target)
        est = cls(FOREST.mdp, FOREST.observation_model, beta=FOREST.beta, prior=FOREST.prior)
        method = data.draw(st.sampled_from(["log_likelihood", "log_likelihood_gradient",
                                            "log_posterior", "log_posterior_gradient"]))
        if data.draw(st.booleans()):
            expect_clear_error(lambda: getattr(est, method)(theta, GOOD_DEMOS), "theta")
        else:
            demos = data.draw(BAD_DEMOS)
            expect_clear_error(lambda: getattr(est, method)(FOREST.true_theta, demos), "demos")


test_fuzz_likelihood_inputs, test_fuzz_likelihood_inputs_heavy = fuzz(_likelihood_case)


def _metrics_and_prior_case(data):
    target = data.draw(st.sampled_from(["mdp", "states", "distance", "prior", "sample",
                                        "domain"]), "target")
    S = FOREST.mdp.n_states
    if target == "mdp":
        mdp = data.draw(st.sampled_from([None, "forest", FOREST.observation_model]))
        fn = data.draw(st.sampled_from([irl.inverse_learning_error, irl.policy_mismatch,
                                        irl.normalized_inverse_learning_error]))
        expect_clear_error(lambda: fn(mdp, FOREST.true_theta, FOREST.true_theta), "mdp")
    elif target == "states":
        states = data.draw(st.one_of(
            st.lists(st.integers(0, S - 1), max_size=3).map(
                lambda x: [*x, data.draw(st.one_of(st.integers(max_value=-1),
                                                   st.integers(S, 10**9)))]),
            st.just([]), st.just([[0, 1]]), st.just([0.5, 1.0]), st.just([True, False]),
            NOT_ARRAYS.filter(lambda v: v is not None)))  # None means every state
        expect_clear_error(lambda: irl.policy_mismatch(FOREST.mdp, FOREST.true_theta,
                                                       FOREST.true_theta, states), "states")
    elif target == "distance":
        a = np.array([1.0, -1.0, 2.0])
        b = data.draw(st.one_of(BAD_THETAS, st.just(np.zeros(3))))
        first = data.draw(st.booleans())
        args = (b, a) if first else (a, b)
        expect_clear_error(lambda: irl.reward_distance(*args),
                           "true_theta" if first else "learned_theta")
    elif target == "prior":
        which = data.draw(st.sampled_from(["mean", "std"]))
        value = data.draw(st.one_of(
            NONFINITE, NOT_ARRAYS, st.just(np.zeros((2, 2))), st.just([]),
            st.floats(max_value=0.0, allow_nan=False) if which == "std" else NONFINITE))
        expect_clear_error(lambda: irl.GaussianPrior(**{which: value}), which)
    elif target == "sample":
        n = data.draw(st.one_of(st.integers(max_value=0), NOT_INTS))
        expect_clear_error(lambda: irl.GaussianPrior().sample(n, 0), "n_features")
    else:
        name = data.draw(st.sampled_from(["forestworld", "onion_sorting"]))
        make = getattr(irl.domains, name)
        how = data.draw(st.sampled_from(["noise", "beta", "discount", "n", "length",
                                         "occlusion", "seed"]))
        if how in ("noise", "beta", "discount"):
            value = data.draw(st.one_of(st.floats(max_value=-1e-9, allow_nan=False),
                                        st.floats(min_value=1.0 + 1e-9) if how != "beta"
                                        else NONFINITE, NONFINITE, NOT_REALS))
            expect_clear_error(lambda: make(**{how: value}), how)
            return
        dom = FOREST if name == "forestworld" else irl.domains.onion_sorting()
        kw = {"n": 1, "length": 3, "occlusion": 0.1, "seed": 0}
        kw[how] = data.draw({
            "n": st.one_of(st.integers(max_value=0), NOT_INTS),
            "length": st.one_of(st.integers(max_value=0), NOT_INTS),
            "occlusion": st.one_of(st.floats(max_value=-1e-9, allow_nan=False),
                                   st.floats(min_value=1.0 + 1e-9), NONFINITE, NOT_REALS),
            "seed": st.one_of(st.integers(max_value=-1), st.floats(), st.text(max_size=2)),
        }[how])
        expect_clear_error(lambda: dom.sample(**kw), how)


test_fuzz_metrics_priors_domains, test_fuzz_metrics_priors_domains_heavy = fuzz(
    _metrics_and_prior_case)


# -- legal edge cases: they work ---------------------------------------------------------------

def _valid_model_case(data):
    """Random small models, demonstrations with any occlusion (all occluded included) and
    weights from 1e-2 to 1e4 times a random direction: the likelihood is finite, the scaled
    pass agrees with the exact log-space one, and the posterior counts every step once."""
    parts, rng = valid_mdp_parts(data)
    parts["transitions"] = np.where(rng.random(parts["transitions"].shape) < 0.3, 0.0,
                                    parts["transitions"])
    parts["transitions"][..., 0] += 1e-3  # every row keeps a successor
    parts["transitions"] /= parts["transitions"].sum(axis=2, keepdims=True)
    mdp = irl.TabularMDP(**parts)
    S, A, K = mdp.n_states, mdp.n_actions, mdp.n_features
    n_obs = data.draw(st.integers(1, 4))
    om = irl.ObservationModel(rng.dirichlet(np.ones(n_obs), size=(S, A)))
    lengths = data.draw(st.lists(st.integers(1, 6), min_size=1, max_size=3))
    occlusion = data.draw(st.sampled_from([0.0, 0.3, 1.0]))
    demos = [irl.Demonstration(observations=[
        None if rng.random() < occlusion else int(rng.integers(n_obs)) for _ in range(n)])
        for n in lengths]
    scale = 10.0 ** data.draw(st.floats(-2.0, 4.0))
    theta = scale * rng.normal(size=K)
    log_pi = log_boltzmann_policy(OptimalQSolver(mdp).q_values(theta), 1.0)

    def check():
        fast = posterior_stats(mdp, log_pi, demos, om)
        exact = posterior_stats(mdp, log_pi, demos, om, method="log")
        assert np.all(np.isfinite(fast.log_likelihood))
        np.testing.assert_allclose(fast.log_likelihood, exact.log_likelihood, rtol=1e-9,
                                   atol=1e-9)
        np.testing.assert_allclose(fast.occupancy, exact.occupancy, atol=1e-9)
        np.testing.assert_allclose(fast.occupancy.sum(axis=(1, 2)), lengths, rtol=1e-9)
        est = irl.MMAPBIRL(mdp, om)
        assert est.log_likelihood(theta, demos) == pytest.approx(fast.log_likelihood.sum())
        if all(d.n_occluded == len(d) for d in demos):
            assert fast.log_likelihood == pytest.approx(0.0, abs=1e-9)
        return True

    # A random demonstration may be impossible under a sparse MDP: that is a clear error too.
    expect_works_or_clear_error(check, "impossible under the model")


test_fuzz_valid_models, test_fuzz_valid_models_heavy = fuzz(_valid_model_case)


@pytest.mark.parametrize("cls", LEARNERS)
def test_an_all_occluded_demonstration_works_or_is_refused_by_name(cls):
    demos = [irl.Demonstration(observations=[None] * 6), irl.Demonstration(observations=[None])]
    est = cls(FOREST.mdp, FOREST.observation_model)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irl.ConvergenceWarning)
        fitted = expect_works_or_clear_error(lambda: est.fit(demos), "demos")
    if cls is irl.MaxEntIRL:
        assert fitted is None  # nothing observed: refused, by name
        return
    assert np.all(np.isfinite(fitted.theta_))
    if cls in (irl.MMAPBIRL, irl.MAPBIRL):
        # The likelihood of seeing nothing is 1 for every theta: the MAP is the prior mean.
        np.testing.assert_allclose(fitted.theta_, np.zeros(3), atol=1e-6)


def test_a_single_step_demonstration_works_for_every_learner():
    demo = FOREST.sample(1, 1, seed=3)[0]
    for cls in LEARNERS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", irl.ConvergenceWarning)
            est = expect_works_or_clear_error(
                lambda c=cls: c(FOREST.mdp, FOREST.observation_model).fit(demo), "demos")
        assert est is not None and np.all(np.isfinite(est.theta_))


@pytest.fixture(scope="module")
def long_demo():
    demos, _ = FOREST.sample(1, 10_000, occlusion=0.3, seed=5)
    return demos


def _long_likelihoods(demos, scale, learners):
    theta = scale * FOREST.true_theta
    kw = {"beta": FOREST.beta, "prior": FOREST.prior}
    calls = {
        irl.MMAPBIRL: lambda: irl.MMAPBIRL(FOREST.mdp, FOREST.observation_model, **kw)
        .log_posterior(theta, demos),
        irl.MAPBIRL: lambda: irl.MAPBIRL(FOREST.mdp, FOREST.observation_model, **kw)
        .log_posterior(theta, demos),
        irl.HiddenDataEM: lambda: irl.HiddenDataEM(FOREST.mdp, FOREST.observation_model)
        .e_step(theta, demos).log_likelihood.sum(),
    }
    values = [expect_works_or_clear_error(calls[cls], "demos") for cls in learners]
    assert np.all(np.isfinite(values)) and max(values) < -1000, values


def test_a_10000_step_demonstration_has_a_finite_likelihood(long_demo):
    _long_likelihoods(long_demo, 1e4, [irl.MMAPBIRL, irl.MAPBIRL])
    _long_likelihoods(long_demo, 1.0, [irl.HiddenDataEM])


@pytest.mark.slow
@pytest.mark.parametrize("scale", [1.0, 300.0, 1e4])
def test_a_10000_step_demonstration_has_a_finite_likelihood_at_every_scale(long_demo, scale):
    _long_likelihoods(long_demo, scale, [irl.MMAPBIRL, irl.MAPBIRL, irl.HiddenDataEM])


def _long_fits(demos, limits):
    for cls, kw in limits.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", irl.ConvergenceWarning)
            est = expect_works_or_clear_error(
                lambda c=cls, k=kw: c(FOREST.mdp, FOREST.observation_model, **k).fit(demos),
                "demos")
        assert est is not None and np.all(np.isfinite(est.theta_)), cls


def test_a_10000_step_demonstration_fits(long_demo):
    _long_fits(long_demo, {irl.MMAPBIRL: {"max_iter": 2}, irl.MAPBIRL: {}, irl.MaxEntIRL: {}})


@pytest.mark.slow
def test_a_10000_step_demonstration_fits_with_every_learner_to_convergence(long_demo):
    _long_fits(long_demo, {cls: {} for cls in LEARNERS})
