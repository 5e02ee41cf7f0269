"""Behaviour cloning: the expert's policy estimated from its actions, with no reward.

Layouts: ``N[s, a]`` (expected) visits of each pair, ``pi[s, a]``, ``m[a]`` the fallback
action distribution, deterministic policies ``policy[s] -> a``.

Both variants estimate a stationary ``pi(a | s)`` by additive smoothing toward ``m``:

    pi(a | s) = (N(s, a) + alpha m(a)) / (N(s) + alpha),        N(s) = sum_a N(s, a)     (1)

``alpha`` (``smoothing``) is a number of pseudo-visits per state, spread over the actions by
``m``: with ``m`` uniform this is additive (Lidstone) smoothing of ``alpha / A`` per action
(``alpha = A`` is Laplace's add-one), and a state never visited (``N(s) = 0``) gets ``m``.
``m`` is uniform (``unseen="uniform"``) or the actions' overall frequencies, Laplace-smoothed,
``m(a) = (sum_s N(s, a) + 1) / (sum_{s,a} N(s, a) + A)`` (``unseen="most-common"``), whose
greedy action is the most common one. With ``alpha <= 1`` a state seen once takes the action
seen there, whatever ``m``.

- **face value** (``variant="face-value"``, the ``bc`` learner): ``N`` counts the perceived
  pairs, each observation read as ``observation_model.nominal[o]``; occluded steps are skipped.
- **through the observation model** (``variant="em"``, ``bc-em``): ``N`` is the expected visits
  ``sum_t P(s_t = s, a_t = a | o, pi)`` of the hidden pairs, from the exact forward-backward
  pass the other learners use (:func:`irl.inference.posterior_stats`) under the current ``pi``,
  and (1) is the M-step. Starting from the uniform policy, each iteration does not lower

      log P(o | pi) + alpha sum_s sum_a m(a) log pi(a | s)                                (2)

  (EM for the MAP under a Dirichlet prior; with ``alpha = 0``, the marginal likelihood of the
  observations itself). For ``unseen="most-common"``, ``m`` is computed once, from the first
  E-step's expected visits, so that (2) is one fixed objective.

The greedy policy ``policy_`` takes ``argmax_a pi(a | s)`` and breaks exact ties uniformly at
random from ``seed``: at a state never visited with ``unseen="uniform"`` that is a uniformly
random action (no action index is favoured), with ``"most-common"`` the most common action.
The default, ``"uniform"``, was chosen on seeds no reported result uses (docs/results.md,
"Behaviour cloning"): on onion sorting it lost less of the expert's value than
``"most-common"`` in 31 of 32 cells of the data-efficiency sweep.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from irl._random import check_random_state
from irl._validation import check_int, check_real, describe
from irl.demonstrations import Demonstration, check_demonstrations
from irl.exceptions import ConvergenceWarning
from irl.inference import check_backend, pack_demonstrations, posterior_stats, scratch_held
from irl.learners.base import LearnerBase
from irl.learners.birl import face_value_counts
from irl.mdp import TabularMDP
from irl.observation import ObservationModel, check_compatible, identity_observation_model

__all__ = ["UNSEEN", "VARIANTS", "BehaviorCloning", "cloned_policy", "fallback_actions",
           "greedy_actions"]

VARIANTS = ("face-value", "em")
UNSEEN = ("uniform", "most-common")


def fallback_actions(counts: np.ndarray, unseen: str) -> np.ndarray:
    """``m[a]``: uniform, or the Laplace-smoothed overall action frequencies of ``counts``
    ``N[s, a]`` (``unseen="most-common"``).

    Parameters
    ----------
    counts : ndarray of shape (S, A)
        ``N[s, a]``, the (expected) visits of each pair.
    unseen : {"uniform", "most-common"}

    Returns
    -------
    ndarray of shape (A,)
        ``m``, summing to 1.
    """
    n_actions = counts.shape[1]
    if unseen == "uniform":
        return np.full(n_actions, 1.0 / n_actions)
    per_action = counts.sum(axis=0)
    return (per_action + 1.0) / (per_action.sum() + n_actions)


def cloned_policy(counts: np.ndarray, smoothing: float, fallback: np.ndarray) -> np.ndarray:
    """``pi[s, a]`` of Eq. (1) from visits ``N[s, a]``, ``alpha = smoothing`` and ``m``; a
    state with ``N(s) + alpha = 0`` gets ``m``.

    Parameters
    ----------
    counts : ndarray of shape (S, A)
        ``N[s, a]``.
    smoothing : float
        ``alpha``, pseudo-visits per state, >= 0.
    fallback : ndarray of shape (A,)
        ``m``, what a state is smoothed toward.

    Returns
    -------
    ndarray of shape (S, A)
        ``pi[s, a] = (N[s, a] + alpha m[a]) / (N(s) + alpha)``; rows sum to 1.
    """
    visits = counts.sum(axis=1, keepdims=True)
    total = visits + smoothing
    pi = np.broadcast_to(fallback, counts.shape).copy()
    seen = total[:, 0] > 0
    pi[seen] = (counts[seen] + smoothing * fallback) / total[seen]
    return pi


def greedy_actions(pi: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``policy[s] = argmax_a pi[s, a]``, exact ties (to 1e-12) broken uniformly at random.

    Parameters
    ----------
    pi : ndarray of shape (S, A)
    rng : numpy.random.Generator
        Breaks the ties.

    Returns
    -------
    ndarray of int, shape (S,)
    """
    best = pi.max(axis=1, keepdims=True)
    ties = pi >= best - 1e-12 * np.maximum(best, 1.0)
    # a uniform key per pair; the largest key among the tied actions wins
    keys = np.where(ties, rng.random(pi.shape), -1.0)
    return keys.argmax(axis=1)


