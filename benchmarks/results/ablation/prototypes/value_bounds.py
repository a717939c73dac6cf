"""Prototype (ablation README, section 16), now the library option ``DENFAC(..., bootstrap_bounds=True)`` (section 17):
eq. (4)'s bootstrap value kept inside the range that the observed rewards allow.

The critic diagnostics of the 0.5 default (``benchmarks/diagnostics.py``, suite ``diagnosis``) show its values leaving
that range: on Hopper-v5 mean Q over D grows from 857 at episode 10 to 2e8 at episode 90 (discounted returns below 100),
on the paper's CartPole, whose rewards are all <= 0, mean Q is positive (up to 138). No discounted return of at least
one reward in [r_min, r_max] leaves [min(r_min, r_min / (1 - gamma)), max(r_max, r_max / (1 - gamma))] (one step's
reward where an episode can end at once, the infinite sum where it cannot), so the targets here are
y = r + gamma (1 - d) clip(Q_bar(s', a'), low, high) with those bounds, r_min and r_max the smallest and largest reward
in D at this update (no env knowledge; the range widens as new rewards are seen). They are read from the buffer's raw
rewards, so with VecNormalize's reward scaling (no run here uses it) the bounds would have to come from the normalised
rewards the update fits instead. Everything else is 0.5's default. Runs ``benchmarks.run`` in this
process with the patch (use ``--workers 0``); ``value_bounds/`` holds its runs.

Usage: ``python value_bounds.py --algos abl:default05 --envs cartpole --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/value_bounds``
"""

import sys

import torch as th

from benchmarks import run
from sb3_denfac.denfac.denfac import DENFAC
from sb3_denfac.denfac.options import bootstrap_range

_make_updater = DENFAC._make_updater


class BoundedCritic:
    """``updater.critic`` (used by DENFAC's update for eq. (4)'s bootstrap value only) clamped to [low, high]."""

    def __init__(self, critic, low: float, high: float):
        self.critic, self.low, self.high = critic, low, high

    def __call__(self, obs: th.Tensor, actions: th.Tensor) -> th.Tensor:
        return self.critic(obs, actions).clamp(self.low, self.high)


def make_updater(self):
    """The updater with its bootstrap value clamped to :func:`~sb3_denfac.denfac.options.bootstrap_range` of D's
    rewards (the range the library's ``bootstrap_bounds=True`` now uses, and the same targets). The runs before that
    form, with ``r_min / (1 - gamma), r_max / (1 - gamma)``, differ only where all rewards have one sign and episodes
    can end (InvertedPendulum's +1 clamped every bootstrap value to 100) or all are < 0 (Pendulum): those runs are in
    ``value_bounds/infinite_sum/``."""
    updater = _make_updater(self)
    rewards = th.as_tensor(self.replay_buffer.rewards[: self.replay_buffer.size()])
    updater.critic = BoundedCritic(updater.critic, *bootstrap_range(rewards, self.gamma))
    return updater


if __name__ == "__main__":
    DENFAC._make_updater = make_updater
    sys.exit(run.main(sys.argv[1:]))
