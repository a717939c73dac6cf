"""The zero action's return on the mujoco100k envs: a reference for reading their 100k-step returns (on Ant-v5 a
policy that does nothing stands for the whole episode). Evaluation episodes seeded 10_000 + i, as the probe's.

    python -m research.frontier_critics.zero_action
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

ENVS = ("HalfCheetah-v5", "Hopper-v5", "Walker2d-v5", "Ant-v5")


def zero_action_returns(env_id: str, episodes: int = 10) -> tuple[list[float], list[int]]:
    """Returns and lengths of ``episodes`` episodes of ``env_id`` played with the action 0."""
    env = gym.make(env_id)
    returns, lengths = [], []
    for i in range(episodes):
        env.reset(seed=10_000 + i)
        total, steps, done = 0.0, 0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape))
            total, steps, done = total + float(reward), steps + 1, terminated or truncated
        returns.append(total)
        lengths.append(steps)
    env.close()
    return returns, lengths


def main() -> None:
    for env_id in ENVS:
        returns, lengths = zero_action_returns(env_id)
        print(f"{env_id}: median return {np.median(returns):.1f}, median length {np.median(lengths):.0f}", flush=True)


if __name__ == "__main__":
    main()
