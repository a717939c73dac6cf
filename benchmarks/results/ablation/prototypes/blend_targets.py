"""Prototype (ablation README, section 25): the soft targets between the critics' mean and their minimum.

Section 25: the minimum in the soft targets holds InvertedPendulum (with K = 20) and stops the sparse Acrobot's
exploration, the mean the reverse. The minimum of two critics is their mean less half their disagreement; this patch
takes off a share ``BLEND`` of it, (1 - beta) mean_j Q_j + beta min_j Q_j (beta = 1: the minimum, 0: the mean; the
form of weighted double Q-learning, Zhang et al. 2017, and of TOP's fixed arms, Moskovitz et al. 2021), in eq. (4)'s
bootstrap value only: the soft actor still ascends the minimum. The patch replaces the fast updater's combination of
the critics when ``critic_target="min"`` (the configurations run here use the fast updater; asserted). Runs
``benchmarks.run`` in this process (use ``--workers 0``); ``blend_targets/`` holds its runs.

Usage: ``BLEND=0.5 python -m benchmarks.results.ablation.prototypes.blend_targets
--algos abl:soft+min+K20 --envs acrobot --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/blend_targets``
"""

import os
import sys

import torch as th

from benchmarks import run
from sb3_denfac.denfac import denfac as denfac_module
from sb3_denfac.denfac import fast
from sb3_denfac.denfac.policies import combine_critics

BETA = float(os.environ.get("BLEND", "0.5"))


def blended(values: list[th.Tensor], how: str) -> th.Tensor:
    """``how`` "min": (1 - BETA) mean + BETA min of the critics' values; "mean": their mean (unchanged)."""
    if how != "min" or len(values) == 1:
        return combine_critics(values, how)
    return (1.0 - BETA) * combine_critics(values, "mean") + BETA * combine_critics(values, "min")


_make_updater = denfac_module.DENFAC._make_updater


def make_updater(self):
    updater = _make_updater(self)
    assert isinstance(updater, fast.FastUpdater), "the patch replaces the fast updater's combination only"
    return updater


if __name__ == "__main__":
    fast.combine_critics = blended
    denfac_module.DENFAC._make_updater = make_updater
    sys.exit(run.main(sys.argv[1:]))
