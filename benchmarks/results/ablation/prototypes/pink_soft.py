"""Prototype (ablation README, section 26): the soft actor exploring with temporally correlated (pink) noise.

Sections 25-26: with the critics' minimum in the targets the soft actor holds InvertedPendulum and stops finding the
sparse Acrobot's swing-ups, and every way tried of moving optimism into the values or the exploring action lands
between the two fixed targets. This patch leaves values, targets and the actor's loss alone and changes only how the
exploring action is drawn: a = tanh(m(s) + std(s) * eps_t) with eps_t, per action dimension, a unit-variance sequence
of a 1/f^``PINK_BETA`` spectrum (pink for 1; Eberhard et al. 2023, "Pink noise is all you need", whose SAC draws its
Gaussian's noise this way) instead of independent draws; one sequence of ``CHUNK`` steps per episode (drawn anew at
every episode start and when used up), from ``powerlaw_noise`` of ``pink_noise.py`` (section 11's prototype for the
deterministic actor). The policy's own mean and width stay what the soft actor learned: the noise is correlated in
time, not larger. ``PINK_BETA=0`` draws white noise through the same path (the library's sampling, another stream).
Patches ``DENFAC._sample_action`` (the soft actor's branch, ``soft_sampling.py``); runs ``benchmarks.run`` in this
process (``--workers 0``); ``pink_soft/`` holds its runs.

Usage: ``python -m benchmarks.results.ablation.prototypes.pink_soft
--algos abl:soft+min+K20 --envs acrobot --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/pink_soft``
"""

import os
import sys

import numpy as np
import torch as th

from benchmarks import run
from benchmarks.results.ablation.prototypes import soft_sampling
from benchmarks.results.ablation.prototypes.pink_noise import powerlaw_noise  # section 11's prototype

BETA = float(os.environ.get("PINK_BETA", "1.0"))
CHUNK = int(os.environ.get("PINK_CHUNK", "1000"))


def noise(self, dim: int) -> np.ndarray:
    """This step's eps_t, (dim,): the next entry of the episode's sequence (a new one at an episode's start)."""
    state = getattr(self, "_pink", None)
    if state is None or state["episode"] != self._episode_num or state["t"] >= CHUNK:
        rng = np.random.default_rng((self.seed or 0, self._episode_num, self.num_timesteps))
        state = self._pink = dict(episode=self._episode_num, t=0, eps=powerlaw_noise(BETA, CHUNK, dim, rng))
    eps = state["eps"][state["t"]]
    state["t"] += 1
    return eps


def draw(self, obs: th.Tensor, mean: th.Tensor, log_std: th.Tensor) -> th.Tensor:
    """tanh(m(s) + std(s) eps_t), eps_t this step's entry of the episode's 1/f sequence."""
    assert mean.shape[0] == 1, "one env: one noise sequence"
    eps = th.as_tensor(noise(self, mean.shape[-1]), dtype=mean.dtype).reshape(mean.shape)
    return th.tanh(mean + log_std.exp() * eps)


if __name__ == "__main__":
    soft_sampling.patch(draw)
    sys.exit(run.main(sys.argv[1:]))
