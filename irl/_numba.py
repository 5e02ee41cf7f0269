"""An optional compiled kernel for the scaled forward-backward pass (needs ``numba``).

:mod:`irl` imports without numba: this module imports it only when the kernel is first called
(and compiles the kernel then, or loads it from numba's cache), and :func:`available` says
whether it can be. The kernel computes what :func:`irl.inference.scaled._scaled_forward_backward`
computes for a stationary policy and one batch, the same products in the same order up to the
order of a few sums, so the results agree to rounding (about 1e-15 relative). It runs one
demonstration at a time, single-threaded, each step in one or two sweeps over the transition
operator, where the numpy pass makes a dozen array operations on the whole batch per step.

Layouts (action-major, as in :mod:`irl.inference.scaled`; ``r = a * S + s`` indexes a pair):

- the transition operator as CSR arrays ``indptr, indices, data``: row ``r = a * S + s``,
  column ``s'``, value ``T[s, a, s']`` (:func:`operator_arrays` of ``mdp._action_major``);
- ``pi[a, s]`` (A, S): ``exp(log_policy).T``;
- ``factor[n, t, a, s]`` (N, T, A, S) and ``shift[n, t]`` (N, T): the shifted observation
  likelihoods of :func:`irl.inference.observation_factors` (ones and 0 at occluded and padded
  steps); or, for a model whose likelihoods factor into a state and an action part
  (:func:`scaled_forward_backward_separable`), ``state[n, t, s]`` (N, T, S) and ``action[n,
  t, a]`` (N, T, A) with ``factor[n, t, a, s] = action[n, t, a] * state[n, t, s]``, as
  :meth:`irl.observation.ObservationModel.separable_likelihoods` returns them; the kernel
  forms each step's row of that product in place when it visits the step (once forward, once
  backward), so the full factor is never held;
- ``lengths[n]``: each demonstration's number of real steps (``<= T``);
- ``p0[s]``: the initial distribution, ``exp(log_p0)`` as the numpy pass takes it.

Algorithm, per demonstration n of length L, with ``E_t[r] = factor[n, t, r] pi[r]``.

Forward (Rabiner scaling): ``pred_0 = p0``; at step t one sweep over the rows forms
``alpha_t[r] = E_t[r] pred_t[s]`` and notes the rows where it is positive; its sum is the
normalizer ``c_t`` (``log P(o) = sum_t shift[n, t] + log c_t``); then ``pred_{t+1}[s'] =
sum_r alpha_t[r] T[r, s'] / c_t``: scattered along the rows of ``T`` from the positive rows
when they are few (an informative observation), gathered along the columns of ``T`` (its
transpose, built once per call) otherwise; both add each column's terms in ascending r.

Backward: ``beta_{L-1} = 1``; at step t, from the last, one sweep over the rows gathers
``beta_t[r] = sum_s' T[r, s'] g_{t+1}[s']`` along row r, forms ``gamma_t[r] = E_t[r]
beta_t[r]``, adds ``gamma_t[r] pred_t[s] / c_t`` (the posterior ``P(s_t, a_t | o)``) to the
occupancy, or at t = 0 also to the initial posterior, and ``gamma_t[r]`` to ``g_t[s]``, which
is then multiplied by ``1 / c_t``. A row with ``E_t[r] = 0`` or ``pred_t[s] = 0`` is skipped:
its posterior and its share of ``g`` are exactly 0 in the numpy pass too (``beta`` is finite,
since every ``g`` is checked finite and the rows of ``T`` sum to 1).

Storage besides the inputs and outputs: ``pred_t`` (L, S), the normalizers, and a few
vectors of S A.

Range checks, as in the numpy pass (see :mod:`irl.inference.scaled`): ``ok`` is False when some
``c_t`` is not positive and finite (an observation impossible given the steps before it, or
one that no pair emits: its factor is undefined), when a positive ``pred_t`` (``p0``
included) is below ``e^-F``, or when a ``g``, the occupancy or the initial posterior is not
finite (a ``g`` that overflows makes the numpy pass's occupancy infinite or NaN). The caller
checks the rest before calling: ``F >= 20`` and ``min_log + log_pi_min >= -F``. One
difference: padded steps are not run at all, whereas the numpy pass runs its forward recursion
through them, so a range failure confined to padding (which cannot affect the result) makes it
fall back where this kernel does not.

Speed (one core, against the numpy pass given the same factors): about 3x on the sorting
domain (12 demonstrations x 20 steps, 0.1 ms a call); on a 10,000-state grid (10 x 100 steps)
about 3x with an informative sensor, where most rows of an observed step are skipped (as fast
as the bare sparse products of the numpy pass), and 1.0-1.3x when every pair stays possible at
every step, where one demonstration at a time re-reads ``T`` for each. Given the separable
parts instead of the full factor, each entry ``action[a] * state[s]`` is formed where it is
used (no ``A S`` row is written and read back), and a Kronecker state part ``head x tail`` is
formed once a step (``S`` floats): at 10,000 and 102,400 states with a factored sensor, 4-8%
less CPU time than forming each step's row (bench/bench_irl.py's grid, 10 x 100 steps).
"""

