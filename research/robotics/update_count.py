"""How many updates DENFAC + HER runs on PandaReach-v3, and what they cost: ``learn(2000)`` (gamma 0.95, seed 0) with
``UpdateStatsCallback``, printing each update's seconds, the wall and CPU seconds and their sum.

    python -m research.robotics.update_count
"""

from __future__ import annotations

import time

import gymnasium as gym
import panda_gym  # noqa: F401  (registers PandaReach-v3)
from stable_baselines3 import HerReplayBuffer

from sb3_denfac import DENFAC
from sb3_denfac.common.callbacks import UpdateStatsCallback


def main() -> None:
    seconds: list[float] = []
    her = dict(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(n_sampled_goal=4))
    model = DENFAC("MultiInputPolicy", gym.make("PandaReach-v3"), seed=0, gamma=0.95, **her)
    start, cpu = time.time(), time.process_time()
    model.learn(2000, callback=UpdateStatsCallback(lambda stats: seconds.append(round(stats.seconds, 2))))
    print("updates", len(seconds), seconds)
    print("wall", round(time.time() - start), "cpu", round(time.process_time() - cpu), "sum of updates", round(sum(seconds)))


if __name__ == "__main__":
    main()
