"""Exact inference over the hidden state-action sequence of observed demonstrations.

Layouts: ``pi[s, a]`` or ``pi[t, s, a]``, packed observations ``obs[n, t]`` (-1 = occluded),
``E[o, s, a]`` emission tables (last row all ones, for occluded steps), ``alpha[t, n, s, a]``.

A demonstration is a hidden Markov model over ``x_t = (s_t, a_t)``:
``P(x_1) = p0(s_1) pi(a_1 | s_1)``,
``P(x_{t+1} | x_t) = T(s_t, a_t, s_{t+1}) pi(a_{t+1} | s_{t+1})``,
emission ``O(o_t | s_t, a_t)`` (1 when step t is occluded). The forward-backward algorithm
computes ``log P(o_1..T)`` and the posterior marginals ``P(s_t, a_t | o)`` exactly in
``O(T (nnz(T) + S A))`` per demonstration, independent of how many steps are occluded. The
pair transition never materializes: the forward message is pushed through ``T`` and then
multiplied by ``pi``. Messages are renormalized at every step (Rabiner scaling) and the log
normalizers summed, so 10,000-step demonstrations neither underflow nor overflow.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from irl.demonstrations import Demonstration, pack_observations
from irl.mdp import TabularMDP

__all__ = ["PosteriorStats", "forward_backward", "group_by_length", "posterior_stats"]


@dataclass(frozen=True)
class PosteriorStats:
    """Sufficient statistics of the posterior over hidden pairs, per demonstration.

    Attributes
    ----------
    log_likelihood : ndarray of shape (N,)
        ``log P(o_1..T)`` of each demonstration.
    occupancy : ndarray of shape (N, S, A)
        ``sum_t P(s_t = s, a_t = a | o)``: expected visits of each pair.
    initial : ndarray of shape (N, S)
        ``P(s_1 = s | o)``.
    """

    log_likelihood: np.ndarray
    occupancy: np.ndarray
    initial: np.ndarray


def group_by_length(demos: Sequence[Demonstration]) -> dict[int, np.ndarray]:
    """Indices of the demonstrations of each length, ``{T: indices}``, for batching."""
    groups: dict[int, list[int]] = {}
    for i, d in enumerate(demos):
        groups.setdefault(len(d), []).append(i)
    return {T: np.array(idx) for T, idx in sorted(groups.items())}


def forward_backward(
    mdp: TabularMDP,
    policy: np.ndarray,
    obs: np.ndarray,
    emissions: np.ndarray,
    *,
    initial: np.ndarray | None = None,
    demo_ids: Sequence[int] | None = None,
) -> PosteriorStats:
    """Forward-backward for a batch of equal-length demonstrations.

    Parameters
    ----------
    mdp : TabularMDP
    policy : ndarray of shape (S, A) or (T, S, A)
        ``pi(a | s)``, stationary or per time step.
    obs : ndarray of int, shape (N, T)
        Observation indices; -1 marks an occluded step.
    emissions : ndarray of shape (n_observations + 1, S, A)
        ``E[o, s, a] = O(o | s, a)`` with a last row of ones (see
        :meth:`irl.observation.ObservationModel.emission_table`).
    initial : ndarray of shape (S,), optional
        Initial state distribution; ``mdp.initial`` by default.
    demo_ids : sequence of int, optional
        Indices of these demonstrations in the caller's list, used in error messages.

    Raises
    ------
    ValueError
        If a demonstration has probability zero under the model; the message names the
        demonstration and the first step at which it becomes impossible.
    """
    obs = np.asarray(obs)
    n_demos, length = obs.shape
    p0 = mdp.initial if initial is None else initial
    ids = np.arange(n_demos) if demo_ids is None else np.asarray(demo_ids)

    def local(t: int) -> np.ndarray:
        pi_t = policy if policy.ndim == 2 else policy[t]
        return pi_t[None] * emissions[obs[:, t]]  # (N, S, A)

    alphas = np.empty((length, n_demos, mdp.n_states, mdp.n_actions))
    log_norm = np.zeros(n_demos)
    pred = np.broadcast_to(p0, (n_demos, mdp.n_states))
    for t in range(length):
        a = pred[:, :, None] * local(t)
        c = a.sum(axis=(1, 2))
        if np.any(c <= 0.0):
            n = int(np.flatnonzero(c <= 0.0)[0])
            o = int(obs[n, t])
            raise ValueError(
                f"demonstration {ids[n]}, step {t}: observation {o} is impossible under the "
                "model given the steps before it (its probability is zero); check the "
                "observation model and the demonstration"
            )
        a /= c[:, None, None]
        alphas[t] = a
        log_norm += np.log(c)
        if t + 1 < length:
            pred = mdp.push_forward(a)

    occupancy = alphas[-1].copy()
    beta = np.ones((n_demos, mdp.n_states, mdp.n_actions))
    initial_post = None
    for t in range(length - 2, -1, -1):
        # beta_t(s, a) = sum_s' T(s, a, s') sum_a' pi(a'|s') e_{t+1}(s', a') beta_{t+1}(s', a'),
        # rescaled so that alpha_t * beta_t, the posterior marginal of step t, sums to 1.
        g = (local(t + 1) * beta).sum(axis=2)  # (N, S')
        nxt = mdp.expect_next(g.T)  # (S, A, N)
        beta = np.moveaxis(nxt, 2, 0)
        beta /= (beta * alphas[t]).sum(axis=(1, 2))[:, None, None]
        gamma_t = alphas[t] * beta
        occupancy += gamma_t
        if t == 0:
            initial_post = gamma_t.sum(axis=2)
    if initial_post is None:
        initial_post = alphas[0].sum(axis=2)
    return PosteriorStats(log_likelihood=log_norm, occupancy=occupancy, initial=initial_post)


def posterior_stats(
    mdp: TabularMDP,
    policy: np.ndarray,
    demos: Sequence[Demonstration],
    observation_model,
    *,
    policies_by_length=None,
) -> PosteriorStats:
    """:func:`forward_backward` over demonstrations of any lengths, in length-batches.

    ``policy`` is a stationary ``pi[s, a]``; alternatively ``policies_by_length(T)`` returns
    a ``(T, S, A)`` policy for demonstrations of length T (finite-horizon models).
    """
    table = observation_model.emission_table()
    n = len(demos)
    ll = np.empty(n)
    occ = np.empty((n, mdp.n_states, mdp.n_actions))
    init = np.empty((n, mdp.n_states))
    for length, idx in group_by_length(demos).items():
        packed = pack_observations([demos[i] for i in idx], observation_model.n_observations)
        pol = policy if policies_by_length is None else policies_by_length(length)
        stats = forward_backward(mdp, pol, packed, table, demo_ids=idx)
        ll[idx], occ[idx], init[idx] = stats.log_likelihood, stats.occupancy, stats.initial
    return PosteriorStats(log_likelihood=ll, occupancy=occ, initial=init)