from __future__ import annotations

from functools import cache

import numpy as np
import scipy.sparse as sp

__all__ = ["available", "operator_arrays", "scaled_forward_backward",
           "scaled_forward_backward_kronecker", "scaled_forward_backward_separable"]


@cache
def available() -> bool:
    """Whether numba can be imported (the kernel can run)."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def operator_arrays(action_major) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, indices, data)`` of the action-major operator ``P[a * S + s, s']`` (a dense
    array or a ``scipy.sparse`` matrix, e.g. ``mdp._action_major``), zeros dropped."""
    csr = sp.csr_matrix(action_major, dtype=float)
    csr.eliminate_zeros()
    return csr.indptr, csr.indices, csr.data


#: The forward pass scatters the rows with mass along ``T`` when they are at most this fraction
#: of all rows, and otherwise gathers every state's predicted mass along the columns of ``T``
#: (a scatter over all rows is bound by the latency of its read-modify-writes; measured flat
#: between 1/16 and 1/2 on the sorting and 10,000-state grid benchmarks).
_SCATTER_FRACTION = 1 / 8


@cache
def _kernel():
    """The compiled kernel (numba imported, and the function compiled or loaded from numba's
    cache, at the first call).

    One function with no calls to other compiled functions (a closure over other dispatchers
    misses numba's cache in every new process). It takes either ``factor`` or ``state`` and
    ``action``, the others None: numba prunes the branches on an argument that is None before
    it types the function, so each entry point gets its own specialization (both kept in the
    on-disk cache), and the full factor's runs the loops it ran before the separable one was
    added, as fast (a runtime flag that picked the row's source cost it 3%). Indices are
    unsigned (``u``) in every hot
    loop: numba wraps a signed index that could be negative, which costs more than the
    arithmetic in these loops (a gather along the rows of ``T`` takes 2.3x as long).
    """
    import numba

    u = numba.uint64

    @numba.njit(cache=True, nogil=True)
    def kernel(indptr, indices, data, pi, factor, state, head, tail, action, shift, lengths,
               p0, tiny, scatter_rows):
        n_demos, length = shift.shape
        n_actions, n_states = u(pi.shape[0]), u(pi.shape[1])
        n_rows = n_actions * n_states
        one = u(1)
        log_likelihood = np.zeros(n_demos)
        occupancy = np.zeros((n_demos, n_states, n_actions))
        initial = np.zeros((n_demos, n_states))
        fail = (False, log_likelihood, occupancy, initial)
        # the transpose of T as CSR (columns of T, rows ascending in each), for the gathers
        nnz = u(len(indices))
        col_ptr = np.zeros(n_states + one, dtype=np.uint64)
        for k in range(nnz):
            col_ptr[indices[k] + one] += one
        for s in range(n_states):
            col_ptr[s + one] += col_ptr[s]
        fill = col_ptr[:-1].copy()
        col_rows = np.empty(nnz, dtype=np.uint64)
        col_vals = np.empty(nnz)
        for r in range(n_rows):
            for k in range(indptr[r], indptr[r + one]):
                j = indices[k]
                col_rows[fill[j]] = r
                col_vals[fill[j]] = data[k]
                fill[j] += one
        local = pi.ravel()  # pi[r], r = a * S + s
        st_buf = np.empty(n_states)  # head x tail: one step's state part
        st = f = st_buf  # defined in every specialization (numba types them all)
        ac = np.empty(n_actions)
        wa = 0.0
        alpha = np.empty(n_rows)
        occ = np.empty(n_rows)  # one demonstration's occupancy, action-major
        live = np.empty(n_rows, dtype=np.uint64)
        preds = np.empty((length, n_states))
        norms = np.empty(length)
        g = np.empty(n_states)
        g_next = np.empty(n_states)
        for s in range(n_states):
            if 0.0 < p0[s] < tiny:
                return fail
        for n in range(n_demos):
            last = lengths[n] - 1
            preds[0] = p0
            log_p = 0.0
            # forward: alpha_t = factor pi pred_t, pushed through T
            for t in range(last + 1):
                pred = preds[t]
                if state is not None:  # factor[n, t, r] is ac[a] * st[s], formed as used
                    st, ac = state[n, t], action[n, t]
                elif head is not None:  # the same, its state part head x tail formed here
                    hd, tl, ac = head[n, t], tail[n, t], action[n, t]
                    n_tail = u(tl.shape[0])
                    for i in range(u(hd.shape[0])):
                        h, off = hd[i], i * n_tail
                        for j in range(n_tail):
                            st_buf[off + j] = h * tl[j]
                    st = st_buf
                if factor is not None:
                    f = factor[n, t].ravel()
                n_live = u(0)
                c = 0.0
                for a in range(n_actions):
                    base = a * n_states
                    if factor is None:
                        wa = ac[a]
                    for s in range(n_states):
                        r = base + s
                        fr = f[r] if factor is not None else wa * st[s]
                        w = fr * local[r] * pred[s]
                        alpha[r] = w
                        c += w
                        if w != 0.0:
                            live[n_live] = r
                            n_live += one
                if not (0.0 < c < np.inf):
                    return fail
                norms[t] = c
                log_p += shift[n, t] + np.log(c)
                if t == last:
                    break
                nxt = preds[t + 1]
                if n_live <= scatter_rows:  # few rows carry mass: scatter them
                    nxt[:] = 0.0
                    for q in range(n_live):
                        r = live[q]
                        w = alpha[r]
                        for k in range(indptr[r], indptr[r + one]):
                            nxt[indices[k]] += w * data[k]
                    for s in range(n_states):
                        nxt[s] /= c
                else:  # gather along the columns, rows ascending: the same sums
                    for s in range(n_states):
                        acc = 0.0
                        for k in range(col_ptr[s], col_ptr[s + one]):
                            acc += alpha[col_rows[k]] * col_vals[k]
                        nxt[s] = acc / c
                for s in range(n_states):
                    if 0.0 < nxt[s] < tiny:
                        return fail
            log_likelihood[n] = log_p
            # backward: beta_t gathered from g_{t+1} along each live row as it is used
            occ[:] = 0.0
            for t in range(last, -1, -1):
                pred = preds[t]
                if state is not None:  # factor[n, t, r] is ac[a] * st[s], formed as used
                    st, ac = state[n, t], action[n, t]
                elif head is not None:  # the same, its state part head x tail formed here
                    hd, tl, ac = head[n, t], tail[n, t], action[n, t]
                    n_tail = u(tl.shape[0])
                    for i in range(u(hd.shape[0])):
                        h, off = hd[i], i * n_tail
                        for j in range(n_tail):
                            st_buf[off + j] = h * tl[j]
                    st = st_buf
                if factor is not None:
                    f = factor[n, t].ravel()
                inv_c = 1.0 / norms[t]
                if t > 0:
                    g[:] = 0.0
                for a in range(n_actions):
                    base = a * n_states
                    if factor is None:
                        wa = ac[a]
                    for s in range(n_states):
                        p = pred[s]
                        if p == 0.0:
                            continue
                        r = base + s
                        fr = f[r] if factor is not None else wa * st[s]
                        e = fr * local[r]
                        if e == 0.0:
                            continue
                        if t == last:
                            beta = 1.0
                        else:
                            beta = 0.0
                            for k in range(indptr[r], indptr[r + one]):
                                beta += data[k] * g_next[indices[k]]
                        gamma = e * beta
                        post = gamma * (p * inv_c)
                        occ[r] += post
                        if t > 0:
                            g[s] += gamma
                        else:
                            initial[n, s] += post
                if t > 0:
                    for s in range(n_states):
                        v = g[s] * inv_c
                        if not np.isfinite(v):
                            return fail
                        g[s] = v
                    g, g_next = g_next, g
            for a in range(n_actions):
                base = a * n_states
                for s in range(n_states):
                    occupancy[n, s, a] = occ[base + s]
        for n in range(n_demos):
            for s in range(n_states):
                if not np.isfinite(initial[n, s]):
                    return fail
                for a in range(n_actions):
                    if not np.isfinite(occupancy[n, s, a]):
                        return fail
        return True, log_likelihood, occupancy, initial

    return kernel


