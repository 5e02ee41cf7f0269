"""The log-space forward-backward pass: every message kept in log space, exact at any dynamic
range.

Layouts: ``log_pi[s, a]`` or ``log_pi[t, s, a]``, packed observations ``obs[n, t]``, messages
``log_pred[n, s]`` and ``log_beta[n, s, a]``. The messages are pushed through the transition
operator with ``logsumexp`` over its positive entries (:meth:`TabularMDP.log_push_forward`,
:meth:`TabularMDP.log_expect_next`), ``O(T nnz(T))`` exponentials per demonstration, about
three times the cost of the scaled pass (:mod:`irl.inference.scaled`), which hands a batch
over to this one when its messages would leave a float's range. It names the first step at
which a demonstration becomes impossible.
"""

from __future__ import annotations

import numpy as np

from irl.inference.packing import PosteriorStats, _Emissions


def _logsumexp(x: np.ndarray, axis) -> np.ndarray:
    """``log sum exp`` over ``axis``; ``-inf`` where every term is ``-inf`` (no warnings)."""
    top = np.max(x, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        out = np.log(np.sum(np.exp(x - top), axis=axis, keepdims=True)) + top
    return np.squeeze(out, axis=axis)


def _impossible(ids, obs, n: int, t: int) -> ValueError:
    return ValueError(
        f"demos[{ids[n]}], step {t}: observation {int(obs[n, t])} is impossible under the "
        "model given the steps before it (its probability is zero); check the observation "
        "model and the demonstration"
    )


def _log_pass(mdp, log_policy, emissions: _Emissions, obs, lengths, log_p0,
              ids) -> PosteriorStats:
    n_demos, length = obs.shape
    S, A = mdp.n_states, mdp.n_actions
    valid = np.arange(length)[:, None] < lengths[None, :]  # (T, N)

    log_preds = np.empty((length, n_demos, S))
    log_norms = np.empty((length, n_demos))
    lp = np.repeat(log_p0[None, :], n_demos, axis=0)
    for t in range(length):
        la = emissions.log(t)
        la += log_policy if log_policy.ndim == 2 else log_policy[t]
        la += lp[:, :, None]
        lc = _logsumexp(la, axis=(1, 2))
        bad = ~np.isfinite(lc) & valid[t]
        if bad.any():
            raise _impossible(ids, obs, int(np.flatnonzero(bad)[0]), t)
        log_preds[t], log_norms[t] = lp, lc
        if t + 1 < length:
            la -= lc[:, None, None]
            lp = mdp.log_push_forward(la)

    occupancy = np.zeros((n_demos, S, A))
    log_beta = np.zeros((n_demos, S, A))
    for t in range(length - 1, -1, -1):
        ends = lengths - 1 == t
        log_beta[ends] = 0.0
        lg = emissions.log(t)
        lg += log_policy if log_policy.ndim == 2 else log_policy[t]
        lg += log_beta  # log(pi e_t beta_t)
        log_post = lg + (log_preds[t] - log_norms[t][:, None])[:, :, None]
        post = np.exp(log_post)
        post[~valid[t]] = 0.0
        occupancy += post
        if t > 0:
            log_beta = mdp.log_expect_next(_logsumexp(lg, axis=2))
            log_beta -= log_norms[t][:, None, None]
    return PosteriorStats(
        log_likelihood=np.where(valid, log_norms, 0.0).sum(axis=0),
        occupancy=occupancy,
        initial=post.sum(axis=2),
    )
