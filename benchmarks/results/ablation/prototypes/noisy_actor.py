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
from sb3_denfac.denfac import eager_steps

SIGMA = float(os.environ.get("AN_SIGMA", "0.1"))


def actor_step(net, ws, obs, fixed, critic, max_grad_norm, inverting, want_objective, proximal=None):
    """``eager_steps.actor_step`` with dQ/da taken at the noisy action."""
    factors = net.advance()
    folds = eager_steps.forward_train(net, ws, obs, fixed)
    eager_steps.update_running_stats(net, folds, obs.shape[1], factors, skip_first=fixed is not None)
    if fixed is not None:
        fixed.step(factors[0])
    pi = ws.outputs[-1]
    noisy = th.randn_like(pi).mul_(SIGMA).add_(pi).clamp_(-1.0, 1.0)
    ascent, objective = critic.action_gradient(noisy, want_objective)
    if inverting:
        ascent = eager_steps.invert_gradients_unit_box(ascent, pi, out=critic.inverted)
    if proximal is None:
        grad_pi = ascent.neg_()
    else:
        coef, old_pi = proximal
        scale = float(th.linalg.vector_norm(ascent, dim=0).sum().clamp_(min=1e-12))
        grad_pi = th.sub(pi, old_pi).mul_(2.0 * coef / pi.shape[1]).sub_(ascent.div_(scale))
    eager_steps.backward(net, ws, obs, folds, grad_pi)
    eager_steps.adam_step(net, max_grad_norm)
    return objective


if __name__ == "__main__":
    eager_steps.actor_step = actor_step
    sys.exit(run.main(sys.argv[1:]))
