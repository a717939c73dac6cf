"""Soak: a long DENFAC run, watching the process memory and the update time per episode for growth.

    python -m benchmarks.studies.soak [--episodes 1000] [--env Pendulum-v1] [--output benchmarks/results/soak]

Trains the default ``DENFAC("MlpPolicy", env)`` for ``--episodes`` episodes and records, per episode, the process's
resident memory (``/proc/self/statm``, no psutil) at the episode's end and the wall time of the update that follows it
(``DENFAC.train``). The replay buffer's arrays are allocated at construction, but the OS maps their pages as they are
first written, and the update's working tensors grow with the transitions in D: memory and update time may grow until
D is full (Pendulum, D = 100 000: episode 500; ``--buffer-size`` reaches that state sooner), and growth after that
would be a leak.
Writes ``soak.json`` (every episode, the summary, commit, machine, load) and ``soak.md`` (the summary) to ``--output``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

PAGE_SIZE = os.sysconf("SC_PAGE_SIZE")


def rss_mib() -> float:
    """The process's resident set size in MiB, from /proc/self/statm (second field: resident pages)."""
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * PAGE_SIZE / 2**20


def _slope(values: list[float]) -> float:
    """Least-squares slope per episode (NaN for fewer than 2 values)."""
    if len(values) < 2:
        return float("nan")
    return float(np.polyfit(np.arange(len(values)), np.asarray(values, dtype=float), 1)[0])


def summarise(rss: list[float], update_s: list[float], window: int = 100) -> dict[str, Any]:
    """Medians of the first and last ``window`` episodes (a tenth of the run, at least 1, when it is shorter than
    2 windows) and the slopes over the whole run and its second half."""
    n = len(rss)
    w = window if n >= 2 * window else max(1, n // 10)
    half = n // 2
    return {
        "episodes": n,
        "window": w,
        "rss_mib_median_first": statistics.median(rss[:w]),
        "rss_mib_median_last": statistics.median(rss[-w:]),
        "rss_mib_slope_per_episode": _slope(rss),
        "rss_mib_slope_per_episode_second_half": _slope(rss[half:]),
        "update_s_median_first": statistics.median(update_s[:w]) if update_s else float("nan"),
        "update_s_median_last": statistics.median(update_s[-w:]) if update_s else float("nan"),
        "update_s_slope_per_episode": _slope(update_s),
        "update_s_slope_per_episode_second_half": _slope(update_s[len(update_s) // 2 :]),
    }


def run(episodes: int, env_id: str, seed: int, buffer_size: int | None = None) -> dict[str, Any]:
    import gymnasium as gym
    from stable_baselines3.common.callbacks import BaseCallback

    from sb3_denfac import DENFAC
    from sb3_denfac.common.callbacks import UpdateStatsCallback

    kwargs = {} if buffer_size is None else {"buffer_size": buffer_size}
    model = DENFAC("MlpPolicy", gym.make(env_id), seed=seed, **kwargs)
    update_s: list[float] = []
    rss: list[float] = []

    class EpisodeEnds(BaseCallback):
        """The resident memory at each episode's end."""

        def _on_step(self) -> bool:
            if self.locals["dones"][0]:
                rss.append(rss_mib())
                if len(rss) % 50 == 0:
                    print(f"episode {len(rss)}: rss {rss[-1]:.1f} MiB, last update {update_s[-1] if update_s else 0:.3f} s")
            return True

    update_times = UpdateStatsCallback(lambda stats: update_s.append(stats.seconds))  # each update's wall time
    start = time.perf_counter()
    max_steps = gym.spec(env_id).max_episode_steps or 1000
    # fixed-length episodes (Pendulum): exactly `episodes`
    model.learn(episodes * max_steps, callback=[EpisodeEnds(), update_times])
    return {"rss_mib": rss, "update_s": update_s[: len(rss)], "wall_s": time.perf_counter() - start}


def write_markdown(report: dict[str, Any], path: Path) -> None:
    s, git, machine, size = report["summary"], report["git"], report["machine"], report["buffer_size"]
    lines = [
        f"# Soak: DENFAC ({'defaults' if size is None else f'D = {size}'}) on {report['env']}, {s['episodes']} episodes",
        "",
        f"Written by `python -m benchmarks.studies.soak --episodes {report['requested_episodes']}"
        f"{'' if size is None else f' --buffer-size {size}'}`. Commit "
        f"`{git.get('commit', '?')}`{' (with uncommitted changes)' if git.get('modified') else ''}; machine: "
        f"{machine['cpu_model']}, {machine['nproc']} CPUs, torch {machine['torch']}; load average at start / end: "
        f"{', '.join(f'{x:.2f}' for x in report['loadavg_start'])} / {', '.join(f'{x:.2f}' for x in report['loadavg_end'])}; "
        f"wall time {report['wall_s']:.0f} s.",
        "",
        f"| measure | median, first {s['window']} episodes | median, last {s['window']} | slope per episode (all) | "
        "slope per episode (second half) |",
        "| --- | --- | --- | --- | --- |",
        f"| resident memory (MiB) | {s['rss_mib_median_first']:.1f} | {s['rss_mib_median_last']:.1f} | "
        f"{s['rss_mib_slope_per_episode']:.4f} | {s['rss_mib_slope_per_episode_second_half']:.4f} |",
        f"| update time (s) | {s['update_s_median_first']:.3f} | {s['update_s_median_last']:.3f} | "
        f"{s['update_s_slope_per_episode']:.5f} | {s['update_s_slope_per_episode_second_half']:.5f} |",
        "",
        "Memory and update time may grow while the replay buffer D fills (its pages are mapped as they are first written; "
        "the update's targets and weights are computed over all of D); growth once D is full would be a leak.",
        "",
    ]
    path.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--env", default="Pendulum-v1")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--buffer-size", type=int, default=None, help="D (default: DENFAC's); small: D full sooner")
    parser.add_argument("--output", type=Path, default=Path("benchmarks/results/soak"))
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be at least 1")

    from benchmarks.runner.task import git_state, machine_info

    load_start = os.getloadavg()
    result = run(args.episodes, args.env, args.seed, args.buffer_size)
    report = {
        "env": args.env,
        "requested_episodes": args.episodes,
        "seed": args.seed,
        "buffer_size": args.buffer_size,
        "summary": summarise(result["rss_mib"], result["update_s"]),
        "loadavg_start": load_start,
        "loadavg_end": os.getloadavg(),
        "git": git_state(),
        "machine": machine_info(),
        **result,
    }
    args.output.mkdir(parents=True, exist_ok=True)
    (args.output / "soak.json").write_text(json.dumps(report, indent=1) + "\n")
    write_markdown(report, args.output / "soak.md")
    print(json.dumps(report["summary"], indent=1))
    return report


if __name__ == "__main__":
    main()