class BehaviorCloning(LearnerBase):
    """Behaviour cloning: ``pi(a | s)`` from the demonstrated actions, no reward.

    Parameters
    ----------
    mdp : TabularMDP
        Its transitions and initial distribution are used by ``variant="em"`` only (the hidden
        sequence's prior); ``"face-value"`` needs only its numbers of states and actions.
    observation_model : ObservationModel, optional
        How the demonstrations' observations were produced; None: the noise-free
        :func:`irl.identity_observation_model` (observation ``s * A + a``).
    variant : {"face-value", "em"}, default "face-value"
        Count the perceived pairs (occluded steps skipped), or estimate the visits of the hidden
        pairs by EM through the observation model (see the module docstring).
    smoothing : float, default 1.0
        ``alpha`` of Eq. (1): pseudo-visits per state, >= 0.
    unseen : {"uniform", "most-common"}, default "uniform"
        The distribution ``m`` a state is smoothed toward and that a state never visited takes:
        uniform (its greedy action: a uniformly random one) or the actions' overall frequencies
        (its greedy action: the most common action). Uniform was the better of the two for both
        variants on fresh seeds (docs/results.md, "Behaviour cloning").
    max_iter : int, default 200
        EM iterations (``variant="em"``).
    tol : float, default 1e-6
        EM stops when no probability of ``pi`` changes by more than ``tol``.
    backend : {"numpy", "numba"}
        Forward-backward kernels (:data:`irl.inference.BACKENDS`), for ``variant="em"``.
    seed : int or Generator, optional
        Breaks ties of the greedy policy.

    Attributes
    ----------
    theta_ : None
        Behaviour cloning learns no reward; every metric reads ``policy_``.
    policy_ : ndarray of shape (S,)
        Greedy action per state (ties broken at random, see ``unseen``).
    action_probabilities_ : ndarray of shape (S, A)
        ``pi[s, a]``, rows summing to 1.
    counts_ : ndarray of shape (S, A)
        ``N[s, a]``: the pairs counted, or their expected visits under the final E-step.
    fallback_ : ndarray of shape (A,)
        ``m[a]``.
    unseen_states_ : ndarray of int
        The states with no (expected) visit, ``N(s) = 0``.
    n_iter_ : int
        EM iterations run (0 at face value).
    history_ : list of dict
        Per EM iteration: ``value`` (Eq. (2) at the E-step's ``pi``: the log posterior under
        the Dirichlet prior, up to a constant), ``log_likelihood`` (``log P(o | pi)``) and
        ``delta`` (the largest change of ``pi``). Empty at face value.
    converged_ : bool
    """

    def __init__(
        self,
        mdp: TabularMDP,
        observation_model: ObservationModel | None = None,
        *,
        variant: str = "face-value",
        smoothing: float = 1.0,
        unseen: str = "uniform",
        max_iter: int = 200,
        tol: float = 1e-6,
        backend: str = "numpy",
        seed: int | np.random.Generator | None = None,
    ) -> None:
        self.mdp = mdp
        self.observation_model = observation_model
        self.variant = variant
        self.smoothing = smoothing
        self.unseen = unseen
        self.max_iter = max_iter
        self.tol = tol
        self.backend = backend
        self.seed = seed

    def _check_params(self) -> dict:
        for name, allowed in (("variant", VARIANTS), ("unseen", UNSEEN)):
            value = getattr(self, name)
            if not isinstance(value, str) or value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}; got {describe(value)}")
        if not isinstance(self.mdp, TabularMDP):
            raise TypeError(f"mdp must be an irl.TabularMDP; got {describe(self.mdp)}")
        om = self.observation_model
        om = identity_observation_model(self.mdp.n_states, self.mdp.n_actions) if om is None \
            else om
        return {
            "observation_model": om,
            "smoothing": check_real(self.smoothing, "smoothing", low=0.0),
            "max_iter": check_int(self.max_iter, "max_iter", low=1),
            "tol": check_real(self.tol, "tol", low=0.0),
            "backend": check_backend(self.backend),
            "rng": check_random_state(self.seed),
        }

    def fit(self, demos: Sequence[Demonstration]):
        """Estimate ``pi`` from ``demos``; returns ``self``. Every parameter is checked here
        (a ``ValueError``/``TypeError`` naming it)."""
        params = self._check_params()
        om = params["observation_model"]
        demos = _check_demos(self.mdp, om, demos)
        alpha = params["smoothing"]
        history: list[dict] = []
        converged = True
        if self.variant == "face-value":
            counts = face_value_counts(demos, om)
            if not counts.any():
                raise ValueError("demos must hold at least one observed step; every step is "
                                 "occluded, so face-value cloning has nothing to count "
                                 "(variant='em' accepts this)")
            fallback = fallback_actions(counts, self.unseen)
            pi = cloned_policy(counts, alpha, fallback)
        else:
            counts, fallback, pi, history, converged = self._em(demos, om, params)
        self.theta_ = None
        self.counts_ = counts
        self.fallback_ = fallback
        self.action_probabilities_ = pi
        self.unseen_states_ = np.flatnonzero(counts.sum(axis=1) == 0)
        self.policy_ = greedy_actions(pi, params["rng"])
        self.n_iter_ = len(history)
        self.history_ = history
        self.converged_ = converged
        return self

    def _em(self, demos, om, params):
        """EM for Eq. (2): ``(counts, fallback, pi, history, converged)``."""
        alpha, backend = params["smoothing"], params["backend"]
        packed = pack_demonstrations(demos, om)
        S, A = self.mdp.n_states, self.mdp.n_actions
        pi = np.full((S, A), 1.0 / A)
        fallback = None
        history: list[dict] = []
        delta = np.inf
        with scratch_held(), np.errstate(divide="ignore"):
            for it in range(params["max_iter"]):
                log_pi = np.log(pi)
                stats = posterior_stats(self.mdp, log_pi, packed, backend=backend)
                counts = stats.occupancy.sum(axis=0)
                if fallback is None:  # fixed from the first E-step: one objective throughout
                    fallback = fallback_actions(counts, self.unseen)
                ll = float(stats.log_likelihood.sum())
                prior = (0.0 if alpha == 0 else
                         float(alpha * (fallback[None, :] * log_pi).sum()))
                new = cloned_policy(counts, alpha, fallback)
                delta = float(np.abs(new - pi).max())
                history.append({"iteration": it, "value": ll + prior, "log_likelihood": ll,
                                "delta": delta})
                pi = new
                if delta <= params["tol"]:
                    break
        converged = delta <= params["tol"]
        if not converged:
            warnings.warn(
                f"BehaviorCloning's EM stopped at max_iter={params['max_iter']} with the policy "
                f"still changing by {delta:.3g} > tol={params['tol']}",
                ConvergenceWarning, stacklevel=3,
            )
        return counts, fallback, pi, history, converged

    def log_likelihood(self, demos: Sequence[Demonstration], pi: np.ndarray | None = None
                       ) -> float:
        """``log P(o | pi)`` of ``demos`` under ``pi[s, a]`` (the fitted one by default),
        every hidden sequence marginalized by forward-backward."""
        params = self._check_params()
        om = params["observation_model"]
        demos = _check_demos(self.mdp, om, demos)
        if pi is None:
            self._check_fitted("action_probabilities_")
            pi = self.action_probabilities_
        pi = np.asarray(pi, float)
        if pi.shape != (self.mdp.n_states, self.mdp.n_actions):
            raise ValueError(f"pi must have shape {(self.mdp.n_states, self.mdp.n_actions)}; "
                             f"got {pi.shape}")
        with np.errstate(divide="ignore"):
            log_pi = np.log(pi)
        stats = posterior_stats(self.mdp, log_pi, demos, om, backend=params["backend"])
        return float(stats.log_likelihood.sum())


def _check_demos(mdp, observation_model, demos) -> list[Demonstration]:
    """The learners' checks (:meth:`LearnerBase._check_problem`) for a resolved model."""
    check_compatible(mdp, observation_model)
    return check_demonstrations(demos, observation_model.n_observations)
