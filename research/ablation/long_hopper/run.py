"""Hopper-v5 past the benchmark's 100 episodes (``research/ablation/journal.md``, section 17): does the 0.5 default's
critic keep diverging, and what do the bootstrap bounds change? ``DENFAC("MlpPolicy", "Hopper-v5", seed=SEED)``, one
torch thread; prints one JSON line per 10 episodes: their mean return, length and return beyond the survival bonus
(return - length), the last update's mean q target (``train/q_target_mean``) and the process's CPU seconds.

The logs here ran on 2026-12-04 at main 1aa7c83..edc87ed (2-core Intel Xeon, load average 3-4: a benchmark sweep and
one other run beside it) with the prototype ``value_bounds.py`` (research/ablation/README.md says where it is kept),
whose targets the library option ``bootstrap_bounds=True`` (used below) computes the same way.

Usage: ``OMP_NUM_THREADS=1 python research/ablation/long_hopper/run.py SEED EPISODES [--bounds]``
"""

import argparse
import json
import time

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from sb3_denfac import DENFAC


class EveryTenEpisodes(BaseCallback):
    def __init__(self, n_episodes: int):
        super().__init__()
        self.n_episodes, self.episodes, self.window = n_episodes, 0, []

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" not in info:
                continue
            self.episodes += 1
            self.window.append((info["episode"]["r"], info["episode"]["l"]))
            if self.episodes % 10 == 0:
                ret, length = np.array(self.window, dtype=float).T
                stats = self.model.last_update  # the last update's statistics (public; None before the first)
                row = dict(ep=self.episodes, ret=ret.mean(), len=length.mean(), beyond=(ret - length).mean(),
                           q=float(stats.q_targets.mean()) if stats else float("nan"), cpu=time.process_time())  # fmt: skip
                print(json.dumps(row), flush=True)
                self.window = []
        return self.episodes < self.n_episodes


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("seed", type=int)
    parser.add_argument("episodes", type=int)
    parser.add_argument("--bounds", action="store_true", help="bootstrap_bounds=True")
    args = parser.parse_args()
    model = DENFAC("MlpPolicy", "Hopper-v5", seed=args.seed, bootstrap_bounds=args.bounds)
    model.learn(10**9, callback=EveryTenEpisodes(args.episodes))
