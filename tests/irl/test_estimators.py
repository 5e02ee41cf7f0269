"""The learners follow scikit-learn's estimator conventions: ``__init__`` only stores its
arguments, ``fit`` validates them and builds everything from their current values, learned
state ends in ``_`` and exists only after ``fit``, ``get_params``/``set_params``/``clone``."""

import warnings

import numpy as np
import pytest

import irl
from irl import NotFittedError

LEARNERS = [irl.MMAPBIRL, irl.MAPBIRL, irl.HiddenDataEM, irl.MaxEntIRL]
BAYESIAN = [irl.MMAPBIRL, irl.MAPBIRL]
FITTED = {
    irl.MMAPBIRL: {"theta_", "policy_", "n_iter_", "history_", "converged_", "log_posterior_",
                   "prior_"},
    irl.MAPBIRL: {"theta_", "policy_", "n_iter_", "history_", "converged_", "log_posterior_",
                  "prior_"},
    irl.HiddenDataEM: {"theta_", "policy_", "n_iter_", "history_", "converged_"},
    irl.MaxEntIRL: {"theta_", "policy_", "n_iter_", "history_", "converged_"},
}


@pytest.fixture(scope="module")
def forest():
    dom = irl.domains.forestworld(noise=0.0)
    demos, _ = dom.sample(4, 10, occlusion=0.0, seed=0)
    return dom, demos


def make(cls, dom, **params):
    if cls in BAYESIAN:
        params = {"beta": dom.beta, "prior": dom.prior, **params}
    return cls(dom.mdp, dom.observation_model, **params)


@pytest.mark.parametrize("cls", LEARNERS)
def test_init_stores_its_arguments_and_nothing_else(cls, forest):
    dom, _ = forest
    est = make(cls, dom, max_iter=7, init=np.ones(3))
    params = est.get_params()
    assert set(vars(est)) == set(params)
    assert params["max_iter"] == 7 and params["init"] is est.init and params["mdp"] is dom.mdp
    # nothing is checked before fit: any value is stored as given
    odd = cls(None, "not a model", max_iter=-3)
    assert (odd.mdp, odd.observation_model, odd.max_iter) == (None, "not a model", -3)


@pytest.mark.parametrize("cls", LEARNERS)
def test_learned_attributes_exist_only_after_fit(cls, forest):
    dom, demos = forest
    est = make(cls, dom)
    assert not [a for a in dir(est) if a.endswith("_") and not a.startswith("_")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irl.ConvergenceWarning)
        est.fit(demos)
    learned = {a for a in vars(est) if a.endswith("_") and not a.startswith("_")}
    assert learned == FITTED[cls]
    assert est.converged_ is True or est.converged_ is False
    assert est.theta_.shape == (3,) and est.policy_.shape == (16,)


def test_prior_is_the_standard_normal_only_once_fitted(forest):
    dom, demos = forest
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta)
    assert not hasattr(est, "prior_")
    est.fit(demos)
    assert isinstance(est.prior_, irl.GaussianPrior)
    assert est.prior_.mean.tolist() == 0.0 and est.prior_.std.tolist() == 1.0
    assert est.prior is None


def test_maxent_reports_convergence(forest):
    dom, demos = forest
    assert irl.MaxEntIRL(dom.mdp, dom.observation_model).fit(demos).converged_ is True
    with pytest.warns(irl.ConvergenceWarning, match="max_iter=1"):
        est = irl.MaxEntIRL(dom.mdp, dom.observation_model, max_iter=1).fit(demos)
    assert est.converged_ is False and est.n_iter_ == 1


def test_soft_policy_before_fit_is_a_clear_error(forest):
    dom, _ = forest
    with pytest.raises(NotFittedError, match="not fitted yet; call fit"):
        irl.HiddenDataEM(dom.mdp, dom.observation_model).soft_policy(3)


# -- fit builds everything from the current attributes ---------------------------------------