def scaled_forward_backward(indptr, indices, data, pi, factor, shift, lengths, p0, floor):
    """The scaled forward-backward pass of one batch, compiled (see the module docstring).

    Parameters
    ----------
    indptr, indices, data : ndarray
        The CSR arrays of ``P[a * S + s, s'] = T[s, a, s']`` (:func:`operator_arrays`).
    pi : ndarray of shape (A, S)
        ``pi[a, s] = exp(log_policy[s, a])``, a stationary policy.
    factor : ndarray of shape (N, T, A, S)
        Shifted observation likelihoods, at most 1 (ones at occluded and padded steps).
    shift : ndarray of shape (N, T)
    lengths : ndarray of int, shape (N,)
        Real steps of each demonstration, in ``[1, T]``; the steps after are ignored.
    p0 : ndarray of shape (S,)
        Initial state distribution.
    floor : float
        ``F`` (:func:`irl.inference.scaled._scaled_floor`): positive predicted probabilities
        must stay above ``e^-F``.

    Returns
    -------
    ok : bool
        False when the numpy pass would return None (then the arrays are meaningless, and the
        caller falls back to the numpy or log-space pass).
    log_likelihood : ndarray of shape (N,)
    occupancy : ndarray of shape (N, S, A)
        C-contiguous, as :attr:`irl.inference.PosteriorStats.occupancy`.
    initial : ndarray of shape (N, S)

    Raises
    ------
    ImportError
        If numba is not installed (see :func:`available`).
    ValueError
        If the shapes or the operator's indices do not fit together (the compiled kernel
        does not check its indices).
    """
    pi = np.ascontiguousarray(pi, dtype=np.float64)
    factor = np.ascontiguousarray(factor, dtype=np.float64)
    if factor.ndim != 4 or pi.shape != factor.shape[2:]:
        raise ValueError(f"factor must have shape (N, T, A, S) with (A, S) = pi.shape "
                         f"{pi.shape}; got {factor.shape}")
    return _run(indptr, indices, data, pi, factor, None, None, None, None, shift, lengths, p0,
                floor, factor.shape[:2])


