"""Probe: DENFAC + HER and SB3 SAC + HER on PandaReach-v3 (panda-gym, the robotics extra), one seed.

    python -m research.robotics.panda_reach_probe denfac 0.95     # DENFAC's default + HerReplayBuffer, gamma 0.95
    python -m research.robotics.panda_reach_probe denfac 0.99
    python -m research.robotics.panda_reach_probe sac 0.95        # SB3 SAC + HER, learning_starts 1000 (zoo style)
    python -m research.robotics.panda_reach_probe denfac_dial 0.95  # with update_to_data_ratio=10, K in (1, 10)

Every 10 training episodes (500 steps), the success rate of 10 deterministic test episodes (goals drawn from seed
500), the wall and CPU seconds so far (the evaluation included). Results and the decision: README.md beside this file.
"""

from __future__ import annotations

import sys
import time

import gymnasium as gym
import numpy as np
import panda_gym  # noqa: F401  (registers PandaReach-v3)
from stable_baselines3 import SAC, HerReplayBuffer

from benchmarks.runner.task import evaluate
from sb3_denfac import DENFAC


def success(model, n: int = 10, seed: int = 500) -> float:
    """The share of ``n`` deterministic test episodes (goals drawn from ``seed``) that end at the goal."""
    env = gym.make("PandaReach-v3")
    env.reset(seed=seed)
    return float(np.mean(evaluate(model, env, n)))


def main() -> None:
    algo, gamma = sys.argv[1], float(sys.argv[2])
    her = dict(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(n_sampled_goal=4))
    env = gym.make("PandaReach-v3")
    if algo == "denfac":
        model = DENFAC("MultiInputPolicy", env, seed=0, gamma=gamma, **her)
    elif algo == "denfac_dial":  # K_e = clip(ceil(10 n / 50), 1, 10): about 10 critic steps per env step
        dial = dict(update_to_data_ratio=10, n_fitted_iterations=(1, 10))
        model = DENFAC("MultiInputPolicy", env, seed=0, gamma=gamma, **dial, **her)
    else:
        model = SAC("MultiInputPolicy", env, seed=0, gamma=gamma, learning_starts=1000, **her)
    start, cpu = time.time(), time.process_time()
    for chunk in range(12):
        model.learn(500, reset_num_timesteps=False)
        print(
            (chunk + 1) * 10,
            success(model),
            round(time.time() - start),
            round(time.process_time() - cpu),
            f"{model._n_updates} updates, {model.num_timesteps} steps",
            flush=True,
        )


if __name__ == "__main__":
    main()
