"""Priors over reward weights."""

from __future__ import annotations

import numpy as np

from irl._random import check_random_state

__all__ = ["GaussianPrior"]


class GaussianPrior:
    """Independent Gaussian prior per weight: ``theta_k ~ N(mean_k, std_k^2)``.

    ``mean`` and ``std`` are scalars or one value per weight. The log-density gradient is
    ``-(theta - mean) / std^2``; the paper's Eq. (gradient of the prior) has an extra factor
    1/2, which is an erratum (see docs/paper-errata.md).
    """

    def __init__(self, mean=0.0, std=1.0) -> None:
        self.mean = np.asarray(mean, dtype=float)
        self.std = np.asarray(std, dtype=float)
        if self.mean.ndim > 1 or self.std.ndim > 1:
            raise ValueError(
                f"mean and std must be scalars or 1-D; got shapes {self.mean.shape} and "
                f"{self.std.shape}"
            )
        if not np.all(np.isfinite(self.mean)):
            raise ValueError(f"mean must be finite; got {self.mean}")
        if not np.all(self.std > 0) or not np.all(np.isfinite(self.std)):
            raise ValueError(f"std must be positive and finite; got {self.std}")

    def _broadcast(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        for name, v in (("mean", self.mean), ("std", self.std)):
            if v.ndim == 1 and v.shape[0] != n:
                raise ValueError(f"prior {name} has {v.shape[0]} entries but theta has {n}")
        return np.broadcast_to(self.mean, (n,)), np.broadcast_to(self.std, (n,))

    def log_prob(self, theta: np.ndarray) -> float:
        """``log p(theta)``, normalized."""
        theta = np.asarray(theta, dtype=float)
        mu, sd = self._broadcast(theta.shape[0])
        z = (theta - mu) / sd
        return float(-0.5 * (z @ z) - np.log(sd).sum() - 0.5 * theta.shape[0] * np.log(2 * np.pi))

    def grad_log_prob(self, theta: np.ndarray) -> np.ndarray:
        """``d log p / dtheta = -(theta - mean) / std^2``."""
        theta = np.asarray(theta, dtype=float)
        mu, sd = self._broadcast(theta.shape[0])
        return -(theta - mu) / sd**2

    def sample(self, n_features: int, seed=None) -> np.ndarray:
        """One draw of theta, shape (n_features,)."""
        mu, sd = self._broadcast(n_features)
        return check_random_state(seed).normal(mu, sd)

    def __repr__(self) -> str:
        return f"GaussianPrior(mean={self.mean.tolist()}, std={self.std.tolist()})"