def scaled_forward_backward_separable(indptr, indices, data, pi, state, action, shift, lengths,
                                      p0, floor):
    """:func:`scaled_forward_backward` for ``factor[n, t, a, s] = action[n, t, a] * state[n,
    t, s]``, never formed: each step's ``A S`` row of it is formed in place when the step is
    visited (once forward, once backward), the product numpy forms, so that the results are
    those of :func:`scaled_forward_backward` given ``action[..., :, None] * state[..., None,
    :]``, bit for bit, and ``ok`` is False in the same cases.

    ``state`` (N, T, S), ``action`` (N, T, A) and ``shift`` (N, T) are what
    :meth:`irl.observation.ObservationModel.separable_likelihoods` returns for ``obs`` of
    shape (N, T) (the caller checks its ``min_log`` as for the full factor); the other
    parameters, the returns and the errors are those of :func:`scaled_forward_backward`.
    Memory: the inputs, the outputs, and the kernel's ``T x S`` predictions and few vectors of
    ``S A``. The inputs hold ``N T S`` floats (800 MB at N = 10, T = 100, S = 100,000); one
    demonstration per call keeps them to ``T (S + A)``, at a cost per call (the transpose of
    ``T`` and fresh work arrays: about 35 ms at S = 100,000, half as much again as the whole
    batch in one call).
    """
    pi = np.ascontiguousarray(pi, dtype=np.float64)
    state = np.ascontiguousarray(state, dtype=np.float64)
    action = np.ascontiguousarray(action, dtype=np.float64)
    if state.ndim != 3 or action.ndim != 3 or state.shape[:2] != action.shape[:2] \
            or (action.shape[2], state.shape[2]) != pi.shape:
        raise ValueError(f"state and action must have shapes (N, T, S) and (N, T, A) with "
                         f"(A, S) = pi.shape {pi.shape}; got {state.shape} and {action.shape}")
    return _run(indptr, indices, data, pi, None, state, None, None, action, shift, lengths, p0,
                floor, state.shape[:2])


