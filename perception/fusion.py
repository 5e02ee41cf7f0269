"""From views to a decision: fusing per-view probabilities, the cost threshold, calibration error.

Pure functions on numbers, no model. Layouts: per-view probabilities ``p[k]`` (K,) that the
onion is blemished, each in (0, 1); per-onion probabilities and labels ``p[n]``, ``y[n]`` (N,).

Two fusion rules turn the K views of one onion into one probability (:data:`FUSION_RULES`):

- ``"noisy-or"``, on *a blemish seen*: each view's probability ``q_k`` is that the view shows
  rot. A good onion shows rot in no view; a blemished one shows it in each view with
  probability ``visibility`` (rot can face away, or lie under the gripper), independently. A
  view's calibrated ``q_k`` (under the share ``train_prior`` of rot views it was calibrated to)
  gives the likelihood ratio ``L_k`` of "rot in view" against "none", and the posterior odds
  of a blemish are the line's prior odds times ``prod_k (1 - visibility + visibility L_k)``:
  one view that shows rot is enough, and a view that shows none lowers the odds only by
  ``1 - visibility`` (it may have looked at a clean side).
- ``"log-odds"``: naive Bayes on the onion's class. Each view's probability ``p_k`` is that
  the onion is blemished, calibrated under ``train_prior``; dividing that prior out leaves the
  view's likelihood ratio, and the fused log-odds are the line's prior log-odds plus their
  sum. Exact if the views were independent given the class; they are not (a blemished onion
  shows the same clean side to several views), so each clean view counts against the onion as
  if it were new evidence.
The robot bins an onion when its fused probability reaches the threshold that minimises the
expected cost, ``waste / (waste + miss)`` (:func:`cost_threshold`), where ``miss`` is the cost of
a blemished onion left on the line and ``waste`` that of a good onion in the bin.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "FUSION_RULES",
    "cost_threshold",
    "expected_calibration_error",
    "fuse",
    "logit",
    "precision_recall_curve",
]

FUSION_RULES = ("noisy-or", "log-odds")
_EPS = 1e-6


def logit(p) -> np.ndarray:
    """``log(p / (1 - p))``, with ``p`` clipped to ``[1e-6, 1 - 1e-6]``."""
    q = np.clip(np.asarray(p, float), _EPS, 1 - _EPS)
    return np.log(q) - np.log1p(-q)


def _check_probability(value, name: str, *, open_interval: bool = True) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number in (0, 1); got {value!r}") from None
    if not (0.0 < v < 1.0 if open_interval else 0.0 <= v <= 1.0):
        bounds = "(0, 1)" if open_interval else "[0, 1]"
        raise ValueError(f"{name} must be in {bounds}; got {value!r}")
    return v


def fuse(view_p, rule: str = "noisy-or", *, prior: float = 0.5, train_prior: float = 0.5,
         visibility: float = 0.8) -> float:
    """One probability that the onion is blemished from its views' probabilities.

    Parameters
    ----------
    view_p : sequence of float, length K >= 1
        Each view's calibrated probability: that the view shows rot (``"noisy-or"``), or that
        the onion is blemished (``"log-odds"``).
    rule : {"noisy-or", "log-odds"}
        See the module docstring.
    prior : float in (0, 1)
        The line's share of blemished onions.
    train_prior : float in (0, 1)
        The share (of rot views, or of blemished onions) the view probabilities are calibrated
        to.
    visibility : float in (0, 1]
        The chance that a view of a blemished onion shows its rot (``"noisy-or"`` only).

    Raises
    ------
    ValueError
        If ``view_p`` is empty or holds a value outside [0, 1], or an argument is out of range.
    """
    if rule not in FUSION_RULES:
        raise ValueError(f"rule must be one of {FUSION_RULES}; got {rule!r}")
    p = np.asarray(view_p, float).ravel()
    if p.size == 0:
        raise ValueError("view_p must hold at least one view's probability; got none")
    if not np.all((p >= 0) & (p <= 1)):
        raise ValueError(f"view_p must hold probabilities in [0, 1]; got {p.tolist()}")
    prior = _check_probability(prior, "prior")
    train_prior = _check_probability(train_prior, "train_prior")
    ratio = logit(p) - logit(train_prior)  # each view's log likelihood ratio
    if rule == "noisy-or":
        v = float(visibility)
        if not 0.0 < v <= 1.0:
            raise ValueError(f"visibility must be in (0, 1]; got {visibility!r}")
        # log((1 - v) + v L) without overflow: logaddexp of the two terms
        terms = np.logaddexp(np.log1p(-v) if v < 1 else -np.inf, np.log(v) + ratio)
        odds = logit(prior) + float(np.sum(terms))
    else:
        odds = logit(prior) + float(np.sum(ratio))
    return float(1.0 / (1.0 + np.exp(-odds)))


def cost_threshold(miss: float, waste: float) -> float:
    """The probability of a blemish above which binning costs less than keeping.

    Keeping an onion costs ``miss * P(blemished)`` in expectation, binning it
    ``waste * (1 - P(blemished))``; binning is cheaper from ``waste / (waste + miss)`` on.

    Raises
    ------
    ValueError
        If a cost is negative, not finite, or both are zero.
    """
    for name, value in (("miss", miss), ("waste", waste)):
        if isinstance(value, bool) or not isinstance(value, int | float | np.number) \
                or not np.isfinite(value) or value < 0:
            raise ValueError(f"{name} must be a finite cost >= 0; got {value!r}")
    if miss + waste == 0:
        raise ValueError("miss and waste cannot both be 0: nothing would decide")
    return float(waste) / (float(miss) + float(waste))


def expected_calibration_error(p, y, n_bins: int = 15) -> float:
    """Expected calibration error of probabilities ``p`` (N,) for binary labels ``y`` (N,).

    The share-weighted mean, over ``n_bins`` equal-width bins of the predicted probability of
    the positive class, of ``|mean(y) - mean(p)|`` in each bin (Guo et al., 2017, on the
    probability of class 1).
    """
    p, y = np.asarray(p, float).ravel(), np.asarray(y, float).ravel()
    if p.shape != y.shape or p.size == 0:
        raise ValueError(f"p and y must be non-empty and of one length; got {p.size} and "
                         f"{y.size}")
    bins = np.minimum((p * n_bins).astype(int), n_bins - 1)
    total = 0.0
    for b in np.unique(bins):
        mine = bins == b
        total += mine.sum() * abs(y[mine].mean() - p[mine].mean())
    return float(total / p.size)


def precision_recall_curve(p, y) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Precision, recall and the threshold of each point of the curve, for calling the
    positive class (blemished) at ``p >= threshold``, thresholds the distinct values of ``p``
    from the highest down (precision is 1 where nothing is called)."""
    p, y = np.asarray(p, float).ravel(), np.asarray(y, bool).ravel()
    if p.shape != y.shape or p.size == 0:
        raise ValueError(f"p and y must be non-empty and of one length; got {p.size} and "
                         f"{y.size}")
    order = np.argsort(-p, kind="stable")
    p_sorted, y_sorted = p[order], y[order]
    last = np.r_[np.flatnonzero(np.diff(p_sorted)), p.size - 1]  # last index of each value
    tp = np.cumsum(y_sorted)[last]
    called = last + 1
    precision = tp / called
    recall = tp / max(int(y.sum()), 1)
    return precision, recall, p_sorted[last]
