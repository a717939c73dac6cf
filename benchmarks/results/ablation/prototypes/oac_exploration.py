"""Prototype (ablation README, section 26): optimistic exploration over pessimistic targets (OAC).

Section 25: the minimum of the two critics in the soft targets holds InvertedPendulum (with K = 20) and stops the
sparse Acrobot's exploration (the policy narrows where the pessimistic values are flat). Optimistic Actor-Critic (OAC,
Ciosek et al. 2019) keeps the pessimistic targets and moves the optimism into the behaviour policy: the exploring action
is drawn from N(m + shift, Sigma), squashed by tanh, where m and Sigma = diag(std^2) are the soft actor's pre-tanh mean
and covariance and shift = sqrt(2 delta) Sigma g / ||g||_Sigma, g the gradient at m of the critics' upper bound
Q_UB = mean_j Q_j + beta_UB * (half their spread) (OAC's eqs. 12-13 with two critics; its MuJoCo values beta_UB 4.66,
delta 23.53 as defaults, ``OAC_BETA`` / ``OAC_DELTA`` to change). Only the exploring action changes: targets, actor
and evaluation are the library's. Patches ``DENFAC._sample_action`` (the soft actor's branch, ``soft_sampling.py``).
Runs ``benchmarks.run`` in this process (``--workers 0``); ``oac_exploration/`` holds its runs.

Usage: ``python -m benchmarks.results.ablation.prototypes.oac_exploration
--algos abl:soft+min+K20 --envs acrobot --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/oac_exploration``
"""

import math
import os
import sys

import torch as th

from benchmarks import run
from benchmarks.results.ablation.prototypes import soft_sampling

BETA_UB = float(os.environ.get("OAC_BETA", "4.66"))
DELTA = float(os.environ.get("OAC_DELTA", "23.53"))


def draw(self, obs: th.Tensor, mean: th.Tensor, log_std: th.Tensor) -> th.Tensor:
    """tanh of a Gaussian sample around the shifted mean m + sqrt(2 delta) Sigma g / ||g||_Sigma (OAC's eq. 12-13)."""
    pre = mean.detach().clone().requires_grad_(True)
    q1, q2 = self.critic.all_q(obs, th.tanh(pre))
    upper = (q1 + q2) / 2 + BETA_UB * (q1 - q2).abs() / 2
    (grad,) = th.autograd.grad(upper.sum(), pre)
    with th.no_grad():
        var = th.exp(2 * log_std)
        norm = th.sqrt((grad * var * grad).sum(dim=1, keepdim=True)).clamp_min(1e-12)
        shifted = mean + math.sqrt(2 * DELTA) * var * grad / norm
        return self.actor.action_dist.actions_from_params(shifted, log_std)


if __name__ == "__main__":
    soft_sampling.patch(draw)
    sys.exit(run.main(sys.argv[1:]))
