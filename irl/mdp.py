"""Tabular Markov decision processes with linear rewards.

Array layouts used throughout the project: ``T[s, a, s']``, ``phi[s, a, k]``, ``p0[s]``,
``R[s, a]``, ``Q[s, a]``, ``pi[s, a]``.

Transitions are given either densely as ``T[s, a, s']`` or as one ``scipy.sparse`` ``S x S``
matrix per action. Internally both become one *flat* operator ``P[s * A + a, s']`` (a dense
array or a CSR matrix), so every kernel is written once and never forms a dense ``S x S``
matrix for a sparse MDP.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from irl._validation import as_float_array, check_probability_rows, check_real, describe

__all__ = ["TabularMDP"]

try:  # scipy's own CSR kernel (see _csr_times); absent in some future scipy, then `@`
    from scipy.sparse._sparsetools import csr_matvecs as _csr_matvecs
except ImportError:  # pragma: no cover - depends on the scipy build
    _csr_matvecs = None

#: Density below which a dense MDP's forward-backward products use a CSR copy of ``T``.
_SPARSE_PRODUCTS = 0.05


class TabularMDP:
    """A finite MDP whose reward is linear in features: ``R(s, a) = phi[s, a] . theta``.

    Parameters
    ----------
    transitions : ndarray of shape (S, A, S) or sequence of A sparse matrices of shape (S, S)
        ``T[s, a, s'] = P(s' | s, a)``; every row sums to 1.
    features : ndarray of shape (S, A, K)
        ``phi[s, a, k]``, the reward features.
    discount : float
        Discount factor gamma in [0, 1).
    initial : ndarray of shape (S,)
        Initial state distribution ``p0[s]``.
    state_names, action_names, feature_names : sequence of str, optional
        Human-readable names, used in reports and plots.

    Attributes
    ----------
    transitions : ndarray or sequence of sparse matrices
        As given.
    features : ndarray of shape (S, A, K)
    discount : float
    initial : ndarray of shape (S,)
    n_states, n_actions, n_features : int
        ``S``, ``A`` and ``K``.
    state_names, action_names, feature_names : list of str
        As given, or ``s0, s1, ...``, ``a0, ...``, ``phi0, ...``.
    """

    def __init__(
        self,
        *,
        transitions: np.ndarray | Sequence[sp.spmatrix],
        features: np.ndarray,
        discount: float,
        initial: np.ndarray,
        state_names: Sequence[str] | None = None,
        action_names: Sequence[str] | None = None,
        feature_names: Sequence[str] | None = None,
    ) -> None:
        if transitions is None or isinstance(transitions, (str, bytes)):
            raise TypeError(
                "transitions must be an (S, A, S) array or a sequence of A (S, S) matrices; "
                f"got {describe(transitions)}"
            )
        self.transitions = transitions
        if sp.issparse(transitions) or (
            isinstance(transitions, Sequence) and not isinstance(transitions, np.ndarray)
        ):
            flat, n_states, n_actions = _flatten_sparse(transitions)
        else:
            flat, n_states, n_actions = _flatten_dense(transitions)
        self._flat = flat
        self._sparse = sp.issparse(flat)
        self.n_states = n_states
        self.n_actions = n_actions

        features = as_float_array(features, "features")
        if features.ndim != 3 or features.shape[:2] != (n_states, n_actions) \
                or features.shape[2] < 1:
            raise ValueError(
                f"features must have shape (S, A, K) = ({n_states}, {n_actions}, K >= 1) to "
                f"match transitions; got {features.shape}"
            )
        self.features = features
        self.n_features = features.shape[2]

        self.discount = check_real(discount, "discount", low=0.0, high=1.0, high_open=True)

        initial = as_float_array(initial, "initial")
        if initial.shape != (n_states,):
            raise ValueError(f"initial must have shape (S,) = ({n_states},); got {initial.shape}")
        check_probability_rows(initial[None, :], "initial")
        self.initial = initial

        self.state_names = _names(state_names, n_states, "state_names", "s")
        self.action_names = _names(action_names, n_actions, "action_names", "a")
        self.feature_names = _names(feature_names, self.n_features, "feature_names", "phi")

    @property
    def is_sparse(self) -> bool:
        """True when transitions are stored as a sparse matrix."""
        return self._sparse

    def reward(self, theta: np.ndarray) -> np.ndarray:
        """Reward table ``R[s, a] = phi[s, a] . theta`` of shape (S, A)."""
        return self.features @ self.check_theta(theta)

    def check_theta(self, theta: np.ndarray, name: str = "theta") -> np.ndarray:
        """Return ``theta`` as a finite float vector of length K, or raise naming ``name``."""
        if theta is None or isinstance(theta, (str, bytes, dict, set)):
            raise TypeError(f"{name} must be an array of {self.n_features} numbers; got "
                            f"{describe(theta)}")
        try:
            theta = np.asarray(theta, dtype=float)
        except (TypeError, ValueError) as exc:
            raise TypeError(f"{name} must be an array of {self.n_features} numbers; got "
                            f"{describe(theta)} ({exc})") from None
        if theta.shape != (self.n_features,):
            raise ValueError(
                f"{name} must have shape (K,) = ({self.n_features},); got {theta.shape}"
            )
        if not np.all(np.isfinite(theta)):
            raise ValueError(f"{name} must be finite; got {describe(theta)}")
        return theta

    # -- flat-operator kernels (shared by the solvers and forward-backward) ------------------

    def expect_next(self, values: np.ndarray) -> np.ndarray:
        """``sum_s' T[s, a, s'] values[s', ...]``, shape (S, A, ...).

        ``values`` has shape (S,) or (S, m); the result keeps the trailing dimension.
        """
        out = self._flat @ values
        return np.asarray(out).reshape((self.n_states, self.n_actions, *values.shape[1:]))

    def push_forward(self, mass: np.ndarray) -> np.ndarray:
        """Next-state mass ``sum_{s, a} mass[..., s, a] T[s, a, s']``, shape (..., S).

        A batch ``mass[n, s, a]`` goes through in one product with the block ``(N, S A)``.
        """
        lead = mass.shape[:-2]
        flat_mass = mass.reshape(-1, self.n_states * self.n_actions)
        out = np.asarray(self._flat_T @ flat_mass.T).T if self._sparse else flat_mass @ self._flat
        return out.reshape((*lead, self.n_states))

    def reachable_states(self) -> np.ndarray:
        """``(S,)`` bool: the states some sequence of actions reaches with positive probability
        from the initial distribution (those a demonstration can show)."""
        reached = self.initial > 0
        for _ in range(self.n_states):
            mass = np.repeat(reached[:, None].astype(float), self.n_actions, axis=1)
            grown = reached | (self.push_forward(mass) > 0)
            if np.array_equal(grown, reached):
                break
            reached = grown
        return reached

    def expect_next_batch(self, values: np.ndarray) -> np.ndarray:
        """``sum_s' T[s, a, s'] values[n, s']`` for a batch ``values[n, s']``, shape (N, S, A).

        The batch-first form of :meth:`expect_next`: one product with the block ``(N, S)``.
        """
        out = np.asarray(self._flat @ values.T).T if self._sparse else values @ self._flat.T
        return out.reshape(values.shape[0], self.n_states, self.n_actions)

    def push_forward_columns(self, mass: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Next-state mass of a batch held in columns: ``out[s', n] = sum_{a, s} mass[a, s, n]
        T[s, a, s']`` for ``mass`` of shape (A, S, N) or (A S, N) and ``out`` (S, N), both
        C-contiguous.

        Forward-backward keeps a batch's messages with the demonstrations innermost, so that
        every product reads and writes its block in place (no transposed copies) and
        broadcasting a state array over the actions runs over whole ``(S, N)`` slabs.
        """
        flat = mass.reshape(-1, mass.shape[-1])
        if not self._products_sparse:
            return np.dot(self._action_major_dense_T, flat, out=out)
        return _csr_times(self._action_major_T, flat, out)

    def expect_next_columns(self, values: np.ndarray, out: np.ndarray) -> np.ndarray:
        """``out[a, s, n] = sum_s' T[s, a, s'] values[s', n]`` for ``values`` of shape (S, N)
        and ``out`` of shape (A, S, N) or (A S, N), both C-contiguous (see
        :meth:`push_forward_columns`)."""
        flat = out.reshape(-1, out.shape[-1])
        if not self._products_sparse:
            np.dot(self._action_major, values, out=flat)
        else:
            _csr_times(self._action_major_csr, values, flat)
        return out

    def column_products(self, n: int, pair_weights: np.ndarray | None = None):
        """``(push, expect)``: :meth:`push_forward_columns` and :meth:`expect_next_columns` for
        a batch of n columns, as two functions that add their product into ``out`` (``push(mass,
        out)``: ``out += `` the next-state mass of ``mass`` (A, S, n); ``expect(values, out)``:
        ``out += `` the expectation (A, S, n) of ``values`` (S, n)), all four arrays flat views
        of C-contiguous ones. Every lookup is done once, for a loop that calls them at every
        step; a caller that writes each product into zeros it set once saves a pass per step.

        With ``pair_weights`` ``w`` (A S,), indexed ``a * S + s``, they are the products of the
        operator whose pair rows are scaled by ``w``: ``push`` sums ``T[s, a, s'] w[a, s]
        mass[a, s, n]`` and ``expect`` adds ``w[a, s] sum_s' T[s, a, s'] values[s', n]``.
        Forward-backward folds a stationary policy into ``T`` this way, once per pass (``O(nnz
        (T))``), and saves a product over every ``(A, S, N)`` message at every step.
        """
        if not self._products_sparse:
            P, PT = self._action_major, self._action_major_dense_T
            if pair_weights is not None:
                P, PT = P * pair_weights[:, None], PT * pair_weights[None, :]

            def push(mass, out):
                out += (PT @ mass.reshape(-1, n)).ravel()

            def expect(values, out):
                out += (P @ values.reshape(-1, n)).ravel()

            return push, expect
        fwd, bwd = self._action_major_T, self._action_major_csr
        f_data, b_data = fwd.data, bwd.data
        if pair_weights is not None:
            f_data = f_data * pair_weights[fwd.indices]
            b_data = b_data * pair_weights[self._action_major_rows]
        if _csr_matvecs is None:
            fwd = sp.csr_matrix((f_data, fwd.indices, fwd.indptr), shape=fwd.shape)
            bwd = sp.csr_matrix((b_data, bwd.indices, bwd.indptr), shape=bwd.shape)
            return (lambda mass, out: out.__iadd__((fwd @ mass.reshape(-1, n)).ravel()),
                    lambda values, out: out.__iadd__((bwd @ values.reshape(-1, n)).ravel()))
        n_pairs, n_states = bwd.shape
        f_args = (n_states, n_pairs, n, fwd.indptr, fwd.indices, f_data)
        b_args = (n_pairs, n_states, n, bwd.indptr, bwd.indices, b_data)
        return (lambda mass, out: _csr_matvecs(*f_args, mass, out),
                lambda values, out: _csr_matvecs(*b_args, values, out))

    def state_block_products(self, block: int, n: int, pair_weights: np.ndarray):
        """``(push, expect)`` by blocks of ``block`` states, for a batch of n columns, or None
        where the products do not go through scipy's CSR kernel (a dense MDP, or a scipy
        without it).

        Block k holds the ``m`` states from ``s0 = k block``, its pairs laid out ``[a, s - s0,
        n]`` (action-major within the block, so that a state array broadcasts over its actions
        as whole ``(m, n)`` slabs). ``push(k, values, out)`` adds to ``out[a, s' - s0, n]``
        the mass that ``values[s, n]`` (S, n) sends to each ``s'`` of block k through action
        a, ``sum_s T[s, a, s'] w[s, a] values[s, n]``; ``expect(k, values, out)`` adds ``w[s,
        a] sum_s' T[s, a, s'] values[s', n]`` to ``out[a, s - s0, n]``. ``w`` is
        ``pair_weights`` (S A,), indexed ``s * A + a``; all arrays are flat views of
        C-contiguous ones.

        Forward-backward with a stationary policy and separable observations computes a step
        block by block this way, so that the ``(A, S, N)`` message of the step lives in the
        cache instead of memory at any S: a block's products are rows of one operator (for the
        push, ``T[s, a, s']`` re-indexed by ``(s', a)``), and the observation's parts are
        applied to the block before it is summed over the actions.
        """
        if not self._products_sparse or _csr_matvecs is None:
            return None
        fwd, fwd_pairs, bwd, bwd_pairs = self._state_block_operators(block)
        f_data = fwd.data * pair_weights[fwd_pairs]
        b_data = bwd.data * pair_weights[bwd_pairs]
        A, S = self.n_actions, self.n_states
        rows = [(s0 * A, min(s0 + block, S) * A) for s0 in range(0, S, block)]
        f_args = [(r1 - r0, S, n, fwd.indptr[r0:r1 + 1], fwd.indices, f_data) for r0, r1 in rows]
        b_args = [(r1 - r0, S, n, bwd.indptr[r0:r1 + 1], bwd.indices, b_data) for r0, r1 in rows]

        def push(k, values, out):
            _csr_matvecs(*f_args[k], values, out)

        def expect(k, values, out):
            _csr_matvecs(*b_args[k], values, out)

        return push, expect

    def _state_block_operators(self, block: int):
        """``(fwd, fwd_pairs, bwd, bwd_pairs)`` of :meth:`state_block_products` (kept per
        block size): ``fwd`` holds ``T[s, a, s']`` in row ``(s', a)`` and column ``s``, ``bwd``
        in row ``(s, a)`` and column ``s'``, as CSR with rows in the blocks' order, and
        ``*_pairs`` the pair ``s * A + a`` of each stored entry."""
        kept = self.__dict__.setdefault("_block_operators", {})
        if block in kept:
            return kept[block]
        csr = sp.csr_matrix(self._flat, dtype=float)
        csr.sum_duplicates()
        csr.eliminate_zeros()
        S, A = self.n_states, self.n_actions
        rows = np.repeat(np.arange(S * A), np.diff(csr.indptr))  # s * A + a of each entry
        states = np.arange(S)
        start = states // block * block
        local = (start * A + states - start)[:, None] + (
            np.minimum(block, S - start)[:, None] * np.arange(A)[None, :])  # [s, a]
        order = np.empty(S * A, dtype=np.int64)
        order[local.ravel()] = np.arange(S * A)  # the pair in each block row
        bwd = csr[order]
        bwd_pairs = np.repeat(order, np.diff(bwd.indptr))
        fwd = sp.csr_matrix((csr.data, (csr.indices * A + rows % A, rows // A)),
                            shape=(S * A, S))[order]
        fwd.sort_indices()
        fwd_pairs = fwd.indices * A + np.repeat(order % A, np.diff(fwd.indptr))
        kept[block] = (fwd, fwd_pairs, bwd, bwd_pairs)
        return kept[block]

    @cached_property
    def _products_sparse(self) -> bool:
        """Whether forward-backward's products go through CSR: a sparse MDP, or a dense one
        whose transitions are mostly zeros (a nearly deterministic task, where a dense product
        would spend its time on zeros)."""
        return self._sparse or np.count_nonzero(self._flat) <= _SPARSE_PRODUCTS * self._flat.size

    @cached_property
    def _action_major_csr(self):
        """``P`` with rows ``a * S + s`` as CSR, whatever the storage."""
        csr = sp.csr_matrix(self._action_major, dtype=float)
        csr.eliminate_zeros()
        return csr

    @cached_property
    def _action_major_rows(self) -> np.ndarray:
        """The row (``a * S + s``) of each stored entry of :attr:`_action_major_csr`."""
        csr = self._action_major_csr
        return np.repeat(np.arange(csr.shape[0]), np.diff(csr.indptr))

    @cached_property
    def _action_major_dense_T(self) -> np.ndarray:
        """``P.T`` of a dense MDP, action-major columns, C-contiguous (for ``np.dot(out=)``)."""
        return np.ascontiguousarray(self._action_major.T)

    @cached_property
    def _action_major(self):
        """``P`` with rows reordered to ``a * S + s``."""
        order = (np.arange(self.n_states)[None, :] * self.n_actions
                 + np.arange(self.n_actions)[:, None]).ravel()
        return self._flat[order]

    @cached_property
    def _action_major_T(self):
        return self._action_major_csr.T.tocsr()

    @cached_property
    def _flat_T(self):
        """``P.T`` as CSR (a sparse MDP's forward products read it row by row)."""
        return self._flat.T.tocsr()

    # -- the same kernels in log space (exact at any dynamic range; used where the scaled
    # linear-space messages of forward-backward would underflow) ---------------------------

    @cached_property
    def _log_operator(self) -> dict[str, np.ndarray]:
        """The positive entries of ``P[s * A + a, s']`` and their logs, by row and by column."""
        csr = sp.csr_matrix(self._flat, dtype=float)
        csr.eliminate_zeros()
        csr.sort_indices()
        csc = csr.tocsc()
        csc.sort_indices()
        return {
            "row_ptr": csr.indptr, "row_index": csr.indices, "row_log": np.log(csr.data),
            "col_ptr": csc.indptr, "col_index": csc.indices, "col_log": np.log(csc.data),
        }

    @cached_property
    def log_initial(self) -> np.ndarray:
        """``log p0[s]``, ``-inf`` where ``p0`` is 0."""
        out = np.full(self.n_states, -np.inf)
        positive = self.initial > 0
        out[positive] = np.log(self.initial[positive])
        return out

    @cached_property
    def min_log_transition(self) -> float:
        """``log`` of the smallest positive transition probability."""
        return float(self._log_operator["row_log"].min())

    def log_expect_next(self, log_values: np.ndarray) -> np.ndarray:
        """``log sum_s' T[s, a, s'] exp(log_values[..., s'])``, shape (..., S, A).

        ``log_values`` has shape (..., S), batch axes first; ``-inf`` entries are zeros.
        """
        op = self._log_operator
        lead = log_values.shape[:-1]
        lv = log_values.reshape(-1, self.n_states)
        terms = lv[:, op["row_index"]] + op["row_log"]
        out = segment_logsumexp(terms, op["row_ptr"])
        return out.reshape((*lead, self.n_states, self.n_actions))

    def log_push_forward(self, log_mass: np.ndarray) -> np.ndarray:
        """``log sum_{s, a} exp(log_mass[..., s, a]) T[s, a, s']``, shape (..., S)."""
        op = self._log_operator
        lead = log_mass.shape[:-2]
        lm = log_mass.reshape(-1, self.n_states * self.n_actions)
        terms = lm[:, op["col_index"]] + op["col_log"]
        return segment_logsumexp(terms, op["col_ptr"]).reshape((*lead, self.n_states))

    def next_state_distribution(self, state: int, action: int) -> np.ndarray:
        """``T[state, action, :]`` as a dense vector of shape (S,)."""
        row = self._flat[state * self.n_actions + action]
        row = row.toarray().ravel() if sp.issparse(row) else np.array(row, dtype=float)
        return row / row.sum()

    def policy_transitions(self, policy: np.ndarray) -> np.ndarray | sp.csr_matrix:
        """``P_pi[s, s'] = T[s, policy[s], s']`` of a deterministic policy (sparse if T is)."""
        rows = np.arange(self.n_states) * self.n_actions + policy
        return self._flat[rows]

    def __repr__(self) -> str:
        kind = "sparse" if self.is_sparse else "dense"
        return (
            f"TabularMDP(n_states={self.n_states}, n_actions={self.n_actions}, "
            f"n_features={self.n_features}, discount={self.discount}, {kind})"
        )


def segment_logsumexp(values: np.ndarray, indptr: np.ndarray) -> np.ndarray:
    """``logsumexp`` of ``values[:, indptr[j]:indptr[j + 1]]`` for each segment j.

    ``values`` has shape (B, n) with finite or ``-inf`` entries; the result has shape
    (B, len(indptr) - 1), ``-inf`` for an empty segment or one of ``-inf`` only.
    """
    n_seg = len(indptr) - 1
    out = np.full((values.shape[0], n_seg), -np.inf)
    lengths = np.diff(indptr)
    nonempty = lengths > 0
    if not nonempty.any():
        return out
    starts = indptr[:-1][nonempty]
    top = np.maximum.reduceat(values, starts, axis=1)
    top = np.where(np.isfinite(top), top, 0.0)
    shifted = values - np.repeat(top, lengths[nonempty], axis=1)
    sums = np.add.reduceat(np.exp(shifted), starts, axis=1)
    with np.errstate(divide="ignore"):
        out[:, nonempty] = np.log(sums) + top
    return out


def _flatten_dense(transitions) -> tuple[np.ndarray, int, int]:
    T = as_float_array(transitions, "transitions")
    if T.ndim != 3 or T.shape[0] != T.shape[2] or min(T.shape) < 1:
        raise ValueError(
            f"transitions must have shape (S, A, S) with S, A >= 1; got {T.shape}"
        )
    n_states, n_actions = T.shape[:2]
    flat = np.ascontiguousarray(T.reshape(n_states * n_actions, n_states))
    check_probability_rows(flat, "transitions")
    return flat, n_states, n_actions


def _flatten_sparse(transitions) -> tuple[sp.csr_matrix, int, int]:
    if sp.issparse(transitions):
        raise TypeError(
            "transitions given as sparse must be a sequence of one (S, S) matrix per action; "
            f"got a single {type(transitions).__name__}"
        )
    mats = []
    for a, m in enumerate(transitions):
        try:
            mats.append(sp.csr_matrix(m if sp.issparse(m) else as_float_array(
                m, f"transitions[{a}]", ndim=2), dtype=float))
        except (TypeError, ValueError) as exc:
            if f"transitions[{a}]" in str(exc):
                raise
            raise TypeError(
                f"transitions[{a}] must be an (S, S) matrix; got {describe(m)}"
            ) from None
    if not mats:
        raise ValueError("transitions must hold at least one action's matrix; got none")
    n_states = mats[0].shape[0]
    for a, m in enumerate(mats):
        if m.shape != (n_states, n_states) or n_states < 1:
            raise ValueError(
                f"transitions[{a}] must have shape (S, S) = ({n_states}, {n_states}); "
                f"got {m.shape}"
            )
    n_actions = len(mats)
    # Interleave rows so that row s * A + a is T[s, a, :].
    stacked = sp.vstack(mats, format="csr")  # row a * S + s
    order = (np.arange(n_states)[:, None] + np.arange(n_actions)[None, :] * n_states).ravel()
    flat = stacked[order].tocsr()
    flat.sum_duplicates()
    check_probability_rows(flat, "transitions")
    return flat, n_states, n_actions


def _names(names, n: int, argname: str, prefix: str) -> list[str]:
    if names is None:
        return [f"{prefix}{i}" for i in range(n)]
    if isinstance(names, (str, bytes)) or not isinstance(names, Sequence | np.ndarray):
        raise TypeError(f"{argname} must be a sequence of {n} str; got {describe(names)}")
    names = [str(x) for x in names]
    if len(names) != n:
        raise ValueError(f"{argname} must have {n} entries; got {len(names)}")
    return names


def _csr_times(csr: sp.csr_matrix, block: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out[...] = csr @ block`` for a C-contiguous block ``(n_col, N)`` and out ``(n_row, N)``.

    Forward-backward makes two such products per step with a few demonstrations; at the
    sizes of the paper's tasks scipy's dispatch around its kernel costs several times the
    kernel itself, so the kernel (``csr_matvecs``, ``Y += A X`` for row-major blocks) is called
    directly where this scipy has it, and ``@`` is the fallback.
    """
    if _csr_matvecs is None or not (block.flags.c_contiguous and out.flags.c_contiguous):
        out[...] = csr @ block
        return out
    out.fill(0.0)
    _csr_matvecs(csr.shape[0], csr.shape[1], block.shape[1], csr.indptr, csr.indices,
                 csr.data, block.ravel(), out.ravel())
    return out
