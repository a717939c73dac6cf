"""Show that the straight-up goal of ``sb3_denfac/ContinuousAcrobot-v0`` is reachable with the chosen torque bound.

A bang-bang energy-pumping controller, ``a = sign(dtheta2)`` (full elbow torque in the direction of the elbow's
motion), is run from the hanging rest state for several values of ``max_torque``; it prints the number of steps
to the goal (normalised tip height >= 0.99; 500 = not reached) and the best height.

Usage: ``python scripts/acrobot_reachability.py [--torques 1 1.5 2]``
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import sb3_denfac  # noqa: F401  (registers the environments)


def bang_bang_episode(max_torque: float, seed: int = 0) -> tuple[float, float]:
    """Run one episode of ``a = sign(dtheta2)``; return (paper_performance, max normalised tip height)."""
    env = gym.make("sb3_denfac/ContinuousAcrobot-v0", max_torque=max_torque)
    obs, _ = env.reset(seed=seed)
    while True:
        dtheta2 = obs[3]  # paper observation [th1, dth1, th2, dth2]
        action = np.array([1.0 if dtheta2 >= 0 else -1.0], dtype=np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            env.close()
            return float(info["paper_performance"]), float(info["max_tip_height"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--torques", type=float, nargs="+", default=[1.0, 1.5, 2.0])
    args = parser.parse_args()
    print("max_torque  steps_to_goal  max_height")
    for torque in args.torques:
        steps, height = bang_bang_episode(torque)
        print(f"{torque:10.2f}  {steps:13.0f}  {height:10.4f}")


if __name__ == "__main__":
    main()
