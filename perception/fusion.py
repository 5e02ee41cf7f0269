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

Both rules add one term per view to the log-odds, and a view's term is bounded (probabilities
are clipped to ``[1e-6, 1 - 1e-6]``; a view that shows no onion adds nothing). So after some of
its views an onion's call can be *settled* (:func:`settled`): no values of the views still to
come could move the fused probability across the threshold, and the robot may stop looking
without changing its decision. Under ``noisy-or`` a view showing rot settles a blemish at once
(a clean view lowers the odds by ``1 - visibility`` at most), and a good onion is never settled
early (one more view could show rot); under ``log-odds`` a view can say as much either way, and
a call settles only once the views so far outweigh all those to come.

**Calibrating the fused probability.** Neither rule's fused probability is calibrated as it
stands: the views are not independent given the class, and ``noisy-or`` with a small
``visibility`` leaves a good onion near the prior odds times ``(1 - visibility)^K`` (about 0.2
after 5 clean views), while a view of rot puts a blemished one near 1. A ``calibration``
``(low, high)`` or ``(low, high, form)`` (under ``"powers"``, two powers after it), both
slopes ``> 0``, maps the fused evidence ``E``
(the sum of the views' terms) with one slope on each side of 0. Under ``form`` ``"slopes"``
(the default) the log-odds become ``logit(prior) + low E`` where ``E < 0`` and ``logit(prior) +
high E`` where ``E >= 0``: a temperature a side. Under ``"log"`` they become ``logit(prior) -
low log(1 + |E|)`` and ``logit(prior) + high log(1 + E)``: strong evidence is compressed and
weak evidence kept, so that one slope above 0 need not hedge a blemish seen weakly in one view
in order to temper one seen strongly in many (:data:`CALIBRATION_FORMS`). Under ``"powers"``,
``(low, high, "powers", low_power, high_power)``, each side has a power of its own too:
``logit(prior) - low |E|^low_power`` and ``logit(prior) + high E^high_power``, which can fall
more steeply than ``"log"`` where a good onion's evidence gathers and still compress the strong
evidence of a blemish. Each is monotone (more blemished evidence never lowers the probability)
and leaves the sign of ``E`` alone: at a threshold equal to the prior, every call is the call
uncalibrated; only how sure it is changes. :func:`settled` applies it to its bounds, so that a
call settled under it stays settled.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "CALIBRATION_FORMS",
    "FUSION_RULES",
    "calibration_within_chance",
    "chance_calibration_error",
    "chance_calibration_errors",
    "check_calibration",
    "cost_threshold",
    "expected_calibration_error",
    "fuse",
    "log_odds",
    "logit",
    "precision_recall_curve",
    "settled",
]

FUSION_RULES = ("noisy-or", "log-odds")
#: The forms of a fused ``calibration`` (:func:`fuse`): ``"slopes"``, a temperature each side of
#: the evidence 0; ``"log"``, the slopes on ``log(1 + |E|)``; ``"powers"``, the slopes on
#: ``|E|`` to a power of each side's own.
CALIBRATION_FORMS = ("log", "slopes", "powers")
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


def check_calibration(calibration) -> tuple | None:
    """``calibration`` as ``(low, high, form)``, or ``(low, high, "powers", low_power,
    high_power)``: floats and one of :data:`CALIBRATION_FORMS`, ``"slopes"`` where only ``(low,
    high)`` is given (None stays None).

    Raises
    ------
    ValueError
        Unless it is None, two finite numbers > 0 or those and a form, and under ``"powers"``
        two finite powers > 0 after it (a map that could lower the probability as the evidence
        of a blemish grows is refused).
    """
    if calibration is None:
        return None
    try:
        parts = [calibration] if isinstance(calibration, str) else list(calibration)
    except TypeError:
        parts = []
    form = parts[2] if len(parts) in (3, 5) else "slopes"
    numbers = parts[:2] + parts[3:] if len(parts) in (3, 5) else parts
    try:
        values = [float(x) for x in numbers]
    except (TypeError, ValueError):
        values = []
    if len(values) != (4 if len(parts) == 5 else 2):
        raise ValueError(f"calibration must be two slopes and an optional form (low, high"
                         f"[, form]), or under 'powers' two powers after the form; got "
                         f"{calibration!r}")
    if not all(np.isfinite(v) and v > 0 for v in values):
        raise ValueError(f"calibration must be finite slopes and powers > 0 (monotone); got "
                         f"{calibration!r}")
    if form not in CALIBRATION_FORMS or (form == "powers") != (len(values) == 4):
        raise ValueError(f"calibration must be of a form in {CALIBRATION_FORMS}, with two "
                         f"powers after it exactly under 'powers'; got {calibration!r}")
    return (*values[:2], form, *values[2:])


