"""The observation-model interface: the likelihood of one observation over every hidden pair.

Layout: ``O[s, a, o] = P(o | s, a)``; a model's likelihoods of observations ``obs[...]`` have
shape ``(*obs.shape, S, A)``, with ``obs = -1`` (an occluded step) giving a factor of 1.

Learners and forward-backward only call :meth:`ObservationModel.log_likelihoods` (and read
``nominal``, the pair an observation reports at face value), so an implementation is free to
store ``O`` however it scales: a dense array, a product of per-factor confusion matrices, a
sparse matrix, a state confusion shared by every action. ``O`` itself is formed only on request
(:attr:`ObservationModel.probs`), for small models and tests.
"""

from __future__ import annotations

import abc
from collections.abc import Sequence
from functools import cached_property

import numpy as np

from irl._validation import as_float_array, describe

__all__ = ["ObservationModel", "check_compatible"]


class ObservationModel(abc.ABC):
    """A discrete observation model ``P(o | s, a)`` over ``n_observations`` observations.

    ``ObservationModel(probs, ...)`` builds the dense implementation
    (:class:`~irl.observation.DenseObservationModel`), as :class:`pathlib.Path` builds a
    concrete path; the others are :class:`~irl.observation.FactoredObservationModel`,
    :class:`~irl.observation.SparseObservationModel` and
    :class:`~irl.observation.StateObservationModel`.

    Parameters
    ----------
    *args, **kwargs
        Those of :class:`~irl.observation.DenseObservationModel` (``probs``, ``nominal``,
        ``observation_names``), which ``ObservationModel(...)`` builds.

    Attributes
    ----------
    n_states, n_actions, n_observations : int
    nominal : ndarray of int, shape (n_observations, 2)
        The ``(s, a)`` each observation reports at face value (``a = -1``: no action), for the
        learners that take observations as exact (MAP-BIRL, MaxEnt).
    observation_names : list of str or None
    """

    n_states: int
    n_actions: int
    n_observations: int
    observation_names: list[str] | None

    #: What ``ObservationModel(...)`` builds: the implementation whose class statement says
    #: ``default=True`` (:class:`~irl.observation.DenseObservationModel`).
    _default: type[ObservationModel] | None = None

    def __init_subclass__(cls, *, default: bool = False, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        if default:
            ObservationModel._default = cls

    def __new__(cls, *args, **kwargs):
        return super().__new__(ObservationModel._default if cls is ObservationModel else cls)

    # -- what every implementation provides ----------------------------------------------

    @abc.abstractmethod
    def _log_likelihoods(self, obs: np.ndarray) -> np.ndarray:
        """``log O(obs[m] | s, a)``, shape (M, S, A), for valid indices ``obs`` of shape (M,);
        a fresh array (callers add to it in place)."""

    @abc.abstractmethod
    def distribution(self, state: int, action: int) -> np.ndarray:
        """``O[state, action, :]``, shape (n_observations,): what is seen from one pair."""

    @cached_property
    def nominal(self) -> np.ndarray:
        """Default: the maximum-likelihood pair ``argmax_{s, a} O[s, a, o]`` of each o."""
        flat = self.probs.reshape(self.n_states * self.n_actions, self.n_observations)
        return np.stack(np.divmod(flat.argmax(axis=0), self.n_actions), axis=1)

    # -- derived -------------------------------------------------------------------------

    def log_likelihoods(self, obs) -> np.ndarray:
        """``log O(obs[...] | s, a)`` over every hidden pair, shape ``(*obs.shape, S, A)``.

        ``obs`` holds observation indices, ``-1`` for occluded steps (a row of zeros);
        ``-inf`` where a pair cannot emit the observation. A fresh array.
        """
        obs = np.asarray(obs)
        flat = obs.reshape(-1)
        seen = flat >= 0
        if seen.all():
            out = self._log_likelihoods(flat)
        else:
            out = np.zeros((flat.size, self.n_states, self.n_actions))
            if seen.any():
                out[seen] = self._log_likelihoods(flat[seen])
        return out.reshape((*obs.shape, self.n_states, self.n_actions))

    def separable_likelihoods(self, obs):
        """``O(obs[...] | s, a) = exp(shift[...]) * state[..., s] * action[..., a]`` for a model
        whose likelihoods factor into a state part and an action part (None otherwise, the
        default): ``(state, action, shift, min_log)`` as in :meth:`scaled_likelihoods`, each
        part at most 1 with maximum 1 (ones where occluded). Forward-backward then never forms
        the ``S A`` factor of a step when the observations are too many to keep.
        """
        return None

    def kronecker_likelihoods(self, obs):
        """:meth:`separable_likelihoods` with the state part itself a product, for a model
        whose state is read through independent factors (None otherwise, the default):
        ``(head, tail, action, shift, min_log)``, with ``state[..., i * n + j] = head[..., i] *
        tail[..., j]`` for ``n = tail.shape[-1]``. ``S / n + n`` floats per observation instead
        of ``S``: the compiled forward-backward takes a whole batch's parts this way, never
        holding (nor touching the memory of) its ``N T S`` state parts.
        """
        return None

    def scaled_likelihoods(self, obs, *, action_major: bool = False
                           ) -> tuple[np.ndarray, np.ndarray, float]:
        """``O(obs[...] | s, a) = exp(shift[...]) * factor[..., s, a]``, scaled so that nothing
        under- or overflows.

        Returns
        -------
        factor : ndarray of shape (*obs.shape, S, A), or (*obs.shape, A, S) if action_major
            In [0, 1], with maximum 1 over the pairs of each observation (ones where occluded);
            C-contiguous.
        shift : ndarray of shape obs.shape
            ``max_{s, a} log O(obs | s, a)``; ``-inf`` where no pair can emit the observation
            (``factor`` is then undefined there).
        min_log : float
            ``log`` of the smallest positive ``factor`` entry (0.0 if none), computed from
            logs, so that a caller can check the range before multiplying factors together.
        """
        ll = self.log_likelihoods(obs)
        shift = ll.max(axis=(-2, -1))
        with np.errstate(invalid="ignore"):
            ll -= shift[..., None, None]
        min_log = finite_min(ll)
        factor = np.exp(ll, out=ll)
        if action_major:
            factor = np.ascontiguousarray(np.swapaxes(factor, -1, -2))
        return factor, shift, min_log

    def log_likelihood(self, observation: int) -> np.ndarray:
        """``log O(observation | s, a)``, shape (S, A)."""
        return self.log_likelihoods(np.array([observation]))[0]

    def likelihood(self, observation: int) -> np.ndarray:
        """``O(observation | s, a)``, shape (S, A)."""
        return np.exp(self.log_likelihood(observation))

    @cached_property
    def probs(self) -> np.ndarray:
        """The dense ``O[s, a, o]``, shape (S, A, n_observations): formed on first access
        (``S * A * n_observations`` floats), for small models and tests."""
        table = np.exp(self._log_likelihoods(np.arange(self.n_observations)))
        return np.ascontiguousarray(np.moveaxis(table, 0, 2))

    @cached_property
    def log_emissions(self) -> np.ndarray:
        """``log E[o, s, a]`` for every observation plus a last row of zeros (occluded),
        shape (n_observations + 1, S, A); dense, for small models."""
        return self.log_likelihoods(np.append(np.arange(self.n_observations), -1))

    @cached_property
    def emissions(self) -> np.ndarray:
        """``exp(log_emissions)``, shape (n_observations + 1, S, A)."""
        return np.exp(self.log_emissions)

    def sample(self, state: int, action: int, rng: np.random.Generator) -> int:
        """One observation drawn from ``O[state, action, :]``."""
        p = self.distribution(state, action)
        return int(rng.choice(p.size, p=p))

    def error_rate(self, weights: np.ndarray | None = None) -> float:
        """Probability that the observation differs from the nominal report of the truth.

        Averaged over ``(s, a)`` with ``weights[s, a]`` (uniform by default); only defined for
        pair observations (``o = s * A + a``).
        """
        S, A = self.n_states, self.n_actions
        if self.n_observations != S * A:
            raise ValueError(
                f"error_rate needs pair observations (n_observations = S * A = {S * A}); "
                f"got {self.n_observations}"
            )
        if weights is None:
            w = np.full((S, A), 1.0 / (S * A))
        else:
            w = as_float_array(weights, "weights")
            if w.shape != (S, A) or w.min() < 0 or not w.sum() > 0:
                raise ValueError(
                    f"weights must be non-negative of shape (S, A) = ({S}, {A}) with a positive "
                    f"sum; got shape {w.shape}"
                )
            w = w / w.sum()
        return float(1.0 - (w * self._correct()).sum())

    def _correct(self) -> np.ndarray:
        """``O[s, a, s * A + a]``, shape (S, A), for pair observations."""
        S, A = self.n_states, self.n_actions
        return self.probs.reshape(S * A, S * A).diagonal().reshape(S, A)

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(n_states={self.n_states}, n_actions={self.n_actions}, "
            f"n_observations={self.n_observations})"
        )


def check_nominal(nominal, n_obs: int, n_states: int, n_actions: int) -> np.ndarray:
    """``nominal`` as an int array (n_obs, 2) of states and actions (or -1), or raise."""
    if isinstance(nominal, (str, bytes, dict, set)):
        raise TypeError(f"nominal must be an integer array ({n_obs}, 2); got "
                        f"{describe(nominal)}")
    try:
        nominal = np.asarray(nominal)
    except ValueError as exc:  # ragged
        raise ValueError(f"nominal must have shape ({n_obs}, 2); got {exc}") from None
    if nominal.dtype == bool or not np.issubdtype(nominal.dtype, np.integer):
        raise TypeError(f"nominal must be an integer array ({n_obs}, 2); got dtype "
                        f"{nominal.dtype}")
    nominal = nominal.astype(np.int64)
    if nominal.shape != (n_obs, 2):
        raise ValueError(f"nominal must have shape ({n_obs}, 2); got {nominal.shape}")
    for col, what, low, high in ((0, "states", 0, n_states), (1, "actions", -1, n_actions)):
        bad = np.flatnonzero((nominal[:, col] < low) | (nominal[:, col] >= high))
        if bad.size:
            o = int(bad[0])
            raise ValueError(
                f"nominal {what} must lie in [{low}, {high}); got nominal[{o}, {col}] = "
                f"{nominal[o, col]} ({bad.size} out of range)"
            )
    return nominal


def check_names(observation_names, n_obs: int) -> list[str] | None:
    """``observation_names`` as a list of ``n_obs`` str (or None), or raise."""
    if observation_names is None:
        return None
    if isinstance(observation_names, (str, bytes)) or not isinstance(
        observation_names, Sequence | np.ndarray
    ):
        raise TypeError(f"observation_names must be a sequence of {n_obs} str; got "
                        f"{describe(observation_names)}")
    if len(observation_names) != n_obs:
        raise ValueError(
            f"observation_names must have {n_obs} entries; got {len(observation_names)}"
        )
    return [str(x) for x in observation_names]


def finite_min(x: np.ndarray) -> float:
    """Smallest finite entry of a log array (0.0 if none)."""
    low = float(x.min()) if x.size else 0.0
    if np.isfinite(low):
        return low
    finite = x[np.isfinite(x)]
    return float(finite.min()) if finite.size else 0.0


def safe_log(x: np.ndarray) -> np.ndarray:
    """``log x`` with ``-inf`` for zeros, without warnings."""
    with np.errstate(divide="ignore"):
        return np.log(x)


def check_compatible(mdp, observation_model) -> None:
    """Raise ``ValueError`` unless the observation model was built for this MDP's (S, A).

    Parameters
    ----------
    mdp : TabularMDP
    observation_model : ObservationModel
        A ``TypeError`` when either is not of its class.
    """
    from irl.mdp import TabularMDP

    if not isinstance(mdp, TabularMDP):
        raise TypeError(f"mdp must be an irl.TabularMDP; got {type(mdp).__name__}")
    if not isinstance(observation_model, ObservationModel):
        raise TypeError(
            "observation_model must be an irl.ObservationModel; got "
            f"{type(observation_model).__name__}"
        )
    got = (observation_model.n_states, observation_model.n_actions)
    want = (mdp.n_states, mdp.n_actions)
    if got != want:
        raise ValueError(
            f"observation_model is for (S, A) = {got} but mdp has (S, A) = {want}"
        )
