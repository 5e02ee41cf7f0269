"""What every learner shares: scikit-learn's estimator conventions, without scikit-learn.

``__init__`` only stores its arguments, under their own names; ``fit`` validates them, builds
what it needs from their current values and sets the learned state, whose names end in ``_``.
:meth:`LearnerBase.get_params` and :meth:`LearnerBase.set_params` read and write the
constructor's arguments, so ``sklearn.base.clone`` gives an equal unfitted learner.
"""

from __future__ import annotations

import inspect

from irl.demonstrations import check_demonstrations
from irl.exceptions import NotFittedError
from irl.mdp import TabularMDP
from irl.observation import check_compatible

__all__ = ["LearnerBase"]

_NO_DEMOS = object()


class LearnerBase:
    """Parameters by name (``get_params``/``set_params``), a readable repr, fitted checks.

    A learner's ``__init__`` stores each argument under its own name and does nothing else;
    ``fit`` checks them and sets the learned state.

    Attributes
    ----------
    mdp : TabularMDP
        The MDP the learner's ``__init__`` was given (every learner takes one).
    observation_model : ObservationModel
        How the demonstrations were observed (likewise).
    """

    @classmethod
    def _param_names(cls) -> list[str]:
        sig = inspect.signature(cls.__init__)
        return [p.name for p in sig.parameters.values()
                if p.name != "self" and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]

    def get_params(self, deep: bool = True) -> dict:
        """The constructor's arguments, ``{name: value}`` (``deep`` is accepted for
        scikit-learn's sake; no parameter is itself an estimator)."""
        return {name: getattr(self, name) for name in self._param_names()}

    def set_params(self, **params):
        """Set constructor arguments by name; returns ``self``. Nothing is validated until
        ``fit``; an unknown name is a ``ValueError``."""
        valid = self._param_names()
        for name, value in params.items():
            if name not in valid:
                raise ValueError(
                    f"set_params got an invalid parameter {name!r} for "
                    f"{type(self).__name__}; valid parameters are {valid}"
                )
            setattr(self, name, value)
        return self

    def __repr__(self) -> str:
        sig = inspect.signature(type(self).__init__)
        shown = []
        for p in sig.parameters.values():
            if p.name == "self" or p.name not in self.__dict__:
                continue
            value = getattr(self, p.name)
            if p.default is not p.empty and _same(value, p.default):
                continue
            shown.append(f"{p.name}={value!r}")
        return f"{type(self).__name__}({', '.join(shown)})"

    # -- checks shared by the learners ----------------------------------------------------

    def _check_problem(self, demos=_NO_DEMOS):
        """Validate ``mdp`` and ``observation_model`` (and ``demos`` when given)."""
        if not isinstance(self.mdp, TabularMDP):
            raise TypeError(f"mdp must be an irl.TabularMDP; got {type(self.mdp).__name__}")
        check_compatible(self.mdp, self.observation_model)
        if demos is _NO_DEMOS:
            return None
        return check_demonstrations(demos, self.observation_model.n_observations)

    def _check_init(self):
        """``init`` as a weight vector of length K, or None."""
        return None if self.init is None else self.mdp.check_theta(self.init, "init")

    def _check_fitted(self, attribute: str = "theta_") -> None:
        if not hasattr(self, attribute):
            raise NotFittedError(
                f"this {type(self).__name__} is not fitted yet; call fit(demos) first"
            )


def _same(a, b) -> bool:
    try:
        return bool(a is b or (type(a) is type(b) and a == b))
    except (TypeError, ValueError):  # arrays
        return False
