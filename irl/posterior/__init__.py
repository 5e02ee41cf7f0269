"""The posterior over reward weights, and how sure the learned policy is in each state.

Layouts: ``theta[n, k]`` posterior samples, ``policies[n, s]`` the greedy action of each
sample, ``confidence[s, a]``, ``Q[n, s, a]`` each sample's optimal Q-function.

MMAP-BIRL's log posterior ``log p(theta) + sum_demos log P(o | theta)`` is exact (every hidden
and noisy step marginalized by forward-backward) and so is its gradient. Two ways to draw from
it (:func:`sample_posterior`):

- ``"laplace"``: a Gaussian at the MAP whose precision is minus the Hessian of the exact log
  posterior, by central differences of the exact gradient (2K gradients). Fast, and exact when
  the posterior is Gaussian; blind to skew and to a second mode.
- ``"mcmc"``: Hamiltonian Monte Carlo with dynamic integration time and multinomial sampling
  (the No-U-Turn family) from the ``mici`` library, on the exact gradient, with the step size
  tuned by dual averaging during warm-up. The chains run in coordinates whitened by the Laplace
  covariance (``theta = MAP + L z``), so the sampler sees a near-standard normal. We chose a
  gradient sampler over an ensemble one because the exact gradient costs what the likelihood
  costs: on onion sorting (12 demonstrations, 6 weights), ``emcee``'s stretch move needed an
  autocorrelation time of about 43 steps and 29,000 likelihoods for split R-hat 1.09-1.16,
  where these chains reach R-hat below 1.01 with 21,000 gradients.

The greedy policy of a sample is the robot's policy had that sample been the truth;
:meth:`Posterior.action_confidence` is the share of samples whose greedy policy takes each
action in each state. :func:`map_policy_risk` scores the MAP policy against every sample (value
at risk), :func:`expected_regret` says where another demonstration is worth most.

Example::

    dom = irl.domains.onion_sorting(noise=0.45)
    demos, _ = dom.sample(n=2, length=10, occlusion=0.2, seed=0)
    est = irl.MMAPBIRL(dom.mdp, dom.observation_model, beta=dom.beta, prior=dom.prior)
    post = sample_posterior(est, demos, n_samples=1000, seed=0, method="laplace")
    post.action_confidence()          # (48, 5), rows sum to 1
"""

from irl.posterior.importance import IMPORTANCE_ADAPTATIONS, IMPORTANCE_PROPOSALS
from irl.posterior.result import Diagnostics, Posterior, SwapComponent, load_posterior
from irl.posterior.risk import PolicyRisk, expected_regret, map_policy_risk
from irl.posterior.sampling import METHODS, sample_posterior
from irl.posterior.swaps import LAPLACE_SHARE, swap_readings

__all__ = [
    "IMPORTANCE_ADAPTATIONS",
    "IMPORTANCE_PROPOSALS",
    "LAPLACE_SHARE",
    "METHODS",
    "Diagnostics",
    "PolicyRisk",
    "Posterior",
    "SwapComponent",
    "expected_regret",
    "load_posterior",
    "map_policy_risk",
    "sample_posterior",
    "swap_readings",
]
