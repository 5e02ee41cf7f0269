"""Warnings raised by the library."""

__all__ = ["ConvergenceWarning"]


class ConvergenceWarning(UserWarning):
    """An iterative solver or optimizer stopped at ``max_iter`` before meeting ``tol``."""