@pytest.mark.parametrize("cls", LEARNERS)
def test_an_estimator_whose_mdp_or_beta_changed_equals_a_fresh_one(cls):
    """The solver used to be built in ``__init__``: after ``est.mdp = other`` the estimator
    kept planning in the old MDP (a wrong likelihood and a wrong gradient)."""
    noisy = irl.domains.forestworld(noise=0.3)
    other_mdp = irl.domains.forestworld(success=0.6).mdp  # same S, A, K; other dynamics
    demos, _ = noisy.sample(4, 12, occlusion=0.25, seed=1)
    om = noisy.observation_model
    new = {"beta": 0.7} if cls in BAYESIAN else {"l2": 0.5}

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irl.ConvergenceWarning)
        est = cls(noisy.mdp, om).fit(demos)  # fitted once: any cache is warm
        before = est.theta_.copy()
        est.mdp = other_mdp
        est.set_params(**new)
        after = est.fit(demos).theta_
        fresh = cls(other_mdp, om, **new).fit(demos).theta_
    np.testing.assert_allclose(after, fresh, rtol=1e-12, atol=1e-12)
    assert np.max(np.abs(after - before)) > 1e-3  # the change mattered
    if cls in BAYESIAN:
        theta = np.array([-1.0, -0.5, 2.0])
        changed = cls(noisy.mdp, om)
        changed.mdp, changed.beta = other_mdp, 0.7
        assert changed.log_posterior(theta, demos) == cls(other_mdp, om, beta=0.7).log_posterior(
            theta, demos)
        np.testing.assert_array_equal(
            changed.log_likelihood_gradient(theta, demos),
            cls(other_mdp, om, beta=0.7).log_likelihood_gradient(theta, demos))


# -- parameters by name ---------------------------------------------------------------------

@pytest.mark.parametrize("cls", LEARNERS)
def test_get_and_set_params(cls, forest):
    dom, _ = forest
    est = make(cls, dom)
    assert est.set_params(max_iter=3, tol=0.5) is est
    assert est.get_params()["max_iter"] == 3 and est.tol == 0.5
    with pytest.raises(ValueError, match=r"invalid parameter 'max_iters' for .*valid parameters"):
        est.set_params(max_iters=3)
    assert est.get_params(deep=True) == est.get_params(deep=False)


def test_repr_shows_the_parameters_that_differ_from_their_defaults(forest):
    dom, _ = forest
    text = repr(irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=2.5, n_restarts=3))
    assert "beta=2.5" in text and "n_restarts=3" in text and "max_iter" not in text


@pytest.mark.parametrize("cls", LEARNERS)
def test_sklearn_clone_gives_an_equal_unfitted_estimator(cls, forest):
    base = pytest.importorskip("sklearn.base")
    dom, demos = forest
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", irl.ConvergenceWarning)
        est = make(cls, dom, max_iter=40).fit(demos)
        twin = base.clone(est)
        assert not hasattr(twin, "theta_")
        a, b = est.get_params(), twin.get_params()
        assert a.keys() == b.keys()
        for name in a:
            if name not in ("mdp", "observation_model", "prior"):  # deep-copied objects
                assert a[name] == b[name], name
        assert repr(twin) == repr(est)
        np.testing.assert_array_equal(twin.fit(demos).theta_, est.theta_)


@pytest.mark.parametrize("cls", LEARNERS)
def test_sklearn_convention_checks(cls, forest):
    checks = pytest.importorskip("sklearn.utils.estimator_checks")
    dom, _ = forest
    est = make(cls, dom)
    name = cls.__name__
    checks.check_no_attributes_set_in_init(name, est)
    checks.check_get_params_invariance(name, est)
    checks.check_parameters_default_constructible(name, est)
    checks.check_do_not_raise_errors_in_init_or_set_params(name, est)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # set_params must neither validate nor change anything
        checks.check_set_params(name, est)


# -- every hyperparameter is checked in fit --------------------------------------------------

