"""Priors over reward weights."""

from __future__ import annotations

import numpy as np

from irl._random import check_random_state
from irl._validation import as_float_array, check_int

__all__ = ["GaussianPrior"]


class GaussianPrior:
    """Independent Gaussian prior per weight: ``theta_k ~ N(mean_k, std_k^2)``.

    ``mean`` and ``std`` are scalars or one value per weight. The log-density gradient is
    ``-(theta - mean) / std^2``; the paper's Eq. (gradient of the prior) has an extra factor
    1/2, which is an erratum (see docs/paper-errata.md). With a Boltzmann-rational expert only
    ``beta * theta`` is identified, so the prior's scale and the learner's ``beta`` are chosen
    together (docs/api.md, "beta and the prior").

    Parameters
    ----------
    mean : float or array of shape (K,), default 0.0
        The prior mean of each weight.
    std : float or array of shape (K,), default 1.0
        The prior standard deviation of each weight, > 0.

    Attributes
    ----------
    mean, std : ndarray of shape () or (K,)
        As given, as float arrays.
    """

    def __init__(self, mean=0.0, std=1.0) -> None:
        self.mean = as_float_array(mean, "mean")
        self.std = as_float_array(std, "std")
        for name, v in (("mean", self.mean), ("std", self.std)):
            if v.ndim > 1 or v.size == 0:
                raise ValueError(f"{name} must be a scalar or a non-empty 1-D array; got shape "
                                 f"{v.shape}")
        if not np.all(self.std > 0):
            raise ValueError(f"std must be positive; got {self.std.min()} among its entries")

    def check_theta(self, theta) -> np.ndarray:
        """``theta`` as a finite 1-D float array whose length matches the prior's, or raise."""
        theta = as_float_array(theta, "theta", ndim=1)
        self._broadcast(theta.shape[0])
        return theta

    def _broadcast(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        for name, v in (("mean", self.mean), ("std", self.std)):
            if v.ndim == 1 and v.shape[0] != n:
                raise ValueError(
                    f"prior must have one {name} per weight (K = {n}) or a scalar; its {name} "
                    f"has {v.shape[0]} entries"
                )
        return np.broadcast_to(self.mean, (n,)), np.broadcast_to(self.std, (n,))

    def log_prob(self, theta: np.ndarray) -> float:
        """``log p(theta)``, normalized."""
        theta = self.check_theta(theta)
        mu, sd = self._broadcast(theta.shape[0])
        z = (theta - mu) / sd
        return float(-0.5 * (z @ z) - np.log(sd).sum() - 0.5 * theta.shape[0] * np.log(2 * np.pi))

    def grad_log_prob(self, theta: np.ndarray) -> np.ndarray:
        """``d log p / dtheta = -(theta - mean) / std^2``."""
        theta = self.check_theta(theta)
        mu, sd = self._broadcast(theta.shape[0])
        return -(theta - mu) / sd**2

    def _value_and_grad(self, n_features: int):
        """``theta -> (log p(theta), d log p / dtheta)`` for thetas of ``n_features`` weights
        already checked, with the prior's constants computed once (for a fit's loop)."""
        mu, sd = (np.array(a, dtype=float) for a in self._broadcast(n_features))
        const = -np.log(sd).sum() - 0.5 * n_features * np.log(2 * np.pi)

        def value_and_grad(theta: np.ndarray) -> tuple[float, np.ndarray]:
            z = (theta - mu) / sd
            return float(const - 0.5 * (z @ z)), -z / sd

        return value_and_grad

    def sample(self, n_features: int, seed=None) -> np.ndarray:
        """One draw of theta, shape (n_features,)."""
        n_features = check_int(n_features, "n_features", low=1)
        mu, sd = self._broadcast(n_features)
        return check_random_state(seed).normal(mu, sd)

    def __repr__(self) -> str:
        return f"GaussianPrior(mean={self.mean.tolist()}, std={self.std.tolist()})"
