"""A noisy grid world with sparse transitions: the scale test of the library (10^4 to 10^5
states), not one of the paper's domains.

Layout: the state is ``s = x * ny + y`` on an ``nx x ny`` grid; four moves (up, right, down,
left as ``+y, +x, -y, -x``), each succeeding with probability ``1 - slip`` and otherwise going
one of the three other ways (moves off the grid stay put). Features are indicators of randomly
chosen cells, the same for every action.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from irl._validation import check_int, check_real
from irl.mdp import TabularMDP

__all__ = ["grid_mdp"]

MOVES = ((0, 1), (1, 0), (0, -1), (-1, 0))


def grid_mdp(nx: int, ny: int, *, slip: float = 0.1, n_features: int = 4,
             feature_fraction: float = 0.05, discount: float = 0.99,
             seed: int = 0) -> TabularMDP:
    """The ``nx x ny`` grid as a :class:`~irl.TabularMDP` with one sparse matrix per move.

    Parameters
    ----------
    nx, ny : int
        Grid size; ``S = nx * ny``.
    slip : float
        Probability that a move goes one of the other three ways (each ``slip / 3``).
    n_features : int
        Reward features; feature k is 1 on a random ``feature_fraction`` of the cells.
    feature_fraction : float
    discount : float
    seed : int
        Seeds the feature cells.

    Returns
    -------
    TabularMDP
        Sparse transitions (``4 S`` nonzeros per move), uniform initial distribution.
    """
    nx, ny = check_int(nx, "nx", low=1), check_int(ny, "ny", low=1)
    slip = check_real(slip, "slip", low=0.0, high=1.0)
    n_features = check_int(n_features, "n_features", low=1)
    feature_fraction = check_real(feature_fraction, "feature_fraction", low=0.0, high=1.0)
    rng = np.random.default_rng(seed)
    n = nx * ny
    x, y = np.divmod(np.arange(n), ny)
    targets = [np.clip(x + dx, 0, nx - 1) * ny + np.clip(y + dy, 0, ny - 1) for dx, dy in MOVES]
    mats = []
    for a in range(len(MOVES)):
        vals = [np.full(n, 1.0 - slip if a == b else slip / 3) for b in range(len(MOVES))]
        rows = np.tile(np.arange(n), len(MOVES))
        mats.append(sp.csr_matrix((np.concatenate(vals), (rows, np.concatenate(targets))),
                                  shape=(n, n)))
    phi = np.zeros((n, len(MOVES), n_features))
    for k in range(n_features):
        cells = rng.choice(n, size=max(1, int(n * feature_fraction)), replace=False)
        phi[cells, :, k] = 1.0
    return TabularMDP(transitions=mats, features=phi, discount=discount,
                      initial=np.full(n, 1.0 / n))
