"""Data-efficiency benchmark: DENFAC on the paper's continuous CartPole (Figure 3, middle panel).

Runs DENFAC with the paper's Cartpole settings (Figure 5: K=10, G=25, D=3000, inverting gradients, no critic reset,
gamma=0.99, critic 50-7, actor 20) for several seeds and records, per episode, the paper's performance measure
(``info["paper_performance"]`` = episode return) and its best-so-far value (the paper's "best registered performance").
Writes ``benchmarks/results/denfac_cartpole.{json,csv,md,png}``: median and quartiles over seeds, and wall time.

Target (issue 3): the median seed reaches a best-so-far return >= -500 within 100 episodes.

Usage: ``python benchmarks/denfac_cartpole.py [--seeds 5] [--episodes 100] [--workers 2]``
"""

from __future__ import annotations

import argparse
import csv
import json
import multiprocessing as mp
import os
import platform
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
ENV_ID = "sb3_denfac/ContinuousCartPole-v0"
TARGET = -500.0

# Paper Figure 5 (Cartpole row) + section 4; learning rates: see the README of the results.
HYPERPARAMS = dict(
    buffer_size=3000,
    gamma=0.99,
    n_fitted_iterations=10,
    critic_steps=10,
    actor_steps=25,
    reset_critic=False,
    reset_actor=True,
    inverting_gradients=True,
    sigma=0.05,
    policy_kwargs=dict(net_arch=dict(pi=[20], qf=[50, 7])),
)


def run_seed(args: tuple[int, int, dict]) -> dict:
    seed, n_episodes, overrides = args
    import gymnasium as gym
    import torch as th

    import sb3_denfac  # noqa: F401  (registers the environments)
    from sb3_denfac.denfac import DENFAC

    th.set_num_threads(1)
    env = gym.make(ENV_ID)
    model = DENFAC("MlpPolicy", env, seed=seed, **{**HYPERPARAMS, **overrides})
    performances: list[float] = []
    update_times: list[float] = []

    from stable_baselines3.common.callbacks import BaseCallback

    class Record(BaseCallback):
        def _on_rollout_start(self) -> None:  # after the update of the previous episode
            if "train/update_time" in self.logger.name_to_value:
                update_times.append(float(self.logger.name_to_value.pop("train/update_time")))

        def _on_step(self) -> bool:
            for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
                if done:
                    performances.append(float(info["paper_performance"]))
            return len(performances) < n_episodes

    start = time.perf_counter()
    model.learn(10**9, callback=Record(), log_interval=10**9)
    wall = time.perf_counter() - start
    return dict(
        seed=seed,
        performance=performances[:n_episodes],
        wall_time_s=wall,
        timesteps=model.num_timesteps,
        n_updates=model._n_updates,
        update_time_median_s=float(np.median(update_times)) if update_times else None,
    )


def summarise(runs: list[dict], n_episodes: int) -> dict:
    perf = np.array([r["performance"] for r in runs])
    best = np.maximum.accumulate(perf, axis=1)
    q1, med, q3 = np.percentile(best, [25, 50, 75], axis=0)
    reached = np.nonzero(med >= TARGET)[0]
    return dict(
        episodes=list(range(1, n_episodes + 1)),
        best_so_far_median=med.tolist(),
        best_so_far_q1=q1.tolist(),
        best_so_far_q3=q3.tolist(),
        final_best_per_seed=best[:, -1].tolist(),
        median_reaches_target_at_episode=int(reached[0] + 1) if len(reached) else None,
        target=TARGET,
        target_met=bool(len(reached)),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--tag", default="", help="suffix of the result files, e.g. _fast")
    parser.add_argument("--params", default="{}", help='JSON dict of DENFAC overrides, e.g. \'{"update_path": "plain"}\'')
    args = parser.parse_args()
    overrides = json.loads(args.params)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    start = time.perf_counter()
    jobs = [(seed, args.episodes, overrides) for seed in range(args.seeds)]
    with mp.get_context("spawn").Pool(args.workers) as pool:
        runs = pool.map(run_seed, jobs)
    total = time.perf_counter() - start
    summary = summarise(runs, args.episodes)
    RESULTS.mkdir(parents=True, exist_ok=True)
    stem = RESULTS / f"denfac_cartpole{args.tag}"
    meta = dict(
        env=ENV_ID,
        hyperparams={**HYPERPARAMS, **overrides},
        seeds=args.seeds,
        episodes=args.episodes,
        workers=args.workers,
        total_wall_time_s=total,
        machine=f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores (shared)",
    )
    stem.with_suffix(".json").write_text(json.dumps(dict(meta=meta, summary=summary, runs=runs), indent=1))
    with stem.with_suffix(".csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["seed", "episode", "performance", "best_so_far"])
        for run in runs:
            best = np.maximum.accumulate(run["performance"])
            for i, (p, b) in enumerate(zip(run["performance"], best, strict=True)):
                writer.writerow([run["seed"], i + 1, p, b])
    rows = [
        f"| {e} | {summary['best_so_far_median'][e - 1]:.0f} | {summary['best_so_far_q1'][e - 1]:.0f} | "
        f"{summary['best_so_far_q3'][e - 1]:.0f} |"
        for e in (1, 10, 20, 30, 50, 75, 100)
        if e <= args.episodes
    ]
    walls = [r["wall_time_s"] for r in runs]
    md = [
        f"# DENFAC on {ENV_ID}",
        "",
        f"{args.seeds} seeds x {args.episodes} episodes, paper Figure 5 Cartpole settings; overrides: {overrides or 'none'}.",
        "Measure: best-so-far episode return (paper_performance), median and quartiles over seeds.",
        "",
        "| episode | median | Q1 | Q3 |",
        "|---|---|---|---|",
        *rows,
        "",
        f"Target: median best-so-far >= {TARGET:.0f} within 100 episodes -> "
        f"{'MET at episode ' + str(summary['median_reaches_target_at_episode']) if summary['target_met'] else 'NOT met'}.",
        f"Final best per seed: {[round(v) for v in summary['final_best_per_seed']]}.",
        f"Wall time per seed: median {np.median(walls):.0f} s (min {min(walls):.0f}, max {max(walls):.0f}); "
        f"total {total:.0f} s with {args.workers} workers on {meta['machine']}.",
    ]
    stem.with_suffix(".md").write_text("\n".join(md) + "\n")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        x = summary["episodes"]
        ax.plot(x, summary["best_so_far_median"], label="DENFAC median")
        ax.fill_between(x, summary["best_so_far_q1"], summary["best_so_far_q3"], alpha=0.3, label="Q1-Q3")
        ax.axhline(TARGET, color="grey", ls="--", lw=1, label="target")
        ax.set_xlabel("episode")
        ax.set_ylabel("best-so-far return")
        ax.set_title(f"DENFAC, {ENV_ID} ({args.seeds} seeds)")
        ax.legend()
        fig.tight_layout()
        fig.savefig(stem.with_suffix(".png"), dpi=100)
    except ImportError:
        pass
    print("\n".join(md))


if __name__ == "__main__":
    main()
