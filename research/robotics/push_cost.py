"""What a PandaPush-v3 run costs here, per env step: DENFAC + HER from the plain call (presets.GOALS' settings) and SB3's
SAC + HER with the RL Zoo's HER settings (one gradient step per env step), timed over ``--steps`` env steps after a
warm-up, one torch thread; the success rate of 20 deterministic test episodes at the end (the push rarely succeeds by
chance: the object starts where the goal is in a few percent of episodes).

    python -m research.robotics.push_cost --steps 3000
    python -m research.robotics.push_cost --probe 100000   # DENFAC only: success every 10k steps up to the budget
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import gymnasium as gym
import panda_gym  # noqa: F401  (registers the Panda envs)
import torch as th
from stable_baselines3 import SAC, HerReplayBuffer

from sb3_denfac import DENFAC

HER = dict(replay_buffer_class=HerReplayBuffer, replay_buffer_kwargs=dict(goal_selection_strategy="future", n_sampled_goal=4))


def success(model, seed: int, episodes: int = 20) -> float:
    env = gym.make("PandaPush-v3")
    wins = 0
    for i in range(episodes):
        obs, _ = env.reset(seed=10_000 + seed * 100 + i)
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(model.predict(obs, deterministic=True)[0])
            done = terminated or truncated
        wins += bool(info.get("is_success"))
    return wins / episodes


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--probe", type=int, default=None, help="DENFAC alone for this many steps, evaluated every 10k")
    args = parser.parse_args()
    th.set_num_threads(1)
    out = Path(__file__).with_name("push_cost.jsonl")
    if args.probe:
        model, curve, cpu = DENFAC("MultiInputPolicy", gym.make("PandaPush-v3"), seed=args.seed, **HER), [], 0.0
        while model.num_timesteps < args.probe:
            start = time.process_time()
            model.learn(10_000, reset_num_timesteps=model.num_timesteps == 0)
            cpu += time.process_time() - start
            curve.append((model.num_timesteps, success(model, args.seed)))
            print(curve[-1], round(cpu), flush=True)
        line = {"row": "denfac_goals_probe", "seed": args.seed, "steps": args.probe, "cpu_s": round(cpu), "success": curve}
        with out.open("a") as f:
            f.write(json.dumps(line) + "\n")
        return
    makers = {
        "denfac_goals": lambda env: DENFAC("MultiInputPolicy", env, seed=args.seed, **HER),
        "sac_her_zoo": lambda env: SAC(
            "MultiInputPolicy", env, seed=args.seed, gamma=0.95, learning_starts=1000, batch_size=256, **HER
        ),
    }
    for name, make in makers.items():
        model = make(gym.make("PandaPush-v3"))
        model.learn(1000)  # warm-up: SAC's random steps, DENFAC's first updates
        start = time.process_time()
        model.learn(args.steps, reset_num_timesteps=False)
        cpu = time.process_time() - start
        line = {
            "row": name,
            "seed": args.seed,
            "steps": args.steps,
            "cpu_s": round(cpu, 1),
            "ms_per_step": round(1000 * cpu / args.steps, 2),
            "success_at_end": success(model, args.seed),
        }
        print(json.dumps(line), flush=True)
        with out.open("a") as f:
            f.write(json.dumps(line) + "\n")


if __name__ == "__main__":
    main()
