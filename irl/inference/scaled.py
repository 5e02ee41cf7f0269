"""The scaled forward-backward pass of a batch: messages in probability space, renormalized
(Rabiner scaling), exact to rounding while they stay within a float's range.

Layouts: the batch's messages are held in columns, demonstrations innermost, ``alpha[a, s, n]``
and ``pred[s, n]`` (``preds[t, s, n]`` for every step), so that the two sparse products of a
step read and write their blocks in place and a state array broadcasts over the few actions as
whole ``(S, N)`` slabs; the local factors are ``E[t, a, s, n]``, or a state part ``state[t, s,
n]`` and an action part ``action[t, a, n]`` where the observations factor that way; the
policy is ``pi[a, s]`` or ``pi[t, a, s]``. The results are returned as ``occupancy[n, s, a]``
and ``initial[n, s]``.

A stationary policy is folded into the products (:meth:`TabularMDP.column_products`), so the
local factors are the observations' alone (kept in this layout by the packing for a whole
fit); a time-indexed one is multiplied in, a chunk of steps at once. A step of the forward pass
is then two to four array operations (``alpha = E_t pred_t``, the push through ``T``, and at a
renormalization the sum and the division), a step of the backward pass four (the products add
into zeros set once per pass, and each beta is received where it becomes gamma), and the
posteriors of a whole chunk are formed at once. When the observations are computed chunk by
chunk (too many to keep) and the model's likelihoods are a state part times an action part
(:meth:`~irl.observation.ObservationModel.separable_likelihoods`), ``E`` is never formed:
``alpha_t / pi = (e_t pred_t) e'_t``. Under a stationary policy on a sparse MDP such a pass
then goes by blocks of states (:mod:`irl.inference.blocked`).

Numerics. Each step's observation log-likelihood is shifted by its maximum over pairs before
it is exponentiated (a whole chunk of steps at once), and the local factor is multiplied into
the predicted state distribution. Messages are renormalized and ``shift + log(normalizer)``
summed, as in dynamax's filter, but only every few steps: as often as the smallest local
factor requires for the mass to fall by less than ``e^(-F/4)`` in between. A step's normalizer
may be any positive number, 1 included (the likelihood adds its log and the backward pass
divides by the same one), except at a demonstration's last step, where it must be the sum of
the forward message; where the observations factor into a state part and an action part, it
is the pushed mass, which is that sum (as far as T's rows sum to 1) without a pass over the
message. The pass is exact to rounding as long as every positive shifted local factor and
every positive predicted probability stays above ``e^-F``, about ``e^-340`` (``F`` depends
on the smallest transition probability, :func:`_scaled_floor`), so that no product of them
underflows; it checks that, and says so where it does not hold (large reward weights make the
policy nearly deterministic, so that a message would span more than the range of a float):
then :mod:`irl.inference.logspace` takes the batch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from irl.inference.blocked import _block_push, _block_size, _blocked_backward, _Blocks
from irl.inference.packing import PosteriorStats, _Emissions
from irl.inference.workspace import _Workspace, _workspace
from irl.mdp import TabularMDP
from irl.observation.base import finite_min

#: Steps of local factors (N * steps * S * A floats) exponentiated at once.
_CHUNK_ELEMENTS = 1 << 19
#: Largest separable observation parts (``N T S`` floats) the scaled pass computes once for
#: both of its passes (128 MB); beyond that, chunk by chunk in each.
_SEPARABLE_ELEMENTS = 1 << 24
#: What the scaled pass returns when renormalizing at every step may keep it in range.
_RENORMALIZE = object()


def _scaled_floor(mdp: TabularMDP) -> float:
    """``F``: the scaled pass keeps local factors and predicted probabilities above ``e^-F``.

    Then ``alpha = pred * local >= e^-2F``, and pushed through ``T`` (entries at least
    ``t_min``) with normalizer at most ``S A``, it stays above ``e^-690``: nothing that is
    positive underflows to 0 (a float's smallest normal number is about ``e^-708``).
    """
    return (690.0 + mdp.min_log_transition - math.log(mdp.n_states * mdp.n_actions)) / 2.0


def _chunks(length: int, per_step: int) -> list[tuple[int, int]]:
    size = max(1, _CHUNK_ELEMENTS // max(per_step, 1))
    return [(t0, min(t0 + size, length)) for t0 in range(0, length, size)]


@dataclass(frozen=True, eq=False)
class _Batch:
    """What the scaled pass knows of a batch before it runs: its sizes, ``F``
    (:func:`_scaled_floor`), the policy's smallest finite log-probability and the policy
    action-major, ``pi[a, s]`` or ``pi[t, a, s]`` (stationary: folded into T's pair rows), the
    chunks of steps whose local factors are formed at once, the lengths (ragged: some shorter
    than the batch), and whether the factors come as a state and an action part (separable)."""

    n_demos: int
    length: int
    S: int
    A: int
    F: float
    log_pi_min: float
    pi: np.ndarray
    stationary: bool
    chunks: list[tuple[int, int]]
    lengths: np.ndarray
    ragged: bool
    separable: bool


def _batch(mdp, log_policy, emissions: _Emissions, shape, lengths) -> _Batch | None:
    """The :class:`_Batch` of a pass; None where ``F`` is too small for the scaled pass."""
    n_demos, length = shape
    S, A = mdp.n_states, mdp.n_actions
    F = _scaled_floor(mdp)
    if F < 20.0:
        return None
    chunks = _chunks(length, n_demos * S * A)
    return _Batch(
        n_demos=n_demos, length=length, S=S, A=A, F=F, log_pi_min=finite_min(log_policy),
        pi=np.exp(np.swapaxes(log_policy, -1, -2)),  # [.., a, s]
        stationary=log_policy.ndim == 2, chunks=chunks, lengths=lengths,
        ragged=bool(lengths.min() < length),
        separable=(emissions.factors is None and len(chunks) > 1
                   and emissions.separable(0, 1) is not None))


class _LocalFactors:
    """The local factors of a batch's steps, a chunk at a time, in the pass's layout.

    Called with ``(t0, t1)``, it returns the chunk's factors and the log of their smallest
    positive entry, ``(E[t, a, s, n], shift[n, t], min_log)``, or ``((state[t, s, n],
    action[t, a, n]), shift, min_log)`` when separable (the state part valid until the next
    call); None outside the safe range. ``E`` leaves out the policy where it is folded into T.
    A separable model's parts of every step are formed once for both passes when they fit in
    ``_SEPARABLE_ELEMENTS`` floats.
    """

    def __init__(self, batch: _Batch, emissions: _Emissions, ws: _Workspace) -> None:
        self.batch, self.emissions, self.ws = batch, emissions, ws
        self.whole = (self._separable_parts(0, batch.length, "whole") if batch.separable
                      and batch.n_demos * batch.length * batch.S <= _SEPARABLE_ELEMENTS
                      else None)

    def _separable_parts(self, t0: int, t1: int, name: str):
        """``(state[t, s, n], action[t, a, n], shift[n, t], min_log)`` of steps t0..t1-1; the
        state part formed in the workspace array ``name`` from its two factors where the model
        has them (the products :meth:`~irl.observation.ObservationModel.separable_likelihoods`
        forms, bit for bit, in the pass's layout), else views of the model's."""
        kron = self.emissions.kronecker(t0, t1)
        if kron is None:
            state, action, shift, min_log = self.emissions.separable(t0, t1)
            return np.moveaxis(state, 0, -1), np.moveaxis(action, 0, -1), shift, min_log
        head, tail, action, shift, min_log = kron
        state = self.ws.get(name, (t1 - t0, self.batch.S, self.batch.n_demos))
        np.multiply(np.moveaxis(head, 0, -1)[:, :, None, :],
                    np.moveaxis(tail, 0, -1)[:, None, :, :],
                    out=state.reshape(t1 - t0, head.shape[-1], tail.shape[-1],
                                      self.batch.n_demos))
        return state, np.moveaxis(action, 0, -1), shift, min_log

    def __call__(self, t0: int, t1: int):
        b, emissions = self.batch, self.emissions
        if b.separable:
            if self.whole is not None:
                state, action, shift, min_log = self.whole
                state, action, shift = state[t0:t1], action[t0:t1], shift[:, t0:t1]
            else:
                state, action, shift, min_log = self._separable_parts(t0, t1, "state")
            if not np.all(np.isfinite(shift)) or min_log + b.log_pi_min < -b.F:
                return None
            return (state, action), shift, min_log
        blk = emissions.steps(t0, t1)
        if not blk.possible:
            return None  # a step no pair can emit: the log-space pass names it
        if blk.min_log + b.log_pi_min < -b.F:
            return None
        if b.stationary and emissions.factors is not None:  # kept in columns for every pass
            return emissions.factors.columns[t0:t1], blk.shift, blk.min_log
        E = self.ws.get("E", (t1 - t0, b.A, b.S, b.n_demos))
        if b.stationary:
            np.copyto(E, np.moveaxis(blk.factor, 0, -1))
        else:
            np.multiply(np.moveaxis(blk.factor, 0, -1), b.pi[t0:t1, ..., None], out=E)
        return E, blk.shift, blk.min_log


def _times_local(E, i: int, pi_t: np.ndarray, vec: np.ndarray, out: np.ndarray,
                 u: np.ndarray) -> None:
    """``out[a, s, n] = E_t[a, s, n] vec`` for the step i of a chunk whose separable factors
    are ``E = (state, action)``, under the time-indexed policy ``pi_t[a, s]`` of that step;
    ``vec`` of shape (S, N) or (A, S, N); ``u`` (S, N) is scratch. (Other passes multiply by
    ``E[i]`` or fold the policy into T.)"""
    state, action = E
    policy = pi_t[:, :, None]
    if vec.ndim == 2:  # pi (e_t pred): the state part joins the (S, N) vector
        np.multiply(policy, np.multiply(state[i], vec, out=u), out=out)
    else:  # the state part is applied by the caller, on the (S, N) sum
        np.multiply(vec, policy, out=out)
    out *= action[i][:, None, :]


@dataclass(frozen=True, eq=False)
class _Products:
    """The products of a pass with ``T`` and the forward pass's scratch: ``push`` and
    ``expect`` of :meth:`TabularMDP.column_products` on whole messages (the policy folded in
    where stationary; then ``alpha``'s sum is ``pair_weights @ alpha``, else ones), or of
    :meth:`TabularMDP.state_block_products` where the pass goes by ``blocks`` (then no
    ``alpha``); ``u[s, n]`` holds ``e_t pred_t`` of separable factors."""

    push: object
    expect: object
    blocks: _Blocks | None
    alpha: np.ndarray | None
    pair_weights: np.ndarray | None
    u: np.ndarray | None


def _forward(b: _Batch, local: _LocalFactors, preds, shifts, norms, products: _Products,
             lazy: bool):
    """The forward pass: ``preds[t, s, n]`` (the first set, the others zero where the pushes
    add into them), ``shifts[t, n]`` and ``norms[t, n]`` filled in place. Returns ``(E,
    lazy_used)``, the last chunk's local factors and whether it renormalized less often than
    at every step, or None where a chunk's factors leave the safe range."""
    closing = np.zeros(b.length, dtype=bool)  # the steps at which some demonstration ends
    closing[b.lengths - 1] = True
    norms[...] = 1.0  # a step not renormalized keeps 1
    since = 0  # steps since the last renormalization
    lazy_used = False
    preds_1d = preds.reshape(b.length, b.S * b.n_demos)
    for t0, t1 in b.chunks:
        got = local(t0, t1)
        if got is None:
            return None
        E, shifts[t0:t1] = got[0], got[1].T
        # renormalize every `every` steps: where every pair can emit what is seen, the
        # mass falls by at most e^min_log a step (the policy sums to 1), so by at most
        # e^(-F/4) between renormalizations; the range check covers the rest
        every = max(1, int(b.F / (4.0 * max(-got[2], 1.0)))) if lazy else 1
        lazy_used = lazy_used or every > 1
        steps = _forward_parts if b.separable and b.stationary else _forward_pairs
        since = steps(b, E, t0, t1, preds, preds_1d, norms, closing, products, since, every)
    return E, lazy_used


def _forward_parts(b: _Batch, E, t0, t1, preds, preds_1d, norms, closing, products, since,
                   every) -> int:
    """Steps t0..t1-1 of the forward pass of separable factors ``E = (state, action)`` under
    a stationary policy: ``alpha / pi = e'_t (e_t pred_t)``, pi in the pushes. Returns the
    steps since the last renormalization."""
    u, alpha, pi, length = products.u, products.alpha, b.pi, b.length
    alpha_1d = None if alpha is None else alpha.reshape(-1)
    for t in range(t0, t1):
        state, action = E[0][t - t0], E[1][t - t0]
        np.multiply(state, preds[t], out=u)
        if products.blocks is None:
            np.multiply(action[:, None, :], u, out=alpha)
        since += 1
        if closing[t]:  # the likelihood's own sum: sum_s e_t pred_t (pi' e'_t)
            np.einsum("sn,sn->n", u, pi.T @ action, out=norms[t])
        if t + 1 < length:
            if products.blocks is None:
                products.push(alpha_1d, preds_1d[t + 1])
            else:
                _block_push(products.push, u, action, preds[t + 1], products.blocks)
            if closing[t] or since >= every:
                if not closing[t]:  # the pushed mass: alpha's sum without a pass over alpha
                    # (see the module's numerics)
                    np.add.reduce(preds[t + 1], axis=0, out=norms[t])
                preds[t + 1] /= norms[t]
                since = 0
    return since


def _forward_pairs(b: _Batch, E, t0, t1, preds, preds_1d, norms, closing, products, since,
                   every) -> int:
    """Steps t0..t1-1 of the forward pass on the whole message ``alpha[a, s, n]`` (``alpha /
    pi`` where the policy is folded into the pushes). Returns the steps since the last
    renormalization."""
    alpha, push, pair_weights, length = (products.alpha, products.push,
                                         products.pair_weights, b.length)
    alpha_flat = alpha.reshape(b.A * b.S, b.n_demos)
    alpha_1d = alpha.reshape(-1)
    for t in range(t0, t1):
        if b.separable:
            _times_local(E, t - t0, b.pi[t], preds[t], alpha, products.u)
        else:
            np.multiply(E[t - t0], preds[t], out=alpha)
        since += 1
        if closing[t] or since >= every:
            np.dot(pair_weights, alpha_flat, out=norms[t])
            if t + 1 < length:  # push, then normalize the (S, N) result
                push(alpha_1d, preds_1d[t + 1])
                preds[t + 1] /= norms[t]
            since = 0
        elif t + 1 < length:
            push(alpha_1d, preds_1d[t + 1])
    return since


def _in_range(preds: np.ndarray, norms: np.ndarray, F: float) -> bool:
    """Whether every normalizer is positive and no positive predicted probability fell below
    ``e^-F`` (checked in chunks of steps: no ``(T, S, N)`` temporaries)."""
    if not norms.min() > 0.0:
        return False
    length, S, n_demos = preds.shape
    tiny = np.exp(-F)
    step = max(1, _CHUNK_ELEMENTS // (n_demos * S))
    for t0 in range(0, length, step):
        p = preds[t0:t0 + step]
        if ((p < tiny) & (p > 0.0)).any():
            return False
    return True


def _backward(b: _Batch, local: _LocalFactors, kept, scale, inv_norms, products: _Products,
              ws: _Workspace):
    """The backward pass on whole ``(A, S, N)`` messages: ``(occupancy[a, s, n], initial[n,
    s])``. ``kept``: the local factors of a single chunk, from the forward pass (else formed
    again chunk by chunk); ``scale`` (T, S, N) is ``pred_t / c_t`` (zero at padded steps).

    At step t, gamma is ``pi e_t beta_t``; ``g_t = sends_t sum_a gamma`` goes back to step t -
    1 through the expectation over the next state, and gamma times the state weights ``scale_t``
    (times the state part ``e_t`` where separable) is the posterior of step t.
    """
    S, A, n_demos = b.S, b.A, b.n_demos
    occupancy = np.zeros((A, S, n_demos))
    restart = b.pi[:, :, None] if b.stationary else 1.0  # pi beta when pi is folded into T
    beta = ws.get("beta", (A, S, n_demos))
    beta[...] = restart
    g = ws.get("g", (S, n_demos))
    for t0, t1 in reversed(b.chunks):
        E = kept if kept is not None else local(t0, t1)[0]
        # unreachable states send nothing back (scale_t > 0 iff pred_t > 0 at a real
        # step; padded steps are zeroed and send nothing either)
        sends = ws.get("sends", (t1 - t0, S, n_demos))
        np.multiply(scale[t0:t1] > 0.0, inv_norms[t0:t1, None, :], out=sends)
        weights = scale[t0:t1]  # (L, S, N): the posterior is gamma times this
        if b.separable:
            sends *= E[0]
            weights = weights * E[0]
        gamma = ws.get("gamma", (t1 - t0, A, S, n_demos))  # pi e_t beta_t of the chunk
        _backward_steps(b, E, t0, t1, gamma, beta, g, sends, restart, products)
        gamma *= weights[:, None]
        occupancy += gamma[0] if t1 - t0 == 1 else np.add.reduce(gamma, axis=0)
    initial = np.ascontiguousarray(gamma[0].sum(axis=0).T)
    return occupancy, initial


def _backward_steps(b: _Batch, E, t0, t1, gamma, beta, g, sends, restart,
                    products: _Products) -> None:
    """Steps t1-1 down to t0 of the backward pass: ``gamma[t - t0] = pi e_t beta_t``, and
    ``beta`` (or, in a single chunk, the gamma of the step before, where it becomes gamma in
    place) receives the expectation of ``g_t``. ``beta_t`` restarts at ``restart`` at each
    demonstration's last step."""
    single = len(b.chunks) == 1
    gamma_1d = gamma.reshape(t1 - t0, -1)
    beta_1d, g_1d = beta.reshape(-1), g.reshape(-1)
    last = b.lengths - 1
    if single:  # every beta is received in gamma, where it becomes gamma in place
        gamma[:-1] = 0.0
        gamma[-1] = restart
    for t in range(t1 - 1, t0 - 1, -1):
        gamma_t = gamma[t - t0]
        beta_t = gamma_t if single else beta
        if b.ragged:
            ends = last == t
            if ends.any():
                beta_t[:, :, ends] = restart
        if b.separable and b.stationary:
            np.multiply(beta_t, E[1][t - t0][:, None, :], out=gamma_t)
        elif b.separable:
            _times_local(E, t - t0, b.pi[t], beta_t, gamma_t, products.u)
        else:
            np.multiply(E[t - t0], beta_t, out=gamma_t)
        if t > 0:
            np.add.reduce(gamma_t, axis=0, out=g)
            g *= sends[t - t0]
            if single:
                products.expect(g_1d, gamma_1d[t - 1])
            else:
                beta.fill(0.0)
                products.expect(g_1d, beta_1d)


def _finish(occupancy, initial, shifts, norms, valid) -> PosteriorStats | None:
    """:class:`PosteriorStats` of the scaled pass from ``occupancy[n, s, a]`` and
    ``initial[n, s]`` (views), its shifts and normalizers ``(T, N)`` and the mask of real steps
    ``valid[t, n]`` (None: every step is real); None where they are not finite."""
    if not np.isfinite(occupancy.sum() + initial.sum()):  # (each entry is at most T)
        return None
    per_step = shifts + np.log(norms)
    if valid is not None:
        per_step = np.where(valid, per_step, 0.0)
    return PosteriorStats(log_likelihood=per_step.sum(axis=0),
                          occupancy=np.ascontiguousarray(occupancy),
                          initial=np.ascontiguousarray(initial))


def _scaled_forward_backward(mdp, log_policy, emissions: _Emissions, shape, lengths, log_p0,
                             lazy: bool = True):
    """The scaled pass of a batch (see the module): :class:`PosteriorStats`; ``None`` when a
    message would leave its safe range, and ``_RENORMALIZE`` when it left it renormalizing
    every few steps (``lazy``), which fewer mass lost between renormalizations may avoid.

    ``shape`` is ``(N, T)``; a separable model under a stationary policy on a sparse MDP goes
    by blocks of states (:mod:`irl.inference.blocked`), anything else on whole messages.
    """
    b = _batch(mdp, log_policy, emissions, shape, lengths)
    if b is None:
        return None
    S, A, n_demos, length = b.S, b.A, b.n_demos, b.length
    ws = _workspace
    u = ws.get("u", (S, n_demos)) if b.separable else None
    local = _LocalFactors(b, emissions, ws)
    # a separable model under a stationary policy goes by blocks of states; None where the
    # MDP's products are dense
    block = _block_size(S, A, n_demos)
    blocked = (mdp.state_block_products(block, n_demos, np.exp(log_policy).ravel())
               if b.separable and b.stationary else None)
    preds = ws.get("preds", (length, S, n_demos))
    shifts = ws.get("shifts", (length, n_demos))
    norms = ws.get("norms", (length, n_demos))
    preds[0] = np.exp(log_p0)[:, None]
    if blocked is None:
        preds[1:] = 0.0  # the pushes add into it (the blocks write theirs)
        pair_weights = b.pi.ravel() if b.stationary else np.ones(A * S)
        products = _Products(*mdp.column_products(n_demos, pair_weights if b.stationary
                                                  else None),
                             blocks=None, alpha=ws.get("alpha", (A, S, n_demos)),
                             pair_weights=pair_weights, u=u)
    else:
        products = _Products(*blocked, blocks=_Blocks(S, A, n_demos, block, ws), alpha=None,
                             pair_weights=None, u=u)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        forward = _forward(b, local, preds, shifts, norms, products, lazy)
        if forward is None:
            return None
        E, lazy_used = forward
        # out of range: with fewer renormalizations than steps, the caller tries again
        # renormalizing at every step; else the log-space pass takes over (and names an
        # impossible demonstration)
        if not _in_range(preds, norms, b.F):
            return _RENORMALIZE if lazy_used else None
        kept = E if len(b.chunks) == 1 else None  # the backward pass reuses it

        # beta_t(s, a) = sum_s' T(s, a, s') sum_a' pi(a'|s') e_{t+1}(s', a') beta_{t+1}(s', a'),
        # divided by c_{t+1} (Rabiner scaling), so that alpha_t * beta_t is the posterior
        # marginal of step t. The local factors carry the forward pass's shifts, so alpha_t
        # and beta_t are scaled consistently. A state the forward pass cannot reach at step t
        # gets g = 0: no pair with forward mass leads there, and so every beta stays below
        # about e^F. Padded steps (t >= lengths[n]) add nothing, and beta restarts at 1 at
        # each last step.
        inv_norms = np.divide(1.0, norms, out=ws.get("inv_norms", norms.shape))
        scale = preds  # becomes pred_t / c_t in place (T, S, N): no second copy
        scale *= inv_norms[:, None, :]
        valid = None
        if b.ragged:
            valid = np.arange(length)[:, None] < lengths[None, :]  # (T, N)
            scale *= valid[:, None, :]
        if blocked is not None:
            occupancy, initial = _blocked_backward(
                products.expect, b.chunks, kept, local, scale, inv_norms,
                lengths if b.ragged else None, b.pi, products.blocks, ws)
            return _finish(occupancy, initial, shifts, norms, valid)
        occupancy, initial = _backward(b, local, kept, scale, inv_norms, products, ws)
    return _finish(occupancy.transpose(2, 1, 0), initial, shifts, norms, valid)
