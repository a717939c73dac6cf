"""The README's main job: train an algorithm (DENFAC by default) on a paper environment and leave results to look at.

    python -m sb3_denfac.quickstart [--algo denfac] [--env sb3_denfac/ContinuousAcrobot-v0] [--episodes 50]

Writes, under ``--log-dir`` (default ``runs/quickstart``):
- ``tensorboard/``: SB3's TensorBoard logs (rollout returns and the algorithm's ``train/`` internals);
- ``0.monitor.csv``: SB3's Monitor file, one row per training episode (return, length, the paper's measure);
- ``learning_curve.png``: per-episode performance and the best registered performance so far (the paper's Figure 3
  measure; the episode return on envs without ``info["paper_performance"]``);
- ``model.zip``: the model after training (``DENFAC.load(path)``);
- ``best_model.zip``: the model as it was when it played its best training episode (the authors' "best of stored
  policies": learning is not monotone, the last policy can be far worse than the best one).
It ends by printing these paths, the TensorBoard command and the deterministic performance of both policies.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.monitor import load_results

from sb3_denfac.common.callbacks import EpisodePerformanceCallback, ProgressBarCallback
from sb3_denfac.common.performance import best_so_far
from sb3_denfac.envs import PAPER_PERFORMANCE_KEY
from sb3_denfac.envs.facts import env_facts
from sb3_denfac.zoo import config as zoo_config


def plot_learning_curve(
    performance: np.ndarray, env_id: str, algo: str, lower_is_better: bool, path: Path, measure: str = "episode return"
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    episodes = np.arange(1, len(performance) + 1)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(episodes, performance, ".", alpha=0.5, label="episode performance (with exploration)")
    ax.plot(episodes, best_so_far(performance, lower_is_better), "-", lw=2, label="best registered performance so far")
    ax.set_xlabel("episode")
    ax.set_ylabel(f"{measure} ({'lower' if lower_is_better else 'higher'} is better)")
    ax.set_title(f"{algo.upper()} on {env_id}")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def evaluate(model, env_id: str, seed: int) -> float:
    """One deterministic episode: its ``paper_performance`` if the env gives one, else its return."""
    env = gym.make(env_id)
    obs, _ = env.reset(seed=seed)
    done, info, episode_return = False, {}, 0.0
    while not done:
        action, _ = model.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, info = env.step(action)
        episode_return += float(reward)
        done = terminated or truncated
    env.close()
    return float(info.get(PAPER_PERFORMANCE_KEY, episode_return))


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algo", default="denfac", choices=[*zoo_config.ALGORITHMS, "td3", "sac", "crossq"])
    parser.add_argument("--env", default="sb3_denfac/ContinuousAcrobot-v0")
    parser.add_argument("--episodes", type=int, default=50, help="training budget in episodes")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--log-dir", type=Path, default=Path("runs/quickstart"))
    parser.add_argument("--progress-bar", action="store_true")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (tiny networks: 1 is fastest)")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    try:  # before anything is written
        zoo_config.register()
        zoo_config.check_env_id(args.env)
        hyperparams = zoo_config.load_hyperparams(args.algo, args.env)  # the package's zoo YAML (the paper's Figure 5 values)
    except zoo_config.ZooConfigError as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")
    # The paper's networks are tiny: extra intra-op threads only add synchronisation. Measured on a loaded 2-core
    # machine, a DENFAC update took 0.1 s with one thread and up to 33 s with the default two.
    th.set_num_threads(args.threads)

    run_dir = args.log_dir / f"{args.algo}_{args.env.replace('/', '-')}_seed{args.seed}"
    run_dir.mkdir(parents=True, exist_ok=True)
    model = zoo_config.make_model(  # built as the RL Zoo builds it
        args.algo, args.env, hyperparams, seed=args.seed, monitor_dir=run_dir, tensorboard_log=str(run_dir / "tensorboard")
    )
    lower = env_facts(args.env).lower_is_better
    # Counts episodes, stops after the budget and saves the policy of each new best episode.
    episodes = EpisodePerformanceCallback(args.episodes, lower_is_better=lower, best_model_path=str(run_dir / "best_model"))
    callbacks = [episodes, *([ProgressBarCallback(max_episodes=args.episodes)] if args.progress_bar else [])]
    max_steps = gym.spec(args.env).max_episode_steps or 1000
    start = time.time()
    model.learn(total_timesteps=args.episodes * max_steps, callback=callbacks, tb_log_name=args.algo.upper())
    wall = time.time() - start
    model.save(run_dir / "model.zip")
    model.get_env().close()

    monitor = load_results(str(run_dir))
    has_measure = PAPER_PERFORMANCE_KEY in monitor.columns
    performance = monitor[PAPER_PERFORMANCE_KEY if has_measure else "r"].to_numpy(dtype=float)
    measure = ("steps to goal" if lower else "paper performance") if has_measure else "episode return"
    plot_learning_curve(performance, args.env, args.algo, lower, run_dir / "learning_curve.png", measure)

    best = best_so_far(performance, lower)[-1]
    best_episode = int(np.flatnonzero(performance == best)[0]) + 1
    final = evaluate(model, args.env, args.seed + 1000)
    best_model = type(model).load(run_dir / "best_model.zip", device="cpu")
    best_eval = evaluate(best_model, args.env, args.seed + 1000)
    summary = {
        "episodes": len(performance),
        "best_training_performance": float(best),
        "best_episode": best_episode,
        "final_deterministic_performance": final,
        "best_model_deterministic_performance": best_eval,
        "wall_time_s": wall,
        "run_dir": str(run_dir),
    }
    direction = "lower" if lower else "higher"
    print(f"Trained {args.algo.upper()} on {args.env} for {len(performance)} episodes in {wall:.0f} s.")
    print(f"  best registered performance ({measure}, {direction} is better): {best:.1f}, at episode {best_episode}")
    print(f"  deterministic policy after training (model.zip): {final:.1f}")
    print(f"  deterministic policy of the best episode (best_model.zip): {best_eval:.1f}")
    print("  Learning is not monotone: the last policy can be far from the best one; the best registered performance")
    print("  was played with exploration noise, so a deterministic replay of that policy can differ too.")
    print(f"  learning curve (PNG):  {run_dir / 'learning_curve.png'}")
    print(f"  per-episode results:   {run_dir / '0.monitor.csv'}")
    print(f"  models:                {run_dir / 'model.zip'}, {run_dir / 'best_model.zip'}")
    print(f"  TensorBoard:           tensorboard --logdir {run_dir / 'tensorboard'}")
    return summary


if __name__ == "__main__":
    main()
