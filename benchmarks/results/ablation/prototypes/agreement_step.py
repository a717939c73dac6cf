"""Prototype, not in the library (ablation README, section 21): the proximal actor's step weighted by the two critics'
agreement on dQ/da.

Section 12 found that the proximal step (the Q gradient normalised to unit mean norm, options.py) keeps moving the
actor by ~1/(2 lambda) per update where dQ/da is only the critic's noise, and that a running gradient scale that slows
it there helps CartPole and stalls locomotion: it cannot tell "at the optimum" from "the critic is flat". The two Q
networks can: where their action gradients agree the direction is a property of the data, where they disagree it is
fitting noise. Per sample n, with g1_n = dQ_1/da and g2_n = dQ_2/da at (s_n, pi(s_n)),

    r_n = ||g1_n + g2_n|| / (||g1_n + g2_n|| + ||g1_n - g2_n||)     in [0, 1] (1: equal; 1/2: orthogonal; 0: opposite)

and the actor step descends -1/N sum_n r_n ghat_n . pi(s_n) + lambda ||pi - pi_old||^2 (ghat_n = g1_n / S, S unchanged:
the mean norm of the unweighted gradients), so a batch on which the critics disagree moves the actor less, and one on
which they agree as far as the default. The actor still ascends Q_1 (one factor changed). A patch of the fast
updater's actor fit (``eager_steps.actor_step`` and the ``EvalCritic`` it reads); runs ``benchmarks.run`` in this
process (use ``--workers 0``); ``agreement_step/`` holds its runs.

Usage: ``python agreement_step.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/agreement_step``
"""

import json
import os
import sys
from pathlib import Path

import torch as th

from benchmarks import run
from sb3_denfac.common.inverting_gradients import invert_gradients_unit_box
from sb3_denfac.denfac import eager_steps, fast
from sb3_denfac.denfac.denfac import DENFAC

_EvalCritic = eager_steps.EvalCritic
_fit_actor = fast.FastUpdater.fit_actor
_twin: dict = {}


class EvalCritics(_EvalCritic):
    """Q_1's eval-mode critic of the fast actor fit, with Q_2's beside it (``twin``)."""

    def __init__(self, affines, slopes, obs_part, action_dim, sizes, n):
        super().__init__(affines, slopes, obs_part, action_dim, sizes, n)
        t = _twin["args"]
        self.twin = _EvalCritic(t[0], t[1], t[2], action_dim, t[3], n)

    def subset(self, idx):
        sub = super().subset(idx)
        sub.twin = self.twin.subset(idx)
        return sub


def fit_actor(self, obs, batches=None):
    twin = self.critic_nets[1]
    affines = twin.eval_affines()
    action_dim = self.actor_net.spec.sizes[-1]
    w_first, b_first = affines[0]
    obs_part = th.addmm(b_first.unsqueeze(1), w_first[:, :-action_dim], obs.float().t().contiguous())
    _twin["args"] = (affines, twin.spec.slopes, obs_part, twin.spec.sizes)
    try:
        return _fit_actor(self, obs, batches)
    finally:
        _twin.clear()


def actor_step(net, ws, obs, fixed, critic, max_grad_norm, inverting, want_objective, proximal=None):
    """``eager_steps.actor_step`` with the agreement weights r_n (module docstring) on the normalised ascent."""
    folds = eager_steps.step_forward(net, ws, obs, fixed)
    pi = ws.outputs[-1]
    ascent, objective = critic.action_gradient(pi, want_objective)
    g2, _ = critic.twin.action_gradient(pi, False)
    both = th.linalg.vector_norm(ascent + g2, dim=0)
    agreement = both / (both + th.linalg.vector_norm(ascent - g2, dim=0)).clamp_(min=1e-12)
    _stats.append(float(agreement.mean()))
    if inverting:
        ascent = invert_gradients_unit_box(ascent, pi, out=critic.inverted)
    assert proximal is not None, "the prototype weights the proximal step (actor_proximal > 0)"
    coef, old_pi = proximal
    scale = th.linalg.vector_norm(ascent, dim=0).sum().clamp_(min=1e-12)
    grad_pi = th.sub(pi, old_pi).mul_(2.0 * coef / pi.shape[1]).sub_(ascent.mul_(agreement).div_(scale))
    eager_steps.backward(net, ws, obs, folds, grad_pi)
    eager_steps.adam_step(net, max_grad_norm)
    return objective


_stats: list[float] = []
_train = DENFAC.train
STATS = Path(os.environ.get("AS_STATS", "benchmarks/results/ablation/prototypes/agreement_step/agreement"))


def train(self, gradient_steps, batch_size=None):
    """The default's update; every 10 updates, the mean agreement of that update's actor steps, per run."""
    _train(self, gradient_steps, batch_size)
    self._agreement_updates = getattr(self, "_agreement_updates", 0) + 1
    if _stats and self._agreement_updates % 10 == 0:
        env_id = self.env.envs[0].spec.id.split("/")[-1]
        STATS.mkdir(parents=True, exist_ok=True)
        with open(STATS / f"{env_id}_{self.seed}.jsonl", "a") as f:
            record = dict(update=self._agreement_updates, timesteps=self.num_timesteps, agreement=sum(_stats) / len(_stats))
            f.write(json.dumps(record) + "\n")
    _stats.clear()


if __name__ == "__main__":
    eager_steps.EvalCritic = EvalCritics
    eager_steps.actor_step = actor_step
    fast.FastUpdater.fit_actor = fit_actor
    DENFAC.train = train
    sys.exit(run.main(sys.argv[1:]))
