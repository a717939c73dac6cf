"""Prototype, not in the library (ablation README, section 13): the actor ascends Q at its exploring actions.

Eq. (5) ascends Q(s, pi(s)), the value of the deterministic action; the episodes are played with pi(s) plus the
truncated Gaussian noise of std sigma, and a policy on a narrow peak of Q falls off it under that noise. SAC's actor
maximises E_{a ~ pi(.|s)} Q(s, a) instead (reparameterised). Here each actor step of the fast updater evaluates
dQ/da at a = clip(pi(s) + eps, -1, 1), eps ~ N(0, AN_SIGMA^2) drawn per sample and step, and passes it to pi(s)
unchanged (d a / d pi = 1): the gradient of E_eps Q(s, pi(s) + eps), a noise-robust actor. Inverting gradients and the
proximal term still use pi(s). Runs ``benchmarks.run`` in this process with the patch (use ``--workers 0``);
``noisy_actor/`` holds its runs.

Usage: ``AN_SIGMA=0.1 python noisy_actor.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/noisy_actor``
"""

import os
import sys

import torch as th

from benchmarks import run
from sb3_denfac.denfac.eager_steps import EvalCritic

SIGMA = float(os.environ.get("AN_SIGMA", "0.1"))
_action_gradient = EvalCritic.action_gradient


def action_gradient(self, pi, want_value):
    """``EvalCritic.action_gradient`` at the noisy action (its one caller, ``eager_steps.actor_step``, keeps pi(s)
    for inverting gradients and the proximal term)."""
    return _action_gradient(self, th.randn_like(pi).mul_(SIGMA).add_(pi).clamp_(-1.0, 1.0), want_value)


if __name__ == "__main__":
    EvalCritic.action_gradient = action_gradient
    sys.exit(run.main(sys.argv[1:]))
