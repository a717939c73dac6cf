"""Prototype (ablation README, section 25): the soft actor ascends the critics' mean, the targets keep their minimum.

Section 25's traces of ``abl:soft+min+K20`` on the sparse Acrobot: the rewards are 0 almost everywhere, so the
policy's entropy stays far above its target (-dim(A)) and alpha falls to ~0 within 30 episodes; SAC's actor objective
is then E_{a~pi}[min(Q_1, Q_2)(s, a)] alone, and the minimum, the two critics' mean less half their disagreement,
pays the policy to narrow where the critics disagree, i.e. away from what it has not tried. Its std falls from 0.9
to 0.1-0.2 and the acrobot stops swinging. REDQ (Chen et al. 2021) takes the minimum for the targets and the ensemble's
mean for the actor; this patch does the same for DENFAC's soft actor (``Updater.fit_soft_actor`` reads
``critic.target_q(obs, actions, ACTOR_Q)``; ``ACTOR_Q`` = "mean", or "min" as the library). Runs ``benchmarks.run``
in this process (use ``--workers 0``); ``actor_mean/`` holds its runs.

Usage: ``python -m benchmarks.results.ablation.prototypes.actor_mean
--algos abl:soft+min+K20 --envs acrobot --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/actor_mean``
"""

import os
import sys

from benchmarks import run
from sb3_denfac.denfac.updaters import Updater

ACTOR_Q = os.environ.get("ACTOR_Q", "mean")
_fit_soft_actor = Updater.fit_soft_actor


def fit_soft_actor(self, obs, batches=None):
    """The library's soft actor step with the critics combined by ``ACTOR_Q`` in its objective."""
    critic = self.policy.critic
    target_q = critic.target_q
    critic.target_q = lambda o, a, how: target_q(o, a, ACTOR_Q)
    try:
        return _fit_soft_actor(self, obs, batches)
    finally:
        del critic.target_q  # back to the class's method


if __name__ == "__main__":
    Updater.fit_soft_actor = fit_soft_actor
    sys.exit(run.main(sys.argv[1:]))
