"""Exact inference over the hidden state-action sequence of observed demonstrations.

Layouts: ``log_pi[s, a]`` or ``log_pi[t, s, a]``, packed observations ``obs[n, t]``
(-1 = occluded or padding), lengths ``lengths[n]``, log-likelihoods of the observations
``log O(obs[n, t] | s, a)`` (0 at occluded steps) kept as ``factor[n, t, a, s] =
exp(log O - shift[n, t])`` with ``shift[n, t] = max_{s, a} log O``; results
``occupancy[n, s, a]`` and ``initial[n, s]``.

A demonstration is a hidden Markov model over ``x_t = (s_t, a_t)``:
``P(x_1) = p0(s_1) pi(a_1 | s_1)``,
``P(x_{t+1} | x_t) = T(s_t, a_t, s_{t+1}) pi(a_{t+1} | s_{t+1})``,
emission ``O(o_t | s_t, a_t)`` (1 when step t is occluded). The forward-backward algorithm
computes ``log P(o_1..T)`` and the posterior marginals ``P(s_t, a_t | o)`` exactly in
``O(T (nnz(T) + S A))`` per demonstration, independent of how many steps are occluded. The
pair transition never materializes: the forward message is pushed through ``T`` and then
multiplied by ``pi``. The emissions come from the observation model one block of steps at a
time (:meth:`irl.observation.ObservationModel.log_likelihoods`), so no dense ``O[s, a, o]`` is
needed. The policy and the emissions come in as log-probabilities, so a Boltzmann policy of
any temperature is represented exactly (``log_softmax``, never ``exp`` then ``log``). A
10,000-step demonstration neither underflows nor overflows.

Modules: ``packing`` (demonstrations in padded batches), ``api`` (the entry points, which hand
each batch to a pass), ``scaled`` (the scaled pass, exact to rounding within a float's range,
which it checks), ``blocked`` (the scaled pass by blocks of states), ``logspace`` (the log-space
pass, exact at any range at about three times the cost), ``compiled`` (the numba backend),
``workspace`` (scratch arrays kept between passes).
"""

from irl.inference.api import forward_backward, posterior_stats
from irl.inference.compiled import BACKENDS, check_backend
from irl.inference.packing import (
    ObservationFactors,
    PackedDemonstrations,
    PosteriorStats,
    group_by_length,
    observation_factors,
    pack_demonstrations,
)
from irl.inference.workspace import scratch_held

__all__ = [
    "BACKENDS",
    "ObservationFactors",
    "PackedDemonstrations",
    "PosteriorStats",
    "check_backend",
    "forward_backward",
    "group_by_length",
    "observation_factors",
    "pack_demonstrations",
    "posterior_stats",
    "scratch_held",
]
