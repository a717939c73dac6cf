"""Prototype (ablation README, section 25): n-step returns in eq. (4)'s targets.

Section 23 found the critics' minimum in the targets erasing the sparse Acrobot's goal: every backup through
min(Q_1, Q_2) takes the critics' disagreement off the bootstrap value, and on a reward of +1 at a goal tens of steps
away (gamma 0.9) that accumulated pessimism is as large as the goal's discounted value. n-step targets (Sutton and
Barto 2018, ch. 7; Rainbow, D4PG and SB3's own ``n_steps`` since 2.6) back the goal's reward up n steps per backup and
take the minimum once per n rewards:

    y_i = sum_{k<m} gamma^k r_{i+k} + gamma^m (1 - d_{i+m-1}) (min_j Q_j(s_{i+m}, a') - alpha log pi(a'|s_{i+m})),

m = min(n, the steps left in the episode of transition i), over D's stored trajectories in their chronological order
(the newest transition ends its stretch: a time-limit-like bootstrap). Uncorrected for the behaviour policy (as SB3's
``NStepReplayBuffer``); the entropy terms of the intermediate steps are left out, as there. The patch rewrites D's
samples for the update (rewards -> the n-step sums, next observations -> s_{i+m}, and the terminal flags so that
DENFAC's ``gamma (1 - done)`` is gamma^m (1 - d)); ``bootstrap_bounds`` keeps reading the one-step rewards. Runs
``benchmarks.run`` in this process (use ``--workers 0``); ``n_step/`` holds its runs. ``NSTEP`` sets n (default 3).

Usage: ``NSTEP=3 python -m benchmarks.results.ablation.prototypes.n_step
--algos abl:soft+min+K20 --envs acrobot --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/n_step``
"""

import os
import sys

import numpy as np
import torch as th

from benchmarks import run
from sb3_denfac.denfac import denfac as denfac_module
from sb3_denfac.denfac.buffers import DENFACReplayBuffer

N_STEP = int(os.environ.get("NSTEP", "3"))
_all_samples = DENFACReplayBuffer.all_samples
_bootstrap_range = denfac_module.bootstrap_range


def n_step_rows(rewards: np.ndarray, ends: np.ndarray, gamma: float, n: int):
    """For chronological one-step rewards and episode ends (1-D arrays): the n-step sums, the index of each row's
    bootstrap transition (i + m - 1) and m."""
    size = len(rewards)
    index = np.arange(size)
    sums = rewards.copy()
    steps = np.ones(size, dtype=np.int64)
    alive = np.ones(size, dtype=bool)
    for k in range(1, n):
        ahead = index + k
        alive &= ahead < size  # the newest transition ends every stretch
        alive[alive] &= ~ends[ahead[alive] - 1]  # and so does an episode's end
        sums[alive] += gamma**k * rewards[ahead[alive]]
        steps += alive
    return sums, index + steps - 1, steps


def all_samples(self, env=None):
    """D's samples with n-step targets' rewards, bootstrap observations and terminal flags (module docstring)."""
    data = _all_samples(self, env)
    assert self.n_envs == 1, "the prototype handles one env"
    size = self.size()
    order = np.arange(size)
    if self.full:
        order = np.roll(order, -self.pos)  # chronological order of a wrapped FIFO
    rewards = data.rewards.numpy()[order, 0].astype(np.float64)
    ends = self.dones[order, 0] > 0  # SB3 stores done for terminations and truncations alike
    sums, last, steps = n_step_rows(rewards, ends, self.gamma_for_n_step, N_STEP)
    new_rewards, new_next, new_dones = data.rewards.clone(), data.next_observations.clone(), data.dones.clone()
    rows = th.as_tensor(order)
    boot = th.as_tensor(order[last])
    new_rewards[rows, 0] = th.as_tensor(sums, dtype=th.float32)
    new_next[rows] = data.next_observations[boot]
    discount_extra = th.as_tensor(self.gamma_for_n_step ** (steps - 1), dtype=th.float32)
    new_dones[rows, 0] = 1.0 - discount_extra * (1.0 - data.dones[boot, 0])
    self.one_step_rewards = data.rewards
    return data._replace(rewards=new_rewards, next_observations=new_next, dones=new_dones)


_setup_model = denfac_module.DENFAC._setup_model


def setup_model(self):
    _setup_model(self)
    self.replay_buffer.gamma_for_n_step = self.gamma
    assert self.bootstrap_on_timeout, "the patch folds gamma^(m-1) into the terminal flags, read with bootstrap_on_timeout"


if __name__ == "__main__":
    DENFACReplayBuffer.all_samples = all_samples
    denfac_module.DENFAC._setup_model = setup_model
    _update = denfac_module.DENFAC._update

    def update(self, n_iterations=None):
        buffer = self.replay_buffer
        original = denfac_module.bootstrap_range
        denfac_module.bootstrap_range = lambda rewards, gamma: _bootstrap_range(buffer.one_step_rewards, gamma)
        try:
            _update(self, n_iterations)
        finally:
            denfac_module.bootstrap_range = original

    denfac_module.DENFAC._update = update
    sys.exit(run.main(sys.argv[1:]))
