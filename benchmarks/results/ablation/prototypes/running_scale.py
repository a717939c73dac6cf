"""Prototype, not in the library (ablation README, section 12): the proximal actor's Q gradient normalised by
max(S, running S) instead of S.

S = sum_n ||a_n|| of the current actor step (``eager_steps.actor_step``, the fast updater); running S = an exponential
average of S over the run's actor steps (decay ``RS_DECAY``, default 0.999: about 4 episodes of 250 actor steps). Near
an optimum, where dQ/da shrinks, the actor's step shrinks with it instead of staying about 1/(2 lambda). Runs
``benchmarks.run`` in this process with the patch (use ``--workers 0``); ``running_scale/`` holds its runs.

Usage: ``RS_DECAY=0.999 python running_scale.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0``
"""

import os
import sys

import torch as th

from benchmarks import run, task
from sb3_denfac.denfac import eager_steps

DECAY = float(os.environ.get("RS_DECAY", "0.999"))
_state: dict[str, float] = {}


def actor_step(net, ws, obs, fixed, critic, max_grad_norm, inverting, want_objective, proximal=None):
    """``eager_steps.actor_step`` with the running scale (one run at a time in this process)."""
    folds = eager_steps.step_forward(net, ws, obs, fixed)
    pi = ws.outputs[-1]
    ascent, objective = critic.action_gradient(pi, want_objective)
    if inverting:
        ascent = eager_steps.invert_gradients_unit_box(ascent, pi, out=critic.inverted)
    if proximal is None:
        grad_pi = ascent.neg_()
    else:
        coef, old_pi = proximal
        scale = float(th.linalg.vector_norm(ascent, dim=0).sum().clamp_(min=1e-12))
        _state["running"] = DECAY * _state.get("running", scale) + (1 - DECAY) * scale
        grad_pi = th.sub(pi, old_pi).mul_(2.0 * coef / pi.shape[1]).sub_(ascent.div_(max(scale, _state["running"])))
    eager_steps.backward(net, ws, obs, folds, grad_pi)
    eager_steps.adam_step(net, max_grad_norm)
    return objective


_run_one = task.run_one


def run_one(cell):
    _state.clear()  # a new run starts with no running scale
    return _run_one(cell)


if __name__ == "__main__":
    eager_steps.actor_step = actor_step
    task.run_one = run_one
    sys.exit(run.main(sys.argv[1:]))
