"""Stage ``suggest``: where another demonstration would help the learned policy most.

Reads a learning run's posterior (``posterior.npz`` of ``onionsort learn --posterior``) and
ranks the task's states by the expected regret of the learned policy's action there,
``E[max_a Q(s, a) - Q(s, pi(s))]`` under the posterior (:func:`irl.posterior.expected_regret`):
the value of perfect information about the best action in that state. A demonstration that
shows the sorter in that state is worth at most that much to the robot there; states where
every posterior sample agrees with the policy are worth nothing and are not listed, nor are
states no sequence of actions reaches from the start (no demonstration can show them).

Example::

    from onionsort.stages.suggest import SuggestConfig, suggest
    rows = suggest(SuggestConfig(run=Path("runs/learn-mmap"), top=5))
"""

from __future__ import annotations

from pathlib import Path

from onionsort.configs.suggest import SuggestConfig
from onionsort.stages.base import log_config

__all__ = ["SuggestConfig", "suggest"]


def suggest(config: SuggestConfig) -> list[dict]:
    """The states most worth another demonstration, the most first: each with its index,
    name, description in the task's words, the learned action, its confidence and the
    expected regret (reward units). Empty when the posterior agrees with the policy
    everywhere."""
    from irl.domains.onion_sorting import describe_state, onion_sorting
    from irl.posterior import expected_regret, load_posterior
    from onionsort.stages.learn import POSTERIOR_FILE

    log_config("suggest", config)
    path = Path(config.run) / POSTERIOR_FILE
    if not path.is_file():
        raise FileNotFoundError(f"{config.run} holds no posterior (no {POSTERIOR_FILE}); learn "
                                "with `onionsort learn ... --posterior` first")
    posterior = load_posterior(path)
    domain = onion_sorting()
    regret = expected_regret(posterior, domain.mdp)
    confidence = posterior.map_confidence()
    reachable = domain.mdp.reachable_states()
    order = [int(s) for s in regret.argsort(kind="stable")[::-1]
             if regret[s] > 1e-12 and reachable[s]][:config.top]
    return [{"state": s, "name": domain.state_names[s], "description": describe_state(s),
             "action": domain.action_names[int(posterior.map_policy[s])],
             "confidence": float(confidence[s]), "expected_regret": float(regret[s])}
            for s in order]
