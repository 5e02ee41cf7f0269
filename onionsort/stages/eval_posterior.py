"""Stage ``eval-posterior``: how well MMAP-BIRL's posterior knows what it does not know, on
synthetic problems where the expert is known.

Each problem (:class:`PosteriorEvalConfig`) draws a few short demonstrations from a domain,
samples MMAP-BIRL's posterior over reward weights (:func:`irl.posterior.sample_posterior`, the
domain's beta and prior) and scores it against the expert's greedy action
(``domain.optimal_policy()``) on two sets of states: those the expert visited in the
demonstrations (each once per problem), and every state of the domain (those no demonstration
showed too). The scores, over all (problem, state) pairs of a set:

- **coverage** at each level of :data:`LEVELS`: the share of pairs whose credible action set
  (:meth:`~irl.posterior.Posterior.credible_actions`) holds the expert's action, and the
  sets' mean size;
- **AUROC**: how well ``1 -`` the posterior's confidence in the MAP policy's action ranks the
  pairs where that action differs from the expert's above those where it agrees
  (Mann-Whitney, ties averaged; None without both kinds).

Also each problem's largest R-hat (None for the Laplace draws, which are independent), the
chains' divergences, and the seconds each problem's sampling took (which, unlike everything
else, depend on the machine).

Example::

    from onionsort.stages.eval_posterior import PosteriorEvalConfig, eval_posterior
    result = eval_posterior(PosteriorEvalConfig(domain="sorting", method="laplace"))
    result["visited"]["coverage"]["0.90"], result["visited"]["auroc"]
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from onionsort.configs.eval_posterior import LEVELS, PosteriorEvalConfig
from onionsort.stages.base import log_config
from onionsort.stages.parallel import run_pieces

__all__ = ["LEVELS", "PosteriorEvalConfig", "auroc", "eval_posterior", "score_problem"]

#: The two sets of states scored: those the expert visited, and every state.
SCOPES = ("visited", "all")


def auroc(scores, labels) -> float | None:
    """Area under the ROC curve of ``scores`` for ``labels`` (True: positive), by the
    Mann-Whitney rank formula with tied scores given their average rank; None without both
    classes."""
    from scipy.stats import rankdata

    labels = np.asarray(labels, bool)
    n_pos, n_neg = int(labels.sum()), int((~labels).sum())
    if n_pos == 0 or n_neg == 0:
        return None
    ranks = rankdata(np.asarray(scores, float))  # ties averaged
    return float((ranks[labels].sum() - n_pos * (n_pos + 1) / 2) / (n_pos * n_neg))


@dataclass(frozen=True)
class _Problem:
    """One problem: a piece of the stage."""

    domain: str
    noise: float
    occlusion: float
    trajectories: int
    length: int
    samples: int
    method: str
    backend: str
    seed: int


def score_problem(problem: _Problem) -> dict:
    """Sample one problem's posterior and score it on each scope of :data:`SCOPES`: per
    level, which pairs' credible sets hold the expert's action and the sets' sizes; per
    state, ``1 -`` the confidence in the MAP action and whether that action is wrong."""
    import irl
    from irl.experiments import DOMAINS
    from irl.posterior import sample_posterior

    dom = DOMAINS[problem.domain](noise=problem.noise)
    expert = np.asarray(dom.optimal_policy())
    demos, trajectories = dom.sample(n=problem.trajectories, length=problem.length,
                                     occlusion=problem.occlusion, seed=problem.seed)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior,
                       backend=problem.backend)
    start = time.perf_counter()
    post = sample_posterior(est, demos, n_samples=problem.samples, seed=problem.seed,
                            method=problem.method)
    seconds = time.perf_counter() - start
    r_hat = post.diagnostics.max_r_hat()
    out = {"seed": problem.seed, "seconds": seconds,
           "max_r_hat": float(r_hat) if np.isfinite(r_hat) else None,
           "divergent": int(post.diagnostics.n_divergent)}
    visited = np.unique(np.concatenate([tr.states for tr in trajectories]))
    confidence = post.map_confidence()
    for scope, states in zip(SCOPES, (visited, np.arange(dom.mdp.n_states)), strict=True):
        sets = {level: post.credible_actions(level) for level in LEVELS}
        out[scope] = {
            "covered": {level: [int(expert[s]) in sets[level][s] for s in states]
                        for level in LEVELS},
            "size": {level: [len(sets[level][s]) for s in states] for level in LEVELS},
            "risk": (1.0 - confidence[states]).tolist(),
            "map_wrong": (post.map_policy[states] != expert[states]).tolist()}
    return out


def _summary(problems: list[dict], scope: str) -> dict:
    """Coverage and mean set size per level, and the AUROC, over one scope's pairs."""
    rows = [p[scope] for p in problems]
    wrong = np.concatenate([r["map_wrong"] for r in rows]).astype(bool)
    risk = np.concatenate([r["risk"] for r in rows])
    return {
        "pairs": int(wrong.size),
        "coverage": {f"{lv:.2f}": float(np.mean(np.concatenate([r["covered"][lv]
                                                                 for r in rows])))
                     for lv in LEVELS},
        "mean_set_size": {f"{lv:.2f}": float(np.mean(np.concatenate([r["size"][lv]
                                                                      for r in rows])))
                          for lv in LEVELS},
        "auroc": auroc(risk, wrong), "map_wrong": int(wrong.sum()),
        "map_right": int((~wrong).sum())}


def eval_posterior(config: PosteriorEvalConfig) -> dict:
    """Score the posterior on ``config.problems`` problems (see the module docstring).

    Returns
    -------
    dict
        ``config`` (the settings), ``visited`` and ``all`` (for each scope: ``pairs``,
        ``coverage`` and ``mean_set_size`` by level (``"0.90"``), ``auroc``, ``map_wrong`` and
        ``map_right``, the pairs where the MAP action differs from the expert's and where it
        agrees), ``max_r_hat`` (each problem's, None for Laplace), ``divergent`` (in all) and
        ``seconds`` (each problem's sampling).
    """
    log_config("eval-posterior", config)
    pieces = [_Problem(config.domain, config.noise, config.occlusion, config.trajectories,
                       config.length, config.samples, config.method, config.backend,
                       config.seed + i) for i in range(config.problems)]
    results: list[dict | None] = [None] * len(pieces)
    for i, result in run_pieces(score_problem, pieces, config,
                                names=[f"problem {p.seed}" for p in pieces],
                                desc="eval-posterior", unit="problem"):
        results[i] = result
    settings = {k: v for k, v in asdict(config).items()
                if k not in ("executor", "workers", "ray_address")}
    return {"config": settings,
            **{scope: _summary(results, scope) for scope in SCOPES},
            "max_r_hat": [r["max_r_hat"] for r in results],
            "divergent": sum(r["divergent"] for r in results),
            "seconds": [round(r["seconds"], 3) for r in results]}
