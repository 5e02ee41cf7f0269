"""Exact inference over the hidden state-action sequence of observed demonstrations.

Layouts: ``pi[s, a]`` or ``pi[t, s, a]``, packed observations ``obs[n, t]`` (-1 = occluded),
emission tables ``E[o, s, a] = O(o | s, a)`` with a last row of ones (for occluded steps),
messages ``alpha[n, s, a]`` over a batch of n demonstrations.

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
        ``E[o, s, a] = O(o | s, a)`` with a last row of ones for occluded steps
        (:attr:`irl.observation.ObservationModel.emissions`).
    initial : ndarray of shape (S,), optional
        Initial state distribution; ``mdp.initial`` by default.
    demo_ids : sequence of int, optional
        Indices of these demonstrations in the caller's list, used in error messages.

    Raises
    ------
    ValueError
        If a demonstration has probability zero under the model; the message names the
        demonstration and the first step at which it becomes impossible.

    Notes
    -----
    The emission table is observation-major, so gathering a step's emissions copies contiguous
    blocks. Only the predicted state marginals ``(T, N, S)`` and the normalizers are stored;
    the forward messages are recomputed during the backward pass.
    """
    obs = np.asarray(obs)
    n_demos, length = obs.shape
    S, A = mdp.n_states, mdp.n_actions
    p0 = mdp.initial if initial is None else initial
    ids = np.arange(n_demos) if demo_ids is None else np.asarray(demo_ids)

    def local(t: int) -> np.ndarray:  # pi(a | s) O(o_t | s, a), shape (N, S, A)
        e = emissions[obs[:, t]]  # contiguous rows: a copy of N blocks
        e *= policy if policy.ndim == 2 else policy[t]
        return e

    preds = np.empty((length, n_demos, S))
    norms = np.empty((length, n_demos))
    pred = np.repeat(p0[None, :], n_demos, axis=0)
    for t in range(length):
        alpha = local(t)
        alpha *= pred[:, :, None]
        c = alpha.sum(axis=(1, 2))
        if not np.all(c > 0.0):
            n = int(np.flatnonzero(~(c > 0.0))[0])
            raise ValueError(
                f"demonstration {ids[n]}, step {t}: observation {int(obs[n, t])} is impossible "
                "under the model given the steps before it (its probability is zero); check "
                "the observation model and the demonstration"
            )
        preds[t], norms[t] = pred, c
        if t + 1 < length:
            alpha /= c[:, None, None]
            pred = mdp.push_forward(alpha)

    # beta_t(s, a) = sum_s' T(s, a, s') sum_a' pi(a'|s') e_{t+1}(s', a') beta_{t+1}(s', a'),
    # divided by c_{t+1} (Rabiner scaling), so that alpha_t * beta_t is the posterior
    # marginal of step t.
    occupancy = np.zeros((n_demos, S, A))
    beta = np.ones((n_demos, S, A))
    for t in range(length - 1, -1, -1):
        gamma_t = local(t)
        gamma_t *= beta
        if t > 0:
            g = gamma_t.sum(axis=2)  # (N, S)
        gamma_t *= (preds[t] / norms[t][:, None])[:, :, None]
        occupancy += gamma_t
        if t > 0:
            beta = np.moveaxis(mdp.expect_next(g.T), 2, 0)
            beta /= norms[t][:, None, None]
    return PosteriorStats(
        log_likelihood=np.log(norms).sum(axis=0),
        occupancy=occupancy,
        initial=gamma_t.sum(axis=2),
    )


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
    emissions = observation_model.emissions
    n = len(demos)
    ll = np.empty(n)
    occ = np.empty((n, mdp.n_states, mdp.n_actions))
    init = np.empty((n, mdp.n_states))
    for length, idx in group_by_length(demos).items():
        packed = pack_observations([demos[i] for i in idx], observation_model.n_observations)
        pol = policy if policies_by_length is None else policies_by_length(length)
        stats = forward_backward(mdp, pol, packed, emissions, demo_ids=idx)
        ll[idx], occ[idx], init[idx] = stats.log_likelihood, stats.occupancy, stats.initial
    return PosteriorStats(log_likelihood=ll, occupancy=occ, initial=init)
