"""The scaled pass by blocks of states: the push of the forward pass and the whole backward
pass of a separable observation model under a stationary policy on a sparse MDP.

Layouts: a block's pairs ``[a, s, n]`` over the block's states alone, the predicted marginals
``scale[t, s, n]``, the results ``occupancy[n, s, a]`` and ``initial[n, s]``. A block's
products (:meth:`TabularMDP.state_block_products`), its action part and its sum over the
actions are done while its ``(A, block, N)`` pairs are in the cache, so that no ``(A, S, N)``
message goes through memory, which at 100,000 states (33 MB for 10 demonstrations) it would at
every step, several times.
"""

from __future__ import annotations

import numpy as np

from irl.inference.workspace import _Workspace

#: Floats of one block of states (``block A N``) that the scaled pass computes at once
#: where it goes by blocks (a separable model, a stationary policy, a sparse MDP; 1 MB, a
#: core's L2 cache on the machine of docs/performance.md): the step's ``(A, S, N)`` message
#: then stays in the cache at any S.
_BLOCK_ELEMENTS = 1 << 17


def _block_size(S: int, A: int, n_demos: int) -> int:
    """States per block: as many as ``_BLOCK_ELEMENTS`` floats of pairs hold, 1 to S."""
    return min(S, max(1, _BLOCK_ELEMENTS // (A * n_demos)))


class _Blocks:
    """The blocks of states of a blocked pass and the views of its scratch that each block
    reads and writes, made once per pass (the loops then make few Python objects per block).

    Attributes
    ----------
    spans : list of (int, int)
        Each block's states ``s0..s1-1``.
    pairs : list of ndarray
        Each block's pairs, flat (``A m N``, one scratch array for all).
    cubes : list of ndarray
        The same as ``(A, m, N)``.
    act : ndarray of shape (A, block, N)
        A step's action part, repeated over a block's states.
    acts : list of ndarray
        Its ``(A, m, N)`` view for each block.
    """

    def __init__(self, S: int, A: int, n_demos: int, block: int, ws: _Workspace) -> None:
        buf = ws.get("block", (A * block * n_demos,))
        self.act = ws.get("act", (A, block, n_demos))
        self.spans = [(s0, min(s0 + block, S)) for s0 in range(0, S, block)]
        self.pairs = [buf[:A * (s1 - s0) * n_demos] for s0, s1 in self.spans]
        self.cubes = [p.reshape(A, -1, n_demos) for p in self.pairs]
        self.acts = [self.act[:, :s1 - s0] for s0, s1 in self.spans]

    def rows(self, array: np.ndarray, axis: int = 0) -> list[np.ndarray]:
        """The view of each block's states in ``array``, whose axis ``axis`` is the state."""
        lead = (slice(None),) * axis
        return [array[(*lead, slice(s0, s1))] for s0, s1 in self.spans]


def _block_push(push, u, action, out, blocks: _Blocks) -> None:
    """``out[s', n] = sum_{s, a} T[s, a, s'] pi(a | s) u[s, n] e'[a, n]``: the forward
    pass's push of ``alpha = u e'`` (``u = e_t pred_t`` (S, N), ``e'`` the action part (A, N)),
    block by block of next states (:meth:`TabularMDP.state_block_products`), so that alpha is
    never formed whole."""
    np.copyto(blocks.act, action[:, None, :])  # then the block's products run over whole slabs
    u_1d = u.reshape(-1)
    for k, (s0, s1) in enumerate(blocks.spans):
        flat, b = blocks.pairs[k], blocks.cubes[k]
        flat.fill(0.0)
        push(k, u_1d, flat)
        b *= blocks.acts[k]
        np.add.reduce(b, axis=0, out=out[s0:s1])


def _blocked_backward(expect, chunks, kept, local, scale, inv_norms, lengths, pi,
                      blocks: _Blocks, ws):
    """The backward pass of a separable model under a stationary policy, block by block of
    states (:meth:`TabularMDP.state_block_products`): ``(occupancy[n, s, a], initial[n, s])``,
    C-contiguous.

    At step t, a block's ``pi beta_t[a, s, n]`` (``pi[a, s]`` at a demonstration's last step,
    else ``pi`` times the expectation of ``g_{t+1}``) is multiplied by the action part
    ``e'_t[a, n]`` into gamma; ``g_t = sends_t sum_a gamma`` goes back to step t - 1, and
    gamma times the state weights ``scale_t e_t`` is the block's posterior. At step 0 a
    block's occupancy is complete, and is written to the ``[n, s, a]`` result while it is in
    the cache (a transposed copy of the whole ``(A, S, N)`` array afterwards reads it from
    memory once per demonstration at large S). ``scale`` (T, S, N)
    is ``pred_t / c_t`` (zero at padded steps), ``lengths`` None when every demonstration is as
    long as the batch; ``ws`` is the thread's :class:`_Workspace`.
    """
    length, S, n_demos = scale.shape
    A = pi.shape[0]
    occupancy = ws.get("occupancy", (A, S, n_demos))
    occupancy.fill(0.0)
    result = np.empty((n_demos, S, A))
    initial = np.empty((n_demos, S))
    g_next, g_cur = ws.get("g", (S, n_demos)), ws.get("g2", (S, n_demos))
    restarts = blocks.rows(pi[:, :, None], axis=1)
    occupancies = blocks.rows(occupancy, axis=1)
    results = [r.transpose(2, 1, 0) for r in blocks.rows(result, axis=1)]  # [a, s, n] views
    initials = [r.T for r in blocks.rows(initial, axis=1)]
    g_rows = {id(g): blocks.rows(g) for g in (g_next, g_cur)}
    # a block's sends and state weights, formed in the block's loop (in the cache)
    block = blocks.act.shape[1]
    sends_buf, weights_buf = (ws.get(name, (block, n_demos)) for name in ("sends", "weights"))
    sends, weights = ([buf[:s1 - s0] for s0, s1 in blocks.spans]
                      for buf in (sends_buf, weights_buf))
    for t0, t1 in reversed(chunks):
        state, action = kept if kept is not None else local(t0, t1)[0]
        for t in range(t1 - 1, t0 - 1, -1):
            i = t - t0
            ends = None if lengths is None else np.flatnonzero(lengths - 1 == t)
            if ends is not None and not ends.size:
                ends = None
            np.copyto(blocks.act, action[i][:, None, :])
            g_1d = g_next.reshape(-1)
            scale_t, state_t, inv_t, g_out = scale[t], state[i], inv_norms[t], g_rows[id(g_cur)]
            for k, (s0, s1) in enumerate(blocks.spans):
                flat, b = blocks.pairs[k], blocks.cubes[k]
                # unreachable states send nothing back (scale_t > 0 iff pred_t > 0 at a real
                # step; padded steps are zeroed and send nothing either); the posterior is
                # gamma times the weights
                sc, st, sends_k, weights_k = scale_t[s0:s1], state_t[s0:s1], sends[k], weights[k]
                np.multiply(sc > 0.0, inv_t, out=sends_k)
                sends_k *= st
                np.multiply(sc, st, out=weights_k)
                if t == length - 1:
                    b[...] = restarts[k]
                else:
                    flat.fill(0.0)
                    expect(k, g_1d, flat)
                    if ends is not None:
                        b[:, :, ends] = restarts[k]
                b *= blocks.acts[k]
                if t > 0:
                    g = np.add.reduce(b, axis=0, out=g_out[k])
                    g *= sends_k
                b *= weights_k
                if t == 0:
                    np.add.reduce(b, axis=0, out=initials[k])
                    np.add(occupancies[k], b, out=results[k])
                else:
                    occupancies[k] += b
            g_next, g_cur = g_cur, g_next
    return result, initial