def scaled_forward_backward_kronecker(indptr, indices, data, pi, head, tail, action, shift,
                                      lengths, p0, floor):
    """:func:`scaled_forward_backward_separable` for ``state[n, t, i * n_tail + j] = head[n,
    t, i] * tail[n, t, j]``, never formed either, as
    :meth:`irl.observation.ObservationModel.kronecker_likelihoods` returns the parts (the
    results are those of the separable kernel given that product, bit for bit). The inputs
    hold ``N T (S / n_tail + n_tail + A)`` floats: at S = 102,400 on a 320 x 320 grid, 5 MB for
    10 demonstrations of 100 steps where the state parts are 820 MB, whose first touch cost as
    much as the kernel's sweeps.
    """
    pi = np.ascontiguousarray(pi, dtype=np.float64)
    head = np.ascontiguousarray(head, dtype=np.float64)
    tail = np.ascontiguousarray(tail, dtype=np.float64)
    action = np.ascontiguousarray(action, dtype=np.float64)
    if head.ndim != 3 or tail.ndim != 3 or action.ndim != 3 \
            or not head.shape[:2] == tail.shape[:2] == action.shape[:2] \
            or (action.shape[2], head.shape[2] * tail.shape[2]) != pi.shape:
        raise ValueError(f"head, tail and action must have shapes (N, T, S / n), (N, T, n) and "
                         f"(N, T, A) with (A, S) = pi.shape {pi.shape}; got {head.shape}, "
                         f"{tail.shape} and {action.shape}")
    return _run(indptr, indices, data, pi, None, None, head, tail, action, shift, lengths, p0,
                floor, head.shape[:2])


def _run(indptr, indices, data, pi, factor, state, head, tail, action, shift, lengths, p0,
         floor, batch):
    """Checks the arguments both entry points share, then runs the kernel (``batch``: (N, T),
    ``pi`` already checked)."""
    shift = np.ascontiguousarray(shift, dtype=np.float64)
    p0 = np.ascontiguousarray(p0, dtype=np.float64)
    lengths = np.ascontiguousarray(lengths, dtype=np.int64)
    indptr = np.ascontiguousarray(indptr, dtype=np.int64)
    indices = np.ascontiguousarray(indices, dtype=np.int64)  # checked, then made unsigned
    data = np.ascontiguousarray(data, dtype=np.float64)
    n_demos, length = batch
    n_actions, n_states = pi.shape
    if shift.shape != (n_demos, length) or p0.shape != (n_states,):
        raise ValueError(f"shift must have shape {(n_demos, length)} and p0 {(n_states,)}; "
                         f"got {shift.shape} and {p0.shape}")
    if lengths.shape != (n_demos,) or (n_demos and not (
            lengths.min() >= 1 and lengths.max() <= length)):
        raise ValueError(f"lengths must hold {n_demos} lengths in [1, {length}]; got {lengths}")
    if indptr.shape != (n_actions * n_states + 1,) or indptr[0] != 0 \
            or indptr[-1] != len(indices) or len(indices) != len(data) \
            or np.any(np.diff(indptr) < 0) \
            or (len(indices) and not (indices.min() >= 0 and indices.max() < n_states)):
        raise ValueError(f"indptr, indices, data must be the CSR arrays of an "
                         f"({n_actions * n_states}, {n_states}) matrix; got lengths "
                         f"{len(indptr)}, {len(indices)}, {len(data)}")
    scatter_rows = int(_SCATTER_FRACTION * n_actions * n_states)
    ok, ll, occ, init = _kernel()(indptr.astype(np.uint64), indices.astype(np.uint64), data, pi,
                                  factor, state, head, tail, action, shift, lengths, p0,
                                  float(np.exp(-floor)), np.uint64(scatter_rows))
    return bool(ok), ll, occ, init
