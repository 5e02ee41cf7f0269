"""Maximizers of a smooth-almost-everywhere objective given as ``f(theta) -> (value, gradient)``.

Two are offered:

- :func:`maximize_lbfgs`: L-BFGS-B from several starts (the default; it needs a fraction of the
  evaluations of plain gradient ascent and has a principled stopping rule);
- :func:`maximize_gradient_ascent`: the paper's Algorithm 1, ``theta += step * decay^n * grad``,
  stopped when ``max |delta theta| < epsilon (1 - gamma) / gamma``.

A value or gradient that is not finite (NaN or inf, e.g. where the weights are so large that the
prior underflows) is a failed step, never an answer: L-BFGS-B is shown a value above every finite
one seen so far, so its line search backtracks (scipy would otherwise stop there and report
convergence), and gradient ascent halves its step and retries from the last finite point. The
objective must be finite at each start; if it is not, a ``ValueError`` names the start.
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
    per iteration, from a learner's ``history_``; ``(None, [])`` if it records neither.

    Parameters
    ----------
    history : list of dict
        A fitted learner's ``history_``.

    Returns
    -------
    key : str or None
        ``"value"`` or ``"log_likelihood"``.
    values : list of float
        The objective per entry of ``history``.
    """
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
        Objective at ``theta`` (finite).
    n_iter : int
        Iterations summed over all starts.
    history : list of dict
        One entry per finite evaluation: ``start``, ``iteration``, ``value``.
    converged : bool
        Whether the best start met its stopping rule before ``max_iter`` without a failed step
        at the end of its search.
    n_failed_steps : int
        Trial points, over all starts, where the objective was not finite.
    """

    theta: np.ndarray
    value: float
    n_iter: int = 0
    history: list[dict] = field(default_factory=list)
    converged: bool = True
    n_failed_steps: int = 0


class _Guarded:
    """An objective that reports non-finite values and gradients as failures (``None``)."""

    def __init__(self, objective: Objective, start: int) -> None:
        self.objective = objective
        self.start = start
        self.n_failed = 0
        self.best: tuple[float, np.ndarray] | None = None
        self.worst = np.inf

    def __call__(self, theta: np.ndarray) -> tuple[float, np.ndarray] | None:
        theta = np.asarray(theta, float)
        if np.isfinite(theta).all():
            with np.errstate(all="ignore"):
                value, grad = self.objective(theta)
            value, grad = float(value), np.asarray(grad, float)
            if np.isfinite(value) and np.isfinite(grad).all():
                if self.best is None or value > self.best[0]:
                    self.best = (value, theta.copy())
                self.worst = min(self.worst, value)
                return value, grad
        else:
            value = np.nan
        if self.best is None:
            raise ValueError(
                f"the objective must be finite at every start; at start {self.start} "
                f"(theta = {np.array2string(theta, precision=4)}) it is {value}; pass an init "
                "(or prior) whose weights give a finite likelihood"
            )
        self.n_failed += 1
        return None

    def failed_step(self, theta: np.ndarray) -> tuple[float, np.ndarray]:
        """For a minimizer: a value above every finite one seen, rising away from the best
        point, so that a line search rejects the step and shortens it."""
        assert self.best is not None
        ceiling = -self.worst + 1.0 + abs(self.worst)
        d = np.nan_to_num(np.asarray(theta, float) - self.best[1], nan=0.0,
                          posinf=1e150, neginf=-1e150)
        scale = float(np.max(np.abs(d)))
        if scale == 0.0:
            return ceiling, np.zeros_like(d)
        u = d / scale
        q2 = float(u @ u)
        # ceiling + log(1 + |d|^2), and its gradient 2 d / (1 + |d|^2), without overflow.
        value = ceiling + float(np.logaddexp(0.0, 2.0 * np.log(scale) + np.log(q2)))
        grad = 2.0 * u / (1.0 / scale + scale * q2)
        return value, grad


def maximize_lbfgs(
    objective: Objective, starts: list[np.ndarray], *, max_iter: int = 200, tol: float = 1e-6,
    warn: bool = True,
) -> OptimizationResult:
    """Maximize with L-BFGS-B from each start; return the best result.

    ``tol`` is the relative reduction of the objective at which a start stops (scipy's
    ``ftol``); the projected-gradient tolerance is ``tol`` too. A non-finite value is a failed
    line-search step (see the module docstring). ``warn=False`` leaves the
    :class:`ConvergenceWarning` to the caller.

    Parameters
    ----------
    objective : callable ``theta -> (value, gradient)``
        The function to maximize and its gradient, shape (K,).
    starts : list of ndarray of shape (K,)
        At least one starting point.
    max_iter : int
        Iterations per start.
    tol : float
    warn : bool
        Warn when the best start did not converge.

    Returns
    -------
    OptimizationResult
        The start of highest value, its iterations summed over every start.
    """
    if not starts:
        raise ValueError("starts must hold at least one starting point; got none")
    best: OptimizationResult | None = None
    history: list[dict] = []
    n_iter = n_failed = 0
    for i, x0 in enumerate(starts):
        guarded = _Guarded(objective, i)
        seen: dict[bytes, float] = {}  # the value at every finite point evaluated
        trace: list[float] = []

        def neg(theta, _g=guarded, _trace=trace, _seen=seen):
            out = _g(theta)
            if out is None:
                return _g.failed_step(theta)
            _seen[np.asarray(theta, float).tobytes()] = out[0]
            _trace.append(out[0])
            return -out[0], -out[1]

        res = minimize(
            neg, np.asarray(x0, float), jac=True, method="L-BFGS-B",
            options={"maxiter": max_iter, "ftol": tol, "gtol": tol},
        )
        history.extend({"start": i, "iteration": k, "value": v} for k, v in enumerate(trace))
        n_iter += int(res.nit)
        n_failed += guarded.n_failed
        theta = np.asarray(res.x, float)
        value = seen.get(theta.tobytes())
        if value is None or value < guarded.best[0]:
            # Never a failed point; and near a kink (a boundary between greedy policies) the
            # search can end below a point it has seen: return the best one.
            value, theta = guarded.best
        # 1: iteration limit; 2: the line search failed, which at an optimum is rounding and
        # after non-finite trial points means the search was blocked.
        converged = res.status == 0 or (res.status == 2 and not guarded.n_failed)
        if guarded.n_failed and res.status == 0:
            converged = False  # scipy may call a search blocked by failed steps converged
        if best is None or value > best.value:
            best = OptimizationResult(theta=theta, value=value, converged=converged)
    assert best is not None
    best.n_iter, best.history, best.n_failed_steps = n_iter, history, n_failed
    if warn and not best.converged:
        warnings.warn(_stop_message("L-BFGS-B", max_iter, f"reaching tol={tol}", n_failed),
                      ConvergenceWarning, stacklevel=3)
    return best


def _stop_message(name: str, max_iter: int, goal: str, n_failed: int) -> str:
    if n_failed:
        return (f"{name} stopped before {goal}: the objective was not finite at {n_failed} "
                f"trial point(s); the result is the best finite point found")
    return f"{name} stopped at max_iter={max_iter} before {goal}"


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
    ``threshold = epsilon (1 - gamma) / gamma``). A step to a point where the objective is not
    finite is undone and the step halved (it still counts as an iteration).

    Parameters
    ----------
    objective : callable ``theta -> (value, gradient)``
    starts : list of ndarray of shape (K,)
        At least one starting point.
    step_size : float
        The first step's size.
    decay : float in (0, 1]
        The step's factor per iteration.
    threshold : float
        The stopping rule's bound on the largest weight change.
    max_iter : int
        Iterations per start.

    Returns
    -------
    OptimizationResult
        The start of highest value.
    """
    if not starts:
        raise ValueError("starts must hold at least one starting point; got none")
    best: OptimizationResult | None = None
    history: list[dict] = []
    n_iter_total = n_failed = 0
    for i, x0 in enumerate(starts):
        guarded = _Guarded(objective, i)
        theta = np.asarray(x0, float).copy()
        value, grad = guarded(theta)  # raises if the start is not finite
        converged = False
        shrink = 1.0
        best_theta, best_value = theta.copy(), value
        for n in range(max_iter):
            n_iter_total += 1
            new = theta + shrink * step_size * decay**n * grad
            out = guarded(new)
            if out is None:
                shrink *= 0.5
                continue
            delta = float(np.max(np.abs(new - theta)))
            theta, (value, grad) = new, out
            history.append({"start": i, "iteration": n, "value": value})
            if value > best_value:
                best_theta, best_value = theta.copy(), value
            if delta < threshold:
                converged = True
                break
        n_failed += guarded.n_failed
        if best is None or best_value > best.value:
            best = OptimizationResult(theta=best_theta, value=best_value, converged=converged)
    assert best is not None
    best.n_iter, best.history, best.n_failed_steps = n_iter_total, history, n_failed
    if not best.converged:
        warnings.warn(
            f"gradient ascent stopped at max_iter={max_iter} before the step fell below "
            f"{threshold:.3g}" + (f" ({n_failed} failed step(s) where the objective was not "
                                  "finite)" if n_failed else ""),
            ConvergenceWarning, stacklevel=3,
        )
    return best
