"""Warnings and errors raised by the library."""

__all__ = ["ConvergenceWarning", "NotFittedError"]


class ConvergenceWarning(UserWarning):
    """An iterative solver or optimizer stopped at ``max_iter`` before meeting ``tol``."""


class NotFittedError(ValueError, AttributeError):
    """A learner's fitted state was asked for before ``fit`` (as scikit-learn's)."""
