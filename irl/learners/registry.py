"""The registry of IRL learners by name: what ``make_estimator`` builds for a domain.

Each learner is a :class:`LearnerSpec` whose ``build(domain, *, seed)`` returns an unfitted
estimator configured with the domain's settings. The four learners of the paper are registered
on import, in this order: ``mmap-birl``, ``map-birl``, ``hidden-data-em``, ``maxent``, then the
behaviour-cloning baselines ``bc`` (face value) and ``bc-em`` (through the observation model),
which learn a policy and no reward (``theta_`` is None). Others can be added with
:func:`register_learner`; a name can be registered once. ``make_estimator``'s ``backend`` goes
to every estimator with a ``backend`` parameter (``get_params``): ``mmap-birl``, ``bc-em``, and
``bc``, which runs no forward-backward and does not use it (HiddenDataEM's E-step has a
time-indexed policy, which the compiled kernel does not take).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from irl.inference import check_backend
from irl.learners.birl import MAPBIRL, MMAPBIRL
from irl.learners.cloning import BehaviorCloning
from irl.learners.maxent import HiddenDataEM, MaxEntIRL

if TYPE_CHECKING:
    from irl.domains.base import Domain

__all__ = [
    "LEARNERS",
    "LearnerSpec",
    "make_estimator",
    "register_learner",
    "unregister_learner",
]


@dataclass(frozen=True)
class LearnerSpec:
    """A named recipe for an estimator.

    Parameters
    ----------
    name : str
        The registry key, e.g. ``"mmap-birl"``: non-empty, no whitespace.
    description : str
        One line saying what the learner is.
    build : callable ``(domain, *, seed) -> estimator``
        An unfitted estimator for ``domain`` (an :class:`irl.domains.Domain`); ``seed`` is an
        int, a ``numpy.random.Generator`` or None, and may be ignored by deterministic learners.

    Attributes
    ----------
    name, description : str
    build : callable
        As given.
    """

    name: str
    description: str
    build: Callable[..., Any]

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise TypeError(f"name must be a str; got {type(self.name).__name__} {self.name!r}")
        if not self.name or any(c.isspace() for c in self.name):
            raise ValueError(f"name must be non-empty without whitespace; got {self.name!r}")
        if not isinstance(self.description, str):
            raise TypeError(
                f"description must be a str; got {type(self.description).__name__}"
            )
        if not self.description.strip() or "\n" in self.description:
            raise ValueError(f"description must be one non-empty line; got {self.description!r}")
        if not callable(self.build):
            raise TypeError(f"build must be callable; got {self.build!r}")


_REGISTRY: dict[str, LearnerSpec] = {}

#: Learner name -> :class:`LearnerSpec`, in registration order (a read-only view; add with
#: :func:`register_learner`).
LEARNERS: Mapping[str, LearnerSpec] = MappingProxyType(_REGISTRY)


def register_learner(spec: LearnerSpec) -> LearnerSpec:
    """Add ``spec`` to :data:`LEARNERS`; a ``ValueError`` if its name is taken.

    A registered learner is a choice of ``onionsort learn --method`` and ``onionsort
    experiment --methods``.

    Parameters
    ----------
    spec : LearnerSpec

    Returns
    -------
    LearnerSpec
        ``spec``.

    Examples
    --------
    >>> import irl
    >>> spec = irl.LearnerSpec("map-birl-b3", "MAP-BIRL with beta 3.",
    ...                        lambda dom, *, seed=None: irl.MAPBIRL(
    ...                            dom.mdp, dom.observation_model, beta=3.0, seed=seed))
    >>> irl.register_learner(spec) is spec, "map-birl-b3" in irl.LEARNERS
    (True, True)
    >>> _ = irl.learners.unregister_learner("map-birl-b3")
    """
    if not isinstance(spec, LearnerSpec):
        raise TypeError(f"spec must be a LearnerSpec; got {type(spec).__name__}")
    if spec.name in _REGISTRY:
        raise ValueError(
            f"a learner named {spec.name!r} is already registered "
            f"({_REGISTRY[spec.name].description}); unregister it first or pick another name"
        )
    _REGISTRY[spec.name] = spec
    return spec


def unregister_learner(name: str) -> LearnerSpec:
    """Remove and return the learner named ``name``; a ``ValueError`` if there is none.

    Parameters
    ----------
    name : str
        A key of :data:`LEARNERS`.

    Returns
    -------
    LearnerSpec
        The learner removed.
    """
    if name not in _REGISTRY:
        raise ValueError(f"name must be one of {tuple(_REGISTRY)}; got {name!r}")
    return _REGISTRY.pop(name)


def make_estimator(name: str, domain: Domain, *, seed=None, backend: str | None = None):
    """The unfitted estimator of the learner ``name``, configured with ``domain``'s settings.

    Parameters
    ----------
    name : str
        A key of :data:`LEARNERS`.
    domain : irl.domains.Domain
    seed : int, Generator or None
        Passed to the learner's ``build``.
    backend : {"numpy", "numba"} or None
        Forward-backward kernels (:data:`irl.inference.BACKENDS`), set on an estimator that
        has a ``backend`` parameter (``get_params``); the others do not run
        forward-backward and are built as they are. None: the estimator's own default.

    Raises
    ------
    ValueError
        If ``name`` is not in :data:`LEARNERS` (the message lists the registered names), or
        ``backend`` is not a backend or cannot run here (:func:`irl.inference.check_backend`).

    Returns
    -------
    estimator
        The learner's class, unfitted (``fit(demos)`` next).
    """
    spec = _REGISTRY.get(name) if isinstance(name, str) else None
    if spec is None:
        raise ValueError(f"method must be one of {tuple(_REGISTRY)}; got {name!r}")
    if backend is not None:
        check_backend(backend)
    estimator = spec.build(domain, seed=seed)
    if backend is not None and _accepts_backend(estimator):
        estimator.set_params(backend=backend)
    return estimator


def _accepts_backend(estimator) -> bool:
    """Whether ``estimator`` has a ``backend`` parameter (in ``get_params``, which
    ``set_params`` then writes), as :class:`MMAPBIRL` has."""
    get_params = getattr(estimator, "get_params", None)
    return callable(get_params) and "backend" in get_params()


def _mmap_birl(domain: Domain, *, seed=None) -> MMAPBIRL:
    return MMAPBIRL(
        domain.mdp, domain.observation_model, beta=domain.beta, prior=domain.prior, seed=seed
    )


def _map_birl(domain: Domain, *, seed=None) -> MAPBIRL:
    return MAPBIRL(
        domain.mdp, domain.observation_model, beta=domain.beta, prior=domain.prior, seed=seed
    )


def _hidden_data_em(domain: Domain, *, seed=None) -> HiddenDataEM:
    return HiddenDataEM(domain.mdp, domain.observation_model)


def _maxent(domain: Domain, *, seed=None) -> MaxEntIRL:
    return MaxEntIRL(domain.mdp, domain.observation_model)


def _bc(domain: Domain, *, seed=None) -> BehaviorCloning:
    return BehaviorCloning(domain.mdp, domain.observation_model, seed=seed)


def _bc_em(domain: Domain, *, seed=None) -> BehaviorCloning:
    return BehaviorCloning(domain.mdp, domain.observation_model, variant="em", seed=seed)


for _spec in (
    LearnerSpec("mmap-birl", "MMAP-BIRL: Bayesian IRL marginalizing hidden, noisy steps exactly.",
                _mmap_birl),
    LearnerSpec("map-birl", "MAP-BIRL: Bayesian IRL reading observed steps at face value.",
                _map_birl),
    LearnerSpec("hidden-data-em", "HiddenDataEM: MaxEnt IRL with EM over the hidden steps.",
                _hidden_data_em),
    LearnerSpec("maxent", "MaxEnt IRL on the runs of observed steps, at face value.", _maxent),
    LearnerSpec("bc", "Behaviour cloning: smoothed counts of the perceived pairs, no reward.",
                _bc),
    LearnerSpec("bc-em", "Behaviour cloning by EM over the hidden pairs through the observation "
                "model.", _bc_em),
):
    register_learner(_spec)
del _spec
