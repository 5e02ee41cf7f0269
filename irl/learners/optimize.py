"""Maximizers of a smooth-almost-everywhere objective given as ``f(theta) -> (value, gradient)``.

Two are offered:

- :func:`maximize_lbfgs`: L-BFGS-B from several starts (the default; it needs a fraction of the
  evaluations of plain gradient ascent and has a principled stopping rule);
- :func:`maximize_gradient_ascent`: the paper's Algorithm 1, ``theta += step * decay^n * grad``,
  stopped when ``max |delta theta| < epsilon (1 - gamma) / gamma``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import minimize

from irl.exceptions import ConvergenceWarning

__all__ = ["OBJECTIVE_KEYS", "OptimizationResult", "maximize_gradient_ascent", "maximize_lbfgs",
           "objective_curve"]

#: Keys under which a learner's ``history_`` records its objective: ``value`` (the log
#: posterior of the Bayesian learners) or ``log_likelihood`` (HiddenDataEM, MaxEnt).
OBJECTIVE_KEYS = ("value", "log_likelihood")


def objective_curve(history) -> tuple[str | None, list[float]]:
    """The objective's key (the first of :data:`OBJECTIVE_KEYS` in ``history[0]``) and its value
    per iteration, from a learner's ``history_``; ``(None, [])`` if it records neither."""
    key = next((k for k in OBJECTIVE_KEYS if history and k in history[0]), None)
    return key, ([float(h[key]) for h in history] if key else [])

Objective = Callable[[np.ndarray], tuple[float, np.ndarray]]


@dataclass
class OptimizationResult:
    """The best point found and how the search went.

    Attributes
    ----------
    theta : ndarray of shape (K,)
    value : float
        Objective at ``theta``.
    n_iter : int
        Iterations summed over all starts.
    history : list of dict
        One entry per iteration: ``start``, ``iteration``, ``value``.
    converged : bool
        Whether the best start met its stopping rule before ``max_iter``.
    """

    theta: np.ndarray
    value: float
    n_iter: int = 0
    history: list[dict] = field(default_factory=list)
    converged: bool = True


def maximize_lbfgs(
    objective: Objective, starts: list[np.ndarray], *, max_iter: int = 200, tol: float = 1e-6
) -> OptimizationResult:
    """Maximize with L-BFGS-B from each start; return the best result.

    ``tol`` is the relative reduction of the objective at which a start stops (scipy's
    ``ftol``); the projected-gradient tolerance is ``tol`` too.
    """
    best: OptimizationResult | None = None
    history: list[dict] = []
    n_iter = 0
    for i, x0 in enumerate(starts):
        trace: list[float] = []

        def neg(theta, _trace=trace):
            value, grad = objective(theta)
            _trace.append(value)
            return -value, -grad

        res = minimize(
            neg, np.asarray(x0, float), jac=True, method="L-BFGS-B",
            options={"maxiter": max_iter, "ftol": tol, "gtol": tol},
        )
        history.extend({"start": i, "iteration": k, "value": v} for k, v in enumerate(trace))
        n_iter += int(res.nit)
        converged = res.status != 1  # 1: iteration limit reached
        if best is None or -res.fun > best.value:
            best = OptimizationResult(
                theta=np.asarray(res.x), value=float(-res.fun), converged=converged
            )
    assert best is not None, "at least one start is required"
    best.n_iter, best.history = n_iter, history
    if not best.converged:
        warnings.warn(
            f"L-BFGS-B stopped at max_iter={max_iter} before reaching tol={tol}",
            ConvergenceWarning, stacklevel=3,
        )
    return best


def maximize_gradient_ascent(
    objective: Objective,
    starts: list[np.ndarray],
    *,
    step_size: float = 0.01,
    decay: float = 0.95,
    threshold: float = 1e-4,
    max_iter: int = 500,
) -> OptimizationResult:
    """The paper's gradient ascent with a decaying step, from each start; return the best.

    Stops a start when ``max_k |theta_new - theta|_k < threshold`` (Algorithm 1 uses
    ``threshold = epsilon (1 - gamma) / gamma``).
    """
    best: OptimizationResult | None = None
    history: list[dict] = []
    n_iter_total = 0
    for i, x0 in enumerate(starts):
        theta = np.asarray(x0, float).copy()
        value, grad = objective(theta)
        converged = False
        best_theta, best_value = theta.copy(), value
        for n in range(max_iter):
            new = theta + step_size * decay**n * grad
            delta = float(np.max(np.abs(new - theta)))
            theta = new
            value, grad = objective(theta)
            history.append({"start": i, "iteration": n, "value": value})
            n_iter_total += 1
            if value > best_value:
                best_theta, best_value = theta.copy(), value
            if delta < threshold:
                converged = True
                break
        if best is None or best_value > best.value:
            best = OptimizationResult(theta=best_theta, value=best_value, converged=converged)
    assert best is not None, "at least one start is required"
    best.n_iter, best.history = n_iter_total, history
    if not best.converged:
        warnings.warn(
            f"gradient ascent stopped at max_iter={max_iter} before the step fell below "
            f"{threshold:.3g}",
            ConvergenceWarning, stacklevel=3,
        )
    return best
