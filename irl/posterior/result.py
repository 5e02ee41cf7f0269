"""The posterior's samples and their file: :class:`Posterior`, its :class:`Diagnostics` and
the readings of a session swap (:class:`SwapComponent`).

Layouts: ``theta[n, k]`` posterior samples, ``policies[n, s]`` the greedy action of each
sample, ``confidence[s, a]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from irl._validation import check_real

POSTERIOR_FORMAT = "onionsort.posterior/1"


@dataclass(frozen=True)
class Diagnostics:
    """How far the samples can be trusted.

    Attributes
    ----------
    r_hat : ndarray of shape (K,)
        Rank-normalized split R-hat per weight (:func:`irl.stats.split_rhat`); NaN for the
        Laplace draws, which are independent by construction.
    ess : ndarray of shape (K,)
        Bulk effective sample size per weight; the number of draws for Laplace.
    acceptance : float
        Mean acceptance statistic of the main (post warm-up) transitions; 1 for Laplace.
    n_chains, n_warmup, n_draws : int
        Chains, warm-up iterations and main draws per chain (1, 0, n for Laplace).
    n_divergent : int
        Main transitions whose energy error diverged (0 for Laplace).
    n_gradients : int
        Gradients of the exact log posterior evaluated, warm-up included (with a session swap,
        a resampled reading's proposals count here too, though each costs a value alone).
    hessian_clipped : int
        Eigenvalues of minus the Hessian at the MAP raised to the prior's precision (the
        Hessian by differences can miss curvature where the MAP lies on the border between two
        greedy policies).
    """

    r_hat: np.ndarray
    ess: np.ndarray
    acceptance: float
    n_chains: int
    n_warmup: int
    n_draws: int
    n_divergent: int
    n_gradients: int
    hessian_clipped: int

    def max_r_hat(self) -> float:
        """The largest R-hat over the weights (NaN for Laplace)."""
        return float(np.max(self.r_hat)) if np.all(np.isfinite(self.r_hat)) else float("nan")

    def to_dict(self) -> dict:
        return {
            "r_hat": [None if not np.isfinite(v) else round(float(v), 5) for v in self.r_hat],
            "ess": [round(float(v), 1) for v in self.ess],
            "acceptance": round(float(self.acceptance), 4),
            "n_chains": self.n_chains, "n_warmup": self.n_warmup, "n_draws": self.n_draws,
            "n_divergent": self.n_divergent, "n_gradients": self.n_gradients,
            "hessian_clipped": self.hessian_clipped,
        }


@dataclass(frozen=True)
class SwapComponent:
    """One reading of the demonstrations in the posterior of a learner with a
    ``session_swap``: which demonstrations it reads swapped, and its share.

    Attributes
    ----------
    swapped : tuple of int
        The demonstrations (their indices) read through the swap.
    weight : float
        Its posterior probability among the readings weighed (they sum to 1).
    log_weight : float
        Its prior probability times its evidence, in logs: ``|z| log rate + (N - |z|)
        log(1 - rate)`` plus the Laplace approximation of ``log p(o_z)`` at its mode.
    n_samples : int
        The posterior's samples drawn from it.
    """

    swapped: tuple[int, ...]
    weight: float
    log_weight: float
    n_samples: int


@dataclass(frozen=True)
class Posterior:
    """Samples of the reward weights given the demonstrations, and their greedy policies.

    Attributes
    ----------
    theta : ndarray of shape (n, K)
    policies : ndarray of shape (n, S)
        The greedy optimal policy of each sample.
    map_theta : ndarray of shape (K,)
        The MAP the samples were drawn around (the estimator's ``theta_``).
    map_policy : ndarray of shape (S,)
    covariance : ndarray of shape (K, K)
        The Laplace covariance at the MAP (the proposal's shape for ``"mcmc"``; with a
        ``session_swap``, of the mixture posterior, while each reading is drawn with its own).
    n_actions : int
    method : str
    diagnostics : Diagnostics
    components : tuple of SwapComponent
        With a learner's ``session_swap``: the readings of the demonstrations weighed, and how
        many samples each gave (empty otherwise).
    """

    theta: np.ndarray
    policies: np.ndarray
    map_theta: np.ndarray
    map_policy: np.ndarray
    covariance: np.ndarray
    n_actions: int
    method: str
    diagnostics: Diagnostics
    components: tuple[SwapComponent, ...] = ()
    _confidence: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        n, S = self.policies.shape
        if self.theta.shape[0] != n:
            raise ValueError(f"theta has {self.theta.shape[0]} samples but policies has {n}")
        counts = np.zeros((S, self.n_actions))
        np.add.at(counts, (np.broadcast_to(np.arange(S), (n, S)), self.policies), 1.0)
        object.__setattr__(self, "_confidence", counts / n)

    @property
    def n_samples(self) -> int:
        return int(self.theta.shape[0])

    def action_confidence(self) -> np.ndarray:
        """``confidence[s, a]``: the share of samples whose greedy policy takes ``a`` in ``s``.
        Each row sums to 1."""
        return self._confidence.copy()

    def map_confidence(self) -> np.ndarray:
        """``(S,)``: the confidence in the MAP policy's action in each state."""
        return self._confidence[np.arange(self.map_policy.size), self.map_policy]

    def credible_actions(self, level: float = 0.9) -> list[tuple[int, ...]]:
        """Per state, the fewest actions whose confidence sums to at least ``level``, the most
        confident first."""
        level = check_real(level, "level", low=0.0, high=1.0, low_open=True)
        sets = []
        for row in self._confidence:
            order = np.argsort(-row, kind="stable")
            k = int(np.searchsorted(np.cumsum(row[order]), level - 1e-12)) + 1
            sets.append(tuple(int(a) for a in order[:min(k, row.size)]))
        return sets

    def save(self, path: Path) -> Path:
        """Write the samples to ``path`` (``.npz``), through a temporary name."""
        path = Path(path)
        tmp = path.with_name(path.name + ".partial")
        with open(tmp, "wb") as f:
            np.savez_compressed(
                f, format=POSTERIOR_FORMAT, theta=self.theta, policies=self.policies,
                map_theta=self.map_theta, map_policy=self.map_policy,
                covariance=self.covariance, n_actions=self.n_actions, method=self.method,
                **{f"diag_{k}": np.asarray(getattr(self.diagnostics, k))
                   for k in Diagnostics.__dataclass_fields__},
                **_components_arrays(self.components))
        tmp.replace(path)
        return path


def load_posterior(path: Path) -> Posterior:
    """Read a :meth:`Posterior.save` file; a one-line ``ValueError`` if it is not one.

    Parameters
    ----------
    path : str or Path
        A ``posterior.npz`` (what ``onionsort learn --posterior`` writes).

    Returns
    -------
    Posterior
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no such posterior file: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["format"]) != POSTERIOR_FORMAT:
                raise ValueError(f"format {str(z['format'])!r}, not {POSTERIOR_FORMAT!r}")
            diag = {k: z[f"diag_{k}"] for k in Diagnostics.__dataclass_fields__}
            return Posterior(
                theta=z["theta"], policies=z["policies"].astype(np.int64),
                map_theta=z["map_theta"], map_policy=z["map_policy"].astype(np.int64),
                covariance=z["covariance"], n_actions=int(z["n_actions"]),
                method=str(z["method"]),
                diagnostics=Diagnostics(
                    r_hat=diag["r_hat"], ess=diag["ess"], acceptance=float(diag["acceptance"]),
                    **{k: int(diag[k]) for k in ("n_chains", "n_warmup", "n_draws",
                                                 "n_divergent", "n_gradients",
                                                 "hessian_clipped")}),
                components=_read_components(z))
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path} is not a posterior file ({exc})") from None


def _components_arrays(components: tuple[SwapComponent, ...]) -> dict[str, np.ndarray]:
    """The swap readings as arrays (``swapped`` as a padded index matrix; -1 pads)."""
    if not components:
        return {}
    width = max(1, max(len(c.swapped) for c in components))
    swapped = np.full((len(components), width), -1, dtype=np.int64)
    for i, c in enumerate(components):
        swapped[i, :len(c.swapped)] = c.swapped
    return {"comp_swapped": swapped,
            "comp_weight": np.array([c.weight for c in components]),
            "comp_log_weight": np.array([c.log_weight for c in components]),
            "comp_n_samples": np.array([c.n_samples for c in components], dtype=np.int64)}


def _read_components(z) -> tuple[SwapComponent, ...]:
    if "comp_swapped" not in z:
        return ()
    return tuple(SwapComponent(swapped=tuple(int(i) for i in row if i >= 0), weight=float(w),
                               log_weight=float(lw), n_samples=int(n))
                 for row, w, lw, n in zip(z["comp_swapped"], z["comp_weight"],
                                          z["comp_log_weight"], z["comp_n_samples"],
                                          strict=True))

