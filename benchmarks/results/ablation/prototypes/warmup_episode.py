"""Prototype, not in the library (ablation README, section 14): the first episode(s) played with uniform actions.

SB3's off-policy algorithms play ``learning_starts`` = 100 uniform warm-up steps before the first update; DENFAC's
default (the paper's) plays its initial actor from the first step. On Pendulum-v1 ``learning_starts=200`` (one episode)
halves the episodes the default needs to hold the pendulum up. A step count is env-specific (200 steps is one
Pendulum episode and 20-40 random InvertedPendulum episodes); this patch counts episodes instead: while fewer than
``WARMUP_EPISODES`` (default 1) episodes have ended, the exploration draws uniform actions (the warm-up branch of
``TruncatedGaussianExplorationMixin._sample_action``), and the end-of-episode update runs as usual. Runs
``benchmarks.run`` in this process with the patch (use ``--workers 0``); ``warmup_episode/`` holds its runs.

Usage: ``WARMUP_EPISODES=1 python warmup_episode.py --algos abl:default05 --envs pendulum --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/warmup_episode``
"""

import os
import sys

from benchmarks import run
from sb3_denfac.common.exploration import TruncatedGaussianExplorationMixin

EPISODES = int(os.environ.get("WARMUP_EPISODES", "1"))
_sample_action = TruncatedGaussianExplorationMixin._sample_action


def sample_action(self, learning_starts, action_noise=None, n_envs=1):
    """Uniform actions until ``EPISODES`` episodes have ended (SB3 counts them in ``_episode_num``)."""
    if self._episode_num < EPISODES:
        learning_starts = max(learning_starts, self.num_timesteps + 1)
    return _sample_action(self, learning_starts, action_noise, n_envs)


if __name__ == "__main__":
    TruncatedGaussianExplorationMixin._sample_action = sample_action
    sys.exit(run.main(sys.argv[1:]))