def fuse(view_p, rule: str = "noisy-or", *, prior: float = 0.5, train_prior: float = 0.5,
         visibility: float = 0.8, calibration=None) -> float:
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
    calibration : (float, float) or (float, float, str) or (float, float, str, float, float) or None
        ``(low, high[, form])``, both slopes ``> 0``: the fused evidence ``E`` scaled by
        ``low`` where it is negative and by ``high`` where it is not, under ``form``
        ``"log"`` its size ``log(1 + |E|)`` first, under ``"powers"`` (two powers after the
        form) its size to its side's power (see the module docstring); None: as fused.

    Raises
    ------
    ValueError
        If ``view_p`` is empty or holds a value outside [0, 1], or an argument is out of range.
    """
    if np.asarray(view_p).size == 0:
        raise ValueError("view_p must hold at least one view's probability; got none")
    odds = log_odds(view_p, rule, prior=prior, train_prior=train_prior, visibility=visibility,
                    calibration=calibration)
    return float(1.0 / (1.0 + np.exp(min(-odds, 700.0))))  # 0 without overflow


def _view_terms(p: np.ndarray, rule: str, train_prior: float, visibility: float) -> np.ndarray:
    """Each view's term (K,) in the fused log-odds under ``rule``."""
    ratio = logit(p) - logit(train_prior)  # each view's log likelihood ratio
    if rule == "log-odds":
        return ratio
    v = float(visibility)
    # log((1 - v) + v L) without overflow: logaddexp of the two terms
    return np.logaddexp(np.log1p(-v) if v < 1 else -np.inf, np.log(v) + ratio)


def _checked(view_p, rule: str, prior, train_prior, visibility) -> tuple[np.ndarray, float,
                                                                          float, float]:
    if rule not in FUSION_RULES:
        raise ValueError(f"rule must be one of {FUSION_RULES}; got {rule!r}")
    p = np.asarray(view_p, float).ravel()
    if not np.all((p >= 0) & (p <= 1)):
        raise ValueError(f"view_p must hold probabilities in [0, 1]; got {p.tolist()}")
    prior = _check_probability(prior, "prior")
    train_prior = _check_probability(train_prior, "train_prior")
    v = float(visibility)
    if rule == "noisy-or" and not 0.0 < v <= 1.0:
        raise ValueError(f"visibility must be in (0, 1]; got {visibility!r}")
    return p, prior, train_prior, v


def log_odds(view_p, rule: str = "noisy-or", *, prior: float = 0.5, train_prior: float = 0.5,
             visibility: float = 0.8, calibration=None) -> float:
    """The fused log-odds that the onion is blemished (:func:`fuse` before the sigmoid); with
    no views, the line's prior log-odds. Arguments as for
    :func:`fuse`."""
    p, prior, train_prior, v = _checked(view_p, rule, prior, train_prior, visibility)
    return _calibrated(float(logit(prior)), float(np.sum(_view_terms(p, rule, train_prior, v))),
                       check_calibration(calibration))


def _calibrated(base: float, evidence, calibration: tuple | None):
    """``base + evidence`` as fused, or with ``evidence`` mapped by ``calibration``: its
    side's slope times its size (under ``"log"``, ``log(1 + size)``; under ``"powers"``,
    ``size`` to its side's power), its sign kept."""
    if calibration is None:
        return base + evidence
    low, high, form, *powers = calibration
    size = abs(evidence)
    if form == "log":
        size = np.log1p(size)
    elif form == "powers":
        size = size ** powers[0 if evidence < 0 else 1]
    return base - low * size if evidence < 0 else base + high * size


def settled(view_p, remaining: int, rule: str = "noisy-or", *, threshold: float = 0.5,
            prior: float = 0.5, train_prior: float = 0.5, visibility: float = 0.8,
            calibration=None) -> bool:
    """Whether the call on an onion seen in views ``view_p`` (those that showed it; possibly
    none) can no longer change: whatever ``remaining`` more views show (or if they miss the
    onion), its fused probability stays on the same side of ``threshold``.

    Each further view adds a term between its values at ``p = 1e-6`` and ``p = 1 - 1e-6`` (or
    nothing, if it misses the onion), so the call is settled when the log-odds stay at or
    above the threshold's after ``remaining`` of the lowest terms, or below it after as many
    of the highest; a ``calibration`` maps both bounds (it is monotone). Other arguments as
    for :func:`fuse`.
    """
    if isinstance(remaining, bool) or not isinstance(remaining, int | np.integer) \
            or remaining < 0:
        raise ValueError(f"remaining must be an int >= 0; got {remaining!r}")
    threshold = _check_probability(threshold, "threshold")
    calibration = check_calibration(calibration)
    odds = log_odds(view_p, rule, prior=prior, train_prior=train_prior, visibility=visibility)
    if remaining == 0:
        return True  # nothing left to see
    low, high = _view_terms(np.array([0.0, 1.0]), rule, train_prior, visibility)
    base = float(logit(prior))
    lowest = _calibrated(base, odds - base + remaining * min(low, 0.0), calibration)
    highest = _calibrated(base, odds - base + remaining * max(high, 0.0), calibration)
    cut = float(np.log(threshold) - np.log1p(-threshold))  # not clipped, as the call is not
    margin = 1e-9 * max(1.0, abs(cut))  # the call itself compares probabilities, not log-odds
    return bool(lowest >= cut + margin or highest < cut - margin)


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


