"""Prototype, not in the library (ablation README, section 15): the actor ascends both Q networks, not Q_1 alone.

With ``n_critics=2`` DENFAC's actor ascends Q_1 (eq. 5 on the first network, as TD3), while SAC's ascends
min(Q_1, Q_2)(s, a) and REDQ's the ensemble's mean. Here each actor step of the fast updater takes dQ/da from both
networks at a = pi(s): ``AC_HOW=min`` keeps, per sample, the gradient of the lower one (SAC's actor: pessimistic
where the two critics disagree, i.e. off the data), ``AC_HOW=mean`` their average. The targets of eq. (4) are
unchanged (the critics' mean at a smoothed next action, 0.5's default). Runs ``benchmarks.run`` in this process with
the patch (use ``--workers 0``); ``actor_critics/`` holds its runs.

Usage: ``AC_HOW=min python actor_critics.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/actor_critics``
"""

import os
import sys

import torch as th

from benchmarks import run
from sb3_denfac.denfac import eager_steps, fast

HOW = os.environ.get("AC_HOW", "min")
if HOW not in ("min", "mean"):
    raise ValueError(f"AC_HOW must be 'min' or 'mean', not {HOW!r}")
_EvalCritic = eager_steps.EvalCritic
_fit_actor = fast.FastUpdater.fit_actor
_context: list = []  # (updater, feature-major observations) of the actor fit in progress


class PairCritic:
    """Q_1 and Q_2 for ``eager_steps.actor_step``: the interface of ``EvalCritic`` it uses (action_gradient,
    inverted, subset)."""

    def __init__(self, critics, nets, obs):
        self.critics, self.nets, self.obs = critics, nets, obs
        self.inverted = critics[0].inverted

    def subset(self, idx):
        return PairCritic([c.subset(idx) for c in self.critics], self.nets, self.obs[:, idx])

    def action_gradient(self, pi, want_value):
        (g1, value), (g2, _) = (c.action_gradient(pi, want_value) for c in self.critics)
        if HOW == "mean":
            return g1.add_(g2).mul_(0.5), value
        inputs = th.cat([self.obs, pi], dim=0)
        q1, q2 = (net.eval_forward(inputs) for net in self.nets)  # (1, N) each
        return th.where(q1 <= q2, g1, g2), value


class PairingEvalCritic(_EvalCritic):
    """Built by ``fit_actor`` for Q_1: a ``PairCritic`` of Q_1 and Q_2 from the updater's second network instead
    (``EvalCritic.subset`` still makes plain copies of this class)."""

    def __new__(cls, affines, slopes, obs_part, action_dim, sizes, n):
        return pair(affines, slopes, obs_part, action_dim, sizes, n)


def pair(affines, slopes, obs_part, action_dim, sizes, n):
    updater, obs_t = _context[-1]
    first = _EvalCritic(affines, slopes, obs_part, action_dim, sizes, n)
    if len(updater.critic_nets) < 2:
        return first
    net2 = updater.critic_nets[1]
    affines2 = net2.eval_affines()
    w, b = affines2[0]
    obs_part2 = th.addmm(b.unsqueeze(1), w[:, :-action_dim], obs_t)
    second = _EvalCritic(affines2, net2.spec.slopes, obs_part2, action_dim, net2.spec.sizes, n)
    return PairCritic([first, second], updater.critic_nets[:2], obs_t)


def fit_actor(self, obs, batches=None):
    _context.append((self, obs.float().t().contiguous()))
    try:
        return _fit_actor(self, obs, batches)
    finally:
        _context.pop()


if __name__ == "__main__":
    eager_steps.EvalCritic = PairingEvalCritic
    fast.FastUpdater.fit_actor = fit_actor
    sys.exit(run.main(sys.argv[1:]))
