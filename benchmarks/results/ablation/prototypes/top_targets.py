"""Prototype (ablation README, section 26): the soft targets' optimism chosen per episode by a bandit (TOP).

Section 25: the minimum of the two critics in the soft targets holds InvertedPendulum (with K = 20) and stops the
sparse Acrobot's exploration; the mean does the reverse, and a fixed halfway blend is worse than either end. Tactical
Optimism and Pessimism (TOP, Moskovitz et al. 2021) lets the returns choose: the bootstrap value is
mean_j Q_j + beta * (half the critics' spread), i.e. beta = -1 the minimum of two critics, beta = 0 their mean, and beta
is drawn anew before each end-of-episode update from an exponentially weighted bandit over the arms {-1, 0} whose
feedback is the change in episode return that the previous arm's update produced (the return of the episode collected
after it, less the one before), normalised by the spread of the last ``WINDOW`` feedbacks. The bandit is written here
after TOP's description (lr, window, decay as its defaults: 0.1, 5, 0.9); the arms act on eq. (4)'s bootstrap value
only, the soft actor still ascends the minimum. Patches the fast updater's combination of the critics when
``critic_target="min"`` (asserted) and ``DENFAC.train``. Runs ``benchmarks.run`` in this process (``--workers 0``);
``top_targets/`` holds its runs; ``TOP_TRACE=path`` appends one JSON line per update (episode return, arm, weights).

Usage: ``python -m benchmarks.results.ablation.prototypes.top_targets
--algos abl:soft+min+K20 --envs acrobot --seeds 0 1 2 --workers 0
--results benchmarks/results/ablation/prototypes/top_targets``
"""

import json
import os
import sys

import numpy as np
import torch as th

from benchmarks import run
from sb3_denfac.denfac import denfac as denfac_module
from sb3_denfac.denfac import fast
from sb3_denfac.denfac.policies import combine_critics

ARMS = [float(a) for a in os.environ.get("TOP_ARMS", "-1,0").split(",")]
LR, WINDOW, DECAY = float(os.environ.get("TOP_LR", "0.1")), 5, 0.9
TRACE = os.environ.get("TOP_TRACE")


class ExpWeights:
    """Exponential weights over ``ARMS`` (EXP3-like: importance-weighted, decayed, normalised feedback)."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng
        self.w = np.zeros(len(ARMS))
        self.arm = int(rng.integers(len(ARMS)))
        self.feedbacks: list[float] = []

    def probabilities(self) -> np.ndarray:
        e = np.exp(self.w - self.w.max())
        return e / e.sum()

    def update(self, feedback: float) -> None:
        self.feedbacks = (self.feedbacks + [feedback])[-WINDOW:]
        spread = float(np.std(self.feedbacks)) if len(self.feedbacks) > 1 else 0.0
        scaled = feedback / spread if spread > 0 else 0.0
        p = self.probabilities()[self.arm]
        self.w[self.arm] = DECAY * self.w[self.arm] + LR * scaled / max(p, 1e-4)

    def sample(self) -> int:
        self.arm = int(self.rng.choice(len(ARMS), p=self.probabilities()))
        return self.arm


BETA = {"value": ARMS[0]}


def optimistic(values: list[th.Tensor], how: str) -> th.Tensor:
    """``how`` "min" with two critics: their mean + beta * half their spread (beta -1: the minimum, 0: the mean)."""
    if how != "min" or len(values) == 1:
        return combine_critics(values, how)
    assert len(values) == 2, "the arms are written for two critics"
    beta = BETA["value"]
    if beta in (-1.0, 0.0):  # the arms exactly as the library computes them (beta -1 bitwise the unpatched minimum)
        return combine_critics(values, "min" if beta == -1.0 else "mean")
    mean = combine_critics(values, "mean")
    return mean + beta * (mean - combine_critics(values, "min"))


_make_updater = denfac_module.DENFAC._make_updater
_train = denfac_module.DENFAC.train


def make_updater(self):
    updater = _make_updater(self)
    assert isinstance(updater, fast.FastUpdater), "the patch replaces the fast updater's combination only"
    assert self.critic_target == "min", "the bandit's arms replace the minimum"
    return updater


def train(self, gradient_steps: int, batch_size: int | None = None) -> None:
    state = getattr(self, "_top", None)
    if state is None:
        state = self._top = dict(bandit=ExpWeights(np.random.default_rng(self.seed)), last=None, seen=0)
    bandit = state["bandit"]
    n_episodes = self._episode_num
    if self.ep_info_buffer and n_episodes > state["seen"]:
        ret = float(self.ep_info_buffer[-1]["r"])
        if state["last"] is not None:
            bandit.update(ret - state["last"])
        state["last"], state["seen"] = ret, n_episodes
        bandit.sample()
    BETA["value"] = ARMS[bandit.arm]
    if TRACE:
        with open(TRACE, "a") as f:
            f.write(
                json.dumps(
                    dict(
                        seed=self.seed,
                        episode=n_episodes,
                        ret=state["last"],
                        beta=BETA["value"],
                        p=bandit.probabilities().round(3).tolist(),
                    )
                )
                + "\n"
            )
    _train(self, gradient_steps, batch_size)


if __name__ == "__main__":
    fast.combine_critics = optimistic
    denfac_module.DENFAC._make_updater = make_updater
    denfac_module.DENFAC.train = train
    sys.exit(run.main(sys.argv[1:]))