def chance_calibration_errors(p, n_bins: int = 15, draws: int = 200, seed: int = 0
                              ) -> np.ndarray:
    """The expected calibration errors (draws,) that a perfectly calibrated predictor shows
    by chance on probabilities ``p`` (N,): :func:`expected_calibration_error` of ``p``, in
    ``n_bins`` bins, against each of ``draws`` label sets drawn from ``p`` itself (each label
    1 with its probability), the generator seeded by ``seed`` so that the figures are
    reproducible.

    Raises
    ------
    ValueError
        If ``p`` is empty or holds a value outside [0, 1], or ``draws`` is not an int >= 1.
    """
    p = np.asarray(p, float).ravel()
    if p.size == 0 or not np.all((p >= 0) & (p <= 1)):
        raise ValueError(f"p must be a non-empty array of probabilities in [0, 1]; got "
                         f"{p.size} values" + ("" if p.size == 0 else
                                               f" in [{p.min():.3g}, {p.max():.3g}]"))
    if isinstance(draws, bool) or not isinstance(draws, int | np.integer) or draws < 1:
        raise ValueError(f"draws must be an int >= 1; got {draws!r}")
    rng = np.random.default_rng(seed)
    bins = np.minimum((p * n_bins).astype(int), n_bins - 1)
    members = np.zeros((p.size, n_bins))
    members[np.arange(p.size), bins] = 1.0  # each onion's bin, one-hot
    p_sums = p @ members  # a bin's ECE term is |sum(y) - sum(p)| over its onions, / N
    out = np.empty(int(draws))
    for start in range(0, out.size, 256):  # label sets drawn in blocks: the same stream
        labels = rng.random((min(256, out.size - start), p.size)) < p
        out[start:start + len(labels)] = np.abs(labels @ members - p_sums).sum(1) / p.size
    return out


def chance_calibration_error(p, n_bins: int = 15, draws: int = 200, seed: int = 0,
                             quantile: float = 0.5) -> float:
    """The expected calibration error that a perfectly calibrated predictor shows by chance
    on probabilities ``p`` (N,): the ``quantile`` (the median by default) of
    :func:`chance_calibration_errors` over ``draws`` label sets drawn from ``p`` itself.

    ECE is a biased figure on a few onions: with 60 of them a model whose probabilities are
    exactly right still shows about 0.05-0.08. Read a measured ECE beside this floor; it says
    how far below it a bar such as 0.05 can be checked on these onions at all.

    Raises
    ------
    ValueError
        As :func:`chance_calibration_errors`, or if ``quantile`` is not in [0, 1].
    """
    q = _check_probability(quantile, "quantile", open_interval=False)
    return float(np.quantile(chance_calibration_errors(p, n_bins, draws, seed), q))


def calibration_within_chance(p, y, *, quantile: float = 0.9, n_bins: int = 15,
                              draws: int = 1000, seed: int = 0) -> dict:
    """Whether probabilities ``p`` (N,) are as well calibrated on labels ``y`` (N,) as
    chance allows: their :func:`expected_calibration_error` is at or under the ``quantile``
    of the errors a perfectly calibrated predictor shows on the same ``p``
    (:func:`chance_calibration_errors`: labels drawn from ``p`` itself, the same bins).

    A perfectly calibrated predictor passes with probability about ``quantile``; a
    miscalibrated one fails the more surely the more onions there are.

    Returns
    -------
    dict
        ``ece``; ``chance_median`` and ``chance_quantile``, the median and the ``quantile`` of
        the errors by chance; ``quantile``; ``onions`` (N); ``within`` (bool).

    Raises
    ------
    ValueError
        If ``p`` and ``y`` are empty or of two lengths, ``y`` is not 0/1, or an argument is
        out of range.
    """
    p, y = np.asarray(p, float).ravel(), np.asarray(y, float).ravel()
    if not np.all((y == 0) | (y == 1)):
        raise ValueError(f"y must hold labels 0 or 1; got {sorted(set(y.tolist()))[:5]}")
    ece = expected_calibration_error(p, y, n_bins)
    q = _check_probability(quantile, "quantile", open_interval=False)
    chance = chance_calibration_errors(p, n_bins, draws, seed)
    limit = float(np.quantile(chance, q))
    return {"ece": ece, "chance_median": float(np.median(chance)), "chance_quantile": limit,
            "quantile": q, "onions": int(p.size), "within": bool(ece <= limit)}


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
