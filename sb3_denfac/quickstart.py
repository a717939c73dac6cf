"""Train one algorithm (DENFAC by default) on one environment and leave results to look at: a learning curve, TensorBoard
logs, the per-episode results and the trained policies.

    python -m sb3_denfac.quickstart [--algo denfac] [--env sb3_denfac/ContinuousAcrobot-v0] [--episodes 50]

Writes, under ``--log-dir`` (default ``runs/quickstart``), in a folder per run (``<algo>_<env>_seed<seed>``):
- ``learning_curve.png``: the performance of every training episode, the best registered performance so far (the
  paper's Figure 3 measure; the episode return on envs without ``info["paper_performance"]``), the episodes that
  reached the env's threshold, and the deterministic replays of the two saved policies;
- ``tensorboard/``: SB3's TensorBoard logs (rollout returns and the algorithm's ``train/`` internals);
- ``0.monitor.csv``: SB3's Monitor file, one row per training episode (return, length, the paper's measure);
- ``model.zip``: the model after training (``DENFAC.load(path)``);
- ``best_model.zip``: the model as it was when it played its best training episode (the authors' "best of stored
  policies": learning is not monotone, the last policy can be far worse than the best one).
It prints the performance first (training, then one deterministic episode of each saved policy), then these paths and
the TensorBoard command.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import load_results

from sb3_denfac.common.callbacks import EpisodePerformanceCallback, ProgressBarCallback
from sb3_denfac.common.performance import best_so_far
from sb3_denfac.common.threads import torch_threads
from sb3_denfac.envs import ALL_ENV_IDS, PAPER_PERFORMANCE_KEY
from sb3_denfac.envs.facts import env_facts
from sb3_denfac.zoo import config as zoo_config
from sb3_denfac.zoo.validation import load_hyperparams


def plot_learning_curve(
    performance: np.ndarray,
    env_id: str,
    algo: str,
    lower_is_better: bool,
    path: Path,
    measure: str = "episode return",
    reached: np.ndarray | None = None,
    threshold_meaning: str = "",
    replays: dict[str, float] | None = None,
) -> None:
    """The learning curve: every training episode (a dot), the best so far (a step line), the episodes that reached
    the env's threshold (``reached``, large stars, the first one annotated) and the deterministic replays of the saved
    policies (``replays``: label -> value, dashed horizontal lines labelled with their value)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    episodes = np.arange(1, len(performance) + 1)
    fig, ax = plt.subplots(figsize=(9, 5.5))
    ax.plot(
        episodes, performance, "o-", color="tab:blue", lw=0.6, ms=4, alpha=0.6, label="training episode (with exploration)"
    )
    best = best_so_far(performance, lower_is_better)
    ax.step(  # constant from a new best's episode until the next one, to the right edge
        np.append(episodes, len(performance) + 0.5),
        np.append(best, best[-1]),
        where="post",
        color="tab:orange",
        lw=2.2,
        label="best registered performance so far",
    )
    if reached is not None and np.any(reached):
        hits = np.flatnonzero(reached)
        meaning = f" ({threshold_meaning})" if threshold_meaning else ""
        ax.plot(
            episodes[hits],
            performance[hits],
            "*",
            color="tab:green",
            ms=16,
            mec="black",
            mew=0.6,
            zorder=5,
            label=f"reached the threshold{meaning}: {len(hits)} episode{'s' if len(hits) > 1 else ''}",
        )
        first = hits[0]
        ax.annotate(
            f"first: episode {first + 1}, {performance[first]:.0f}",
            (episodes[first], performance[first]),
            xytext=(-10 if first + 1 > len(performance) / 2 else 10, -14 if lower_is_better else 10),
            textcoords="offset points",
            ha="right" if first + 1 > len(performance) / 2 else "left",
            color="tab:green",
            fontweight="bold",
        )
    lines = []
    for (label, value), color in zip((replays or {}).items(), ("tab:red", "tab:purple"), strict=False):
        if np.isfinite(value):
            ax.axhline(value, ls="--", color=color, lw=1.5, label=f"{label}: {value:.1f}")
            lines.append(("final" if "model.zip" in label and "best" not in label else "best", value, color))
    ax.margins(y=0.08)
    low, high = ax.get_ylim()
    for text, value, color, offset in replay_labels(lines, high - low):
        ax.annotate(
            f" {text}",
            (1.0, value),
            xycoords=("axes fraction", "data"),
            xytext=(0, offset),
            textcoords="offset points",
            color=color,
            va="center",
            fontsize=8,
            annotation_clip=False,
        )
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlim(0.5, len(performance) + 0.5)
    ax.set_xlabel("training episode")
    ax.set_ylabel(f"{measure}\n({'lower' if lower_is_better else 'higher'} is better)")
    ax.set_title(f"{algo.upper()} on {env_id}: {len(performance)} training episodes")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def replay_labels(lines: list[tuple[str, float, str]], span: float) -> list[tuple[str, float, str, float]]:
    """The labels at the right edge of the replay lines ``(name, value, colour)``: ``(text, value, colour, vertical
    offset in points)``. Two values that print the same share one label ("final = best 500"); two within 4% of the
    axis' ``span`` are moved apart, the higher up, so that their labels do not overlap."""
    if len(lines) == 2 and f"{lines[0][1]:.0f}" == f"{lines[1][1]:.0f}":
        (name, value, _), (other, _, color) = lines  # the colour of the line drawn last, on top
        return [(f"{name} = {other} {value:.0f}", value, color, 0.0)]
    labels = [(f"{name} {value:.0f}", value, color, 0.0) for name, value, color in lines]
    if len(labels) == 2 and abs(labels[0][1] - labels[1][1]) < 0.04 * span:
        up = 0 if labels[0][1] >= labels[1][1] else 1
        labels = [(text, value, color, 5.0 if i == up else -5.0) for i, (text, value, color, _) in enumerate(labels)]
    return labels


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
    parser = argparse.ArgumentParser(
        prog="python -m sb3_denfac.quickstart",
        description="Train an algorithm (DENFAC by default) on an environment with its zoo hyperparameters "
        "(hyperparams/<algo>.yml: the paper's values on the paper's envs), then print how the final and the best "
        "policy perform and where the learning curve, the TensorBoard logs and the saved models are.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    parser.add_argument(
        "--algo", default="denfac", choices=[*zoo_config.ALGORITHMS, "td3", "sac", "crossq"], help="the algorithm"
    )
    parser.add_argument(
        "--env",
        default="sb3_denfac/ContinuousAcrobot-v0",
        help="a Gymnasium id with a continuous (Box) action space: one of this package's "
        f"({', '.join(ALL_ENV_IDS)}) or any other, e.g. Pendulum-v1",
    )
    parser.add_argument("--episodes", type=int, default=50, help="training budget in episodes")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the model and the env")
    parser.add_argument("--log-dir", type=Path, default=Path("runs/quickstart"), help="where the run's folder is written")
    parser.add_argument("--progress-bar", action="store_true", help="show a progress bar over the episodes")
    parser.add_argument("--threads", type=int, default=1, help="torch threads while training (tiny networks: 1 is fastest)")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")
    try:  # before anything is written
        zoo_config.register()
        zoo_config.check_env_id(args.env)
        hyperparams = load_hyperparams(args.algo, args.env)  # the package's zoo YAML (the paper's Figure 5 values)
    except zoo_config.ZooConfigError as error:
        parser.exit(2, f"{parser.prog}: error: {error}\n")
    if args.threads < 1:
        parser.error("--threads must be at least 1")

    run_dir = args.log_dir / f"{args.algo}_{args.env.replace('/', '-')}_seed{args.seed}"
    run_dir.mkdir(parents=True, exist_ok=True)
    model = zoo_config.make_model(  # built as the RL Zoo builds it
        args.algo, args.env, hyperparams, seed=args.seed, monitor_dir=run_dir, tensorboard_log=str(run_dir / "tensorboard")
    )
    if hasattr(model, "torch_threads"):  # this package's algorithms: torch threads inside learn() (common/threads.py)
        model.torch_threads = args.threads
    facts = env_facts(args.env)
    lower = facts.lower_is_better
    # Counts episodes, stops after the budget and saves the policy of each new best episode.
    episodes = EpisodePerformanceCallback(args.episodes, lower_is_better=lower, best_model_path=str(run_dir / "best_model"))
    callbacks = [episodes, *([ProgressBarCallback(max_episodes=args.episodes)] if args.progress_bar else [])]
    max_steps = gym.spec(args.env).max_episode_steps or 1000
    start = time.time()
    if hasattr(model, "torch_threads"):
        model.learn(total_timesteps=args.episodes * max_steps, callback=callbacks, tb_log_name=args.algo.upper())
    else:  # SB3's algorithms: the same threads, the caller's setting restored after
        with torch_threads(args.threads):
            model.learn(total_timesteps=args.episodes * max_steps, callback=callbacks, tb_log_name=args.algo.upper())
    wall = time.time() - start
    model.save(run_dir / "model.zip")
    model.get_env().close()

    monitor = load_results(str(run_dir))
    has_measure = PAPER_PERFORMANCE_KEY in monitor.columns
    performance = monitor[PAPER_PERFORMANCE_KEY if has_measure else "r"].to_numpy(dtype=float)
    measure = ("steps to goal" if lower else "paper performance") if has_measure else "episode return"

    best = best_so_far(performance, lower)[-1]
    best_episode = int(np.flatnonzero(performance == best)[0]) + 1
    final = evaluate(model, args.env, args.seed + 1000)
    best_model = type(model).load(run_dir / "best_model.zip", device="cpu")
    best_eval = evaluate(best_model, args.env, args.seed + 1000)
    replays = {
        "final policy, deterministic (model.zip)": final,
        f"best episode's policy, deterministic (best_model.zip, episode {best_episode})": best_eval,
    }
    reached = np.array([facts.reached(value) for value in performance], dtype=bool)
    plot_learning_curve(
        performance,
        args.env,
        args.algo,
        lower,
        run_dir / "learning_curve.png",
        measure,
        reached,
        facts.threshold_meaning,
        replays,
    )
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
