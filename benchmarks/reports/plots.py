"""Plots of the sweep: best-so-far curves (the paper's Figure 3 layout), the data-efficiency vs compute trade-off, and
rliable's performance profile."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.runner.algos import ALGOS
from sb3_denfac.envs.facts import env_facts


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _color(algo: str):
    import matplotlib.pyplot as plt

    return plt.get_cmap("tab10")(list(ALGOS).index(algo) % 10 if algo in ALGOS else 9)


def _label(algo: str, n: int) -> str:
    return f"{ALGOS[algo].label if algo in ALGOS else algo} (n={n})"


def curves(episodes: pd.DataFrame, envs: list[str], algos: list[str], path: Path) -> None:
    """Per env: median and quartiles of the best-so-far (top row) and of the 10-episode running mean of the exploring
    policy's measure (bottom row), against episodes."""
    plt = _plt()
    fig, axes = plt.subplots(2, len(envs), figsize=(4.6 * len(envs), 7.4), squeeze=False)
    for col, env in enumerate(envs):
        facts = env_facts(env)
        for algo in algos:
            mine = episodes[(episodes["env"] == env) & (episodes["algo"] == algo)]
            if mine.empty:
                continue
            n = mine["seed"].nunique()
            running = mine.groupby("seed")["performance"].transform(lambda s: s.rolling(10, min_periods=1).mean())
            for row, values in enumerate((mine["best_so_far"], running)):
                q = values.groupby(mine["episode"]).quantile([0.25, 0.5, 0.75]).unstack()
                ax = axes[row, col]
                ax.plot(
                    q.index, q[0.5], color=_color(algo), lw=2.0 if algo.startswith("denfac") else 1.2, label=_label(algo, n)
                )
                ax.fill_between(q.index, q[0.25], q[0.75], color=_color(algo), alpha=0.12, lw=0)
        for row, what in enumerate(("best so far", "mean of the last 10 episodes")):
            ax = axes[row, col]
            if facts.threshold is not None:
                ax.axhline(facts.threshold, color="grey", ls=":", lw=1)
            ax.set_title(f"{facts.label}: {what}", fontsize=9)
            ax.set_xlabel("episode")
            ax.grid(alpha=0.3)
        axes[0, col].legend(fontsize=7)
    fig.suptitle("Median and quartiles over seeds: best registered performance (top), exploring policy (bottom)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def compute_tradeoff(episodes: pd.DataFrame, envs: list[str], algos: list[str], path: Path) -> None:
    """Per env: median best-so-far against the median cumulative training CPU seconds at each episode (log scale)."""
    plt = _plt()
    fig, axes = plt.subplots(1, len(envs), figsize=(4.6 * len(envs), 3.9), squeeze=False)
    for ax, env in zip(axes[0], envs, strict=True):
        for algo in algos:
            mine = episodes[(episodes["env"] == env) & (episodes["algo"] == algo)]
            if mine.empty:
                continue
            by_episode = mine.groupby("episode")[["best_so_far", "cpu_time"]].median()
            ax.plot(by_episode["cpu_time"].clip(lower=1e-2), by_episode["best_so_far"], color=_color(algo),
                    label=_label(algo, mine["seed"].nunique()), drawstyle="steps-post")  # fmt: skip
            last = by_episode.iloc[-1]
            ax.plot([max(last["cpu_time"], 1e-2)], [last["best_so_far"]], "o", color=_color(algo), ms=4)
        ax.set_xscale("log")
        ax.set_title(env_facts(env).label, fontsize=9)
        ax.set_xlabel("training CPU seconds (median over seeds, log)")
        ax.set_ylabel("best so far (median)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle("Data efficiency against compute: median run per algorithm, a dot at its budget", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def performance_profile(scores: dict[str, np.ndarray], path: Path, title: str, reps: int) -> None:
    """rliable's performance profile (fraction of runs with normalised score > tau) of ``{algo: (runs, envs)}``."""
    from rliable import library as rly
    from rliable import plot_utils

    plt = _plt()
    scores = {ALGOS[a].label if a in ALGOS else a: s for a, s in scores.items() if s.size}
    if not scores:
        return
    taus = np.linspace(0.0, 1.0, 21)
    profiles, cis = rly.create_performance_profile(scores, taus, reps=reps)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    colors = {k: _color(a) for a in ALGOS for k in scores if k == ALGOS[a].label}
    plot_utils.plot_performance_profiles(profiles, taus, performance_profile_cis=cis, colors=colors, ax=ax,
                                         xlabel=r"normalised score $\tau$")  # fmt: skip
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