COMMON = [
    ("mdp", None, TypeError, r"mdp must be an irl.TabularMDP; got NoneType"),
    ("observation_model", "noise", TypeError, r"observation_model must be an irl.Observation"),
    ("max_iter", 0, ValueError, r"max_iter must be an integer >= 1; got 0"),
    ("max_iter", -5, ValueError, r"max_iter must be an integer >= 1; got -5"),
    ("max_iter", 2.5, TypeError, r"max_iter must be an integer; got float 2.5"),
    ("max_iter", True, TypeError, r"max_iter must be an integer; got bool True"),
    ("tol", -1, ValueError, r"tol must be a finite number >= 0.0; got -1.0"),
    ("tol", np.nan, ValueError, r"tol must be a finite number >= 0.0; got nan"),
    ("tol", "1e-3", TypeError, r"tol must be a real number; got str '1e-3'"),
    ("init", np.zeros(2), ValueError, r"init must have shape \(K,\) = \(3,\); got \(2,\)"),
    ("init", [0.0, np.inf, 1.0], ValueError, r"init must be finite"),
    ("init", "zeros", TypeError, r"init must be an array of 3 numbers; got str"),
]
BAYES_ONLY = [
    ("beta", True, TypeError, r"beta must be a real number; got bool True"),
    ("beta", 0.0, ValueError, r"beta must be a finite number > 0.0; got 0.0"),
    ("beta", -1.5, ValueError, r"beta must be a finite number > 0.0; got -1.5"),
    ("beta", np.inf, ValueError, r"beta must be a finite number > 0.0; got inf"),
    ("beta", "1", TypeError, r"beta must be a real number; got str '1'"),
    ("prior", "normal", TypeError, r"prior must be an irl.GaussianPrior or None; got str"),
    ("prior", irl.GaussianPrior(mean=[0.0, 0.0]), ValueError,
     r"prior must have one mean per weight \(K = 3\)"),
    ("optimizer", "adam", ValueError, r"optimizer must be one of .*; got 'adam'"),
    ("optimizer", 3, TypeError, r"optimizer must be one of .*; got int 3"),
    ("n_restarts", 0, ValueError, r"n_restarts must be an integer >= 1; got 0"),
    ("step_size", -0.01, ValueError, r"step_size must be a finite number > 0.0; got -0.01"),
    ("step_size", 0, ValueError, r"step_size must be a finite number > 0.0; got 0.0"),
    ("decay", 0.0, ValueError, r"decay must be in \(0.0, 1.0\]; got 0.0"),
    ("decay", 1.5, ValueError, r"decay must be in \(0.0, 1.0\]; got 1.5"),
    ("epsilon", -1e-3, ValueError, r"epsilon must be a finite number >= 0.0; got -0.001"),
    ("seed", "abc", TypeError, r"seed must be an int, a numpy Generator or None; got str"),
    ("seed", 1.5, TypeError, r"seed must be an int, a numpy Generator or None; got float"),
    ("seed", True, TypeError, r"seed must be an int, a numpy Generator or None; got bool"),
    ("seed", -1, ValueError, r"seed must be a non-negative int; got -1"),
]
MCE_ONLY = [
    ("l2", -0.1, ValueError, r"l2 must be a finite number >= 0.0; got -0.1"),
    ("l2", np.nan, ValueError, r"l2 must be a finite number >= 0.0; got nan"),
    ("l2", None, TypeError, r"l2 must be a real number; got NoneType None"),
]
EM_ONLY = [
    ("m_step_max_iter", 0, ValueError, r"m_step_max_iter must be an integer >= 1; got 0"),
    ("m_step_tol", -1e-8, ValueError, r"m_step_tol must be a finite number >= 0.0; got -1e-08"),
]
CASES = (
    [(cls, *case) for cls in LEARNERS for case in COMMON]
    + [(cls, *case) for cls in BAYESIAN for case in BAYES_ONLY]
    + [(cls, *case) for cls in (irl.HiddenDataEM, irl.MaxEntIRL) for case in MCE_ONLY]
    + [(irl.HiddenDataEM, *case) for case in EM_ONLY]
)


@pytest.mark.parametrize(("cls", "param", "value", "error", "message"), CASES,
                         ids=[f"{c[0].__name__}-{c[1]}={c[2]!r}" for c in CASES])
def test_fit_refuses_a_bad_hyperparameter_by_name(cls, param, value, error, message, forest):
    dom, demos = forest
    est = make(cls, dom)
    est.set_params(**{param: value})  # accepted as given ...
    with pytest.raises(error, match=message) as info:  # ... and refused by fit
        est.fit(demos)
    assert "\n" not in str(info.value)
    assert not hasattr(est, "theta_")


@pytest.mark.parametrize("cls", BAYESIAN)
def test_the_likelihood_methods_check_the_model_parameters(cls, forest):
    dom, demos = forest
    est = make(cls, dom, beta=True)
    with pytest.raises(TypeError, match="beta must be a real number"):
        est.log_likelihood(dom.true_theta, demos)
    est.beta = 1.0
    with pytest.raises(ValueError, match=r"theta must have shape \(K,\) = \(3,\)"):
        est.log_posterior(np.zeros(4), demos)
